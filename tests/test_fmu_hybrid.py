"""Hybrid models in the FMU: when, pre, edge, sample, reinit, discrete variables and asserts run
in FMPy as Co-Simulation (defaults) and Model Exchange like mcl's own engine: a bouncing ball
against its exact solution, a sampled PI controller against its exact recursion, a hysteresis
controller against its switching times, two MSL examples against the in-process engine."""
import shutil

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave

from helpers import msl_path, series
from mcl import compile_model, simulate
from mcl.compile.fmu.export import build_fmu, validate_fmu
from mcl.engine_casadi import CasadiEngine
from mcl.model import FmuModel
from mcl.simulation import SimulationOptions
from test_events import BALL, HYSTERESIS, LATCH, STOPPING, _ball_truth

SAMPLED = """
model Sampled "a sampled PI controller holding its output between ticks, on a first-order plant"
  parameter Real Ts = 0.1 "sampling period";
  parameter Real kp = 2;
  parameter Real ki = 1;
  input Real r "set point";
  Real x(start = 0, fixed = true) "plant";
  discrete Real u(start = 0, fixed = true) "held control";
  discrete Real e_int(start = 0, fixed = true);
  Integer ticks(start = 0, fixed = true);
  output Real y;
equation
  der(x) = -x + u;
  y = x;
  when sample(0, Ts) then
    e_int = pre(e_int) + Ts * (r - x);
    u = kp * (r - x) + ki * e_int;
    ticks = pre(ticks) + 1;
  end when;
end Sampled;
"""

LIMITED = """
model Limited
  Real x(start = 0, fixed = true);
equation
  der(x) = 1;
  assert(x < 0.45, "x left its range");
end Limited;
"""


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("hybrid")
    out = {}
    for name, text in (("Ball", BALL), ("Hysteresis", HYSTERESIS), ("Sampled", SAMPLED), ("Limited", LIMITED),
                       ("Stopping", STOPPING), ("Latch", LATCH)):
        (d / f"{name}.mo").write_text(text)
        model = compile_model([d / f"{name}.mo"], name)
        out[name] = (model, build_fmu(model, d / f"{name}.fmu"))
    return out


def at(res, times):
    """FMPy's records at ``times``: Model Exchange also records each event, with the values
    before and after it; the last record of an instant is what the in-process engine gives."""
    t = res["time"]
    last = res[np.r_[t[1:] != t[:-1], True]]
    k = np.searchsorted(last["time"], times - 1e-9 * np.maximum(1.0, np.abs(times)))
    assert np.allclose(last["time"][k], times, rtol=1e-9, atol=1e-12)
    return last[k]


def event_times(res, name, least: float = 0.0):
    """Where Model Exchange recorded a jump of ``name`` (twice the same instant) by more than
    ``least``."""
    t, v = res["time"], res[name]
    return t[np.flatnonzero((t[1:] == t[:-1]) & (np.abs(v[1:] - v[:-1]) > least))]


def test_discrete_variables_are_exported_as_discrete_reals(fmus):
    model, path = fmus["Ball"]
    assert validate_fmu(path) == []
    md = read_model_description(str(path))
    var = {v.name: v for v in md.modelVariables}
    assert md.numberOfContinuousStates == 2 and md.numberOfEventIndicators == 1
    assert (var["n"].variability, var["n"].type, var["n"].initial) == ("discrete", "Real", "exact")
    assert var["vimp"].variability == "discrete" and var["h"].variability == "continuous"
    assert not any(n.startswith("$") for n in var)      # when-conditions' memories stay hidden
    assert [d.variable.name for d in md.derivatives] == ["der(h)", "der(v)"]
    _, hyst = fmus["Hysteresis"]
    out = {v.name: v for v in read_model_description(str(hyst)).modelVariables}["y"]
    assert (out.causality, out.variability) == ("output", "discrete")       # y = if on then 1 else 0


@pytest.mark.parametrize("kind", ["CoSimulation", "ModelExchange"])
def test_a_bouncing_ball_reinitialised_at_each_impact(fmus, kind):
    model, path = fmus["Ball"]
    res = simulate_fmu(str(path), stop_time=3.0, output_interval=0.01, fmi_type=kind,
                       output=["h", "v", "n", "vimp"])
    assert res["time"][-1] == pytest.approx(3.0)
    t = np.linspace(0, 3, 301)
    g = at(res, t)
    h, n, vimp = _ball_truth(t)
    tol = 1e-9 if kind == "CoSimulation" else 1e-4      # the embedded solver is exact on parabolas
    assert np.max(np.abs(g["h"] - h)) < tol
    assert np.array_equal(g["n"], n) and np.max(np.abs(g["vimp"] - vimp)) < 10 * tol
    own = CasadiEngine().simulate(model, series(t), options=SimulationOptions(rtol=1e-9, atol=1e-11))
    assert np.max(np.abs(own.states[:, 0] - g["h"])) < 1e-3 * np.ptp(h)
    if kind == "ModelExchange":          # the impacts, where FMPy's CVode located them
        g_, e = 9.81, 0.8
        impacts = np.sqrt(2 / g_) * (1 + 2 * np.cumsum(e ** np.arange(1, 7)) - 2 * e ** np.arange(1, 7))
        assert np.allclose(event_times(res, "n"), impacts[:6], atol=1e-6)


@pytest.mark.parametrize("kind", ["ModelExchange", "CoSimulation"])
def test_a_clutch_that_cycles_with_pre_held_starts_in_the_fmu_as_in_process(fmus, kind):
    """The FMU's event iteration falls back as the engine's does (test_events' Latch)."""
    _, path = fmus["Latch"]
    res = simulate_fmu(str(path), stop_time=2.0, output_interval=0.05, fmi_type=kind, output=["w", "startForward"])
    t = np.linspace(0, 2, 41)
    g = at(res, t)
    w = np.where(t < 1, 0.0, 0.25 * (t ** 2 - 1) - 0.2 * (t - 1))
    assert np.max(np.abs(g["w"] - w)) < 1e-4


def test_a_sampled_controller_against_its_exact_recursion(fmus):
    """u is held between the ticks of sample(0, 0.1): x = u + (x_k - u) exp(-(t - t_k))."""
    model, path = fmus["Sampled"]
    t = np.linspace(0, 3, 301)
    x, xs, u, e_int, tk = 0.0, [], 0.0, 0.0, 0.0
    k = 0
    for ti in t:
        while 0.1 * k <= ti + 1e-12:        # the tick at 0.1 k, then the held control
            x = u + (x - u) * np.exp(-(0.1 * k - tk))
            tk, e_int = 0.1 * k, e_int + 0.1 * (1 - x)
            u, k = 2 * (1 - x) + e_int, k + 1
        xs.append(u + (x - u) * np.exp(-(ti - tk)))
    exact = np.array(xs)
    ones = series(t, r=np.ones_like(t))
    opts = {"rtol": 1e-9, "atol": 1e-11}
    own, fmu = simulate(model, ones, options=opts), simulate(FmuModel.read(path), ones, options=opts)
    assert own.ok and fmu.ok and fmu.engine == "fmu", (own.reason, fmu.reason)
    assert np.max(np.abs(own.output("y") - exact)) < 1e-6 and np.max(np.abs(fmu.output("y") - exact)) < 1e-9
    table = np.array([(0.0, 1.0), (3.0, 1.0)], dtype=[("time", float), ("r", float)])
    for kind, tol in (("CoSimulation", 1e-9), ("ModelExchange", 1e-4)):
        res = at(simulate_fmu(str(path), stop_time=3.0, output_interval=0.01, input=table, fmi_type=kind,
                              output=["y", "ticks"]), t)
        assert np.max(np.abs(res["y"] - exact)) < tol, kind
        assert res["ticks"][-1] == 31, kind                 # 0, 0.1, ..., 3.0


# FMPy's own logger prints the FMU's messages (a logger of one's own is not used here: FMPy keeps
# the last one in a global of its native logging proxy, which crashes the next FMU that logs
# once the callback is gone)

def test_a_hysteresis_switches_where_it_should(fmus, capsys):
    model, path = fmus["Hysteresis"]
    for kind in ("CoSimulation", "ModelExchange"):
        res = simulate_fmu(str(path), stop_time=10.0, output_interval=0.05, fmi_type=kind,
                           output=["T", "on", "k", "s"])
        t = np.linspace(0, 10, 201)
        g = at(res, t)
        T = np.interp(t, [0, 1, 5, 7, 11], [20, 22, 18, 22, 18])
        assert np.max(np.abs(g["T"] - T)) < 1e-6, kind
        away = np.min(np.abs(t[:, None] - np.array([1.0, 5.0, 7.0])), axis=1) > 1e-6   # not on a switch
        assert np.array_equal(g["on"][away], ((t < 1) | ((t > 5) & (t < 7)))[away]), kind
        assert np.array_equal(g["k"][away], np.where(t > 5, 2, 1)[away]), kind     # one per rising edge of on
        ticks = np.floor(t / 0.25 + 1e-9) * 0.25
        assert np.allclose(g["s"], np.interp(ticks, [0, 1, 5, 7, 11], [20, 22, 18, 22, 18]), atol=1e-6)
        if kind == "ModelExchange":
            assert np.allclose(event_times(res, "on"), [1, 5, 7], atol=1e-8)
        warnings = [line for line in capsys.readouterr().out.splitlines() if line.startswith("[WARNING]")]
        assert len(warnings) == 1 and "too warm" in warnings[0], kind     # level warning: logged once


def test_an_assert_of_level_error_fails_with_its_message(fmus, capsys):
    _, path = fmus["Limited"]
    for kind, call in (("CoSimulation", "fmi2DoStep"), ("ModelExchange", "fmi2CompletedIntegratorStep")):
        with pytest.raises(Exception, match=call):
            simulate_fmu(str(path), stop_time=1.0, fmi_type=kind)
        out = capsys.readouterr().out
        assert "[ERROR] assertion failed at t = 0.45: x left its range" in out, kind
    t = np.linspace(0, 1, 11)
    res = simulate(FmuModel.read(path), series(t))
    assert not res.ok and "x left its range" in res.reason and "Limited.mo:6" in res.reason


def test_terminate_ends_the_fmus_run_in_both_kinds(fmus, capsys):
    """terminate() in the FMU: Co-Simulation's step returns fmi2Discard with fmi2Terminated
    true, Model Exchange's completed step and event update ask the importer to stop; FMPy ends
    each run there, and mcl's FMU engine gives the points up to it, as its own engine does."""
    _, path = fmus["Stopping"]
    for kind in ("CoSimulation", "ModelExchange"):
        res = simulate_fmu(str(path), stop_time=1.0, fmi_type=kind, output=["level"])
        assert 0.549 <= res["time"][-1] <= 0.5501 and np.isclose(res["level"][-1], 2 * res["time"][-1], atol=1e-6), kind
        assert "terminated at t = 0.55" in capsys.readouterr().out, kind
    t = np.linspace(0, 1, 11)
    res = simulate(FmuModel.read(path), series(t))
    assert res.ok and len(res.time) == 6 and res.time[-1] == pytest.approx(0.5)
    assert "the tank is full" in res.terminated


def test_discrete_start_values_are_settable_and_the_state_restorable(fmus):
    _, path = fmus["Ball"]
    res = simulate_fmu(str(path), stop_time=1.0, output_interval=0.1, start_values={"n": 5}, output=["n"])
    assert res["n"][0] == 5 and res["n"][-1] == 6                     # one impact before t = 1, at 0.45
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzipped = extract(str(path))
    try:
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier)
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.doStep(0.0, 0.3)
        saved = fmu.getFMUState()
        fmu.doStep(0.3, 0.7)                                            # across the first impact
        first = fmu.getReal([vr["h"], vr["n"], vr["vimp"]])
        fmu.setFMUState(saved)
        assert fmu.getReal([vr["n"]]) == [0.0]
        fmu.doStep(0.3, 0.7)
        assert fmu.getReal([vr["h"], vr["n"], vr["vimp"]]) == first and first[1] == 1.0
        fmu.freeFMUState(saved)
        fmu.terminate()
        fmu.freeInstance()
    finally:
        shutil.rmtree(unzipped, ignore_errors=True)


# -- MSL examples with events: CS and ME against the in-process engine --------------------------

MSL = msl_path()
MSL_HYBRID = ["Modelica.Thermal.HeatTransfer.Examples.ControlledTemperature",     # OnOffController: pre
              "Modelica.Electrical.PowerConverters.Examples.ACDC.Rectifier1Pulse.Thyristor1Pulse_R"]  # sample


@pytest.fixture(scope="module")
def msl_fmus(tmp_path_factory):
    """The examples' FMUs, their DefaultExperiment from the class's annotation (in the library
    given)."""
    if MSL is None:
        pytest.skip("the Modelica Standard Library is not found (MODELICAPATH or ../shared/msl)")
    d = tmp_path_factory.mktemp("msl_hybrid")
    out = {}
    for name in MSL_HYBRID:
        model = compile_model([], name, libraries=[MSL])
        out[name] = (model, build_fmu(model, d / f"{name.split('.')[-1]}.fmu", libraries=[MSL]))
    return out


def _ambiguous(t, ode):
    """Grid points on a clock tick or time event: values from either side of the event are right."""
    hit = np.zeros(len(t), dtype=bool)
    eps = 1e-9 * np.maximum(1.0, np.abs(t))
    for start, period in ode.events["clocks"]:
        n = np.round((t - start) / period)
        hit |= (n >= 0) & (np.abs(start + n * period - t) <= eps)
    for te in ode.time_events:
        hit |= np.abs(t - te) <= eps
    return hit


@pytest.mark.slow
@pytest.mark.parametrize("name", MSL_HYBRID)
def test_msl_hybrid_examples_agree_with_the_in_process_engine(msl_fmus, name):
    """FMPy with its defaults (Co-Simulation, the DefaultExperiment) and as Model Exchange reach
    the stop time; every state within 1e-3 of its range of the in-process engine on the same
    grid; Model Exchange's events (located by CVode) fall where the in-process values jump."""
    model, path = msl_fmus[name]
    assert validate_fmu(path) == []
    md = read_model_description(str(path))
    stop = float(md.defaultExperiment.stopTime)
    assert stop == {"ControlledTemperature": 10.0, "Thyristor1Pulse_R": 0.1}[name.split(".")[-1]]
    names = [n for n in model.ode.x_names if not n.startswith("$")]
    discrete = {v.name for v in md.modelVariables if v.variability == "discrete" and v.causality == "local"}
    assert discrete and discrete <= set(names)
    t = None
    for kind in ("CoSimulation", "ModelExchange"):
        if kind == "CoSimulation":            # all defaults: FMPy's grid over the DefaultExperiment
            res = simulate_fmu(str(path), output=names)
            t = res["time"]
            own = CasadiEngine().simulate(model, series(t), options=SimulationOptions(rtol=1e-8, atol=1e-10))
            assert own.ok, own.reason
        else:                                 # defaults but the output grid, to compare on the same one
            res = simulate_fmu(str(path), output=names, fmi_type=kind, output_interval=float(t[1] - t[0]))
        assert res["time"][-1] == pytest.approx(stop), kind
        g = at(res, t)
        skip = _ambiguous(t, model.ode)
        slack = 1e-4 * stop            # how far apart two solvers put one state event
        for n in names:
            ref = own.states[:, model.ode.x_names.index(n)]
            near = np.zeros(len(t), dtype=bool)
            if kind == "ModelExchange" and n in discrete:
                # (a jump within the values' tolerance is none to match: a period's mean
                # current computed again at a tick, equal to rounding in steady state)
                events = event_times(res, n, 1e-3 * max(np.ptp(ref), 1e-12))
                jumps = np.flatnonzero(ref[1:] != ref[:-1])
                for te in events:               # inside a step where the in-process value jumps
                    assert np.any((t[jumps] - slack <= te) & (te <= t[jumps + 1] + slack)), (n, te)
                near = np.min(np.abs(t[:, None] - events[None, :]), axis=1, initial=np.inf) <= slack
            err = np.max(np.abs(g[n] - ref)[~(skip | near)]) / max(np.ptp(ref), 1e-12)
            assert err < 1e-3, (kind, n, err)


DIODE_SAMPLER = """
model DiodeSampler "a diode charging a capacitor through a resistor; the peak sampled"
  parameter Real R = 100 "series resistance";
  parameter Real C = 1e-3 "capacitance";
  parameter Real Is = 1e-9 "diode saturation current";
  parameter Real Vt = 0.025 "thermal voltage";
  Real vC(start = 0, fixed = true) "capacitor voltage";
  Real v1 "diode anode";
  Real i "diode current";
  discrete Real peak(start = 0, fixed = true) "largest sampled capacitor voltage";
  output Real y;
equation
  i = (2 * sin(2 * 3.14159265358979 * 5 * time) - v1) / R;
  i = Is * (exp((v1 - vC) / Vt) - 1);
  C * der(vC) = i;
  when sample(0, 0.01) then
    peak = max(pre(peak), vC);
  end when;
  y = vC;
end DiodeSampler;
"""


def test_a_hybrid_model_with_an_algebraic_loop_keeps_its_loop_solve_compact(tmp_path):
    """A when-clause beside a diode's loop (its anode voltage): the in-process engine and the
    FMU follow SciPy's solution, and the loop's Newton solve is not unrolled into every
    function (expanded, its fallbacks made 4 MB of C code, evaluated in full at each call)."""
    import zipfile

    from scipy.integrate import solve_ivp
    from scipy.optimize import brentq

    (tmp_path / "DiodeSampler.mo").write_text(DIODE_SAMPLER)
    model = compile_model([tmp_path / "DiodeSampler.mo"], "DiodeSampler")
    assert model.ode.nonlinear_blocks == 1

    def dvc(t, v):
        vs, vc = 2 * np.sin(2 * np.pi * 5 * t), v[0]
        v1 = brentq(lambda a: (vs - a) / 100 - 1e-9 * np.expm1((a - vc) / 0.025),
                    min(vs, vc) - 1, max(vs, vc) + 1, xtol=1e-14)
        return [(vs - v1) / 100 / 1e-3]

    t = np.linspace(0, 0.5, 501)
    truth = solve_ivp(dvc, (0, 0.5), [0.0], t_eval=t, rtol=1e-10, atol=1e-12, max_step=1e-3).y[0]
    res = simulate(model, series(t), t_out=t, options={"rtol": 1e-9, "atol": 1e-11})
    assert res.ok, res.reason
    assert np.max(np.abs(res.output("y") - truth)) < 1e-4 * np.ptp(truth)

    fmu = build_fmu(model, tmp_path / "DiodeSampler.fmu")
    with zipfile.ZipFile(fmu) as z:
        assert z.getinfo("sources/mcl_funcs.c").file_size < 1.5e6
    theirs = simulate_fmu(str(fmu), stop_time=0.5, output_interval=0.001, relative_tolerance=1e-8,
                          output=["y"])
    assert np.max(np.abs(np.interp(t, theirs["time"], theirs["y"]) - truth)) < 2e-3 * np.ptp(truth)
