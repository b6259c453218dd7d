"""Large branches of if-expressions are evaluated only when taken (:mod:`mcl.compile.branches`).

IF97's water properties compute each region's equations inside one if-expression; as SX
evaluates both sides of every if, a pump's right-hand side evaluated every region. The branches
are moved into functions behind CasADi switches: the values and their first and second
derivatives must stay those of the if-expression, on each side of it.
"""
import casadi as ca
import numpy as np
import pytest

from helpers import msl_path, needs_msl, probed, unforced_run
from mcl.compile.branches import short_circuited
from mcl.compile.guards import guarded

X = ca.SX.sym("x", 3)


def _heavy(e, k, n=150):
    """A smooth chain of ``n`` steps: a branch worth its own function."""
    for _ in range(n):
        e = e + 0.003 * ca.sin(e * e + k)
    return e


def _calls(f: ca.Function) -> int:
    return sum(f.instruction_id(k) == ca.OP_CALL for k in range(f.n_instructions()))


def _same(f, g, points):
    """f and g agree at ``points`` in value, Jacobian and Hessian (SX and MX derivatives)."""
    xm = ca.MX.sym("x", 3)
    for F, sym in ((ca.Function("j", [X], [ca.jacobian(f(X), X)]), ca.Function("j", [X], [ca.jacobian(g(X), X)])),
                   (ca.Function("h", [xm], [ca.jacobian(ca.jacobian(f(xm), xm), xm)]),
                    ca.Function("h", [xm], [ca.jacobian(ca.jacobian(g(xm), xm), xm)]))):
        for v in points:
            np.testing.assert_allclose(np.array(F(v)), np.array(sym(v)), rtol=1e-12, atol=1e-14)
    for v in points:
        np.testing.assert_allclose(np.array(f(v)), np.array(g(v)), rtol=1e-14, atol=1e-15)


def test_a_large_branch_runs_only_when_taken_and_keeps_its_values_and_derivatives():
    r = X[2]
    a = _heavy(X[0] * X[1], 0.1)
    b = _heavy(X[1] - X[0], 0.2)
    shared = ca.cos(X[0])           # read on both sides and outside: computed once, outside
    y1 = ca.if_else(r > 1, a + shared, ca.if_else(r > 2, b, _heavy(X[0], 0.4) * shared))
    y2 = ca.if_else(r > 1, 2 * a, shared)
    f = ca.Function("f", [X], [ca.vertcat(y1, y2, shared)])
    g = short_circuited(f, smallest=100)
    assert _calls(g) >= 2 and g.n_instructions() < f.n_instructions() / 10
    _same(f, g, [[0.3, 0.5, 1.5], [0.3, 0.5, 0.5], [-0.7, 0.2, 2.5]])
    # saved and read back (the compile cache), it computes the same
    back = ca.Function.deserialize(g.serialize())
    np.testing.assert_array_equal(np.array(back([0.3, 0.5, 0.5])), np.array(f([0.3, 0.5, 0.5])))


def test_a_branch_of_the_same_form_in_another_function_reads_its_own_inputs():
    """A branch made once is reused where another function has one of the same form (the same
    medium function at another pipe segment); each call still reads its own function's
    values: here other inputs and another constant."""
    def f_of(a, k):
        return ca.Function("f", [X], [ca.if_else(X[2] > 1, _heavy(a, k), ca.cos(a))])
    first = f_of(X[0] * X[1], 0.1)
    second = f_of(X[1] - X[0], 0.7)
    for f in (first, second, f_of(X[0] * X[1], 0.1)):
        _same(f, short_circuited(f, smallest=100), [[0.3, 0.5, 1.5], [-0.7, 0.2, 0.5]])


def test_a_branch_not_taken_leaves_no_nan_behind():
    """The side not taken may be undefined there (a logarithm of a negative number), as in an
    if-expression guarding it: the value and its derivative are those of the side taken."""
    safe = X[0] > 0
    f = ca.Function("f", [X], [ca.if_else(safe, _heavy(ca.log(X[0]) * X[1], 0.3), -X[0] * X[1])])
    g = short_circuited(f, smallest=100)
    assert _calls(g)
    at = [-2.0, 0.5, 0.0]
    assert np.isfinite(float(g(at))) and float(g(at)) == pytest.approx(1.0)
    J = ca.Function("J", [X], [ca.jacobian(g(X), X)])
    np.testing.assert_allclose(np.array(J(at)).ravel(), [-0.5, 2.0, 0.0])


def test_two_ifs_on_one_condition_the_second_reading_the_first_stay_correct():
    """A branch whose inputs need another branch's result on the same condition (an algorithm
    assigning under ``if region == 1`` twice) is left inline: no call may need its own result."""
    c = X[2] > 0
    first = ca.if_else(c, _heavy(X[0], 0.1), X[1])
    second = ca.if_else(c, _heavy(first * X[1], 0.2), first)
    f = ca.Function("f", [X], [second])
    g = short_circuited(f, smallest=100)
    _same(f, g, [[0.4, 0.3, 1.0], [0.4, 0.3, -1.0]])


def test_guarded_branches_keep_their_values_and_derivatives_where_taken():
    """A singular operation only an if-branch uses gets a safe operand where the branch is not
    taken (:mod:`mcl.compile.guards`); where it is taken, nothing changes, nested branches
    included, and expressions without one are returned as they are."""
    speed = ca.fabs(X[0])
    friction = ca.if_else(speed > 0.5, ca.if_else(X[2] > 1, X[1] / speed + ca.log(speed), ca.sqrt(speed) * X[1]),
                          X[0] * X[1])
    shared = X[1] / (X[0] + 3)              # (needed outside any branch: left as it is)
    e = ca.vertcat(friction + shared, ca.if_else(X[2] > 0, shared ** 0.5, 0))
    g = guarded([e])[0]
    assert ca.n_nodes(g) > ca.n_nodes(e)
    _same(ca.Function("f", [X], [e]), ca.Function("g", [X], [g]),
          [[0.7, 0.4, 1.5], [-0.9, 0.4, 0.5], [0.2, 0.4, 1.5], [-0.6, 1.3, -1.0]])
    plain = ca.vertcat(ca.if_else(X[0] > 0, X[1] * X[2], X[0] + 1), X[1] / X[2])
    assert guarded([plain])[0] is plain


def test_a_value_comparisons_read_keeps_its_value_and_no_nan_reaches_the_reverse_jacobian():
    """IF97 picks its region by comparing T with a boundary ``572.5 + sqrt((p - 13.9)/0.001)``,
    NaN below 13.9 (the comparison then false, as meant), and reads the boundary again inside a
    branch, a function behind a switch. Reverse mode passes the NaN node an adjoint of 0 and
    multiplies it by its NaN partial: a Jacobian of one row was NaN where every directional
    derivative is finite. The guard keeps every value (NaN included) and the derivatives."""
    p, T, v = X[0], X[1], X[2]
    boundary = 572.5 + ca.sqrt((p - 13.9) / 0.001)
    region = ca.if_else(T < boundary, 3, 2)
    e = ca.if_else(region == 2, _heavy(T * v, 0.1) + p ** 2, _heavy((T - boundary) * v, 0.2) + T) \
        + ca.log(ca.fabs(p) + 1) * v
    f = short_circuited(ca.Function("f", [X], [e]), smallest=100)
    g = short_circuited(ca.Function("g", [X], guarded([e])), smallest=100)
    assert _calls(f) and _calls(g)
    below, above, edge = [5.0, 600.0, 0.3], [20.0, 600.0, 0.3], [13.9, 500.0, 0.3]
    for at in (below, above, edge):
        assert float(g(at)) == float(f(at))
    boundary_g = ca.Function("b", [X], guarded([ca.vertcat(boundary, T < boundary)]))
    assert np.isnan(float(boundary_g(below)[0])) and float(boundary_g(above)[1]) == 1.0
    forward = ca.Function("f", [X], [f(X)], {"ad_weight": 0, "ad_weight_sp": 0}).jacobian()
    assert not np.all(np.isfinite(np.array(f.jacobian()(below, 0))))     # reverse: the failure guarded against
    for at in (below, above):
        np.testing.assert_allclose(np.array(g.jacobian()(at, 0)), np.array(forward(at, 0)), rtol=1e-12)


def test_small_functions_are_left_as_they_are():
    f = ca.Function("f", [X], [ca.if_else(X[0] > 0, ca.sin(X[1]), ca.cos(X[2]))])
    assert short_circuited(f) is f


BOILER = """
model Boiler "A kilogram of water heated at 1 bar through boiling, losing heat to the room"
  import Modelica.Units.SI;
  package Medium = Modelica.Media.Water.StandardWater;
  parameter SI.Pressure p = 1e5 "pressure";
  parameter SI.Power Q = 2e3 "heater";
  parameter SI.ThermalConductance G = 10 "loss to the room";
  parameter SI.Temperature T_room = 293.15;
  parameter SI.Mass m = 1 "mass of water";
  SI.SpecificEnthalpy h(start = 84e3, fixed = true);
  Modelica.Blocks.Interfaces.RealOutput T(unit = "K") "temperature";
  Modelica.Blocks.Interfaces.RealOutput d(unit = "kg/m3") "density";
equation
  m*der(h) = Q - G*(T - T_room);
  T = Medium.temperature_ph(p, h);
  d = Medium.density_ph(p, h);
end Boiler;
"""


@needs_msl()
def test_water_heated_through_boiling_follows_the_steam_tables(tmp_path):
    """IF97 in the right-hand side (the loss reads T(p, h)), its regions behind switches: liquid
    at 20 C, the plateau at the saturation temperature of 1 bar, steam at T_room + Q/G."""
    from mcl import compile_model

    (tmp_path / "Boiler.mo").write_text(BOILER)
    model = compile_model([tmp_path / "Boiler.mo"], "Boiler", libraries=[msl_path()])
    assert any(f.class_name() == "Switch" for f in model.ode.ode.find_functions())
    t, res = unforced_run(model, 6000.0, 601)
    v = probed(model, res)
    T, d = v["T"], v["d"]
    assert d[0] == pytest.approx(998.21, abs=0.01)             # liquid water, 1 bar, 20 C
    boiling = (t > 600) & (t < 1800)                              # h between h' and h'' at 1 bar
    np.testing.assert_allclose(T[boiling], 372.756, atol=5e-3)    # T_sat(1 bar) = 99.606 C
    assert T[-1] == pytest.approx(493.15, abs=0.01)               # steady: Q = G (T - T_room)
    assert d[-1] == pytest.approx(1 / 2.2659, rel=2e-3)           # steam at 1 bar, 220 C: v = 2.266 m3/kg


DRAINED_TANK = """
model DrainedTank "an engineer's heated tank draining through a pipe to the room"
  import Modelica.Fluid;
  replaceable package Medium = Modelica.Media.Water.StandardWater
    constrainedby Modelica.Media.Interfaces.PartialMedium;
  inner Fluid.System system(energyDynamics = Fluid.Types.Dynamics.FixedInitial);
  Fluid.Vessels.OpenTank tank(redeclare package Medium = Medium, height = 2, crossArea = 0.5,
    level_start = 1.5, nPorts = 1, use_HeatTransfer = true, T_start = 293.15,
    portsData = {Fluid.Vessels.BaseClasses.VesselPortsData(diameter = 0.05)});
  Fluid.Pipes.StaticPipe pipe(redeclare package Medium = Medium, length = 5, diameter = 0.05);
  Fluid.Sources.FixedBoundary room(redeclare package Medium = Medium, p = 1.01325e5, T = 293.15, nPorts = 1);
  Modelica.Thermal.HeatTransfer.Sources.FixedHeatFlow heater(Q_flow = 5e4);
  Modelica.Blocks.Interfaces.RealOutput level(unit = "m");
equation
  connect(tank.ports[1], pipe.port_a);
  connect(pipe.port_b, room.ports[1]);
  connect(heater.port, tank.heatPort);
  level = tank.level;
end DrainedTank;

model DrainedTankConstant "the same with water of constant properties"
  extends DrainedTank(redeclare package Medium = Modelica.Media.Water.ConstantPropertyLiquidWater);
end DrainedTankConstant;
"""


@needs_msl()
def test_a_tank_of_steam_table_water_drains_as_its_twin_of_constant_properties(tmp_path):
    """An open tank of IF97 water drained through a pipe failed at its first step
    (CV_CONV_FAILURE): its solver's Jacobian was NaN in every entry, the NaN of a region
    boundary that only comparisons read, passed back by reverse mode (see :mod:`guards`). It
    drains as its twin of constant-property water does: within a few millimetres over 200 s."""
    from mcl import compile_model

    (tmp_path / "Drained.mo").write_text(DRAINED_TANK)
    levels = {}
    for name in ("DrainedTank", "DrainedTankConstant"):
        model = compile_model([tmp_path / "Drained.mo"], name, libraries=[msl_path()])
        t, res = unforced_run(model, 200.0, 201)
        levels[name] = np.asarray(res.outputs).reshape(len(t), -1)[:, 0]
    steam, constant = levels["DrainedTank"], levels["DrainedTankConstant"]
    assert steam[0] == pytest.approx(1.5) and np.all(np.diff(steam) < 0) and steam[-1] < 0.2
    np.testing.assert_allclose(steam, constant, atol=5e-3)
