"""The in-process engine reports its work (solver steps) and stops a run that exceeds its work
budget or its wall-clock limit during the integration, not only between output chunks."""
import numpy as np
import pytest

from mcl import compile_model, simulate
from mcl.data import TimeSeries

# x chatters around 0 (noEvent: no event to restart at), so the solver crawls once it is there
CRAWL = """
model Crawl
  Real x(start = 1, fixed = true);
  Real y(start = 0, fixed = true);
  output Real o;
equation
  der(x) = if noEvent(x > 0) then -1 - 100*y^2 else 1 + 100*y^2;
  der(y) = 1;
  o = x;
end Crawl;
"""


@pytest.fixture(scope="module")
def crawl(tmp_path_factory):
    d = tmp_path_factory.mktemp("crawl")
    (d / "Crawl.mo").write_text(CRAWL)
    return compile_model([d / "Crawl.mo"], "Crawl")


def _none(t):
    return TimeSeries(t, np.zeros((len(t), 0)), [])


def test_a_run_reports_its_solver_steps(crawl):
    t = np.linspace(0, 0.2, 11)             # before x reaches 0 (t = 0.29): a smooth run
    res = simulate(crawl, _none(t))
    assert res.ok, res.reason
    assert res.steps > 0
    assert np.allclose(res.output("o"), 1 - t - 100 * t**3 / 3, atol=1e-4)
    more = simulate(crawl, _none(t), options={"rtol": 1e-10, "atol": 1e-12})
    assert more.steps > res.steps            # a tighter tolerance is more work


def test_a_run_beyond_its_work_budget_fails_saying_so(crawl):
    t = np.linspace(0, 1000, 11)
    res = simulate(crawl, _none(t), options={"max_work": 5000, "max_steps": 10**7})
    assert not res.ok and "work budget of 5000 solver steps" in res.reason


def test_the_time_limit_stops_a_crawling_integration(crawl):
    """One output interval needs millions of steps: the limit is enforced inside it."""
    t = np.linspace(0, 1000, 3)
    res = simulate(crawl, _none(t), options={"time_limit": 1.0, "max_steps": 10**8, "rtol": 1e-10,
                                             "atol": 1e-12})
    assert not res.ok and "time limit of 1 s exceeded" in res.reason


def test_the_time_limit_stops_a_crawl_whose_work_budget_is_far_away(crawl):
    """A work budget sizes the calls (a fit's path does not follow the machine's load), but not
    where the time left allows far fewer steps: the limit is still enforced inside a call."""
    t = np.linspace(0, 1000, 3)
    res = simulate(crawl, _none(t), options={"time_limit": 1.0, "max_steps": 10**8, "max_work": 10**9,
                                             "rtol": 1e-10, "atol": 1e-12})
    assert not res.ok and "time limit of 1 s exceeded" in res.reason


GROW = """
model Grow "unstable: x = exp(2 t)"
  Real x(start = 1, fixed = true);
  output Real o;
equation
  der(x) = 2*x;
  o = x;
end Grow;
"""


def test_a_run_that_passes_its_state_bound_stops_there(tmp_path):
    (tmp_path / "Grow.mo").write_text(GROW)
    grow = compile_model([tmp_path / "Grow.mo"], "Grow")
    t = np.linspace(0, 20, 201)                       # exp(40) at the end: 2e17
    free = simulate(grow, _none(t))
    assert free.ok and np.allclose(free.output("o"), np.exp(2 * t), rtol=1e-4)
    bounded = simulate(grow, _none(t), options={"state_bound": 1e3})
    assert not bounded.ok and "diverged" in bounded.reason
    crossed = float(bounded.reason.rsplit("t = ", 1)[1])
    assert np.log(1e3) / 2 <= crossed <= np.log(1e3) / 2 + 0.1     # stopped where it crossed
    assert bounded.steps < free.steps


OSCILLATOR = """
model Oscillator "a lightly damped oscillator driven by its input"
  input Real u;
  Real x(start = 0, fixed = true);
  Real v(start = 0, fixed = true);
  output Real y;
equation
  der(x) = v;
  der(v) = u - 0.2*v - 40*x;
  y = x;
end Oscillator;
"""


@pytest.mark.parametrize("work", [None, 10**9])
def test_a_runs_numbers_do_not_follow_the_machines_speed(tmp_path, monkeypatch, work):
    """The same run on a machine far slower (the step rate the budget measures) gives the same
    numbers to the last digit, with a work budget (a candidate's fit) or without one (the
    calibration): the calls, and so the solver's restarts, are not sized by the measured rate
    while the run fits in its time, nor ever with a work budget (they were: a loaded machine
    moved the fits)."""
    import mcl.engine_casadi as engine

    (tmp_path / "Oscillator.mo").write_text(OSCILLATOR)
    model = compile_model([tmp_path / "Oscillator.mo"], "Oscillator")
    t = np.linspace(0, 20, 20001)
    u = TimeSeries(t, np.sin(3.0 * t)[:, None] + np.sin(7.3 * t)[:, None], ["u"])
    steps = simulate(model, u).steps
    record = engine._Budget.record
    runs = []
    # the measured rate, made up: a fast machine, one where the run would take 4 s at 4x its
    # steps (a 15th of the time limit), and, with a work budget, one where it would take 100 s,
    # beyond the limit of 60 s (the budget's steps size the calls and the time is checked
    # between them; it sized them, and a loaded machine gave the Wiener-Hammerstein fits 29
    # calls where a quiet one gave 3)
    for seconds_per_step in (1e-7, 4.0 / (4 * steps), *([100.0 / (4 * steps)] if work else [])):
        monkeypatch.setattr(engine._Budget, "record", lambda self, n, seconds, points=0, r=seconds_per_step:
                            record(self, n, r * max(int(n), 1), points))
        res = simulate(model, u, options={"max_work": work})
        assert res.ok, res.reason
        runs.append(res.outputs)
    assert all(np.array_equal(runs[0], other) for other in runs[1:])


def test_a_failed_call_tells_how_many_of_its_points_it_got_past():
    """A call out of steps at its sixth point: the five before it are kept (the retry is those
    five, then the sixth alone with more steps; it was the first alone, over and over)."""
    import casadi as ca

    from mcl.engine_casadi import _passed

    x, t = ca.SX.sym("x", 2), ca.SX.sym("t")
    stiffening = 1 + 1e6 / (1 + ca.exp(-(t - 0.55) / 1e-3))       # a millionfold past t = 0.55
    grid = np.linspace(0.1, 1.0, 10)
    ode = ca.vertcat(x[1], -stiffening * x[0])                       # (an oscillator: 1000 rad/s)
    integ = ca.integrator("I", "cvodes", {"x": x, "t": t, "ode": ode}, 0.0, grid.tolist(),
                          {"max_num_steps": 200})
    with pytest.raises(RuntimeError, match="TOO_MUCH_WORK"):
        integ(x0=[1.0, 0.0])
    assert _passed(integ, grid) == 5


ONSET = """
model Onset "a slow oscillator whose spring stiffens a millionfold halfway"
  Real x(start = 1, fixed = true);
  Real v(start = 0, fixed = true);
  output Real o;
equation
  der(x) = v;
  der(v) = -(1 + 1e6/(1 + exp(-(time - 5)/0.1)))*x - 0.1*v;
  o = x;
end Onset;
"""


def test_a_run_that_turns_stiff_halfway_runs_within_its_work_budget(tmp_path):
    """Under a work budget (a fit's runs) each call's points get a few times the steps the
    points have needed: the run's second half needs 20x those of its first, and runs on, to
    the solution of the run without a budget, in about as many steps."""
    (tmp_path / "Onset.mo").write_text(ONSET)
    model = compile_model([tmp_path / "Onset.mo"], "Onset")
    t = np.linspace(0, 10, 201)
    free = simulate(model, _none(t), options={"max_steps": 10**6})
    budgeted = simulate(model, _none(t), options={"max_work": 10**7, "max_steps": 10**6})
    assert free.ok and budgeted.ok, (free.reason, budgeted.reason)
    assert np.allclose(budgeted.output("o"), free.output("o"), atol=1e-3)
    assert budgeted.steps < 1.5 * free.steps, (budgeted.steps, free.steps)
