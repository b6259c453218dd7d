"""Feasibility models q(w): cross-entropy fit, the online step of Algorithm 3, gradients."""
import numpy as np
import pytest

from mcl import hookimpl
from mcl.feasibility import LogisticFeasibility, NeuralFeasibility, binary_entropy
from mcl.registry import Registry


def test_untrained_model_is_maximally_uncertain():
    q = LogisticFeasibility()
    W = np.random.default_rng(0).normal(size=(5, 3))
    assert np.allclose(q.predict_proba(W), 0.5)
    assert np.allclose(binary_entropy(q.predict_proba(W)), 1.0)


def test_logistic_finds_a_hyperplane_through_the_origin():
    rng = np.random.default_rng(1)
    beta = np.array([-1.0, 0.3, 2.0])
    W = rng.uniform(-1, 1, (400, 3))
    y = W @ beta > 0
    q = LogisticFeasibility().fit(W[:300], y[:300])
    assert np.mean(q.predict(W[300:]) == y[300:]) > 0.95
    cos = q.coef_ @ beta / np.linalg.norm(q.coef_) / np.linalg.norm(beta)
    assert cos > 0.98


def test_symmetric_axis_handles_laws_invariant_under_sign_flip():
    """Feasible iff w1*w3 > 0: symmetric under w -> -w, a hyperplane after fixing sign(w1)."""
    rng = np.random.default_rng(2)
    W = rng.uniform(-1, 1, (400, 3))
    y = W[:, 0] * W[:, 2] > 0
    plain = LogisticFeasibility().fit(W[:300], y[:300])
    sym = LogisticFeasibility(symmetric_axis=0).fit(W[:300], y[:300])
    assert np.mean(plain.predict(W[300:]) == y[300:]) < 0.7
    assert np.mean(sym.predict(W[300:]) == y[300:]) > 0.95


def test_online_step_matches_hand_computed_gradient():
    """Algorithm 3, line 10: beta <- beta - alpha (q - y) w / ln 2 (h in bits)."""
    q = LogisticFeasibility(learning_rate=0.5)
    w = np.array([[0.2, -0.4, 0.1]])
    q.predict_proba(w)                      # scale_ = |w|, beta = 0, q = 0.5
    x = w[0] / q.scale_
    q.partial_fit(w, 0)
    assert np.allclose(q.theta_, -0.5 * (0.5 - 0.0) * x / np.log(2))
    assert q.predict_proba(w)[0] < 0.5      # the infeasible point became less likely


def test_cross_entropy_in_bits():
    q = LogisticFeasibility()
    W = np.array([[1.0, 0.0], [0.0, 1.0]])
    assert q.cross_entropy(W, [1, 0]) == pytest.approx(1.0)  # q = 0.5: one bit per example


@pytest.mark.parametrize("cls", [LogisticFeasibility, NeuralFeasibility])
def test_gradients_match_finite_differences(cls):
    rng = np.random.default_rng(3)
    W = rng.uniform(-1, 1, (200, 3))
    q = cls().fit(W, (W[:, 0] + W[:, 1] ** 2 > 0.2))
    w0 = np.array([[0.3, -0.2, 0.5]])
    g = q.grad_proba(w0)[0]
    gl = q.grad_log_proba(w0)[0]
    h = 1e-6
    fd = np.array([(q.predict_proba(w0 + h * e) - q.predict_proba(w0 - h * e))[0] / (2 * h) for e in np.eye(3)])
    assert np.allclose(g, fd, rtol=1e-5, atol=1e-8)
    assert np.allclose(gl, fd / q.predict_proba(w0)[0], rtol=1e-5, atol=1e-8)


def test_neural_model_learns_a_curved_boundary():
    rng = np.random.default_rng(4)
    W = rng.uniform(-1, 1, (600, 2))
    y = W[:, 0] ** 2 + W[:, 1] ** 2 < 0.5
    q = NeuralFeasibility(hidden=8).fit(W[:450], y[:450])
    assert np.mean(q.predict(W[450:]) == y[450:]) > 0.9


class Always:
    name = "always"

    def __init__(self, **_):
        pass

    def predict_proba(self, W):
        return np.ones(len(np.atleast_2d(W)))


class FeasibilityPlugin:
    @hookimpl
    def mcl_feasibility_models(self):
        return [Always]


def test_feasibility_models_are_plugins():
    reg = Registry(external=False, extra=[FeasibilityPlugin()])
    assert set(reg.feasibility_models) >= {"logistic", "neural", "always"}
    assert reg.feasibility_model("always").predict_proba([[1.0]])[0] == 1.0
