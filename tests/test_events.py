"""State events: a relation on the states switches the equations; the crossing is located and
the solver restarted there. Exact solutions derived by hand."""

import numpy as np
import pytest

from mcl import compile_model
from mcl.data import TimeSeries
from mcl.engine_casadi import CasadiEngine
from mcl.simulation import SimulationOptions
from helpers import msl_path, needs_msl, probed

KINK = """
model Kink "x falls at rate 1 while positive, at rate 3 once negative; y integrates x"
  Real x(start = 0.5, fixed = true);
  Real y(start = 0, fixed = true);
  output Real out;
equation
  der(x) = if x > 0 then -1 else -3;
  der(y) = if noEvent(x > 10) then 0 else x;   // noEvent: no event indicator
  out = y;
end Kink;
"""


def test_a_state_event_is_located_and_the_solution_is_exact(tmp_path):
    (tmp_path / "Kink.mo").write_text(KINK)
    model = compile_model([tmp_path / "Kink.mo"], "Kink")
    assert model.ode.zero is not None and model.ode.zero.size1_out(0) == 1   # x > 0 only
    t = np.linspace(0, 1.05, 8)                       # the crossing, t = 0.5, between two points
    engine = CasadiEngine()
    res = engine.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    plan = next(iter(engine._plans.values()))
    assert plan.hybrid.count == 1
    x = np.where(t < 0.5, 0.5 - t, -3 * (t - 0.5))
    y = np.where(t < 0.5, 0.5 * t - t**2 / 2, 0.125 - 1.5 * (t - 0.5) ** 2)
    assert np.max(np.abs(res.states[:, 0] - x)) < 1e-6
    assert np.max(np.abs(res.output("out") - y)) < 1e-5


def test_a_model_without_relations_on_states_has_no_event_function(tmp_path):
    (tmp_path / "Plain.mo").write_text("model Plain\n  Real x(start = 1, fixed = true);\n  input Real u;\n"
                                       "equation\n  der(x) = if time > 0.5 then -x else u;\nend Plain;\n")
    model = compile_model([tmp_path / "Plain.mo"], "Plain")
    assert model.ode.zero is None and model.ode.time_events == (0.5,)


def test_the_fmu_carries_the_event_indicators(tmp_path):
    """FMPy's solver locates the zeros of the FMU's event indicators (the same relations)."""
    from fmpy import read_model_description

    from mcl import simulate
    from mcl.compile.fmu.export import build_fmu
    from mcl.model import FmuModel

    (tmp_path / "Kink.mo").write_text(KINK)
    fmu = build_fmu(compile_model([tmp_path / "Kink.mo"], "Kink"), tmp_path / "kink.fmu")
    assert read_model_description(str(fmu)).numberOfEventIndicators == 1
    t = np.linspace(0, 1.05, 8)
    res = simulate(FmuModel.read(fmu), TimeSeries(t, np.zeros((len(t), 0)), []))
    assert res.ok, res.reason
    y = np.where(t < 0.5, 0.5 * t - t**2 / 2, 0.125 - 1.5 * (t - 0.5) ** 2)
    assert np.max(np.abs(res.output("out") - y)) < 1e-4


# -- hybrid models: when, pre, reinit, discrete variables, sample, asserts -------------------

BALL = """
model Ball
  parameter Real e = 0.8;
  Real h(start = 1, fixed = true);
  Real v(start = 0, fixed = true);
  Integer n(start = 0, fixed = true) "bounces";
  discrete Real vimp(start = 0, fixed = true) "speed at the last impact";
equation
  der(h) = v;
  der(v) = -9.81;
  when h < 0 then
    reinit(v, -e * pre(v));
    n = pre(n) + 1;
    vimp = v;
  end when;
end Ball;
"""


def _ball_truth(t, e=0.8, g=9.81):
    """Height, bounce count and impact speed of the ball, bounce by bounce."""
    t_k, v_k = np.sqrt(2 / g), np.sqrt(2 * g)          # first impact and the speed then
    starts, speeds = [0.0], [0.0]
    while t_k < t[-1] + 1:
        starts.append(t_k)
        speeds.append(e * v_k)
        v_k *= e
        t_k += 2 * v_k / g
    k = np.searchsorted(starts, t, side="right") - 1
    s, v0 = np.array(starts)[k], np.array(speeds)[k]
    h = np.where(k == 0, 1 - g * t**2 / 2, v0 * (t - s) - g * (t - s) ** 2 / 2)
    return h, k, np.where(k == 0, 0.0, -np.array(speeds)[k] / e)


def test_a_bouncing_ball_reinitialises_at_each_impact(tmp_path):
    (tmp_path / "Ball.mo").write_text(BALL)
    model = compile_model([tmp_path / "Ball.mo"], "Ball")
    assert model.ode.discrete == 3                   # n, vimp and the memory of h < 0
    t = np.linspace(0, 3, 301)
    # (at the default rtol of 1e-6, h is off by 1e-4 after ten bounces and an impact moves by
    # 5e-5 s, to the other side of an output point now and then; at 1e-8, by 1.2e-6 m)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []),
                                  options=SimulationOptions(rtol=1e-8))
    assert res.ok, res.reason
    h, n, vimp = _ball_truth(t)
    names = model.ode.x_names
    assert np.max(np.abs(res.states[:, names.index("h")] - h)) < 1e-5
    assert np.array_equal(res.states[:, names.index("n")], n)
    # the when-clause sees v before the reinit (MLS 8.3.6)
    assert np.allclose(res.states[:, names.index("vimp")], vimp, atol=1e-4)


HYSTERESIS = """
model Hysteresis "a two-point controller: heat until 22, cool until 18"
  Real T(start = 20, fixed = true);
  Boolean on(start = true, fixed = true);
  output Real y;
  Integer k(start = 0, fixed = true);
  discrete Real s(start = 0, fixed = true);
equation
  der(T) = if on then 2 else -1;
  on = not pre(on) and T < 18 or pre(on) and T < 22;
  y = if on then 1 else 0;
  when sample(0, 0.25) then
    s = T;
  end when;
  when {initial(), edge(on)} then
    k = pre(k) + 1;
  end when;
  assert(T < 21, "too warm", AssertionLevel.warning);
end Hysteresis;
"""


LATCH = """
model Latch "a one-way clutch's start: locked, it holds the whole torque; rolling, its path variable is half of it"
  parameter Real tau_max = 1 "breakaway torque";
  parameter Real tau0 = 0.2 "sliding torque";
  Real sa "the torque held while locked, the driving torque less the acceleration while rolling";
  Real w(start = 0, fixed = true);
  Boolean startForward(start = false, fixed = true);
  Boolean locked(start = true, fixed = true);
equation
  sa = if locked then time else 0.5 * time;
  startForward = sa > tau_max or pre(startForward) and sa > tau0;
  locked = not startForward;
  der(w) = if locked then 0 else sa - tau0;
end Latch;
"""


def test_a_clutch_that_has_no_fixed_point_with_pre_held_starts_as_modelica_says(tmp_path):
    """At t = 1 the held torque passes tau_max: startForward, so the clutch rolls, its path
    variable halves and startForward is false again, so it locks: with pre() held the event
    iteration cycles. In Modelica's iteration pre() takes the new values, and
    pre(startForward) keeps it rolling (0.5 t > tau0): w = int_1^t (0.5 s - 0.2) ds."""
    (tmp_path / "Latch.mo").write_text(LATCH)
    model = compile_model([tmp_path / "Latch.mo"], "Latch")
    t = np.linspace(0, 2, 41)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    names = model.ode.x_names
    w = np.where(t < 1, 0.0, 0.25 * (t ** 2 - 1) - 0.2 * (t - 1))
    assert np.max(np.abs(res.states[:, names.index("w")] - w)) < 1e-5
    assert np.array_equal(res.states[t != 1, names.index("startForward")], (t[t != 1] > 1).astype(float))


def test_a_hysteresis_controller_switches_where_it_should(tmp_path, caplog):
    (tmp_path / "H.mo").write_text(HYSTERESIS)
    model = compile_model([tmp_path / "H.mo"], "Hysteresis")
    assert model.ode.events["clocks"] == [[0.0, 0.25]]
    t = np.linspace(0, 10, 201)
    with caplog.at_level("WARNING", logger="mcl"):
        res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    # heats 20 -> 22 (1 s), cools 22 -> 18 (4 s), heats 18 -> 22 (2 s), cools (4 s) ...
    switches = [1.0, 5.0, 7.0]
    T = np.interp(t, [0, 1, 5, 7, 11], [20, 22, 18, 22, 18])
    names = model.ode.x_names
    assert np.max(np.abs(res.states[:, names.index("T")] - T)) < 1e-5
    on = (t < 1) | ((t >= 5) & (t < 7))
    away = np.min(np.abs(t[:, None] - np.array(switches)[None]), axis=1) > 1e-6
    assert np.array_equal(res.output("y")[away] > 0.5, on[away])
    # k: 1 at initialisation, then one per rising edge of on (at t = 5)
    assert np.array_equal(res.states[away, names.index("k")], np.where(t >= 5, 2, 1)[away])
    # s holds T sampled at the last tick of 0.25
    ticks = np.floor(t / 0.25 + 1e-9) * 0.25
    assert np.allclose(res.states[:, names.index("s")], np.interp(ticks, [0, 1, 5, 7, 11], [20, 22, 18, 22, 18]),
                       atol=1e-5)
    assert any("too warm" in r.getMessage() for r in caplog.records)     # level warning: logged only


def test_an_assert_that_fires_fails_the_run_with_its_message(tmp_path):
    (tmp_path / "A.mo").write_text("model A\n  Real x(start = 0, fixed = true);\nequation\n  der(x) = 1;\n"
                                   "  assert(x < 0.45, \"x left its range\");\nend A;\n")
    model = compile_model([tmp_path / "A.mo"], "A")
    t = np.linspace(0, 1, 11)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert not res.ok
    assert "x left its range" in res.reason and "t = 0.5" in res.reason and "A.mo:5" in res.reason


PUMP_INLET = """
model PumpInlet "an engineer's check, as Fluid's pumps do it: the margin to vapour pressure
  by a function that asserts it is positive, its message given at each call"
  function positiveDifference
    input Real a;
    input Real b;
    input String message;
    output Real d;
  algorithm
    d := a - b;
    assert(d >= 0, message);
  end positiveDifference;
  parameter Real p_vap = 0.35;
  Real p(start = 1, fixed = true);
  Real inlet = positiveDifference(p, p_vap, "Cavitation occurs at the pump inlet");
  Real outlet = positiveDifference(p + 1, p_vap, "Cavitation occurs in the pump");
equation
  der(p) = -1;
end PumpInlet;
"""


def test_a_string_passed_to_a_function_is_the_message_of_its_assert(tmp_path):
    """p falls through p_vap at t = 0.65: the inlet's check fails with the message its call
    passed, and the outlet's (the same function, another message) holds."""
    (tmp_path / "PumpInlet.mo").write_text(PUMP_INLET)
    model = compile_model([tmp_path / "PumpInlet.mo"], "PumpInlet")
    t = np.linspace(0, 1, 11)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert not res.ok
    assert "Cavitation occurs at the pump inlet" in res.reason and "in the pump" not in res.reason
    assert "t = 0.7" in res.reason


STOPPING = """
model Stopping "a tank that fills at 2 per second; the run ends once it holds 1.1"
  parameter Real q = 2 "inflow";
  parameter String why = "the tank is full";
  Real v(start = 0, fixed = true, unit = "m3");
  output Real level = v;
equation
  der(v) = q;
  when v >= 1.1 then
    terminate(why);
  end when;
end Stopping;
"""


def test_terminate_ends_the_run_where_its_condition_is_met(tmp_path):
    """terminate() ends the run there, as in other tools: a result (not a failure) with the
    points up to that instant and the model's words; a fit over the whole data, which needs
    every point, takes such a run as failed."""
    (tmp_path / "Stopping.mo").write_text(STOPPING)
    model = compile_model([tmp_path / "Stopping.mo"], "Stopping")
    t = np.linspace(0, 1, 11)
    inputs = TimeSeries(t, np.zeros((len(t), 0)), [])
    res = CasadiEngine().simulate(model, inputs, options=None)
    assert res.ok and res.time[-1] == pytest.approx(0.5) and len(res.outputs) == 6
    assert np.allclose(res.output("level"), 2 * res.time, atol=1e-8)
    assert "the tank is full" in res.terminated and "t = 0.55" in res.terminated
    slow = CasadiEngine().simulate(model, inputs, {"q": 1.0}, options=None)   # full at 1.1: never
    assert slow.ok and slow.terminated is None and len(slow.time) == 11
    failed = res.through(t)
    assert not failed.ok and "terminated the run at t = 0.55" in failed.reason and failed.outputs.shape == (11, 1)


def test_an_assert_on_parameters_only_is_checked_once_and_still_fires(tmp_path):
    """An assert that reads no state, input or time (the MSL's range checks) is evaluated at one
    point, not at every output point: the same verdict, without the model's loops solved n times."""
    from mcl.engine_casadi import _varies

    (tmp_path / "B.mo").write_text("model B\n  parameter Real k = 2;\n  Real x(start = 1, fixed = true);\n"
                                   "equation\n  der(x) = -k*x;\n  assert(k > 0, \"k must be positive\");\nend B;\n")
    model = compile_model([tmp_path / "B.mo"], "B")
    assert not _varies(model.ode.asserts)
    t = np.linspace(0, 1, 11)
    inputs = TimeSeries(t, np.zeros((len(t), 0)), [])
    assert CasadiEngine().simulate(model, inputs, options=None).ok
    res = CasadiEngine().simulate(model, inputs, {"k": -1.0}, options=None)
    assert not res.ok and "k must be positive" in res.reason and "t = 0" in res.reason
    from mcl.engine_casadi import _Hybrid

    n = 500
    X, P = np.ones((1, n)), np.repeat(model.parameter_vector({"k": -1.0})[:, None], n, 1)
    V = _Hybrid(model.ode, np.linspace(0, 1, n)).assert_values(X, np.zeros((0, n)), P, np.linspace(0, 1, n))
    assert V.shape == (1, n) and np.all(V > 0.5)


@pytest.mark.slow
def test_a_5000_term_sum_compiles(tmp_path):
    """rumoca recurses as deep as the sum nests (it runs with a large stack); the translation
    is iterative."""
    terms = " + ".join(f"{i % 7 + 1}*x" for i in range(5000))
    (tmp_path / "S.mo").write_text(f"model S\n  Real x(start = 1, fixed = true);\n  output Real y;\nequation\n"
                                   f"  der(x) = -x;\n  y = {terms};\nend S;\n")
    model = compile_model([tmp_path / "S.mo"], "S")
    t = np.linspace(0, 1, 11)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []),
                                  options=SimulationOptions(rtol=1e-10, atol=1e-12))
    total = sum(i % 7 + 1 for i in range(5000))
    assert res.ok and np.allclose(res.output("y"), total * np.exp(-t), rtol=1e-5)


BACKLASH = """
model Backlash "an inertia on an elasto-backlash (the MSL's equations, with its if-equation on
  initial()): free in the gap, a spring and a damper that never pulls in contact"
  parameter Real c = 20e3, d = 50, b = 0.7853981633974483, J = 5;
  parameter Real bMax = b/2, bMin = -bMax;
  Real phi(start = 1.570796326794897, fixed = true);
  Real w(start = 0, fixed = true);
  Real tau_c, tau_d, tau;
  output Real y = phi;
equation
  der(phi) = w;
  J*der(w) = -tau;
  if initial() then
    tau_c = if phi > 1.5*bMax then c*(phi - bMax) else if phi < 1.5*bMin then c*(phi - bMin) else (c/3)*phi;
    tau_d = d*w;
    tau = tau_c + tau_d;
  elseif phi > bMax then
    tau_c = c*(phi - bMax);
    tau_d = d*w;
    tau = smooth(0, noEvent(if tau_c + tau_d <= 0 then 0 else tau_c + min(tau_c, tau_d)));
  elseif phi < bMin then
    tau_c = c*(phi - bMin);
    tau_d = d*w;
    tau = smooth(0, noEvent(if tau_c + tau_d >= 0 then 0 else tau_c + max(tau_c, tau_d)));
  else
    tau_c = 0;
    tau_d = 0;
    tau = 0;
  end if;
end Backlash;
"""


def test_if_equation_branches_follow_their_conditions(tmp_path):
    """An if-equation's branch conditions (initial(), relations) are the IR's condition
    coordinates; read as variables they once chose the initial() branch for the whole run (a
    backlash that damped in its gap). Checked against the same law integrated by SciPy."""
    from scipy.integrate import solve_ivp

    c, d, J, half = 20e3, 50.0, 5.0, 0.7853981633974483 / 2

    def tau(p, w):
        if p > half:
            tc = c * (p - half)
            return 0.0 if tc + d * w <= 0 else tc + min(tc, d * w)
        if p < -half:
            tc = c * (p + half)
            return 0.0 if tc + d * w >= 0 else tc + max(tc, d * w)
        return 0.0

    t = np.linspace(0.0, 0.3, 61)
    ref = solve_ivp(lambda _t, s: [s[1], -tau(s[0], s[1]) / J], (0, 0.3), [np.pi / 2, 0.0], t_eval=t,
                    rtol=1e-10, atol=1e-12, max_step=1e-4).y[0]
    src = tmp_path / "Backlash.mo"
    src.write_text(BACKLASH)
    res = CasadiEngine().simulate(compile_model([src], "Backlash"), TimeSeries(t, np.zeros((len(t), 0)), []),
                                  t_out=t, options=SimulationOptions(rtol=1e-9, atol=1e-11))
    assert res.ok, res.reason
    np.testing.assert_allclose(res.output("y"), ref, atol=2e-3 * np.ptp(ref))


WINDING = """
package Windings
  model Winding "a three-phase winding's star or delta connection, picked by its letter as the
    MSL's transformers pick theirs from the vector group"
    parameter String connection = "Y";
    parameter String tag = "three-phase";
    parameter Real R = 2;
    input Real u "phase-to-phase voltage";
    output Real i "line current";
  equation
    if connection == "D" or connection == "d" then
      i = sqrt(3)*u/R;
    elseif tag + "/" + connection <> "three-phase/Y" then
      i = -1;
    else
      i = u/(sqrt(3)*R);
    end if;
  end Winding;
  model Delta = Winding(connection = "D");
end Windings;
"""


def test_string_comparisons_pick_the_branch_of_constant_strings(tmp_path):
    """An if-equation on constant strings (a String parameter, literals, + joining them) picks
    its branch when the model is compiled, as other tools do; strings were refused."""
    src = tmp_path / "Windings.mo"
    src.write_text(WINDING)
    t = np.linspace(0, 1, 11)
    inputs = TimeSeries(t, 3 * np.ones((len(t), 1)), ["u"])
    star = CasadiEngine().simulate(compile_model([src], "Windings.Winding"), inputs, options=None)
    delta = CasadiEngine().simulate(compile_model([src], "Windings.Delta"), inputs, options=None)
    assert star.ok and delta.ok
    assert np.allclose(star.output("i"), 3 / (np.sqrt(3) * 2)) and np.allclose(delta.output("i"), np.sqrt(3) * 3 / 2)


NANO = """
model Nano "an RC of 1 ns charged by a pulse train; the period count starts from time, as the MSL's Trapezoid"
  parameter Real startTime = 2e-9, period = 4e-9, width = 2e-9, tau = 1e-9;
  Integer count "period count";
  discrete Real T_start "start of the current period";
  Real v(start = 0, fixed = true);
  output Real u;
initial algorithm
  count := integer((time - startTime)/period);
  T_start := startTime + count*period;
equation
  when integer((time - startTime)/period) > pre(count) then
    count = pre(count) + 1;
    T_start = time;
  end when;
  u = if time >= startTime and time < T_start + width then 1 else 0;
  tau*der(v) = u - v;
end Nano;
"""


def test_a_nanosecond_circuit_moves_and_a_discrete_start_reads_time(tmp_path):
    """Output points 0.5 ns apart (CasADi's integrator skips output times within 1e-9 s of the
    last, unless time is scaled), and count's initial value -1 computed from time: the first
    pulse starts at 2 ns, not one period late."""
    (tmp_path / "Nano.mo").write_text(NANO)
    model = compile_model([tmp_path / "Nano.mo"], "Nano")
    t = np.linspace(0, 12e-9, 25)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    names = model.ode.x_names
    assert res.states[0, names.index("count")] == -1
    v, exact = 0.0, []          # charge over [2, 4) ns, [6, 8), [10, 12); discharge between
    for a, b in zip(t[:-1], t[1:]):
        exact.append(v)
        on = ((a - 2e-9) % 4e-9) < 2e-9 - 1e-21 and a >= 2e-9 - 1e-21
        v = (1.0 if on else 0.0) + (v - (1.0 if on else 0.0)) * np.exp(-(b - a) / 1e-9)
    exact.append(v)
    assert np.max(np.abs(res.states[:, names.index("v")] - np.array(exact))) < 1e-4   # rtol 1e-6


PULSE_EDGE = """
model PulseEdge "a pulse defined at all times; a switch that holds its state and notes its edges"
  discrete Real start(start = 0, fixed = true);
  Boolean y;
  Boolean off(start = true);
  discrete Real tSwitch(start = -1, fixed = true);
  output Real opened = if off then 1 else 0;
  output Real switched = tSwitch;
equation
  when sample(0, 1) then
    start = time;
  end when;
  y = time >= start and time < start + 0.5;   // rumoca lists no event for this relation
  off = not y;                                // read by edge(): held between events
  when edge(off) then
    tSwitch = time;
  end when;
end PulseEdge;
"""


def test_a_pulse_edge_updates_a_held_switch(tmp_path):
    """A relation in a discrete value's definition is an event: the pulse's falling edge at
    0.5 s (between the clock's ticks) changes ``off`` and fires edge(off)."""
    (tmp_path / "PulseEdge.mo").write_text(PULSE_EDGE)
    model = compile_model([tmp_path / "PulseEdge.mo"], "PulseEdge")
    t = np.linspace(0.0, 2.0, 9)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    phase = t % 1.0
    np.testing.assert_array_equal(res.output("opened"), (phase >= 0.5).astype(float))
    np.testing.assert_allclose(res.output("switched"), np.where(t < 0.5, -1.0, np.where(t < 1.5, 0.5, 1.5)))


def test_div_mod_rem_keep_the_model_whole_and_switch_at_each_integer(tmp_path):
    """rumoca numbers the nodes of div/mod/rem's quotient without listing them: every node
    after one used to be read as another. A sawtooth of a state integrates exactly."""
    (tmp_path / "Saw.mo").write_text("""
model Saw
  parameter Integer n = -7;
  parameter Real q = div(n, 2) + 10*rem(n, 2) + 100*mod(n, 2) "-3 - 10 + 100";
  Real s(start = 0, fixed = true);
  Real y(start = 0, fixed = true);
  output Real out;
equation
  der(s) = 1;
  der(y) = mod(s, 0.3);
  out = q;
end Saw;
""")
    model = compile_model([tmp_path / "Saw.mo"], "Saw")
    assert model.ode.zero is not None                 # mod of a state: an event at each tooth
    t = np.linspace(0, 1, 11)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    assert res.output("out")[0] == pytest.approx(87)
    tooth = 0.3 ** 2 / 2
    exact = [np.floor(v / 0.3) * tooth + (v % 0.3) ** 2 / 2 for v in t]
    assert np.max(np.abs(res.states[:, model.ode.x_names.index("y")] - exact)) < 5e-6




def test_mod_of_a_variable_is_not_taken_for_the_variable(tmp_path):
    """``a = x - floor(x)`` has the Jacobian of ``a = x`` (floor's derivative is 0): alias
    elimination solved it as ``a = x + 0``. And a div/mod in a function's body makes no event,
    so rumoca leaves no gap in its numbering after it (the MSL's wrapAngle: every later node
    was read as another). A model an engineer writes with both, read at times between events."""
    (tmp_path / "Angles.mo").write_text("""
model Angles
  function wrap "an angle in [0, period)"
    input Real u;
    input Real period = 2;
    output Real y;
  algorithm
    y := mod(u, period);
  end wrap;
  Real x(start = 0, fixed = true);
  output Real a = mod(x, 1) "a sawtooth";
  output Real b = wrap(x);
  output Real c = div(x, 0.5);
  output Real d "in a loop with e, through a step";
  output Real e;
equation
  der(x) = 1;
  d + e = 3*x;
  d - e = floor(d);
end Angles;
""")
    model = compile_model([tmp_path / "Angles.mo"], "Angles")
    t = np.array([0.0, 0.25, 0.75, 1.25, 1.6, 2.3, 2.9])
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    x = t
    assert res.output("a") == pytest.approx(x % 1, abs=1e-9)
    assert res.output("b") == pytest.approx(x % 2, abs=1e-9)
    assert res.output("c") == pytest.approx(np.trunc(x / 0.5), abs=1e-9)
    d, e = res.output("d"), res.output("e")
    assert d + e == pytest.approx(3 * x, abs=1e-9)
    assert d - e == pytest.approx(np.floor(d), abs=1e-9)

ARC = """
model Arc "an inductive current driven down by an arc voltage until the arc quenches"
  parameter Real L = 0.1, R = 1, Vs = 50, Varc = 60, Goff = 1e-5;
  Real i(start = 10, fixed = true);
  Real v;
  Boolean quenched(start = false, fixed = true);
equation
  quenched = abs(i) <= abs(v)*Goff or pre(quenched);
  L*der(i) = Vs - R*i - v;
  if quenched then
    i = Goff*v;
  else
    v = Varc*noEvent(sign(i));
  end if;
end Arc;
"""


def test_a_crossing_the_solver_ran_past_is_found_after_it_gives_up(tmp_path):
    """The current falls as -10 + 20 exp(-10 t) until, 6e-4 A from zero, the arc quenches
    (MSL's switches with arc). On grid points coarser than that window the solver runs past it
    into i = 0, where v = Varc noEvent(sign(i)) chatters, and gives up; the failed call is
    probed point by point, intervals halved, until the relation's sign change is seen and
    handled. After the quench the current is Vs/(R + 1/Goff)."""
    _quenches(tmp_path, ARC)


def test_a_sign_is_an_event_where_its_argument_crosses_zero(tmp_path):
    """sign() generates an event, as Modelica has it (the MSL's arcs are written that way): the
    arc's voltage flips at i = 0, where the quench relation is true, and the arc quenches there;
    the same solution, in a few events and no failed call."""
    hybrid = _quenches(tmp_path, ARC.replace("noEvent(sign(i))", "sign(i)"))
    assert hybrid.count <= 3


def _quenches(tmp_path, source):
    (tmp_path / "Arc.mo").write_text(source)
    model = compile_model([tmp_path / "Arc.mo"], "Arc")
    t = np.linspace(0, 0.2, 11)
    engine = CasadiEngine()
    res = engine.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    i = res.states[:, model.ode.x_names.index("i")]
    before = t < 0.1 * np.log(2) - 1e-3
    assert np.abs(i[before] - (-10 + 20 * np.exp(-10 * t[before]))).max() < 1e-4
    assert np.abs(i[t > 0.08] - 50 / (1 + 1e5)).max() < 1e-8
    return next(iter(engine._plans.values())).hybrid


PULSED_RC = """
model PulsedRC "a capacitor charged while a pulse is on, discharging while it is off"
  discrete Real start(start = 0, fixed = true);
  Boolean on;
  Real v(start = 0, fixed = true);
  output Real y = v;
equation
  when sample(0, 0.2) then
    start = time;
  end when;
  on = time >= start and time < start + 0.07;
  der(v) = if on then (1 - v)/0.1 else -v;
end PulsedRC;
"""


def test_a_pulse_edge_on_time_alone_is_foreseen_and_the_solution_is_exact(tmp_path):
    """The falling edge (time against a discrete value) is found without integrating past it,
    and the switch of the right-hand side with it is not integrated across; a tick that sets
    start = time makes time >= start exactly 0, which is no second event."""
    (tmp_path / "PulsedRC.mo").write_text(PULSED_RC)
    model = compile_model([tmp_path / "PulsedRC.mo"], "PulsedRC")
    t = np.linspace(0.0, 1.0, 41)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    v, exact, grid = 0.0, [0.0], np.union1d(t, [k * 0.2 + d for k in range(5) for d in (0.0, 0.07)])
    for a, b in zip(grid[:-1], grid[1:]):
        on = (a + 1e-12) % 0.2 < 0.07
        v = 1 + (v - 1) * np.exp(-(b - a) / 0.1) if on else v * np.exp(-(b - a))
        if np.any(np.isclose(b, t)):
            exact.append(v)
    np.testing.assert_allclose(res.output("y"), exact, atol=1e-4)


SAWTOOTH = """
model Sawtooth "x integrates 1 and is reset every millisecond, as the MSL's Mean block does"
  Real x(start = 0, fixed = true);
  output Real y = x;
equation
  der(x) = 1;
  when sample(0.001, 0.001) then
    reinit(x, 0);
  end when;
end Sawtooth;
"""


def test_a_tick_computed_a_rounding_away_from_an_output_time_happens_at_that_time(tmp_path):
    """0.001 + 85 * 0.001 is 0.08600000000000001: the output at 0.086 is the value after the
    reset there (0), not the one before it (0.001), as at every other tick."""
    (tmp_path / "Sawtooth.mo").write_text(SAWTOOTH)
    model = compile_model([tmp_path / "Sawtooth.mo"], "Sawtooth")
    t = np.round(np.arange(0, 101) * 0.001, 12)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    np.testing.assert_allclose(res.output("y"), 0.0, atol=1e-9)


GATED = """
model Gated "an assert in a function holds only where the branch calling it is taken"
  function root "a square root that checks its argument"
    input Real x;
    output Real y;
  algorithm
    assert(x >= 0, "root: negative argument");
    y := sqrt(x);
  end root;
  parameter Real tSwitch = 5;
  Real x(start = 1, fixed = true);
  output Real y = if time < tSwitch then root(x) else 0;
equation
  der(x) = -1;
end Gated;
"""


@pytest.mark.parametrize("t_switch, fires", [(0.5, False), (5.0, True)])
def test_an_assert_in_a_function_counts_only_where_its_branch_is_taken(tmp_path, t_switch, fires):
    """x = 1 - t turns negative at t = 1: root(x) is only called (and its assert only
    checked) while time < tSwitch."""
    (tmp_path / "Gated.mo").write_text(GATED)
    model = compile_model([tmp_path / "Gated.mo"], "Gated")
    t = np.linspace(0.0, 2.0, 21)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []),
                                  params={"tSwitch": t_switch}, options=None)
    assert res.ok is not fires, res.reason
    if fires:
        assert "root: negative argument" in res.reason
    else:
        np.testing.assert_allclose(res.output("y"), np.where(t < t_switch, np.sqrt(np.clip(1 - t, 0, None)), 0), atol=1e-6)


def test_a_when_statement_runs_its_assignments_in_order(tmp_path):
    """An algorithm's when-statement (a sampled PI controller with an anti-windup clamp):
    each assignment reads the ones before it, a later one overrides an earlier one. The plant
    is integrated exactly between samples, so the samples are known in closed form."""
    (tmp_path / "SampledPI.mo").write_text("""
model SampledPI
  parameter Real T = 0.1 "sample period";
  parameter Real k = 2, Ti = 0.5, umax = 1;
  Real x(start = 0, fixed = true) "first-order plant";
  discrete Real e(start = 0, fixed = true);
  discrete Real I(start = 0, fixed = true);
  discrete Real u(start = 0, fixed = true);
  output Real y = x;
  output Real command = u;
equation
  der(x) = -x + u;
algorithm
  when sample(0, T) then
    e := 1 - x;
    I := I + T*e/Ti;
    u := k*(e + I);
    if u > umax then
      u := umax;
      I := I - T*e/Ti;
    end if;
  end when;
end SampledPI;
""")
    model = compile_model([tmp_path / "SampledPI.mo"], "SampledPI")
    t = np.round(np.arange(0, 2.0001, 0.05), 10)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    x, integral, u, xs, us = 0.0, 0.0, 0.0, [], []
    for _ in range(20):                       # the samples at 0, 0.1, ..., 1.9
        e = 1 - x
        integral += 0.1 * e / 0.5
        u = 2 * (e + integral)
        if u > 1:
            u, integral = 1.0, integral - 0.1 * e / 0.5
        us.append(u)
        x = u + (x - u) * np.exp(-0.1)
        xs.append(x)
    halfway = t[1::2][:20]                    # 0.05, 0.15, ...: between samples
    assert res.output("command")[1::2][:20] == pytest.approx(us, abs=1e-4)   # x sampled at rtol 1e-6
    assert min(us) < 1 and max(us) == 1       # the clamp acts, then releases
    exact = [ui + (xi_prev - ui) * np.exp(-0.05) for ui, xi_prev in zip(us, [0.0, *xs[:-1]])]
    assert res.output("y")[1::2][:20] == pytest.approx(exact, abs=1e-5)
    assert halfway[-1] == pytest.approx(1.95)


def test_initial_equations_between_discrete_values_set_their_starts(tmp_path):
    """A discrete value started by an initial equation that reads another (y = 2*x, as a noise
    block's r = f(pre(state))): its start was left at 0. Sampled at 1 and 2 only, the
    integral of x + y + n is exact: 18 per second, then 26, then 35."""
    (tmp_path / "Counter.mo").write_text("""
model Counter
  parameter Real a = 5;
  discrete Real x;
  discrete Real y;
  Integer n;
  Real z(start = 0, fixed = true);
  output Real total = z;
initial equation
  x = a;
  y = 2*x;
  n = 3;
equation
  when sample(1, 1) then
    x = pre(x) + 1;
    y = pre(y) + x;
    n = pre(n) + 1;
  end when;
  der(z) = x + y + n;
end Counter;
""")
    model = compile_model([tmp_path / "Counter.mo"], "Counter")
    t = np.linspace(0.0, 2.5, 11)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    exact = np.where(t <= 1, 18 * t, np.where(t <= 2, 18 + 26 * (t - 1), 44 + 35 * (t - 2)))
    np.testing.assert_allclose(res.output("total"), exact, atol=1e-6)


@needs_msl()
def test_pre_of_a_continuous_output_is_its_value_before_the_event(tmp_path, monkeypatch):
    """The MSL's TriggeredTrapezoid reads pre(y) of its continuous output to start a ramp from
    where the last one stopped: switched off mid-ramp, it falls from there, not from the top."""
    monkeypatch.setenv("MODELICAPATH", str(msl_path()))
    (tmp_path / "Valve.mo").write_text("""
model Valve "a valve command ramped by a triggered trapezoid, switched off mid-ramp"
  import Modelica.Blocks.Logical.TriggeredTrapezoid;
  import Modelica.Blocks.Sources.BooleanPulse;
  TriggeredTrapezoid ramp(amplitude = 2, rising = 1, falling = 1);
  BooleanPulse on(width = 25, period = 2, startTime = 0.5) "on from t = 0.5 to 1";
  Modelica.Blocks.Interfaces.RealOutput command;
equation
  connect(on.y, ramp.u);
  connect(ramp.y, command);
end Valve;
""")
    model = compile_model([tmp_path / "Valve.mo"], "Valve")
    t = np.round(np.arange(0, 3.0001, 0.125), 6)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    # up at 2/s from 0.5 until switched off at 1 (y = 1), down at 2/s from there; again at 2.5
    expected = np.interp(t, [0, 0.5, 1.0, 1.5, 2.5, 3.0], [0, 0, 1, 0, 0, 1])
    assert res.output("command") == pytest.approx(expected, abs=1e-9)


STAIRS = """
model Stairs "y's slope steps up where x passes 0.3 and again at 0.6; x and the steps meet in one output interval"
  Real x(start = 0, fixed = true);
  Real y(start = 0, fixed = true);
  Real z(start = 0, fixed = true);
equation
  der(x) = 1;
  der(y) = (if x > 0.3 then 1 else 0) + (if x > 0.6 then 1 else 0);
  der(z) = if y > 0.1 then 1 else 0;     // y reaches 0.1 at t = 0.4
end Stairs;
"""


def test_crossings_on_the_states_are_located_in_their_order_to_the_last_digits(tmp_path):
    """Three relations on the states cross between two output points (and their detection
    points): each is located on the solution by narrowing its interval, the earliest first."""
    (tmp_path / "Stairs.mo").write_text(STAIRS)
    model = compile_model([tmp_path / "Stairs.mo"], "Stairs")
    t = np.linspace(0, 1.0, 3)
    engine = CasadiEngine()      # (tight tolerances: the error left is the events' location)
    res = engine.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []),
                          options=SimulationOptions(rtol=1e-10, atol=1e-12))
    assert res.ok, res.reason
    assert next(iter(engine._plans.values())).hybrid.count == 3
    names = model.ode.x_names
    y = np.maximum(t - 0.3, 0) + np.maximum(t - 0.6, 0)
    assert np.max(np.abs(res.states[:, names.index("y")] - y)) < 1e-8
    assert np.max(np.abs(res.states[:, names.index("z")] - np.maximum(t - 0.4, 0))) < 1e-8


def test_a_function_reading_a_variable_its_path_left_unset_only_warns(tmp_path, caplog):
    """rumoca checks that a function never reads a variable its executed path left unassigned.
    Other tools do not, and the MSL's water properties copy records with such fields (cv), so
    the check is a warning: the run goes on."""
    (tmp_path / "U.mo").write_text("""
model Unset
  function f
    input Real x;
    output Real y;
  protected
    Real a;
    Real b;
  algorithm
    if x > 0 then
      a := x;
    end if;
    b := a;
    y := 2*x + 0*b;
  end f;
  Real x(start = -1, fixed = true);
  output Real y;
equation
  der(x) = 1;
  y = f(x);
end Unset;
""")
    model = compile_model([tmp_path / "U.mo"], "Unset")
    t = np.linspace(0, 2, 21)
    with caplog.at_level("WARNING", logger="mcl"):
        res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    assert np.allclose(res.output("y"), 2 * (t - 1), atol=1e-8)
    assert any("used without a value" in r.getMessage() for r in caplog.records)


HALF_WAVE = """
model HalfWave "A half-wave rectifier charging a smoothing capacitor"
  import Modelica.Electrical.Analog.Basic;
  import Modelica.Electrical.Analog.Ideal;
  import Modelica.Electrical.Analog.Sources;
  Sources.SineVoltage mains(V = 10, f = 50);
  Ideal.IdealDiode diode;
  Basic.Resistor Rs(R = 1) "source resistance";
  Basic.Capacitor C(C = 1e-3, v(start = 0, fixed = true));
  Basic.Resistor load(R = 100);
  Basic.Ground ground;
  Modelica.Blocks.Interfaces.RealOutput vC = C.v;
equation
  connect(mains.p, Rs.p);
  connect(Rs.n, diode.p);
  connect(diode.n, C.p);
  connect(C.n, ground.p);
  connect(load.p, C.p);
  connect(load.n, ground.p);
  connect(mains.n, ground.p);
end HalfWave;
"""


@needs_msl()
def test_a_diode_relation_is_held_between_events_and_the_rectifier_is_exact(tmp_path, monkeypatch):
    """The ideal diode's off = s < 0 is held between events, as Modelica specifies (a discrete
    variable set at each located switching): the solver never steps over a jump in its
    right-hand side. Ten mains periods, 20 switchings, against a hand-written reference."""
    from scipy.integrate import solve_ivp

    monkeypatch.setenv("MODELICAPATH", str(msl_path()))
    (tmp_path / "HalfWave.mo").write_text(HALF_WAVE)
    model = compile_model([tmp_path / "HalfWave.mo"], "HalfWave")
    assert model.ode.discrete == 1 and model.ode.zero.size1_out(0) == 1
    t = np.linspace(0, 0.2, 2001)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []))
    assert res.ok, res.reason
    Ron = Goff = 1e-5

    def rhs(time, v):      # the diode with its source resistance: on, or off with a leak
        vs = 10 * np.sin(2 * np.pi * 50 * time)
        i = (vs - v[0]) / (1 + Ron)
        i = i if i > 0 else Goff * (vs - v[0]) / (1 + Goff)
        return [(i - v[0] / 100) / 1e-3]
    ref = solve_ivp(rhs, (0, 0.2), [0.0], t_eval=t, rtol=1e-10, atol=1e-12, max_step=1e-5).y[0]
    assert np.max(np.abs(res.output("vC") - ref)) < 1e-3          # of 10 V


CLOCKED = """
model Clocked "a sample() clock read by an equation, and initial(), with no discrete variable"
  import Modelica.Blocks.Sources;
  Sources.SampleTrigger trigger(period = 0.5, startTime = 0.25) "a tick every 0.5 s";
  Real x(start = 1, fixed = true);
  output Real y;
  output Real first;
equation
  der(x) = if trigger.y then 0 else -x;
  y = x;
  first = if initial() then 5 else x;
end Clocked;
"""


@needs_msl()
def test_a_clock_read_by_an_equation_alone_makes_the_model_hybrid(tmp_path):
    """A SampleTrigger whose tick only a continuous equation reads (no when, no discrete
    variable): the tick and initial() are the discrete part. It was a CasADi error ("flags_2 are
    free") where it is an engineer's model; its ticks are instants, so x decays as exp(-t)."""
    (tmp_path / "Clocked.mo").write_text(CLOCKED)
    model = compile_model([tmp_path / "Clocked.mo"], "Clocked", libraries=[msl_path()])
    assert model.ode.events["clocks"] == [[0.25, 0.5]]
    t = np.linspace(0, 2, 21)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    assert np.max(np.abs(res.output("y") - np.exp(-t))) < 1e-5
    assert np.max(np.abs(res.output("first")[1:] - np.exp(-t[1:]))) < 1e-5


INTERLOCK = """
model Interlock "A press interlock: the door sensor feeds both the run gate and the alarm"
  import Modelica.Blocks.MathBoolean;
  import Modelica.Blocks.MathInteger;
  import Modelica.Blocks.Sources;
  Sources.BooleanPulse door(width=50, period=1) "door closed";
  Sources.BooleanPulse key(width=30, period=0.4) "operator's key";
  Sources.BooleanStep stop(startTime=1.5) "emergency stop";
  MathBoolean.And run(nu=2);
  MathBoolean.Or alarm(nu=2);
  Sources.IntegerStep level(height=2, offset=1, startTime=0.7);
  MathInteger.Sum total(nu=2);
  MathInteger.Product square(nu=2);
  Modelica.Blocks.Interfaces.BooleanOutput running;
  Modelica.Blocks.Interfaces.BooleanOutput alarmed;
  Modelica.Blocks.Interfaces.IntegerOutput doubled;
  Modelica.Blocks.Interfaces.IntegerOutput squared;
equation
  connect(key.y, run.u[1]);
  connect(door.y, run.u[2]);
  connect(stop.y, alarm.u[1]);
  connect(door.y, alarm.u[2]);
  connect(level.y, total.u[1]);
  connect(level.y, total.u[2]);
  connect(level.y, square.u[1]);
  connect(level.y, square.u[2]);
  connect(run.y, running);
  connect(alarm.y, alarmed);
  connect(total.y, doubled);
  connect(square.y, squared);
end Interlock;
"""


@needs_msl()
def test_one_logic_signal_fed_to_elements_of_two_gates_inputs_compiles_and_is_exact(tmp_path):
    """The door sensor drives an element of both the And and the Or gate's vector input (and
    one Integer source all four elements of two blocks): rumoca 0.10.2 refuses such a
    connection set ("invalid Appendix B discrete solved form"); written as equations it is the
    same model. The gates' outputs are the truth tables of the sources, computed here."""
    (tmp_path / "Interlock.mo").write_text(INTERLOCK)
    source = (tmp_path / "Interlock.mo").read_text()
    model = compile_model([tmp_path / "Interlock.mo"], "Interlock", libraries=[msl_path()])
    assert (tmp_path / "Interlock.mo").read_text() == source      # the user's file is not touched
    t = np.arange(0.05, 2, 0.1)                                   # between the sources' edges
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    door, key, stop = (t % 1) < 0.5, (t % 0.4) < 0.12, t >= 1.5
    level = np.where(t >= 0.7, 3, 1)
    assert np.array_equal(res.output("running"), (door & key).astype(float))
    assert np.array_equal(res.output("alarmed"), (door | stop).astype(float))
    assert np.array_equal(res.output("doubled"), 2.0 * level)
    assert np.array_equal(res.output("squared"), 1.0 * level ** 2)


RECTIFIER = """
model Rectifier "a three-phase thyristor bridge fired at 60 degrees into an R-L load"
  import Modelica.Electrical.Analog;
  import Modelica.Electrical.Polyphase;
  import Modelica.Electrical.PowerConverters.ACDC;
  parameter Integer m = 3;
  Polyphase.Sources.SineVoltage mains(m = m, V = fill(sqrt(2) * 230, m), f = fill(50, m),
    phase = -Polyphase.Functions.symmetricOrientation(m));
  Polyphase.Basic.MultiStarResistance star(m = m);
  Analog.Basic.Ground ground;
  ACDC.ThyristorBridge2mPulse bridge(m = m);
  ACDC.Control.VoltageBridge2mPulse firing(m = m, f = 50, useFilter = false, constantFiringAngle = Modelica.Constants.pi / 3);
  Analog.Basic.Resistor load(R = 20);
  Analog.Basic.Inductor choke(L = 0.05, i(start = 0, fixed = true));
  Modelica.Blocks.Interfaces.RealOutput i = choke.i;
equation
  connect(mains.plug_n, star.plug);
  connect(star.pin, ground.p);
  connect(mains.plug_p, bridge.ac);
  connect(firing.ac, mains.plug_p);
  connect(firing.fire_p, bridge.fire_p);
  connect(firing.fire_n, bridge.fire_n);
  connect(bridge.dc_p, load.p);
  connect(load.n, choke.p);
  connect(choke.n, bridge.dc_n);
end Rectifier;
"""


@needs_msl()
def test_a_thyristor_bridge_runs_the_same_with_its_blocks_fused(tmp_path, monkeypatch):
    """The bridge's currents are a linear block whose coefficients change with the thyristors'
    states, solved at run time; the blocks around it are fused into a few SX functions
    (:func:`mcl.compile.structure.fused`): the same run as with them called one by one."""
    from mcl.compile import structure

    monkeypatch.setenv("MODELICAPATH", str(msl_path()))
    monkeypatch.setenv("MCL_NO_COMPILE_CACHE", "1")
    (tmp_path / "Rectifier.mo").write_text(RECTIFIER)
    t = np.linspace(0, 0.06, 121)
    runs = []
    for solves in (structure.FUSE_STAGES_MAX, 0):
        monkeypatch.setattr(structure, "FUSE_STAGES_MAX", solves)
        model = compile_model([tmp_path / "Rectifier.mo"], "Rectifier")
        engine = CasadiEngine()
        res = engine.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
        assert res.ok, res.reason
        runs.append((model, res, next(iter(engine._plans.values())).hybrid.count))
    (fused, res, crossings), (plain, ref, ref_crossings) = runs
    # the stages around the solve are called, not every block
    assert _flat_calls(fused.ode.ode) <= 3 < _flat_calls(plain.ode.ode)
    assert crossings == ref_crossings >= 10         # the thyristors fire and block every half period
    i = res.output("i")
    assert i.max() > 1.0                            # 230 V into 20 ohm: amperes
    assert np.max(np.abs(i - ref.output("i"))) < 1e-6 * np.max(np.abs(i)) + 1e-9


def _flat_calls(f) -> int:
    """Function calls in ``f`` with the MX functions it calls inlined."""
    import casadi as ca
    from mcl.compile.structure import _inlined

    g = _inlined(f)[2]
    return sum(g.instruction_id(k) == ca.OP_CALL for k in range(g.n_instructions()))


def test_an_event_that_gives_a_non_finite_value_names_the_variable(tmp_path):
    """A when-equation whose new value is NaN (the square root of a negative number) fails the
    run at the event, naming the variable, not only the instant."""
    (tmp_path / "Blowup.mo").write_text(
        "model Blowup\n  Real x(start = 1, fixed = true);\n  discrete Real d(start = 1, fixed = true);\n"
        "equation\n  der(x) = -x;\n  when x < 0.5 then\n    d = sqrt(pre(d) - 2);\n  end when;\nend Blowup;\n")
    model = compile_model([tmp_path / "Blowup.mo"], "Blowup")
    t = np.linspace(0, 1, 11)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert not res.ok
    assert "non-finite values at t = 0.693" in res.reason and "(d)" in res.reason


STOP = """
model EndStop "a shaken mass on a spring meets a stop at s0 now and then; in contact the stop
  pushes back as an MSL ElastoGap does, by the depth's magnitude: held in contact past the
  parting, it pushes the mass off ever faster"
  parameter Real m = 0.5, k = 200, c = 1e4, s0 = 0.06;
  Real s(start = 0, fixed = true);
  Real v(start = 0, fixed = true);
  Boolean contact;
equation
  contact = s > s0;
  der(s) = v;
  m*der(v) = 40*sin(2*3.14159*2*time) - k*s + (if contact then -c*abs(s - s0) else 0);
end EndStop;
"""


def test_a_call_that_diverges_past_a_crossing_is_probed_for_it(tmp_path):
    """A call that runs past the parting with the contact held drives the states past the
    run's bound (1000x their size): the crossing is looked for before the run is called
    diverged (a discovery's candidates next to an end stop failed at their start). Bounded or
    not, the run follows the exact solution."""
    (tmp_path / "EndStop.mo").write_text(STOP)
    model = compile_model([tmp_path / "EndStop.mo"], "EndStop")
    t = np.linspace(0, 3, 301)
    free = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert free.ok, free.reason
    top = np.max(np.abs(free.states))
    bounded = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []),
                                      options=SimulationOptions(state_bound=1e3 * top))
    assert bounded.ok, bounded.reason
    exact = _end_stop_by_scipy(t)
    for run in (free, bounded):      # (within the engine's error about the stiff contacts)
        assert np.max(np.abs(run.states[:, :2] - exact)) < 2e-3 * top


def _end_stop_by_scipy(t):
    """EndStop's (s, v) at ``t``, integrated to 1e-12 from contact change to contact change."""
    from scipy.integrate import solve_ivp

    def rhs(tt, x, contact):
        s, v = x
        return [v, (40 * np.sin(2 * 3.14159 * 2 * tt) - 200 * s - (1e4 * abs(s - 0.06) if contact else 0)) / 0.5]

    def touch(tt, x, contact):
        return x[0] - 0.06

    touch.terminal = True
    out, t0, x, contact = np.zeros((len(t), 2)), 0.0, [0.0, 0.0], False
    while True:
        touch.direction = -1 if contact else 1
        sol = solve_ivp(rhs, (t0, t[-1]), x, args=(contact,), events=touch, rtol=1e-12, atol=1e-14,
                        dense_output=True)
        inside = (t >= t0) & (t <= sol.t[-1])
        out[inside] = sol.sol(t[inside]).T
        if sol.status != 1:
            return out
        t0, x, contact = sol.t[-1], sol.y_events[0][0], not contact


SWITCH_OFF = """
model SwitchOff "a lamp switched off once time is past 1 s; a count of the lamps on, read
  through integer() of a sum of flows (as a StateGraph counts its active steps), and a flag
  that holds while the count is positive"
  Boolean on(start = true, fixed = true);
  Real share;
  Integer lit;
  Boolean any;
  output Real y = if on then 1 else 0;
  output Real count = lit;
  output Real anyLit = if any then 1 else 0;
equation
  when time > 1 then
    on = false;
  end when;
  share = -(if on then 1.0 else 0.0);
  lit = -integer(share);
  any = lit > 0;
end SwitchOff;
"""


def test_a_when_on_time_past_an_instant_fires_at_its_time_event_in_process_and_in_the_fmu(tmp_path):
    """``time > 1`` is false at 1 itself and true just after: the time event at 1 fires the
    when-clause (it waited for the run's end), and a relation between whole numbers reads its
    value there without the band that keeps a continuous relation from chattering (lit > 0 at
    lit = 0 stayed true)."""
    from fmpy import simulate_fmu

    from mcl.compile.fmu.export import build_fmu

    (tmp_path / "SwitchOff.mo").write_text(SWITCH_OFF)
    model = compile_model([tmp_path / "SwitchOff.mo"], "SwitchOff")
    t = np.linspace(0, 3, 7)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    after = (t >= 1).astype(float)        # at 1 itself: the value after the event
    for name in ("y", "count", "anyLit"):
        assert np.array_equal(res.output(name), 1 - after), name
    fmu = build_fmu(model, tmp_path / "switch.fmu")
    for kind in ("CoSimulation", "ModelExchange"):
        out = simulate_fmu(str(fmu), fmi_type=kind, stop_time=3, output_interval=0.5)
        late, early = out["time"] > 1 + 1e-9, out["time"] < 1 - 1e-9
        for name in ("y", "count", "anyLit"):
            assert np.all(out[name][early] == 1) and np.all(out[name][late] == 0), (kind, name)


THERMOSTAT = """
package Heating
  type Mode = enumeration(Off "off", Heating "heating", Cooling "cooling");
  model Room "a room heated below T_low and cooled above T_high; the mode at the start follows
    the start temperature"
    import Modelica.Units.SI;
    parameter SI.Temperature T_low = 293.15;
    parameter SI.Temperature T_high = 297.15;
    parameter SI.HeatCapacity C = 1000;
    parameter SI.ThermalConductance G = 10;
    Modelica.Blocks.Interfaces.RealInput T_amb(unit = "K");
    SI.Temperature T(start = 290, fixed = true);
    Mode mode;
    Integer level "the mode as a number, set the same way";
    SI.HeatFlowRate Q;
    output Real Tout = T;
    output Real levelOut = level;
  initial equation
    mode = if T < T_low then Mode.Heating else Mode.Off;
    level = if T < T_low then 2 else 1;
  equation
    when T < T_low then
      mode = Mode.Heating;
      level = 2;
    elsewhen T > T_high then
      mode = Mode.Cooling;
      level = 3;
    end when;
    Q = if mode == Mode.Heating then 200 elseif mode == Mode.Cooling then -100 else 0;
    C*der(T) = G*(T_amb - T) + Q;
  end Room;
end Heating;
"""


@needs_msl()
def test_a_discrete_value_set_at_the_start_from_a_state_starts_there(tmp_path):
    """Initial equations that set a mode (an enumeration's, rumoca refused: 'found Enumeration')
    and an Integer from the start temperature: the room starts cold, so heating, and warms as
    T = 300 - 10 exp(-t/100) until T_high (t = 100 ln(10/2.85)), then cools. Dropped, the mode
    started off and the room cooled to the ambient 280 K."""
    (tmp_path / "Heating.mo").write_text(THERMOSTAT)
    model = compile_model([tmp_path / "Heating.mo"], "Heating.Room", libraries=[msl_path()])
    t = np.linspace(0, 120, 13)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.full((len(t), 1), 280.0), ["T_amb"]), options=None)
    assert res.ok, res.reason
    # (within the solver's default tolerance, rtol 1e-6 of 300 K)
    assert np.max(np.abs(res.output("Tout") - (300 - 10 * np.exp(-t / 100)))) < 1e-3
    assert np.all(res.output("levelOut") == 2)


def test_a_when_on_time_against_a_parameter_fires_where_the_runs_value_puts_it(tmp_path):
    """``when time > t0``: its time event sits where the compiled t0 puts it; a run (a fit, a
    calibration) that sets another t0 saw no event there, and the clause waited for the run's
    end. Watched as a relation on time, its crossing is found where the run's t0 puts it."""
    (tmp_path / "Late.mo").write_text("""
model Late
  parameter Real t0 = 1;
  Boolean a(start = true, fixed = true);
  output Real ya = if a then 1 else 0;
equation
  when time > t0 then
    a = false;
  end when;
end Late;
""")
    model = compile_model([tmp_path / "Late.mo"], "Late")
    t = np.linspace(0, 4, 17)
    for t0 in (1.0, 2.6):
        res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), params={"t0": t0},
                                      options=None)
        assert res.ok, res.reason
        off = t > t0 + 1e-9
        assert np.all(res.output("ya")[off] == 0) and np.all(res.output("ya")[t < t0 - 1e-9] == 1), t0


GEARED_AXIS = """
model Axis "a geared axis held against a load torque at rest, its speed controlled by a PI
  whose reference steps at 0.5 s; started at rest with its acceleration 0, as a robot's axis"
  import Modelica.Mechanics.Rotational;
  import Modelica.Blocks;
  Rotational.Components.Inertia motorJ(J = 0.01);
  Rotational.Components.BearingFriction friction(tau_pos = [0, 0.5; 1, 0.6]);
  Rotational.Components.IdealGear gear(ratio = 50);
  Rotational.Components.Inertia arm(J = 2);
  Rotational.Sources.ConstantTorque load(tau_constant = -20);
  Rotational.Sources.Torque drive;
  Rotational.Sensors.SpeedSensor speed;
  Blocks.Continuous.PI pi(k = 2, T = 0.1);
  Blocks.Sources.Step ref(height = 1, startTime = 0.5);
  Blocks.Math.Feedback err;
initial equation
  arm.phi = 0;
  arm.w = 0;
  arm.a = 0;
equation
  connect(drive.flange, motorJ.flange_a);
  connect(motorJ.flange_b, friction.flange_a);
  connect(friction.flange_b, gear.flange_a);
  connect(gear.flange_b, arm.flange_a);
  connect(load.flange, arm.flange_b);
  connect(speed.flange, arm.flange_b);
  connect(ref.y, err.u1);
  connect(speed.w, err.u2);
  connect(err.y, pi.u);
  connect(pi.y, drive.tau);
end Axis;
"""


@needs_msl()
def test_an_axis_started_at_rest_with_its_bearing_stuck_holds_its_load(tmp_path):
    """At rest the bearing friction is stuck, so arm.a = 0 holds whatever the controller's
    state: that state keeps its start value (0), the motor gives no torque, and the bearing
    holds the load through the gear, 20/50 N.m, below its 0.5 N.m of static friction. At the
    step the axis breaks loose and the controller brings it to speed 1."""
    (tmp_path / "Axis.mo").write_text(GEARED_AXIS)
    model = compile_model([tmp_path / "Axis.mo"], "Axis", libraries=[msl_path()])
    t = np.linspace(0, 2, 201)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    at = probed(model, res)
    still = t < 0.5
    assert np.all(at["friction.locked"][still] == 1)
    assert np.max(np.abs(at["pi.x"][still])) < 1e-12 and np.max(np.abs(at["arm.w"][still])) < 1e-12
    assert np.max(np.abs(np.abs(at["friction.tau"][still]) - 20 / 50)) < 1e-9
    assert at["friction.locked"][-1] == 0 and abs(at["arm.w"][-1] - 1) < 0.01


WEIR = """
model WeirTank "a tank that spills over a weir, started in steady state"
  import Modelica.Units.SI;
  parameter SI.Area A = 0.5 "cross-section";
  parameter SI.Height h_weir = 0.2 "crest of the weir";
  parameter Real k(unit = "m2/s") = 0.4 "weir coefficient, linearised";
  parameter SI.VolumeFlowRate q_in = 0.1 "inflow";
  SI.Height h(start = 1) "level";
  output SI.VolumeFlowRate q_out "spill";
initial equation
  der(h) = 0;
equation
  A*der(h) = q_in - q_out;
  q_out = if h >= h_weir then k*(h - h_weir) else 0;
end WeirTank;
"""


@needs_msl()
def test_a_relation_held_between_events_starts_as_the_start_values_make_it(tmp_path):
    """Steady in- and outflow: h = h_weir + q_in/k = 0.45. The relation h >= h_weir, held false
    at the start, shut the weir: no steady state (q_in = 0), h stayed at its start value 1 and
    drained to 0.45 after the first event. As the start value makes it (1 >= 0.2, spilling),
    the steady state is found and kept."""
    model, res = _weir_started(tmp_path, WEIR, "WeirTank")
    assert np.max(np.abs(res.output("q_out") - 0.1)) < 1e-9
    # the FMU starts there too (its discrete starts are the same expressions)
    from fmpy import simulate_fmu

    from mcl.compile.fmu.export import build_fmu

    fmu = build_fmu(model, tmp_path / "weir.fmu")
    out = simulate_fmu(str(fmu), stop_time=5.0, output=["h", "q_out"])
    assert np.max(np.abs(out["h"] - 0.45)) < 1e-9 and np.max(np.abs(out["q_out"] - 0.1)) < 1e-9


@needs_msl()
def test_a_held_relation_after_one_constant_in_time_starts_as_the_start_values_make_it(tmp_path):
    """The weir again, behind a relation on a variable the parameters fix (c > 0.3, read once at
    the parameters' values and left out of the relations watched): the weir's relation is then
    the first watched but the second met, and was read at the wrong place (past the end: never
    started as its start value makes it; the tank drained from 1 to 0.45)."""
    _weir_started(tmp_path, WEIR.replace("WeirTank", "WeirBehind").replace(
        'SI.Height h(start = 1) "level";', 'SI.Height h(start = 1) "level";\n  Real c;\n  Real q;').replace(
        "A*der(h) = q_in - q_out;", "c = 2*h_weir;\n  q = if c > 0.3 then q_in else 0.5*q_in;\n  A*der(h) = q - q_out;"),
        "WeirBehind")


def _weir_started(tmp_path, text: str, name: str):
    """(the model, its run over 5 s) of a weir tank ``text``, checked to start and stay at its
    steady level 0.45."""
    (tmp_path / "Weir.mo").write_text(text)
    model = compile_model([tmp_path / "Weir.mo"], name, libraries=[msl_path()])
    assert model.ode.init_unmet <= 1e-9
    t = np.linspace(0, 5, 6)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    assert np.max(np.abs(res.states[:, 0] - 0.45)) < 1e-9
    return model, res


CHECK_VALVE = """
package CheckValve
  function characteristic "a pump's head at its nominal speed, extrapolated linearly outside its data"
    input Real q "volume flow rate at nominal speed";
    output Real head;
  algorithm
    if q < 0 then
      head := 100 - 120*q;
    elseif q > 0.5 then
      head := -280*(q - 0.5);
    else
      head := 100 + q*(-120 - 160*q);
    end if;
  end characteristic;

  model Tank "a pump with a check valve lifts water into a tank; as its speed falls the valve shuts"
    parameter Real N_nominal = 1200 "rpm";
    parameter Real A(unit = "m2") = 2 "the tank's cross-section";
    parameter Real lift(unit = "m") = 60 "the static head the pump works against";
    input Real N "the pump's speed, rpm";
    Real level(unit = "m", start = 1, fixed = true);
    Real rho(unit = "kg/m3") "density (a little lower as the level rises)";
    Real head(unit = "m");
    Real V_flow(unit = "m3/s");
    Real m_flow(unit = "kg/s");
    Real s(start = 0) "the check valve's curvilinear abscissa (the MSL pump's)";
  equation
    rho = 1000 - 0.1*level;
    head = lift + level + 1e3*V_flow^2;
    V_flow = if s > 0 then s/rho else 0;
    head = if s > 0 then (N/N_nominal)^2*characteristic(V_flow*N_nominal/N) else (N/N_nominal)^2*100 - s;
    m_flow = rho*V_flow;
    A*rho*der(level) = m_flow - 0.01*level;
  end Tank;
end CheckValve;
"""


def test_a_pump_check_valve_in_a_loop_opens_and_shuts_as_its_law_says(tmp_path):
    """The MSL pump's check valve (``s > 0``, held between events) in an algebraic loop: shut,
    s is the head the pump lacks, its coefficient in the head equation 1; open, s is the flow
    and that coefficient 0. Torn to one unknown by dividing by it (PumpingSystem's loop), the
    solution was 0/0 once the valve opened. Against the level integrated by SciPy, the flow
    found by bisection on the pump's characteristic at each step."""
    from scipy.integrate import solve_ivp
    from scipy.optimize import brentq

    (tmp_path / "CheckValve.mo").write_text(CHECK_VALVE)
    model = compile_model([tmp_path / "CheckValve.mo"], "CheckValve.Tank")
    t = np.linspace(0, 40, 401)
    speed = 900 + 400 * np.sin(0.5 * t)          # the valve is open while (N/1200)^2 100 > 60 + level
    res = CasadiEngine().simulate(model, TimeSeries(t, speed[:, None], ["N"]),
                                  options=SimulationOptions(rtol=1e-9))
    assert res.ok, res.reason
    assert len(res.switches) >= 4                 # it opened and shut twice each

    def char(q):
        return 100 - 120 * q if q < 0 else -280 * (q - 0.5) if q > 0.5 else 100 + q * (-120 - 160 * q)

    def flow(level, n):
        need = 60 + level
        if (n / 1200) ** 2 * 100 <= need:
            return 0.0
        return brentq(lambda v: (n / 1200) ** 2 * char(v * 1200 / n) - need - 1e3 * v * v, 0, 1, xtol=1e-15)

    def rhs(tt, y):
        rho = 1000 - 0.1 * y[0]
        return [(rho * flow(y[0], np.interp(tt, t, speed)) - 0.01 * y[0]) / (2 * rho)]
    ref = solve_ivp(rhs, (0, 40), [1.0], t_eval=t, rtol=1e-10, atol=1e-12, max_step=0.01).y[0]
    level = res.states[:, model.ode.x_names.index("level")]
    assert np.ptp(level) > 1.0
    np.testing.assert_allclose(level, ref, atol=1e-5)


def test_a_call_that_runs_past_a_crossing_fails_soon_and_the_crossing_is_found(tmp_path):
    """The pump of the check-valve model held at speed, then slowed: the valve's relation has
    no trend to see while the speed is steady, so a long call starts and runs past the
    crossing with the valve held open, where the open branch has no solution. That call must
    fail within the steps its points have needed so far (frugal), not after 20 000 a point
    (13 s for this model), and the crossing be found after it: the valve shuts once, when the
    pump's head no longer lifts the water, as SciPy's integration of the same law says."""
    from scipy.integrate import solve_ivp

    (tmp_path / "CheckValve.mo").write_text(CHECK_VALVE)
    model = compile_model([tmp_path / "CheckValve.mo"], "CheckValve.Tank")
    t = np.linspace(0, 40, 401)
    speed = np.interp(t, [0, 5, 15, 40], [1100, 1100, 600, 600])
    res = CasadiEngine().simulate(model, TimeSeries(t, speed[:, None], ["N"]))
    assert res.ok, res.reason
    assert res.steps < 5000, res.steps            # no call given 20 000 steps to fail
    assert len(res.switches) == 1
    level = res.states[:, model.ode.x_names.index("level")]
    # shut: the level falls by its leak alone, 0.01 level / (A rho) a second
    shut = res.switches[0].time
    after = t > shut + 0.5
    ref = solve_ivp(lambda tt, y: [-0.01 * y[0] / (2 * (1000 - 0.1 * y[0]))], (t[after][0], 40),
                    [level[after][0]], t_eval=t[after], rtol=1e-10, atol=1e-12).y[0]
    np.testing.assert_allclose(level[after], ref, atol=1e-6)
    # it shuts where the pump's zero-flow head, (N/1200)^2 100, falls to the lift, 60 + level
    n_shut = np.interp(shut, t, speed)
    assert abs((n_shut / 1200) ** 2 * 100 - 60 - np.interp(shut, t, level)) < 1e-3
