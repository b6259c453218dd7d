"""Feasibility models q(w; beta) ~ P(simulation with parameters w succeeds) (paper 000, sec. III).

Both follow scikit-learn's conventions: the constructor stores options, ``fit`` learns from
labelled points by minimising the cross-entropy of Proposition 3.2,

    H(beta; S) = -1/|S| sum_i [ p_i log2 q(w_i) + (1 - p_i) log2(1 - q(w_i)) ],

and ``partial_fit`` takes the single online gradient step of Algorithm 3, line 10:
beta <- beta - alpha * grad h(beta; (w, y)). Before any data, q = 0.5 everywhere (q_0 of
Algorithm 1), which a zero output layer gives exactly.

``symmetric_axis``: a template linear in w describes the same law for w and -w (G(xi; w) = 0 iff
G(xi; -w) = 0), so feasibility is symmetric under w -> -w and no single hyperplane through the
origin can separate it globally. Mapping each w to the half-space where w[axis] > 0 first makes
the paper's hyperplane model apply (sec. V: beta^T w > 0) without losing anything.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

LN2 = np.log(2.0)


def _sigmoid(z):
    return 0.5 * (1.0 + np.tanh(0.5 * np.asarray(z, dtype=float)))


def binary_entropy(q) -> np.ndarray:
    """-(q log2 q + (1-q) log2(1-q)) in bits; 1 at q = 0.5, 0 at q in {0, 1}."""
    q = np.clip(np.asarray(q, dtype=float), 1e-15, 1 - 1e-15)
    return -(q * np.log2(q) + (1 - q) * np.log2(1 - q))


class FeasibilityModel:
    """Base class. Subclasses implement ``_logit``, ``_logit_grad_params``, ``_logit_grad_w``."""

    name = ""

    def __init__(self, l2: float = 1e-4, learning_rate: float = 0.5, symmetric_axis: int | None = None):
        self.l2 = l2
        self.learning_rate = learning_rate
        self.symmetric_axis = symmetric_axis

    # ---- what subclasses provide --------------------------------------------------------
    def _init_params(self, n: int) -> np.ndarray:
        raise NotImplementedError

    def _logit(self, theta, X) -> np.ndarray:
        raise NotImplementedError

    def _logit_grad_params(self, theta, X) -> np.ndarray:
        """d logit / d theta, shape (N, len(theta))."""
        raise NotImplementedError

    def _logit_grad_x(self, theta, X) -> np.ndarray:
        """d logit / d x, shape (N, n)."""
        raise NotImplementedError

    # ---- shared machinery -------------------------------------------------------------------
    def _sign(self, W) -> np.ndarray:
        if self.symmetric_axis is None:
            return np.ones(len(W))
        return np.where(W[:, self.symmetric_axis] < 0, -1.0, 1.0)

    def _ensure(self, W):
        W = np.atleast_2d(np.asarray(W, dtype=float))
        W = W * self._sign(W)[:, None]
        if not hasattr(self, "theta_"):
            norms = np.linalg.norm(W, axis=1)
            self.scale_ = float(np.median(norms[norms > 0])) if np.any(norms > 0) else 1.0
            self.theta_ = self._init_params(W.shape[1])
            self.n_updates_ = 0
        return W / self.scale_

    def predict_proba(self, W) -> np.ndarray:
        """q(w) for each row of W (0.5 everywhere before any training)."""
        X = self._ensure(W)
        return _sigmoid(self._logit(self.theta_, X))

    def predict(self, W) -> np.ndarray:
        return self.predict_proba(W) >= 0.5

    def cross_entropy(self, W, y) -> float:
        """H~(beta; S) of Proposition 3.2 in bits."""
        q = np.clip(self.predict_proba(W), 1e-15, 1 - 1e-15)
        y = np.asarray(y, dtype=float)
        return float(-np.mean(y * np.log2(q) + (1 - y) * np.log2(1 - q)))

    def _loss(self, theta, X, y):
        z = self._logit(theta, X)
        q = _sigmoid(z)
        # cross-entropy in nats, stable form (log(1 + e^z) - y z, written so that a logit of
        # +-inf, weights far apart in scale, costs inf, not inf - inf); divided by ln 2 for bits
        loss = np.mean(y * np.logaddexp(0, -z) + (1 - y) * np.logaddexp(0, z)) / LN2 + 0.5 * self.l2 * theta @ theta
        grad = ((q - y) @ self._logit_grad_params(theta, X)) / (len(y) * LN2) + self.l2 * theta
        return loss, grad

    def fit(self, W, y) -> "FeasibilityModel":
        """Batch training on labelled points (y = 1 feasible, 0 infeasible)."""
        X = self._ensure(W)
        y = np.asarray(y, dtype=float).ravel()
        if len(y) == 0:
            return self
        res = minimize(self._loss, self.theta_, args=(X, y), jac=True, method="L-BFGS-B",
                       options={"maxiter": 500})
        self.theta_ = res.x
        return self

    def partial_fit(self, w, y, learning_rate: float | None = None) -> "FeasibilityModel":
        """One online gradient step on a single example (Algorithm 3, line 10)."""
        X = self._ensure(np.atleast_2d(w))
        y = float(np.asarray(y).ravel()[0])
        z = self._logit(self.theta_, X)
        grad = (_sigmoid(z) - y) * self._logit_grad_params(self.theta_, X)[0] / LN2
        self.theta_ = self.theta_ - (learning_rate or self.learning_rate) * grad
        self.n_updates_ += 1
        return self

    def grad_log_proba(self, W) -> np.ndarray:
        """d log q / d w, for gradient-based fitting: (1 - q) d logit / dw."""
        W = np.atleast_2d(np.asarray(W, dtype=float))
        X = self._ensure(W)
        q = _sigmoid(self._logit(self.theta_, X))
        return (1 - q)[:, None] * self._logit_grad_x(self.theta_, X) * self._sign(W)[:, None] / self.scale_

    def grad_proba(self, W) -> np.ndarray:
        """d q / d w."""
        W = np.atleast_2d(np.asarray(W, dtype=float))
        X = self._ensure(W)
        q = _sigmoid(self._logit(self.theta_, X))
        return (q * (1 - q))[:, None] * self._logit_grad_x(self.theta_, X) * self._sign(W)[:, None] / self.scale_


class LogisticFeasibility(FeasibilityModel):
    """q(w) = sigma(beta^T w) (paper 000, sec. V): the boundary is the hyperplane beta^T w = 0.

    With ``bias=True`` the hyperplane need not pass through the origin (beta^T w + b = 0).
    """

    name = "logistic"

    def __init__(self, bias: bool = False, l2: float = 1e-4, learning_rate: float = 0.5,
                 symmetric_axis: int | None = None):
        super().__init__(l2=l2, learning_rate=learning_rate, symmetric_axis=symmetric_axis)
        self.bias = bias

    def _init_params(self, n):
        return np.zeros(n + int(self.bias))

    def _split(self, theta):
        return (theta[:-1], theta[-1]) if self.bias else (theta, 0.0)

    def _logit(self, theta, X):
        beta, b = self._split(theta)
        return X @ beta + b

    def _logit_grad_params(self, theta, X):
        return np.hstack([X, np.ones((len(X), 1))]) if self.bias else X

    def _logit_grad_x(self, theta, X):
        beta, _ = self._split(theta)
        return np.broadcast_to(beta, X.shape)

    @property
    def coef_(self) -> np.ndarray:
        """beta in the units of w (the hyperplane beta^T w + intercept_ = 0)."""
        beta, _ = self._split(self.theta_)
        return beta / self.scale_

    @property
    def intercept_(self) -> float:
        return float(self._split(self.theta_)[1])


class NeuralFeasibility(FeasibilityModel):
    """q(w) = sigma(v^T tanh(A w + a) + c): a small network before the logistic output."""

    name = "neural"

    def __init__(self, hidden: int = 8, l2: float = 1e-3, learning_rate: float = 0.2, seed: int = 0,
                 symmetric_axis: int | None = None):
        super().__init__(l2=l2, learning_rate=learning_rate, symmetric_axis=symmetric_axis)
        self.hidden, self.seed = hidden, seed

    def _init_params(self, n):
        rng = np.random.default_rng(self.seed)
        self.n_in_ = n
        A = rng.normal(0, 1.0, (self.hidden, n))
        return np.concatenate([A.ravel(), np.zeros(self.hidden), np.zeros(self.hidden), [0.0]])

    def _unpack(self, theta):
        H, n = self.hidden, self.n_in_
        A = theta[: H * n].reshape(H, n)
        a = theta[H * n: H * n + H]
        v = theta[H * n + H: H * n + 2 * H]
        return A, a, v, theta[-1]

    def _logit(self, theta, X):
        A, a, v, c = self._unpack(theta)
        return np.tanh(X @ A.T + a) @ v + c

    def _logit_grad_params(self, theta, X):
        A, a, v, c = self._unpack(theta)
        h = np.tanh(X @ A.T + a)                 # (N, H)
        dh = (1 - h**2) * v                      # (N, H): d logit / d pre-activation
        dA = dh[:, :, None] * X[:, None, :]      # (N, H, n)
        return np.hstack([dA.reshape(len(X), -1), dh, h, np.ones((len(X), 1))])

    def _logit_grad_x(self, theta, X):
        A, a, v, c = self._unpack(theta)
        h = np.tanh(X @ A.T + a)
        return ((1 - h**2) * v) @ A
