"""Arrays keep their shape through the rumoca front end: matrices in equations and functions
(transpose, products, 2-D subscripts, arrays filled element by element), checked against numpy;
and a MultiBody pendulum (3x3 orientation matrices in every frame) against its own ODE."""
from pathlib import Path

import numpy as np
import pytest

import mcl
from mcl.data import TimeSeries

MSL = Path(__file__).resolve().parents[2] / "shared" / "msl"

MATRICES = """
function g
  input Real A[3,3];
  input Real v[3];
  output Real w[3];
protected
  Real B[2,3];
algorithm
  for i in 1:2 loop
    for j in 1:3 loop
      B[i,j] := A[i,j] + i;
    end for;
  end for;
  w := transpose(A)*v + A*v .* v + (v*v)*v + v*A;
  w[1] := w[1] + A[2,3] + sum(A[:,1]) + sum(A[2,:]) + B[2,1];
end g;

model Matrices
  parameter Real A[3,3] = [1,2,3;4,5,6;7,8,10];
  parameter Real C[2,2] = {{1,2},{3,4}};
  Real v[3](each start=1, each fixed=true);
  output Real w[3] = g(A, {1.0,2.0,3.0});
  output Real q = C[1,2] + identity(3)*v*v + C[2,:]*{1.0,1.0};
  output Real s = (transpose(C)*C)[1,2] + skew({1.0,2.0,3.0})[1,2];
equation
  der(v) = -g(A, v)*1e-3;
end Matrices;
"""


def test_matrix_expressions_and_functions_follow_modelica(tmp_path):
    src = tmp_path / "Matrices.mo"
    src.write_text(MATRICES)
    model = mcl.compile_model([src], "Matrices")
    t = np.array([0.0, 1.0])
    res = mcl.simulate(model, TimeSeries(t, np.zeros((2, 0)), []), t_out=t)
    assert res.ok, res.reason
    out = dict(zip(res.output_names, res.outputs[0]))

    A, v, C = np.array([[1, 2, 3], [4, 5, 6], [7, 8, 10.0]]), np.array([1, 2, 3.0]), np.array([[1, 2], [3, 4.0]])
    w = A.T @ v + (A @ v) * v + (v @ v) * v + v @ A
    w[0] += A[1, 2] + A[:, 0].sum() + A[1, :].sum() + (A[1, 0] + 2)
    np.testing.assert_allclose([out[f"w[{k}]"] for k in (1, 2, 3)], w, rtol=1e-12)
    assert out["q"] == pytest.approx(C[0, 1] + 3 + C[1].sum())       # v(0) = ones: v*v = 3
    assert out["s"] == pytest.approx((C.T @ C)[0, 1] - 3)


@pytest.mark.slow
@pytest.mark.skipif(not (MSL / "Modelica" / "package.mo").is_file(), reason=f"the MSL is not at {MSL}")
def test_a_multibody_pendulum_swings_like_its_ode(monkeypatch):
    from scipy.integrate import solve_ivp

    monkeypatch.setenv("MODELICAPATH", str(MSL))
    model = mcl.compile_model([], "Modelica.Mechanics.MultiBody.Examples.Elementary.Pendulum")
    t = np.linspace(0.0, 3.0, 301)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    phi = res.states[:, model.ode.x_names.index("rev.phi")]
    # the example: a 1 kg body 0.5 m from a revolute joint (axis z, damping 0.1 N.m.s/rad),
    # gravity 9.81 along -y, started at rest horizontally; the body's own inertia is 0.001
    J = 1.0 * 0.5 ** 2 + 0.001
    ref = solve_ivp(lambda _t, y: [y[1], (-9.81 * 0.5 * np.cos(y[0]) - 0.1 * y[1]) / J], (0, 3), [0, 0],
                    t_eval=t, rtol=1e-10, atol=1e-12).y[0]
    assert np.abs(phi - ref).max() < 2e-3 * np.ptp(ref)


INTERPOLATE = """
model Interp
  parameter Real one[1, 2] = [0, 0.5];
  parameter Real three[3, 2] = [0, 0; 1, 1; 2, 4];
  output Real a = Modelica.Math.Vectors.interpolate(one[:, 1], one[:, 2], time, 1);
  output Real b = Modelica.Math.Vectors.interpolate(three[:, 1], three[:, 2], time, 1);
end Interp;
"""


@pytest.mark.skipif(not (MSL / "Modelica" / "package.mo").is_file(), reason=f"the MSL is not at {MSL}")
def test_msl_interpolation_of_one_and_many_rows(tmp_path, monkeypatch):
    """rumoca refuses the MSL's Vectors.interpolate on a one-row table (the friction elements'
    default); mcl's overlay of the library's search compiles it, with the same values."""
    monkeypatch.setenv("MODELICAPATH", str(MSL))
    src = tmp_path / "Interp.mo"
    src.write_text(INTERPOLATE)
    model = mcl.compile_model([src], "Interp")
    t = np.array([0.0, 0.5, 1.5, 2.5])
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    np.testing.assert_allclose(res.output("a"), 0.5)
    np.testing.assert_allclose(res.output("b"), [0.0, 0.5, 2.5, 5.5])     # extrapolated past x = 2


def test_an_overlay_rewrites_only_the_text_it_was_written_for(tmp_path):
    from mcl.compile.overlays import REWRITES
    from mcl.compile.subset import link_whole

    (old, new), = REWRITES[("Modelica", ("Math", "package.mo"))]
    lib = tmp_path / "lib" / "Modelica"
    (lib / "Math").mkdir(parents=True)
    (lib / "Blocks").mkdir()
    (lib / "package.mo").write_text("package Modelica end Modelica;\n")
    (lib / "Math" / "package.mo").write_text("head\n" + old + "tail\n")
    (lib / "Math" / "Other.mo").write_text("x\n")
    (tmp_path / "root").mkdir()
    root = tmp_path / "root" / "Modelica"
    link_whole(root, lib)
    written = (root / "Math" / "package.mo")
    assert not written.is_symlink() and written.read_text() == "head\n" + new + "tail\n"
    assert (root / "Math" / "Other.mo").is_symlink() and (root / "Blocks").is_symlink()
    assert (lib / "Math" / "package.mo").read_text() == "head\n" + old + "tail\n"     # the library untouched
    # another version's text: the whole library is one link
    (lib / "Math" / "package.mo").write_text("head\n" + old.replace("iLast", "iFirst") + "tail\n")
    (tmp_path / "again").mkdir()
    link_whole(tmp_path / "again" / "Modelica", lib)
    assert (tmp_path / "again" / "Modelica").is_symlink()


@pytest.mark.slow
@pytest.mark.skipif(not (MSL / "Modelica" / "package.mo").is_file(), reason=f"the MSL is not at {MSL}")
def test_a_clutch_and_a_brake_stick_and_slip(monkeypatch):
    """The MSL's Rotational Friction example: a clutch (J3 = 1, its friction torque
    cgeo*fn_max*mu = 1*160*0.5 = 80 N.m) slips while the brake holds the rest of the drive,
    then sticks. Its event iteration settles only when the discrete values are taken one at a
    time (updated all at once, locked and startForward swing between two sets)."""
    monkeypatch.setenv("MODELICAPATH", str(MSL))
    model = mcl.compile_model([], "Modelica.Mechanics.Rotational.Examples.Friction")
    t = np.linspace(0.0, 3.0, 301)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    w = {n: res.states[:, model.ode.x_names.index(n)] for n in ("inertia1.w", "inertia2.w", "inertia3.w")}
    slip = (t >= 0.8) & (t <= 1.4)
    assert np.polyfit(t[slip], w["inertia3.w"][slip], 1)[0] == pytest.approx(-80.0, rel=5e-3)
    assert np.abs(w["inertia1.w"][t >= 0.8]).max() < 1e-6          # braked
    late = t >= 2.0
    assert np.abs(w["inertia3.w"][late] - w["inertia2.w"][late]).max() < 1e-6    # the clutch sticks


@pytest.mark.slow
@pytest.mark.skipif(not (MSL / "Modelica" / "package.mo").is_file(), reason=f"the MSL is not at {MSL}")
def test_massless_pipes_at_zero_flow_keep_a_temperature(monkeypatch):
    """FluidHeatFlow's TwoMass: a pump started from zero flow through massless pipes. At zero
    flow a junction's enthalpy is multiplied only by flows (semiLinear), so its linear block is
    singular; mcl keeps its start value there instead of dividing 0 by 0 (rumoca's own
    simulator fails on it). The two masses then cool towards the ambient, never past it."""
    monkeypatch.setenv("MODELICAPATH", str(MSL))
    model = mcl.compile_model([], "Modelica.Thermal.FluidHeatFlow.Examples.TwoMass")
    t = np.linspace(0.0, 1.5, 151)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    for name, start in (("heatCapacitor1.T", 313.15), ("heatCapacitor2.T", 333.15)):
        T = res.states[:, model.ode.x_names.index(name)]
        assert T[0] == pytest.approx(start)
        assert np.all((T > 293.15) & (T <= start + 1e-9))
        assert T[-1] < start - 0.8 * (start - 293.15)


VECTORISED = """
function sq "a function of scalars"
  input Real x;
  input Real c;
  output Real y;
algorithm
  y := x*x + c;
end sq;

model Vectorised
  parameter Real v[2] = {2.0, 4.0};
  Real s[2](each start = 1.0, each fixed = true);
  output Real y[3] = sq({1.0, 2.0, 3.0}, 1.0);
  output Real w[2] = sq(v, 0.5);
equation
  der(s) = -sq(s, 0.0);     // each s' = -s^2: s(t) = 1/(1 + t)
end Vectorised;
"""


def test_a_function_of_scalars_called_on_a_vector_applies_to_each_element(tmp_path):
    """Modelica's vectorised call: f(v) is {f(v[i])} (rumoca writes it as a comprehension;
    inside f, x*x of a vector would be a scalar product)."""
    (tmp_path / "Vectorised.mo").write_text(VECTORISED)
    model = mcl.compile_model([tmp_path / "Vectorised.mo"], "Vectorised")
    t = np.array([0.0, 1.0])
    res = mcl.simulate(model, TimeSeries(t, np.zeros((2, 0)), []), t_out=t)
    assert res.ok, res.reason
    out = dict(zip(res.output_names, res.outputs[0]))
    np.testing.assert_allclose([out[f"y[{k}]"] for k in (1, 2, 3)], [2.0, 5.0, 10.0])
    np.testing.assert_allclose([out["w[1]"], out["w[2]"]], [4.5, 16.5])
    np.testing.assert_allclose(res.states[-1], [0.5, 0.5], rtol=1e-5)



DILUTION = """
model Dilution "n well-mixed tanks flushed with fresh water carrying nC substances"
  model Probe "a sampling point"
    parameter Integer nC = 1;
    Real c[nC];
  end Probe;
  parameter Integer n = 2;
  parameter Integer nC = 1;
  parameter Real q[n] = {1, 2} "flushing rates (1/s)";
  parameter Real c_in[nC] = fill(3, nC);
  Real c[n, nC](each start = 0, each fixed = true);
  Real inflow[n, nC];
  Probe probes[n](each nC = nC);
equation
  for i in 1:n loop
    inflow[i, :] = q[i]*c_in;
    der(c[i, :]) = inflow[i, :] - q[i]*c[i, :];
    probes[i].c = c[i, :];
  end for;
end Dilution;

model TwoSubstances
  extends Dilution(nC = 2, c_in = {3, 5});
end TwoSubstances;
"""


@pytest.mark.parametrize("name, c_in", [("Dilution", [3.0]), ("TwoSubstances", [3.0, 5.0])])
def test_for_equations_on_rows_of_one_element_or_more(tmp_path, name, c_in):
    """Array equations in a for-loop (rows of a matrix, a component's array member), whose
    arrays have one element (which rumoca refuses as written: written element by element) or
    two: each tank's concentration approaches the inflow's as c_in (1 - exp(-q t))."""
    (tmp_path / "Dilution.mo").write_text(DILUTION)
    probes = [f"probes[{i}].c[{k}]" for i in (1, 2) for k in range(1, len(c_in) + 1)]
    model = mcl.compile_model([tmp_path / "Dilution.mo"], name).with_outputs(probes)
    t = np.linspace(0.0, 2.0, 5)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    for i, q in ((1, 1.0), (2, 2.0)):
        for k, c in enumerate(c_in, start=1):
            expected = c * (1 - np.exp(-q * t))
            np.testing.assert_allclose(res.states[:, model.ode.x_names.index(f"c[{i},{k}]")], expected, atol=1e-5 * c)
            np.testing.assert_allclose(res.output(f"probes[{i}].c[{k}]"), expected, atol=1e-5 * c)
