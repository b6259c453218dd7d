"""The in-process engine integrates a run by Adams' methods where the model is not stiff at the
spacing of its output points (finely sampled data: the sampled inputs' kinks then cost BDF's
low orders for nothing), by BDF elsewhere, and by BDF again where an Adams run fails."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.signal import lsim, lti

from helpers import msl_path, needs_msl
from mcl import compile_model, simulate
from mcl.data import TimeSeries

MODELS = """
model Filter "a second-order low-pass at 50 Hz, driven by a sampled input"
  parameter Real w = 2*3.141592653589793*50;
  parameter Real d = 0.3;
  input Real u;
  Real x(start = 0, fixed = true);
  Real v(start = 0, fixed = true);
  output Real y = x;
equation
  der(x) = v;
  der(v) = w^2*(u - x) - 2*d*w*v;
end Filter;

model Stiffening "not stiff at its start, stiff by its end"
  input Real u;
  Real x(start = 1, fixed = true);
  output Real y = x;
equation
  der(x) = -(1 + 1e7*time^8)*x + u;
end Stiffening;
"""


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    d = tmp_path_factory.mktemp("method")
    (d / "Models.mo").write_text(MODELS)
    return {name: compile_model([d / "Models.mo"], name, libraries=[]) for name in ("Filter", "Stiffening")}


def _noise(t, seed=0):
    rng = np.random.default_rng(seed)
    return TimeSeries(t, rng.standard_normal((len(t), 1)), ["u"])


def _reference(rhs, data, x0):
    """The same model integrated by SciPy (Radau, tight), its input linear between samples."""
    u = lambda t: np.interp(t, data.time, data.values[:, 0])
    return solve_ivp(lambda t, x: rhs(t, x, u(t)), data.time[[0, -1]], x0, method="Radau", t_eval=data.time,
                     rtol=1e-10, atol=1e-12, max_step=float(np.diff(data.time).min())).y


def test_a_finely_sampled_model_runs_by_adams_and_agrees_with_an_independent_solver(models):
    data = _noise(np.arange(2000) * 1e-3)            # 1 kHz: the fastest mode times the spacing is 0.31
    res = simulate(models["Filter"], data)
    assert res.ok and res.method == "adams", (res.method, res.reason)
    w, d = 2 * np.pi * 50, 0.3
    # (exact for an input linear between samples: lsim's first-order hold)
    plant = lti([[0, 1], [-w**2, -2 * d * w]], [[0], [w**2]], [[1, 0]], [[0]])
    _, ref, _ = lsim(plant, data.values[:, 0], data.time, interp=True)
    assert np.max(np.abs(res.output("y") - ref)) < 1e-4 * np.ptp(ref)


def test_a_model_stiff_at_the_output_spacing_runs_by_bdf(models):
    coarse = simulate(models["Filter"], _noise(np.arange(200) * 0.1))    # the fastest mode times 0.1 s: 31
    assert coarse.ok and coarse.method == "bdf", coarse.method


def test_an_adams_run_that_the_solver_gives_up_is_run_again_by_bdf(models):
    """Stiffening's mode is 1/s at its start (Adams' methods at 0.01 s) and 1e7/s at its end,
    where Adams' methods fall back to their lowest orders: about 9 300 steps where BDF takes
    3 300. With a work budget of 6 000 steps the Adams run gives up; the run is taken again by
    BDF and succeeds."""
    data = _noise(np.arange(101) * 0.01)
    assert simulate(models["Stiffening"], data).method == "adams"
    res = simulate(models["Stiffening"], data, options={"max_work": 6000})
    assert res.ok and res.method == "bdf", (res.method, res.reason)
    ref = _reference(lambda t, x, u: [-(1 + 1e7 * t**8) * x[0] + u], data, [1.0])
    assert np.max(np.abs(res.output("y") - ref[0])) < 1e-4 * np.ptp(ref[0])


@needs_msl()
def test_a_call_whose_error_test_keeps_failing_is_tried_again_with_tighter_tolerances():
    """The MSL's induction machine started through a transformer: CVODES gave up on the call
    after its start at the default tolerances on a 2001-point grid (CV_ERR_FAILURE: its error
    test failing over and over) and ran on others. Tried again at a tenth of the tolerances,
    it runs on both grids, and the two runs agree."""
    model = compile_model([], "Modelica.Magnetic.FundamentalWave.Examples.BasicMachines.InductionMachines.IMC_Transformer",
                          libraries=[msl_path()]).with_outputs(["aimc.wMechanical"])
    runs = []
    for n in (2001, 5001):
        t = np.linspace(0.0, 2.5, n)
        res = simulate(model, TimeSeries(t, np.zeros((n, 0)), []), t_out=t)
        assert res.ok, res.reason
        runs.append((t, res.output("aimc.wMechanical")))
    (t1, w1), (t2, w2) = runs
    assert np.ptp(w2) > 100.0                          # (the machine runs up)
    assert np.max(np.abs(w1 - np.interp(t1, t2, w2))) < 1e-4 * np.ptp(w2)
