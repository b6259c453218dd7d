"""Hidden constraints: equations matched one to one with their unknowns whose sum cancels them
all (Kirchhoff's law around a floating island leaves a constraint on the chokes' currents).
Pantelides' algorithm cannot see them; mcl finds them numerically and index reduction then
differentiates them. Without that the island's potentials come from a singular solve."""
import numpy as np

from helpers import msl_path, needs_msl, unforced_run
from mcl import compile_model
from mcl.compile.dae import eliminate_aliases
from mcl.compile.hidden import revealed

SERIES = """
model Series "two chokes in series through a floating pair of resistors"
  parameter Real V = 10, L1 = 0.1, L2 = 0.3, R1 = 2, R2 = 3;
  Real i1(start = 0, fixed = true), i2(start = 0), va, vb, iR1, iR2;
  output Real i = i1;
equation
  L1*der(i1) = V - va;
  L2*der(i2) = vb;
  R1*iR1 = va - vb;
  R2*iR2 = va - vb;
  i1 = iR1 + iR2;
  iR1 + iR2 = i2;
end Series;
"""

RECTIFIER = """
model {name} "grid, chokes, a diode bridge and the DC link it feeds"
  import Modelica.Electrical.Polyphase;
  import Modelica.Electrical.Analog;
  import Modelica.Electrical.PowerConverters;
  constant Integer m = 3;
  Polyphase.Sources.SineVoltage grid(m = m, V = fill(400*sqrt(2/3), m), f = fill(50, m),
    phase = -Modelica.Electrical.Polyphase.Functions.symmetricOrientation(m));
  Polyphase.Basic.Star star(m = m);
  Analog.Basic.Ground ground;
  Polyphase.Basic.Resistor resistor(m = m, R = fill(10e-3, m));
  Polyphase.Basic.Inductor choke(m = m, L = fill(500e-6, m));
  PowerConverters.ACDC.DiodeBridge2mPulse rectifier(m = m);
  Analog.Basic.Capacitor link(C = 5e-3, v(fixed = true, start = 560));
  Analog.Basic.Resistor load(R = 10);
  {extra}
equation
  connect(star.pin_n, ground.p);
  connect(star.plug_p, grid.plug_n);
  connect(grid.plug_p, resistor.plug_p);
  connect(resistor.plug_n, choke.plug_p);
  connect(choke.plug_n, rectifier.ac);
  connect(rectifier.dc_p, link.p);
  connect(rectifier.dc_n, link.n);
  connect(link.p, load.p);
  connect(link.n, load.n);
  {connect}
end {name};
"""

WINDING = """
model Winding5 "a five-phase fundamental-wave winding in star (its star point floating), beside the inductors it equals"
  import Modelica.Electrical.Polyphase;
  import Modelica.Electrical.Analog;
  import Modelica.Magnetic.FundamentalWave;
  parameter Integer m = 5;
  parameter Real N = 5 "effective turns";
  parameter Modelica.Units.SI.Inductance L = 0.05 "main inductance per phase";
  parameter Modelica.Units.SI.Inductance Lsigma = 0.005;
  Polyphase.Sources.SineVoltage source(m = m, V = fill(100, m), f = fill(50, m),
    phase = -Polyphase.Functions.symmetricOrientation(m));
  Polyphase.Basic.Star sourceStar(m = m);
  Analog.Basic.Ground ground;
  FundamentalWave.BasicMachines.Components.SymmetricPolyphaseWinding winding(m = m, RRef = 1,
    TRef = 293.15, TOperational = 293.15, Lsigma = Lsigma, Lzero = Lsigma, effectiveTurns = N, GcRef = 0);
  Polyphase.Basic.Star windingStar(m = m);
  FundamentalWave.Components.Reluctance core(R_m(d = m*N^2/2/L, q = m*N^2/2/L));
  FundamentalWave.Components.Ground magneticGround;
  Polyphase.Basic.Resistor resistor(m = m, R = fill(1, m));
  Polyphase.Basic.Inductor inductor(m = m, L = fill(L + Lsigma, m));
  Polyphase.Basic.Star inductorStar(m = m);
initial equation
  winding.electroMagneticConverter.Phi = Complex(0, 0);
  inductor.i[1:m-1] = zeros(m-1);
equation
  connect(source.plug_n, sourceStar.plug_p);
  connect(sourceStar.pin_n, ground.p);
  connect(source.plug_p, winding.plug_p);
  connect(winding.plug_n, windingStar.plug_p);
  connect(winding.port_p, core.port_p);
  connect(core.port_n, winding.port_n);
  connect(winding.port_n, magneticGround.port_p);
  connect(source.plug_p, resistor.plug_p);
  connect(resistor.plug_n, inductor.plug_p);
  connect(inductor.plug_n, inductorStar.plug_p);
end Winding5;
"""

WATCHED = ["link.v", "choke.inductor[1].i", "choke.inductor[2].i", "choke.inductor[3].i"]


def test_chokes_in_series_through_a_floating_pair_follow_the_series_circuit(tmp_path):
    (tmp_path / "Series.mo").write_text(SERIES)
    model = compile_model([tmp_path / "Series.mo"], "Series")
    assert model.ode.index == 2          # the hidden i1 = i2, differentiated
    t, res = unforced_run(model, 1.0, 101)
    R = 2 * 3 / 5                        # i(t) of L1 + L2 in series with R1 || R2
    assert np.max(np.abs(res.output("i") - 10 / R * (1 - np.exp(-t * R / 0.4)))) < 1e-5


def test_a_regular_model_is_left_as_it_is(tmp_path):
    (tmp_path / "Series.mo").write_text(SERIES.replace("  iR1 + iR2 = i2;", "  vb = 0.5*i2;"))
    dae = eliminate_aliases(compile_model([tmp_path / "Series.mo"], "Series").dae)
    assert revealed(dae) is dae


@needs_msl()
def test_a_floating_dc_link_behind_a_diode_bridge_runs_as_one_grounded_through_a_megohm(tmp_path):
    """The link floats (as in the MSL's inverter drive): its potential is fixed only through
    the sum of the chokes' currents. Grounded through 1 MOhm it is a regular circuit whose
    leak changes nothing visible: the two must agree."""
    runs = {}
    for name, extra, link in (("Floating", "", ""),
                              ("Grounded", "Analog.Basic.Resistor leak(R = 1e6); Analog.Basic.Ground g2;",
                               "connect(link.n, leak.p); connect(leak.n, g2.p);")):
        (tmp_path / f"{name}.mo").write_text(RECTIFIER.format(name=name, extra=extra, connect=link))
        model = compile_model([tmp_path / f"{name}.mo"], name, libraries=[msl_path()])
        dae = eliminate_aliases(model.dae)
        model = model.with_outputs(WATCHED)
        assert (revealed(dae) is dae) == (name == "Grounded")
        runs[name] = unforced_run(model, 0.06, 201)[1]
    for var in WATCHED:
        a, b = (runs[k].output(var) for k in ("Floating", "Grounded"))
        assert np.max(np.abs(a - b)) < 0.002 * np.max(np.abs(b)), var
    currents = sum(runs["Floating"].output(f"choke.inductor[{k}].i") for k in (1, 2, 3))
    assert np.max(np.abs(currents)) < 1e-6


@needs_msl()
def test_a_five_phase_winding_in_star_with_its_zero_sequence_inductor_runs_as_its_inductors(tmp_path):
    """The winding's zero-sequence inductor (m i0 = sum(i)) beside its floating star point
    (sum(i) = 0) hides i0 = 0 in the part of the system that index reduction works on (the
    model's index is 2: the inductors' star). Unseen, the star point's potential came from a
    singular solve (NaN: the MSL's ComparisonPolyphase machines failed so). Seen, the winding
    carries the currents of the inductors it equals (main plus stray inductance per phase)."""
    (tmp_path / "Winding5.mo").write_text(WINDING)
    watched = [f"{part}.i[{k}]" for part in ("winding", "inductor") for k in range(1, 6)]
    model = compile_model([tmp_path / "Winding5.mo"], "Winding5", libraries=[msl_path()]).with_outputs(watched)
    res = unforced_run(model, 0.1, 501)[1]
    winding, inductors = (np.array([res.output(n) for n in watched[k:k + 5]]) for k in (0, 5))
    assert np.max(np.abs(inductors)) > 5.0                  # 100 V at 50 Hz through ~16 ohm
    assert np.max(np.abs(winding - inductors)) < 1e-6 * np.max(np.abs(inductors))
    assert np.max(np.abs(winding.sum(axis=0))) < 1e-9
