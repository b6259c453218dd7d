"""Constraint-aware fitting of a template's parameters w (paper 000, sections III-IV).

Pieces, each cited to the paper:

- :class:`FitProblem`: the cost J(w) of eq. (3), the mean squared output error of the simulated
  model against the measurements, with its exact gradient from the engine's sensitivities
  (sec. IV: grad J = -2/N sum (y_m - y) dy/dw). The algorithms see J divided by a scale
  (``normalise``): by default the cost of the first feasible point, so J starts at 1 in any
  units and the failure penalty -log(2 mu) of Algorithm 2 (about 13) always exceeds it — with
  J in raw units a failure can look better than a poor feasible start and attract the search.
  ``normalise="data"`` divides by the mean square of the measurements, ``None`` keeps eq. (3).
- :class:`PseudoFeasibility`: p~(w) of eq. (9), Gaussian bumps at the infeasible points found
  so far, and the equivalent cost J~(w) = p~ J - log(p~ + mu) of Algorithm 2.
- :class:`Algorithm3`: the one-shot heuristic cost
  J'(w) = J~(w) - lambda1 log q(w) + lambda2 [q log q + (1 - q) log(1 - q)] with the online
  update of q after every simulation, for any unconstrained optimiser.
- :class:`Algorithm1`: the sequence of constrained problems (5)-(8) with the schedules
  delta_k1 = eps + (1 - eps)(lambda + eps)^k, delta_k2 = 1 + eps - lambda^k, q_0 = 0.5, solved by
  COBYLA or SLSQP; q is retrained on every point visited after each outer step.
- :class:`LevenbergMarquardt`: a low-budget fit (ours): Gauss-Newton steps with the exact
  Jacobian dy/dw, a failed simulation treated as a rejected step (more damping), and every point
  recorded for q like the others.

Every simulation is recorded (:class:`Recorder`): point, cost, feasible or not and why. Records
go to a JSON-lines file when a path is given; a rerun replays them from that file instead of
simulating again, so an interrupted fit resumes where it stopped.
"""
from __future__ import annotations

import json
import logging
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from .data import TimeSeries
from .errors import ConfigError, DataError, FitError
from .feasibility import LogisticFeasibility, binary_entropy
from .stats import gram_inverse

LOG_EPS = 1e-12
log = logging.getLogger(__name__)
#: the relative tolerance of a switched system's fits (SimulationResult.switched)
SWITCHED_RTOL = 1e-8


@dataclass
class Evaluation:
    """One simulation: where, what it cost, whether it failed and why."""

    index: int
    w: list[float]
    cost: float | None
    feasible: bool
    reason: str | None
    seconds: float
    gradient: list[float] | None = None
    tag: str = ""


class Recorder:
    """Every evaluation in order; optionally appended to a JSON-lines file and replayed from it."""

    def __init__(self, path=None):
        self.evaluations: list[Evaluation] = []
        self.path = Path(path) if path else None
        self.replayed = 0
        self._replay: dict[tuple, Evaluation] = {}
        if self.path and self.path.exists():
            for line in self.path.read_text().splitlines():
                if line.strip():
                    ev = Evaluation(**json.loads(line))
                    self._replay[self._key(ev.w, ev.gradient is not None)] = ev

    @staticmethod
    def _key(w, gradient: bool) -> tuple:
        return (tuple(np.round(np.asarray(w, dtype=float), 15)), gradient)

    def lookup(self, w, gradient: bool) -> Evaluation | None:
        return self._replay.get(self._key(w, gradient)) or (
            None if gradient else self._replay.get(self._key(w, True)))

    def add(self, ev: Evaluation) -> Evaluation:
        ev.index = len(self.evaluations)
        self.evaluations.append(ev)
        if self.path:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with self.path.open("a") as fh:
                fh.write(json.dumps(asdict(ev)) + "\n")
                fh.flush()
        return ev

    @property
    def simulations(self) -> int:
        return len(self.evaluations)

    @property
    def failures(self) -> int:
        return self.failures_since(0)

    def failures_since(self, start: int) -> int:
        return sum(not e.feasible for e in self.evaluations[start:])

    def points(self):
        W = np.array([e.w for e in self.evaluations])
        y = np.array([e.feasible for e in self.evaluations])
        return W, y


class FitProblem:
    """J(w) (eq. 3) for a compiled model whose free parameters ``parameters`` are w.

    ``data`` holds the model's inputs and the measured outputs (columns named like the model's).
    ``sensitivity``: ``linearised`` (default; :mod:`mcl.sensitivity`) or ``integrator`` (the
    engine integrates the sensitivity equations with the states: exact, several times dearer).
    """

    def __init__(self, model, data: TimeSeries, parameters: list[str], outputs=None,
                 fixed: dict | None = None, options=None, normalise: str | None = "start",
                 engine=None, recorder: Recorder | None = None, sensitivity: str = "linearised"):
        from .engine_casadi import CasadiEngine
        from .simulation import SimulationOptions

        self.model, self.parameters = model, list(parameters)
        missing = [p for p in self.parameters if p not in model.parameters]
        if missing:
            raise ConfigError(f"model {model.name} has no free parameter(s) {', '.join(missing)}")
        self.outputs = list(outputs or [o for o in model.output_names if o in data.names])
        if not self.outputs:
            raise DataError(f"the data has none of the model's outputs ({', '.join(model.output_names)})",
                            where=data.source)
        self.inputs = data.select(model.input_names) if model.input_names else data
        self.y_meas = data.select(self.outputs).values
        self.measured = np.isfinite(self.y_meas)      # blank cells: not measured, not fitted
        self.weights = data.weight_of(self.outputs)   # (outputs in other units: in units of their noise)
        self.time = data.time
        self.idx = [model.output_names.index(o) for o in self.outputs]
        self.fixed = dict(fixed or {})
        self.options = options if isinstance(options, SimulationOptions) else SimulationOptions.from_dict(options)
        if normalise not in ("start", "data", None):
            raise ConfigError(f"normalise: 'start', 'data' or None, not {normalise!r}")
        self.normalise = normalise
        self._scale = float(np.nanmean((self.y_meas * self.weights)**2)) if normalise == "data" else (
            None if normalise == "start" else 1.0)
        self.engine = engine or CasadiEngine()
        self.recorder = recorder or Recorder()
        from .sensitivity import SUBSTEPS

        self.sensitivity, self.substeps, self._grid_checked = sensitivity, SUBSTEPS, False
        #: the model switched its right-hand side at an event (SimulationResult.switched)
        self.switched = False

    @property
    def scale(self) -> float:
        """Divisor of J for the algorithms (fixed at the first feasible cost for 'start')."""
        if self._scale is None:
            first = next((e.cost for e in self.recorder.evaluations if e.feasible), None)
            if first is None:
                return 1.0
            self._scale = first if first > 0 else 1.0
        return self._scale

    def scaled(self, ev: Evaluation):
        """(J / scale, grad J / scale) of an evaluation (None for a failed one)."""
        if not ev.feasible:
            return None, None
        s = self.scale
        return ev.cost / s, (None if ev.gradient is None else np.asarray(ev.gradient) / s)

    def params(self, w) -> dict:
        return {**self.fixed, **dict(zip(self.parameters, map(float, w)))}

    def simulate(self, w, gradient: bool = False):
        if gradient and self.linearised:
            return self._linearised(w)
        return self.engine.simulate(self.model, self.inputs, self.params(w), t_out=self.time,
                                    options=self.options,
                                    sensitivities=self.parameters if gradient else None).through(self.time)

    @property
    def linearised(self) -> bool:
        """Sensitivities from the model linearised along the run (:mod:`mcl.sensitivity`): one
        plain simulation on a finer grid, instead of the integrator carrying them (several)."""
        from .model import CompiledModel

        return isinstance(self.model, CompiledModel) and self.sensitivity == "linearised"

    def _linearised(self, w):
        import dataclasses

        from .sensitivity import Linearisation, fine_grid, substeps_for

        params = self.params(w)
        while True:
            fine, at = fine_grid(self.time, self.substeps)
            res = self.engine.simulate(self.model, self.inputs, params, t_out=fine, options=self.options).through(fine)
            self.switched = self.switched or res.switched
            if res.switched and self.options.rtol > SWITCHED_RTOL:
                # a switching time is as accurate as the states' crossing: at the fits' usual
                # tolerance a furnished room's 4th switch was 3 s late, its temperature 0.2 K off
                # by the end, and the fit chased the solver's error (and, on the linearisation,
                # a thermostat's wall came out with the radiation law, 44 % off; the integrator's
                # sensitivities, which stop 83 took for switched systems instead, cost 25 % more)
                self.options = dataclasses.replace(self.options, rtol=SWITCHED_RTOL)
                continue
            if not res.ok:
                return dataclasses.replace(res, time=self.time, outputs=np.full((len(self.time), len(res.output_names)), np.nan))
            lin = Linearisation(self.model, res.states, fine, self.inputs, self.model.parameter_vector(params),
                                self.parameters, res.switches)
            if not self._grid_checked:       # dynamics fast against the data's sampling: a finer grid
                self._grid_checked = True
                h = float(np.max(np.diff(self.time)))
                need = max(self.substeps, substeps_for(lin.rate(), h))
                if need > self.substeps:
                    self.substeps = need
                    continue
            out = dataclasses.replace(res, time=self.time, outputs=res.outputs[at], states=res.states[at])
            out.sensitivities = lin.parameters(at)
            out.sensitivity_names = list(self.parameters)
            return out

    def evaluate(self, w, gradient: bool = False, tag: str = "") -> Evaluation:
        """Simulate at w (or replay a recorded run): J(w) and, if asked, grad J(w)."""
        w = np.asarray(w, dtype=float)
        old = self.recorder.lookup(w, gradient)
        if old is not None:
            self.recorder.replayed += 1
            return self.recorder.add(Evaluation(0, old.w, old.cost, old.feasible, old.reason,
                                                old.seconds, old.gradient, tag or old.tag))
        t0 = time.perf_counter()
        res = self.simulate(w, gradient)
        r, cost = self.residual_and_cost(res)
        grad = None
        if res.ok and gradient:
            S = self.output_sensitivities(res)                 # (N, ny, nw)
            grad = (-2.0 * np.einsum("ki,kij->j", r, S) / len(r)).tolist()
        return self.recorder.add(Evaluation(0, w.tolist(), cost, bool(res.ok), res.reason,
                                            time.perf_counter() - t0, grad, tag))

    def residual_and_cost(self, res):
        """Output residuals y_m - y (N, ny) and J of eq. (3) of a simulation; (None, None) if failed."""
        if not res.ok:
            return None, None
        r = np.where(self.measured, (self.y_meas - res.outputs[:, self.idx]) * self.weights, 0.0)
        with np.errstate(over="ignore"):
            return r, float(np.mean(np.sum(r**2, axis=1)))

    def output_sensitivities(self, res) -> np.ndarray:
        """d y / d w of the fitted outputs (N, ny, nw), weighted as their residuals are."""
        return res.sensitivities[:, self.idx, :] * self.weights[None, :, None]

    def residuals(self, w):
        """Output residuals y_m - y(w) (N, ny) or None when the simulation fails."""
        return self.residual_and_cost(self.simulate(w))[0]

    def rms_error(self, w) -> float:
        r = self.residuals(w)
        return float("nan") if r is None else float(np.sqrt(np.sum(r**2) / max(self.measured.sum(), 1)))


class PseudoFeasibility:
    """p~(w) = 1 - sum_i exp(-|w - w_i|^2 / (2 sigma^2)) + mu over infeasible points (eq. 9).

    The exponent's sign is garbled in the text; it must be negative for the bumps to be local.
    p~ is kept >= mu so that -log(p~ + mu) stays finite where bumps overlap.
    """

    def __init__(self, sigma: float = 0.01, mu: float = 1e-6):
        self.sigma, self.mu = sigma, mu
        self.infeasible: list[np.ndarray] = []

    def add(self, w) -> None:
        self.infeasible.append(np.asarray(w, dtype=float))

    def value_and_grad(self, w):
        w = np.asarray(w, dtype=float)
        p, g = 1.0 + self.mu, np.zeros_like(w)
        for wi in self.infeasible:
            d = w - wi
            b = np.exp(-d @ d / (2 * self.sigma**2))
            p -= b
            g += b * d / self.sigma**2
        if p < self.mu:
            return self.mu, np.zeros_like(w)
        return p, g

    def __call__(self, w) -> float:
        return self.value_and_grad(w)[0]

    def equivalent_cost(self, J: float | None, w, grad_J=None):
        """Algorithm 2: J~ = p~ J - log(p~ + mu), or -log(p~ + mu) when the simulation failed."""
        p, gp = self.value_and_grad(w)
        barrier = -np.log(p + self.mu)
        g_barrier = -gp / (p + self.mu)
        if J is None:
            return barrier, g_barrier
        value = p * J + barrier
        grad = p * (np.zeros_like(gp) if grad_J is None else np.asarray(grad_J)) + J * gp + g_barrier
        return value, grad


def feasibility_terms(q_model, w, lambda1: float, lambda2: float):
    """-lambda1 log q + lambda2 [q log q + (1-q) log(1-q)] and its gradient (natural logs)."""
    w2 = np.atleast_2d(w)
    q = float(np.clip(q_model.predict_proba(w2)[0], LOG_EPS, 1 - LOG_EPS))
    dq = q_model.grad_proba(w2)[0]
    neg_entropy = q * np.log(q) + (1 - q) * np.log(1 - q)
    value = -lambda1 * np.log(q) + lambda2 * neg_entropy
    grad = (-lambda1 / q + lambda2 * (np.log(q) - np.log(1 - q))) * dq
    return value, grad


def restore_feasibility(problem: FitProblem, w0, q, budget: int = 24, seed: int = 0,
                        on_failure=None, tag: str = "restore", fixed=()):
    """A feasible start near ``w0`` (beyond the paper: its algorithms start where they are told).

    When w0 does not simulate, candidates at growing distances from it are ranked by q and the
    most likely feasible ones simulated, q learning from every outcome (Algorithm 3's online
    step), until one succeeds; coordinates ``fixed`` (the law's scale) are not moved. Returns
    (start point, whether it is feasible).
    """
    w0 = np.asarray(w0, dtype=float)
    ev = problem.evaluate(w0, tag=tag)
    q.partial_fit(np.atleast_2d(w0), float(ev.feasible))
    if ev.feasible:
        return w0, True
    if on_failure:
        on_failure(w0)
    rng = np.random.default_rng(seed)
    scale, n, used = float(np.linalg.norm(w0)) or 1.0, len(w0), 1
    for radius in (0.1, 0.3, 1.0, 3.0):
        step = radius * scale * rng.normal(size=(64, n)) / np.sqrt(n)
        step[:, list(fixed)] = 0.0
        cand = w0 + step
        for c in cand[np.argsort(-q.predict_proba(cand))[:6]]:
            if used >= budget:
                return w0, False
            ev = problem.evaluate(c, tag=tag)
            used += 1
            q.partial_fit(np.atleast_2d(c), float(ev.feasible))
            if ev.feasible:
                return c, True
            if on_failure:
                on_failure(c)
    return w0, False


@dataclass
class FitResult:
    w: np.ndarray
    cost: float
    simulations: int
    failed: int
    seconds: float
    feasibility: object = None
    message: str = ""
    extra: dict = field(default_factory=dict)

    def normalised(self, axis: int = 0) -> np.ndarray:
        """w / w[axis]: the law is unchanged by scaling w (paper 000, Table I)."""
        return self.w / self.w[axis]


SCIPY_OPTIMISERS = ("Nelder-Mead", "Powell", "COBYLA", "SLSQP", "BFGS", "CG", "L-BFGS-B")
_GRADIENT_OPTIMISERS = {"SLSQP", "BFGS", "CG", "L-BFGS-B"}


class Fitter:
    """Base of the fitting algorithms: what they share is here, each writes :meth:`_minimise`.

    :meth:`fit` counts the simulations and failures a fit spends (its budget is the algorithm's
    own ``max_simulations``), times it and returns the :class:`FitResult`; :meth:`_start` finds
    a feasible start near the given one (:func:`restore_feasibility`). Algorithms are chosen by
    name (:data:`FITTERS`, ``fitting: {algorithm: ...}`` in a run file)."""

    name = ""

    def fit(self, problem: FitProblem, w0) -> FitResult:
        t0 = time.perf_counter()
        start = problem.recorder.simulations
        w, cost, message, feasibility = self._minimise(problem, np.asarray(w0, dtype=float), start)
        return FitResult(np.asarray(w, dtype=float), cost, problem.recorder.simulations - start,
                         problem.recorder.failures_since(start), time.perf_counter() - t0, feasibility, message)

    def _minimise(self, problem: FitProblem, w0: np.ndarray, start: int):
        """(w, cost, message, feasibility model) of a fit from ``w0``; ``start`` is the number of
        simulations the problem's recorder held before it."""
        raise NotImplementedError

    @staticmethod
    def _start(problem: FitProblem, w0, q, on_failure=None, budget: int = 24, fixed=()):
        return restore_feasibility(problem, w0, q, budget=budget, on_failure=on_failure, fixed=fixed)


class Algorithm3(Fitter):
    """One-shot heuristic of sec. IV (Algorithm 3) with any scipy optimiser.

    ``gradient=True`` gives gradient-based optimisers the exact grad J' from sensitivities
    (one simulation per gradient instead of n + 1 with finite differences).
    """

    def __init__(self, optimizer: str = "Powell", lambda1: float = 1.0, lambda2: float = 0.1,
                 sigma: float = 0.01, mu: float = 1e-6, maxiter: int = 1000, maxfev: int = 1500,
                 gradient: bool = False, feasibility=None, learning_rate: float | None = None,
                 fd_step: float = 1e-4, symmetric_axis: int | None = 0, tol: float | None = None):
        if optimizer not in SCIPY_OPTIMISERS:
            raise ConfigError(f"optimizer '{optimizer}': choose from {', '.join(SCIPY_OPTIMISERS)}")
        self.optimizer, self.lambda1, self.lambda2 = optimizer, lambda1, lambda2
        self.sigma, self.mu, self.maxiter, self.maxfev = sigma, mu, maxiter, maxfev
        self.gradient, self.feasibility, self.learning_rate = gradient, feasibility, learning_rate
        self.fd_step, self.symmetric_axis, self.tol = fd_step, symmetric_axis, tol

    def cost(self, problem: FitProblem, w, gradient: bool):
        """J'(w) (Algorithm 3, lines 3-10); returns (value, grad or None)."""
        ev = problem.evaluate(w, gradient=gradient, tag="alg3")
        if not ev.feasible:
            self.p_tilde_.add(w)
        J, gJ = problem.scaled(ev)
        jt, gjt = self.p_tilde_.equivalent_cost(J, w, gJ)
        ft, gft = feasibility_terms(self.feasibility_, w, self.lambda1, self.lambda2)
        self.feasibility_.partial_fit(np.atleast_2d(w), float(ev.feasible), self.learning_rate)
        if ev.feasible and (self.best_cost_ is None or ev.cost < self.best_cost_):
            self.best_cost_, self.w_best_ = ev.cost, np.asarray(w, dtype=float).copy()
        return jt + ft, (gjt + gft if gradient else None)

    name = "algorithm3"

    def _minimise(self, problem: FitProblem, w0, start):
        self.feasibility_ = self.feasibility or LogisticFeasibility(symmetric_axis=self.symmetric_axis)
        self.p_tilde_ = PseudoFeasibility(self.sigma, self.mu)
        self.best_cost_, self.w_best_ = None, w0.copy()
        w0, ok = self._start(problem, w0, self.feasibility_, on_failure=self.p_tilde_.add)
        if ok:
            self.best_cost_, self.w_best_ = problem.recorder.evaluations[-1].cost, w0.copy()
        use_grad = self.gradient and self.optimizer in _GRADIENT_OPTIMISERS
        options = {"maxiter": self.maxiter}
        if self.optimizer in ("Nelder-Mead", "Powell"):
            options["maxfev"] = self.maxfev
        elif self.optimizer in _GRADIENT_OPTIMISERS and not use_grad:
            options["eps"] = self.fd_step
        if self.optimizer == "L-BFGS-B":
            options["maxfun"] = self.maxfev
        if self.optimizer == "COBYLA":
            options["rhobeg"] = 0.5 * float(np.max(np.abs(w0))) or 0.1

        budget = self.maxfev

        def fun(w):
            if problem.recorder.simulations - start >= budget:
                raise _BudgetExhausted
            value, grad = self.cost(problem, w, use_grad)
            return (value, grad) if use_grad else value

        message = ""
        try:
            # the paper sets xtol = ftol = 1e-16 so that budgets bind; ``tol`` does that when given
            res = minimize(fun, w0, method=self.optimizer, jac=use_grad or None, tol=self.tol,
                           options=options)
            message = str(res.message)
        except _BudgetExhausted:
            message = f"simulation budget of {budget} reached"
        cost = self.best_cost_ if self.best_cost_ is not None else float("nan")
        return self.w_best_, cost, message, self.feasibility_


class _BudgetExhausted(Exception):
    pass


def delta_schedule(k: int, eps: float = 1e-7, lam: float = 0.8) -> tuple[float, float]:
    """delta_k1 = eps + (1 - eps)(lam + eps)^k and delta_k2 = 1 + eps - lam^k (sec. V)."""
    return eps + (1 - eps) * (lam + eps) ** k, 1 + eps - lam**k


class Algorithm1(Fitter):
    """Iterative constrained optimisation with constraint discovery (Algorithm 1, eqs. 5-8).

    Outer step k solves min J~(w) subject to g_k1 = 1 - delta_k1 - q_k(w) <= 0 and
    g_k2 = 1 - delta_k2 - H(q_k(w)) <= 0 (H the binary entropy in bits, eq. 8), then retrains
    q on every point visited so far. q_0 = 0.5 everywhere, so (P_0) is unconstrained.
    """

    def __init__(self, optimizer: str = "COBYLA", outer: int = 25, inner_maxiter: int = 300,
                 eps: float = 1e-7, lam: float = 0.8, sigma: float = 0.01, mu: float = 1e-6,
                 feasibility=None, symmetric_axis: int | None = 0, max_simulations: int | None = None,
                 gradient: bool = False, fd_step: float = 1e-4, tol: float | None = None):
        if optimizer not in ("COBYLA", "SLSQP"):
            raise ConfigError("Algorithm 1 needs a constrained optimiser: COBYLA or SLSQP")
        self.optimizer, self.outer, self.inner_maxiter = optimizer, outer, inner_maxiter
        self.eps, self.lam, self.sigma, self.mu = eps, lam, sigma, mu
        self.feasibility, self.symmetric_axis = feasibility, symmetric_axis
        self.max_simulations, self.gradient = max_simulations, gradient
        self.fd_step, self.tol = fd_step, tol

    name = "algorithm1"

    def _minimise(self, problem: FitProblem, w0, start):
        w = w0
        q = self.feasibility or LogisticFeasibility(symmetric_axis=self.symmetric_axis)
        p_tilde = PseudoFeasibility(self.sigma, self.mu)
        best = [None, w.copy()]
        budget = self.max_simulations or 10**9
        w, ok = self._start(problem, w, LogisticFeasibility(symmetric_axis=self.symmetric_axis),
                            on_failure=p_tilde.add)
        if ok:
            best[:] = [problem.recorder.evaluations[-1].cost, w.copy()]
        use_grad = self.gradient and self.optimizer == "SLSQP"
        self.deltas_ = []

        def objective(x):
            if problem.recorder.simulations - start >= budget:
                raise _BudgetExhausted
            ev = problem.evaluate(x, gradient=use_grad, tag="alg1")
            if not ev.feasible:
                p_tilde.add(x)
            elif best[0] is None or ev.cost < best[0]:
                best[0], best[1] = ev.cost, np.asarray(x, dtype=float).copy()
            J, gJ = problem.scaled(ev)
            value, grad = p_tilde.equivalent_cost(J, x, gJ)
            return (value, grad) if use_grad else value

        message = ""
        try:
            for k in range(self.outer):
                d1, d2 = delta_schedule(k, self.eps, self.lam)
                self.deltas_.append((d1, d2))
                cons = [{"type": "ineq", "fun": lambda x, d=d1: q.predict_proba(np.atleast_2d(x))[0] - (1 - d)},
                        {"type": "ineq", "fun": lambda x, d=d2: binary_entropy(
                            q.predict_proba(np.atleast_2d(x)))[0] - (1 - d)}]
                opts = {"maxiter": self.inner_maxiter}
                if self.optimizer == "COBYLA":
                    opts["rhobeg"] = 0.5 * float(np.max(np.abs(w))) or 0.1
                elif not use_grad:
                    opts["eps"] = self.fd_step  # paper: gradient step 1e-4
                res = minimize(objective, w, method=self.optimizer, jac=use_grad or None,
                               constraints=cons, tol=self.tol, options=opts)
                w = res.x
                W, y = problem.recorder.points()
                W, y = W[start:], y[start:]
                if 0 < y.sum() < len(y):  # both classes seen: retrain q on all visited points
                    q.fit(W, y)
            message = f"{self.outer} outer iterations"
        except _BudgetExhausted:
            message = f"simulation budget of {budget} reached"
        cost = best[0] if best[0] is not None else float("nan")
        return best[1], cost, message, q


#: simulations over which a fit's pace is measured (see LevenbergMarquardt._hopeless)
STALL = 10
#: simulations over which a fit with ``settle`` must gain its share of the cost to go on
SETTLE = 8


class LevenbergMarquardt(Fitter):
    """Low-budget fit: damped Gauss-Newton on the output residuals with the exact Jacobian.

    One simulation (with sensitivities) per trial step. A failed simulation is a rejected step:
    the damping grows and the point is recorded as infeasible, as everywhere else. The law is
    invariant to scaling w, so the step is taken with w[axis] held fixed (that removes the
    flat direction of J instead of leaving it to the damping).
    """

    def __init__(self, max_simulations: int = 150, axis: int | None = 0, damping: float = 1e-3,
                 tol: float = 1e-10, feasibility=None, give_up=None, progress=None, restore: int = 24,
                 settle: float | None = None, by_gain: bool = False):
        self.max_simulations, self.axis, self.damping, self.tol = max_simulations, axis, damping, tol
        #: stop once the last SETTLE simulations together lowered the cost by less than this
        #: share: a crawl along a valley (steps taken and rejected in turn, each gaining a
        #: fraction of a percent) cannot change the answer within the budget
        self.settle = settle
        #: after a step taken, shrink the damping by how much of its predicted gain it made
        #: (Nielsen's rule) instead of always by 3: the discovery's fits keep the rule their
        #: answers were measured with (the tanks' law changed with the last bit of the damping)
        self.by_gain = by_gain
        #: simulations spent looking for a feasible start near the given one when it fails
        self.restore = restore
        self.feasibility = feasibility
        #: progress(cost): told the cost J of every better point reached
        self.progress = progress
        #: give_up(reachable, current): True stops the fit, given the least residual sum of
        #: squares the Gauss-Newton model at the current point can reach and the current one
        #: (discovery: another candidate is already better than this one can get)
        self.give_up = give_up

    name = "levenberg-marquardt"

    def _minimise(self, problem: FitProblem, w0, start):
        w = w0.copy()
        free = [k for k in range(len(w)) if k != self.axis]
        lam = self.damping
        q = self.feasibility or LogisticFeasibility(symmetric_axis=self.axis)
        w, ok = self._start(problem, w, q, budget=self.restore, fixed=[] if self.axis is None else [self.axis])
        current = self._step_data(problem, w) if ok else None
        if current is None:
            why = next((ev.reason for ev in problem.recorder.evaluations[start:] if ev.reason), None)
            raise FitError("no start point of the fit simulates (tried around the given one)"
                           + (f"; at the given one: {why}" if why else ""))
        if self.progress:
            self.progress(current[2])
        message = "budget reached"
        trusted = False
        costs = []          # J after each simulation of the loop
        while problem.recorder.simulations - start < self.max_simulations:
            r, Jac, cost = current
            A = Jac[:, free]
            g = A.T @ r
            H = A.T @ A
            if self.give_up is not None and self._hopeless(problem, start, r, g, H, costs, trusted):
                message = "stopped: it cannot beat another candidate"
                break
            step = self._step(A, g, H, lam)
            # the Gauss-Newton model's predicted decrease: below tol, no step can pay for a
            # simulation (at the optimum, the solver's own noise would only reject steps)
            predicted = (r @ r - np.sum((r + A @ step) ** 2)) / max(r @ r, 1e-300)
            if predicted < self.tol:
                message = "converged"
                break
            trial = w.copy()
            trial[free] += step
            new = self._step_data(problem, trial)
            costs.append(min(cost, new[2]) if new is not None else cost)
            if new is not None and new[2] < cost:
                rel = (cost - new[2]) / max(cost, 1e-300)
                trusted = rel >= 0.25 * predicted
                # (by_gain: a step that made little of its gain is followed by a shorter one,
                # not by a longer one to be rejected)
                gained = rel / max(predicted, 1e-300)
                shrunk = lam * max(1 / 3, 1 - (2 * min(gained, 1.0) - 1) ** 3) if self.by_gain else lam / 3
                w, current, lam = trial, new, max(shrunk, 1e-12)
                if self.progress:
                    self.progress(current[2])
                if rel < self.tol or np.linalg.norm(step) < 1e-12 * (1 + np.linalg.norm(w)):
                    message = "converged"
                    break
            else:
                lam *= 4
                if lam > 1e12:
                    message = "no descent step found"
                    break
            if self.settle and len(costs) > SETTLE and costs[-1] > (1 - self.settle) * costs[-1 - SETTLE]:
                message = "settled"
                break
        W, y = problem.recorder.points()
        if 0 < y[start:].sum() < len(y[start:]):
            q.fit(W[start:], y[start:])
        return w, current[2], message, q

    @staticmethod
    def _step(A, g, H, lam) -> np.ndarray:
        """The damped Gauss-Newton step. A coordinate the residual does not depend on at this
        point is not moved: the scale inside a term whose coefficient is still 0 (tanh(v/s1)
        at the start) has a zero column, and the damping alone would let it jump anywhere.
        Only an exact zero: a column a trillion times smaller than another is a parameter of
        another scale (the rise of exp(h/s) behind a coefficient of 1e-11), still fitted (a
        threshold relative to the largest column froze it, and the tanks' outflow law was lost)."""
        step = -np.linalg.solve(H + lam * np.diag(np.diag(H) + 1e-30), g)
        step[~np.any(A != 0, axis=0)] = 0.0
        return step

    def _hopeless(self, problem, start, r, g, H, costs, trusted) -> bool:
        """Whether ``give_up`` stops the fit, told what it can reach: what the Gauss-Newton
        model predicts, where it has proven itself (the last step did at least a quarter of what
        it predicted: from a poor start it can be far too pessimistic), and no better than the
        pace of its last STALL simulations carried over the simulations it has left (a slow fit
        far behind cannot catch up within its budget, whatever the linear model promises)."""
        rss = float(r @ r)
        reach = float(rss - g @ gram_inverse(H) @ g) if trusted else None
        if len(costs) > STALL and costs[-1 - STALL] > 0:
            left = self.max_simulations - (problem.recorder.simulations - start)
            paced = rss * min(costs[-1] / costs[-1 - STALL], 1.0) ** (max(left, 0) / STALL)
            reach = paced if reach is None else max(reach, paced)
        return reach is not None and self.give_up(reach, rss)

    @staticmethod
    def _step_data(problem: FitProblem, w):
        """(residual vector, its Jacobian d r / d w, J) at w, or None when w fails."""
        res = problem.simulate(w, gradient=True)
        r, ev_cost = problem.residual_and_cost(res)
        S = problem.output_sensitivities(res) if res.ok else None
        ok, reason = bool(res.ok), res.reason
        if ok and not np.all(np.isfinite(S)):      # (a run that grows without bound in its sensitivities)
            ok, reason = False, "its sensitivities are not finite"
        problem.recorder.add(Evaluation(0, np.asarray(w, float).tolist(), ev_cost if ok else None, ok,
                                        reason, res.seconds, None, "lm"))
        if not ok:
            return None
        return r.ravel(), -S.reshape(-1, S.shape[2]), ev_cost


#: the fitting algorithms by name (``fitting: {algorithm: ...}``)
FITTERS = {c.name: c for c in (LevenbergMarquardt, Algorithm1, Algorithm3)}


def fitter(name: str, budget: int, **lm) -> Fitter:
    """The algorithm called ``name`` with a budget of ``budget`` simulations; ``lm`` are the
    options only Levenberg-Marquardt takes (give_up, progress, restore, tol), which the paper's
    algorithms do without."""
    if name not in FITTERS:
        from .errors import did_you_mean

        raise ConfigError(f"fitting algorithm '{name}'{did_you_mean(name, FITTERS)}: choose {', '.join(FITTERS)}")
    if name == "levenberg-marquardt":
        return LevenbergMarquardt(max_simulations=budget, axis=None, **lm)
    if name == "algorithm1":
        return Algorithm1(max_simulations=budget, symmetric_axis=None, optimizer="SLSQP", gradient=True)
    return Algorithm3(optimizer="L-BFGS-B", gradient=True, maxfev=budget, symmetric_axis=None)
