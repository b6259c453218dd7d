"""Full-discretisation LM and backward elimination (paper 004)."""
import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mcl.lm import (Blocks, IdentificationProblem, Measurements, direct_step,
                         discretisation_grid, levenberg_marquardt, removal_estimates, structured_step)
from mcl.sparsify import AllAtOnce, BackwardElimination

MONOMIALS = ["1", "x1", "x2", "x1^2", "x1*x2", "x2^2"]
DEGREES = [0, 1, 1, 2, 2, 2]
NAMES = [f"x1:{m}" for m in MONOMIALS] + [f"x2:{m}" for m in MONOMIALS]


def library_rhs(t, x, a):
    phi = ca.vertcat(1, x[0], x[1], x[0] ** 2, x[0] * x[1], x[1] ** 2)
    return ca.vertcat(ca.dot(a[:6], phi), ca.dot(a[6:], phi))


def random_blocks(N, m, n, p, seed):
    rng = np.random.default_rng(seed)
    b = Blocks(rng.normal(size=(N, m)), rng.normal(size=(N, m, n)), rng.normal(size=(N, m, n)),
               rng.normal(size=(N, m, p)), rng.normal(size=p), 0.1 * np.eye(p))
    b.Z[-1] = 0
    b.X[::3, -2:] = 0          # rows of unmeasured outputs are zero padding
    return b


@pytest.mark.parametrize("segments", [1, 2, 7, 40])
def test_structured_step_equals_direct_sparse_solve(segments):
    b = random_blocks(N=301, m=9, n=3, p=5, seed=segments)
    ref = direct_step(b, 1e-2)
    got = structured_step(b, 1e-2, segments)
    assert np.max(np.abs(got - ref)) <= 1e-10 * np.max(np.abs(ref))


def test_appendix_a_grid_keeps_measurement_times():
    t_m = np.array([0.0, 0.3, 0.35, 1.0, 2.2])
    t_d, idx = discretisation_grid(t_m, 0.1)
    assert np.allclose(t_d[idx], t_m)
    assert np.max(np.diff(t_d)) <= 0.1 + 1e-12 and np.all(np.diff(t_d) > 0)


def oscillator_problem(seed=0, partial=True):
    """x1' = x2, x2' = -2 x1 - 0.4 x2 + 0.5 x1^2 (hidden quadratic term); irregular samples,
    x2 measured only at every second sample."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0, 15, 120))
    t[0] = 0.0
    sol = solve_ivp(lambda s, x: [x[1], -2 * x[0] - 0.4 * x[1] + 0.5 * x[0] ** 2], (0, 15), [1.0, 0.0],
                    t_eval=t, rtol=1e-10, atol=1e-12)
    y = sol.y + rng.normal(0, 0.01, sol.y.shape)
    series = [(t, y[0], 0), (t[::2], y[1, ::2], 1)] if partial else [(t, y[0], 0), (t, y[1], 1)]
    meas = Measurements.merge(series, 2)
    return IdentificationProblem(library_rhs, lambda s, x: x, 2, 12, meas, dt=0.02, Sx=0.1, Sy=0.01,
                                 mu_x=1e-8, mu_a=1e-6)


def test_recovers_hidden_term_with_partial_irregular_measurements():
    prob = oscillator_problem()
    res = BackwardElimination("bic", segments=8, lm_options={"max_iter": 60}).fit(
        prob, prob.initial_states(), np.zeros(12), NAMES, DEGREES * 2)
    terms = res.terms()
    assert set(terms) == {"x1:x2", "x2:x1", "x2:x2", "x2:x1^2"}
    assert terms["x1:x2"] == pytest.approx(1.0, rel=0.02)
    assert terms["x2:x1"] == pytest.approx(-2.0, rel=0.02)
    assert terms["x2:x1^2"] == pytest.approx(0.5, rel=0.15)


def test_removal_estimate_matches_the_retrained_cost():
    prob = oscillator_problem(partial=False)
    fit = levenberg_marquardt(prob, prob.initial_states(), np.zeros(12), segments=4, max_iter=80)
    est = removal_estimates(prob.blocks(fit.X, fit.a), fit.a, segments=4)
    for k in (3, 4, 5, 10, 11):  # terms whose true value is zero: the linearisation is accurate there
        active = np.ones(12, bool)
        active[k] = False
        refit = levenberg_marquardt(prob, fit.X, fit.a, active, segments=4, max_iter=80)
        assert est[k] == pytest.approx(refit.cost, rel=1e-2)
    assert np.all(est >= fit.cost * (1 - 1e-9))   # removing a term never lowers the minimum


def test_pruning_stops_where_the_threshold_says():
    prob = oscillator_problem(partial=False)
    tau = 0.05
    res = BackwardElimination("threshold", threshold=tau, prioritiser=AllAtOnce(), segments=4,
                              lm_options={"max_iter": 60}).fit(prob, prob.initial_states(), np.zeros(12), NAMES)
    dense = res.path[0].cost
    accepted = [s for s in res.path[1:] if s.accepted]
    refused = [s for s in res.path[1:] if not s.accepted]
    assert accepted and all(s.cost <= (1 + tau) * dense for s in accepted)
    assert len(refused) == 1 and refused[0].cost > (1 + tau) * dense   # stops at the first refusal
    assert res.path[-1] is refused[0]


@pytest.mark.parametrize("variance", ["known", "estimated"])
def test_pruning_stops_where_the_information_criterion_says(variance):
    prob = oscillator_problem(partial=False)
    res = BackwardElimination("bic", variance=variance, prioritiser=AllAtOnce(), segments=4,
                              lm_options={"max_iter": 60}).fit(prob, prob.initial_states(), np.zeros(12), NAMES)
    n = prob.M.sum()

    def bic(step):   # recomputed from the path: V + k ln n, or n ln(V/n) + k ln n
        fit = step.cost if variance == "known" else n * np.log(step.cost / n)
        return fit + len(step.active) * np.log(n)

    best = bic(res.path[0])
    for step in res.path[1:]:
        assert step.accepted == (bic(step) <= best)
        best = bic(step) if step.accepted else best
    assert not res.path[-1].accepted


def test_batch_removal_and_kept_parameters():
    prob = oscillator_problem(partial=False)
    one = BackwardElimination("bic", segments=4, lm_options={"max_iter": 60}).fit(
        prob, prob.initial_states(), np.zeros(12), NAMES, DEGREES * 2)
    many = BackwardElimination("bic", segments=4, lm_options={"max_iter": 60}, batch=4).fit(
        prob, prob.initial_states(), np.zeros(12), NAMES, DEGREES * 2, keep=["x1:1"])
    assert set(many.terms()) == set(one.terms()) | {"x1:1"}
    assert any(s.accepted and s.removed.count(",") >= 1 for s in many.path[1:])   # several at once
    assert all("x1:1" in s.active for s in many.path)


def test_exchange_swaps_a_wrongly_kept_term_for_the_true_one():
    from mcl.sparsify import _State

    prob = oscillator_problem(partial=False)
    wrong = np.array([n in {"x1:x2", "x2:x1", "x2:x2", "x2:x1*x2"} for n in NAMES])  # x1*x2, not x1^2
    fit = levenberg_marquardt(prob, prob.initial_states(), np.zeros(12), wrong, segments=4, max_iter=80)
    pruner = BackwardElimination("bic", segments=4, lm_options={"max_iter": 80}, exchange=True)
    pruner._dense = fit.cost
    st = _State(wrong, fit.X, fit.a, fit.cost, pruner._score(prob, fit.X, fit.a, wrong, fit.cost, fit.cost))
    path = []
    assert pruner._exchange(prob, st, np.ones(12, bool), NAMES, path)
    assert {n for n, on in zip(NAMES, st.active) if on} == {"x1:x2", "x2:x1", "x2:x2", "x2:x1^2"}
    assert path[-1].removed == "x2:x1*x2 -> x2:x1^2" and path[-1].cost < fit.cost
    assert not pruner._exchange(prob, st, np.ones(12, bool), NAMES, [])   # nothing better left


def test_segment_groups_on_more_threads_than_cores(monkeypatch):
    monkeypatch.setenv("MCL_LM_THREADS", "3")
    b = random_blocks(N=200, m=6, n=2, p=4, seed=3)
    assert np.allclose(structured_step(b, 1e-3, 11), direct_step(b, 1e-3), rtol=1e-9, atol=1e-12)


def test_backward_elimination_path_plot(tmp_path):
    prob = oscillator_problem()
    res = BackwardElimination("bic", segments=4, lm_options={"max_iter": 40}).fit(
        prob, prob.initial_states(), np.zeros(12), NAMES, DEGREES * 2)
    res.save(tmp_path, grid=prob.t)
    assert (tmp_path / "path.png").stat().st_size > 10_000
    law = (tmp_path / "law.txt").read_text()
    assert law.startswith("dx1/dt = ") and "*x1^2" in law.splitlines()[1]
    states = np.loadtxt(tmp_path / "states.csv", delimiter=",", skiprows=1)
    assert states.shape == (prob.N, 3) and np.allclose(states[:, 1:], res.X)


def test_prioritisers_are_plugins():
    from mcl import hookimpl
    from mcl.registry import Registry
    from mcl.sparsify import Prioritiser

    class LinearFirst(Prioritiser):
        name = "linear-first"

        def stages(self, names, degrees):
            return [[k for k, d in enumerate(degrees) if d == 1]]

    class Plugin:
        @hookimpl
        def mcl_prioritisers(self):
            return [LinearFirst]

    reg = Registry(external=False, extra=[Plugin()])
    assert {"degree", "all", "linear-first"} <= set(reg.prioritisers)
    stages = reg.prioritisers["degree"]().stages(NAMES, DEGREES * 2)
    assert [sorted({DEGREES[k % 6] for k in s}) for s in stages] == [[2], [1], [0]]
    assert reg.prioritisers["linear-first"]().stages(NAMES, DEGREES * 2) == [[1, 2, 7, 8]]



def test_criteria_are_plugins():
    """A third party's criterion is found by name and scores like the built-in ones."""
    from mcl import hookimpl
    from mcl.errors import ConfigError
    from mcl.registry import Registry
    from mcl.stats import Criterion

    class HannanQuinn(Criterion):
        name = "hqc"

        def penalty(self, n):
            return 2.0 * np.log(np.log(max(n, 3)))

    class Plugin:
        @hookimpl
        def mcl_criteria(self):
            return [HannanQuinn]

    reg = Registry(external=False, extra=[Plugin()])
    assert {"bic", "aic", "aicc", "hqc"} <= set(reg.criteria)
    hqc, bic = reg.criterion("hqc"), reg.criterion("bic")
    n, rss = 1000, 2.5
    assert hqc.score(rss, n, 3) - hqc.score(rss, n, 2) == pytest.approx(2 * np.log(np.log(n)))
    assert bic.score(rss, n, 3) - bic.score(rss, n, 2) == pytest.approx(np.log(n))
    assert reg.criterion(hqc) is hqc
    with pytest.raises(ConfigError, match="no criterion named 'hq'.*did you mean 'hqc'"):
        reg.criterion("hq")

def test_blockwise_gradient_equals_sparse_jacobian_product():
    from mcl.lm import jacobian_matrix

    b = random_blocks(N=50, m=7, n=3, p=4, seed=9)
    ref = 2 * jacobian_matrix(b).T @ np.concatenate([b.g.ravel(), b.ga])
    assert np.allclose(b.gradient(), ref, rtol=1e-12, atol=1e-12)


def test_compiled_model_with_template_terms_as_parameters(tmp_path):
    """f = the compiled RC circuit with Rx replaced by w1 i = w2 v + w3 v^3 (w1 fixed at 1);
    full-discretisation LM recovers the hidden law from noisy output samples."""
    from helpers import LIB, RC_MODEL
    from mcl.api import compile_model
    from mcl.data import TimeSeries
    from mcl.graph import build_graph
    from mcl.lm import CompiledRhs
    from mcl.swap import swap_component, write_package
    from mcl.templates import PolynomialTemplate

    path = write_package(tmp_path, "FitCircuit", [RC_MODEL])
    graph = build_graph([LIB, path], "FitCircuit.RC")
    tm = swap_component(graph, "Rx", PolynomialTemplate(lhs=["i"], rhs=["v", "v^3"]), tmp_path / "learn")
    model = compile_model(tm.sources, tm.model_name)
    t = np.linspace(0, 20, 20001)
    u = 1.5 * np.sin(0.9 * t) + 0.8 * np.sin(2.3 * t + 1.0)
    sol = solve_ivp(lambda s, e: [((np.interp(s, t, u) - e[0]) - 0.5 * e[0] - 0.3 * e[0] ** 3) / 0.5],
                    (0, 20), [0.0], t_eval=t[::50], rtol=1e-10, atol=1e-12, max_step=0.01)
    rng = np.random.default_rng(0)
    meas = Measurements(t[::50], (sol.y[0] + rng.normal(0, 0.01, sol.y.shape[1]))[:, None])
    rhs = CompiledRhs(model, TimeSeries(t, u[:, None], ["u"]), ["Rx.w2", "Rx.w3"], {"Rx.w1": 1.0})
    prob = IdentificationProblem(rhs, rhs.output, len(model.ode.x_names), 2, meas, dt=0.05,
                                 Sx=0.1, Sy=0.01, mu_x=1e-8, mu_a=1e-8)
    fit = levenberg_marquardt(prob, prob.initial_states(), np.array([0.1, 0.1]), segments=8, max_iter=100)
    assert fit.a == pytest.approx([0.5, 0.3], rel=0.03)


def test_model_written_in_plain_numpy():
    """f with np.sin / np.array instead of CasADi calls: a pendulum's gain recovered."""
    t = np.linspace(0, 10, 101)
    sol = solve_ivp(lambda s, x: [x[1], -3.0 * np.sin(x[0]) - 0.2 * x[1]], (0, 10), [1.0, 0.0],
                    t_eval=t, rtol=1e-10, atol=1e-12)
    meas = Measurements(t, sol.y.T + np.random.default_rng(1).normal(0, 1e-3, sol.y.T.shape))

    def f(s, x, a):
        return np.array([x[1], -a[0] * np.sin(x[0]) - a[1] * x[1]])

    prob = IdentificationProblem(f, lambda s, x: x, 2, 2, meas, dt=0.02, Sx=0.1, Sy=1e-3, mu_a=1e-8)
    fit = levenberg_marquardt(prob, prob.initial_states(), np.zeros(2), segments=4, max_iter=50)
    assert fit.a == pytest.approx([3.0, 0.2], rel=2e-3)


def test_steps_outside_the_model_domain_are_rejected():
    """f = -sqrt(a) x is NaN for a < 0. From a = 1 the first Gauss-Newton step overshoots to
    a < 0: that step is refused (lambda grows) and LM still converges to a = 0.04; states
    outside the domain are a clear error."""
    from mcl.lm import BlockEvaluationFailed

    t = np.linspace(0, 4, 41)
    meas = Measurements(t, np.exp(-0.2 * t)[:, None])
    prob = IdentificationProblem(lambda s, z, a: -ca.sqrt(a[0]) * z, lambda s, z: z, 1, 1, meas, dt=0.01,
                                 Sx=0.01, Sy=1e-3, mu_a=1e-9)
    X0 = prob.initial_states()
    failed, evaluate = [], prob.blocks

    def blocks(X, a):
        try:
            return evaluate(X, a)
        except BlockEvaluationFailed:
            failed.append(a.copy())
            raise

    prob.blocks = blocks
    fit = levenberg_marquardt(prob, X0, np.array([1.0]), lam0=1e-9, max_iter=100)
    assert failed and failed[0][0] < 0
    assert fit.a[0] == pytest.approx(0.04, rel=1e-2)
    with pytest.raises(BlockEvaluationFailed):
        evaluate(X0, np.array([-1.0]))
