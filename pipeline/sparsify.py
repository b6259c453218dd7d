"""Backward elimination: from a dense fitted law to a sparse, readable one (paper 004, sec. V).

Each round estimates, for every remaining candidate parameter, the minimal cost after setting
it to zero (Algorithm 3, :func:`mcl.lm.removal_estimate`: the state eliminations are
shared), retrains the best candidate with Levenberg-Marquardt, and accepts the removal if the
criterion says so:

- ``threshold``: the cost stays within (1 + tau) of the dense model's;
- ``aic`` / ``bic``: V + 2k, or V + k log n, does not increase (n measured values). With the
  weights W_x, W_y the covariances of the errors (the statistical reading of eq. 6) the cost V is
  -2 log L up to a constant; ``variance="estimated"`` uses n log(V / n) instead, for weights
  that only set relative scales;
- ``cv``: the cost on held-out measurements (a second problem) does not increase.

Which parameters may be removed next is a plugin point (``mcl_prioritisers``): ``all`` offers
every remaining one; ``degree`` offers the highest monomial degree first and moves to the next
degree when a removal there is refused (the stage-wise removal of section VI-A).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import ConfigError
from .progress import log
from .lm import (BlockEvaluationFailed, IdentificationProblem, LMResult, levenberg_marquardt,
                 reduced_parameter_rows, removal_estimate, restrict)


class Prioritiser:
    """Base of prioritisers: ``stages(names, degrees)`` gives candidate groups, tried in order."""

    name = ""

    def stages(self, names: list[str], degrees: list[int]) -> list[list[int]]:
        raise NotImplementedError


class AllAtOnce(Prioritiser):
    name = "all"

    def stages(self, names, degrees):
        return [list(range(len(names)))]


class HighestDegreeFirst(Prioritiser):
    name = "degree"

    def stages(self, names, degrees):
        return [[k for k, d in enumerate(degrees) if d == deg] for deg in sorted(set(degrees), reverse=True)]


@dataclass
class PruneStep:
    removed: str | None
    estimate: float | None
    cost: float
    criterion: float
    accepted: bool
    active: list[str]


@dataclass
class SparseResult:
    names: list[str]
    active: np.ndarray
    a: np.ndarray
    X: np.ndarray
    cost: float
    path: list[PruneStep] = field(default_factory=list)
    dense_a: np.ndarray | None = None     # the parameters of the dense fit the pruning started from

    def terms(self) -> dict[str, float]:
        return {n: float(v) for n, v, on in zip(self.names, self.a, self.active) if on}

    def equation(self, digits: int = 4) -> str:
        """The sparse law, one line per state for names 'state:monomial' ("dx1/dt = -9.4*x1 + ..."),
        else one line per surviving parameter."""
        lines: dict[str, list[str]] = {}
        for name, v in self.terms().items():
            state, _, mono = name.partition(":")
            if not mono:
                lines.setdefault(name, []).append(f"{v:.{digits}g}")
                continue
            coef = f"{v:.{digits}g}"
            lines.setdefault(f"d{state}/dt", []).append(coef if mono == "1" else f"{coef}*{mono}")
        out = [f"{lhs} = " + " + ".join(rhs).replace("+ -", "- ") for lhs, rhs in lines.items()]
        return "\n".join(out)

    def save(self, directory, grid=None) -> None:
        """law.txt (the equation), path.png (the pruning path), path.json, and states.csv (the
        fitted states at the grid points ``grid``, if given)."""
        import json
        from pathlib import Path

        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        (d / "law.txt").write_text(self.equation() + "\n")
        (d / "path.json").write_text(json.dumps([s.__dict__ for s in self.path], indent=1))
        self.plot_path(d / "path.png")
        if grid is not None:
            head = "time," + ",".join(f"x{k + 1}" for k in range(self.X.shape[1]))
            np.savetxt(d / "states.csv", np.column_stack([grid, self.X]), delimiter=",", header=head,
                       comments="")

    def plot_path(self, path) -> None:
        """Cost against the number of remaining terms, accepted and refused removals marked."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7, 4))
        k = [len(s.active) for s in self.path]
        c = [s.cost for s in self.path]
        ok = [s.accepted for s in self.path]
        ax.semilogy(k, c, "-", color="tab:gray", lw=1)
        ax.semilogy([x for x, a in zip(k, ok) if a], [y for y, a in zip(c, ok) if a], "o",
                    color="tab:green", label="accepted")
        ax.semilogy([x for x, a in zip(k, ok) if not a], [y for y, a in zip(c, ok) if not a], "x",
                    color="tab:red", label="refused")
        ax.invert_xaxis()
        ax.set_xlabel("number of terms")
        ax.set_ylabel("cost ||g(b)||^2")
        ax.set_title("backward elimination path")
        ax.legend()
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)


class BackwardElimination:
    """Algorithm 3 (paper 004) with retraining and an acceptance criterion."""

    def __init__(self, criterion: str = "bic", threshold: float = 0.1, prioritiser=None,
                 segments: int = 1, lm_options: dict | None = None, validation: IdentificationProblem | None = None,
                 batch: int = 1, variance: str = "known", exchange: bool = False, on_step=None):
        from .stats import Criterion, criterion as information_criterion

        # an information criterion (an object, or a built-in's name) scores by its complexity;
        # threshold and cv are the paper's own acceptance rules
        self.information = criterion if isinstance(criterion, Criterion) else (
            information_criterion(criterion) if criterion not in ("threshold", "cv") else None)
        if self.information is not None:
            criterion = "ic"
        if criterion == "cv" and validation is None:
            raise ConfigError("criterion 'cv' needs a validation problem (held-out measurements)")
        self.criterion, self.threshold = criterion, threshold
        self.prioritiser = prioritiser or HighestDegreeFirst()
        self.segments, self.lm_options = segments, dict(lm_options or {})
        self.validation = validation
        self.batch = max(1, int(batch))
        if variance not in ("known", "estimated"):
            raise ConfigError(f"variance '{variance}': choose known (weights are covariances) or estimated")
        self.variance = variance
        self.exchange = exchange
        self.on_step = on_step    # called with each PruneStep as it is taken (progress)

    def _score(self, problem, X, a, active, cost, dense_cost) -> float:
        n = max(int(problem.M.sum()), 1)
        k = int(active.sum())
        if self.information is not None:
            fit = cost if self.variance == "known" else n * np.log(cost / n)
            return fit + self.information.complexity(n, k)
        if self.criterion == "threshold":
            return cost / dense_cost
        Xv = self.validation.initial_states()
        return levenberg_marquardt(self.validation, Xv, a, active, segments=self.segments,
                                   **self.lm_options).cost

    def _penalty(self, problem) -> float:
        return 0.0 if self.information is None else self.information.penalty(int(problem.M.sum()))

    def _accept(self, new: float, old: float) -> bool:
        if self.criterion == "threshold":
            return new <= 1 + self.threshold
        return new <= old

    def fit(self, problem: IdentificationProblem, X, a, names: list[str], degrees=None,
            keep=()) -> SparseResult:
        """Prune ``names`` (the parameters a) stage by stage; names in ``keep`` are never removed.

        With ``batch`` > 1 (beyond the paper, for large networks) a round removes up to that many
        parameters with the smallest estimates together: the count doubles after an accepted
        round and halves after a refused one; a stage ends when a single removal is refused.
        """
        names = list(names)
        degrees = list(degrees) if degrees is not None else [0] * len(names)
        removable = np.array([nm not in set(keep) for nm in names])
        active = np.ones(len(names), bool)
        fit = levenberg_marquardt(problem, X, a, active, segments=self.segments, **self.lm_options)
        self._dense = fit.cost
        st = _State(active, fit.X, fit.a, fit.cost, self._score(problem, fit.X, fit.a, active, fit.cost, fit.cost))
        path: list[PruneStep] = []
        self._record(path, PruneStep(None, None, float(st.cost), float(st.score), True, list(names)))
        for stage in self.prioritiser.stages(names, degrees):
            while True:
                self._prune_stage(problem, st, [k for k in stage if removable[k]], names, path)
                in_stage = np.isin(np.arange(len(names)), stage) & removable
                if not (self.exchange and self._exchange(problem, st, in_stage, names, path)):
                    break
        return SparseResult(names, st.active, st.a, st.X, st.cost, path, fit.a.copy())

    def _record(self, path: list, step: PruneStep) -> None:
        path.append(step)
        if self.on_step is not None:
            self.on_step(step)

    def _refit(self, problem, st, trial):
        """LM on the ``trial`` support from the current fit; a support the model cannot be
        evaluated on (e.g. a loop that no longer converges) scores infinitely bad."""
        try:
            refit = levenberg_marquardt(problem, st.X, st.a, trial, segments=self.segments, **self.lm_options)
        except BlockEvaluationFailed as err:
            return LMResult(st.X, st.a, np.inf, 0, [], str(err)), np.inf
        return refit, self._score(problem, refit.X, refit.a, trial, refit.cost, self._dense)

    def _adopt(self, st, trial, refit, new_score) -> None:
        """Make ``trial`` the current support; the threshold keeps comparing with the dense fit."""
        st.update(trial, refit, new_score if self.criterion != "threshold" else st.score)

    def _prune_stage(self, problem, st, stage: list[int], names, path) -> None:
        """Remove parameters of one stage until the criterion refuses a single removal."""
        size = 1
        while True:
            cand = [k for k in stage if st.active[k]]
            if not cand or st.active.sum() <= 1:
                return
            G = reduced_parameter_rows(restrict(problem.blocks(st.X, st.a), st.active), self.segments)
            idx = list(np.flatnonzero(st.active))
            a_act = st.a[st.active]
            est = {k: removal_estimate(G, a_act, [idx.index(k)]) for k in cand}
            take = sorted(cand, key=est.get)[:min(size, len(cand), int(st.active.sum()) - 1)]
            trial = st.active.copy()
            trial[take] = False
            refit, new_score = self._refit(problem, st, trial)
            # a batch must pass as if it were one removal: its whole cost increase within
            # one parameter's penalty (BIC would otherwise trade a true term for two false ones)
            ok = bool(self._accept(new_score, st.score - (len(take) - 1) * self._penalty(problem)))
            joint = removal_estimate(G, a_act, [idx.index(k) for k in take])
            self._record(path, PruneStep(", ".join(names[k] for k in take), float(joint), float(refit.cost),
                                         float(new_score), ok, [n for n, on in zip(names, trial) if on]))
            if not ok:
                if len(take) > 1:           # too many at once: try fewer
                    size = max(1, len(take) // 2)
                    continue
                return                      # this stage is done: move to the next one
            self._adopt(st, trial, refit, new_score)
            size = min(2 * size, self.batch)

    def _exchange(self, problem, st, removable, names, path, tries: int = 3) -> bool:
        """Beyond the paper: swap one kept parameter for one removed one (both ``removable``: the
        current stage's) when that fits better.

        Greedy removal decides between nearly collinear terms (x1^2, x1*x2, x2^2 on data where
        x1 ~ x2) on noise; a wrong early choice is never revisited. Linearised at the current
        optimum with every parameter free (the same shared recursion as Algorithm 3), the minimal
        cost of each swapped support is one small least-squares problem; the best few swaps are
        retrained and the first that lowers the cost (or the validation cost) is kept.
        Returns whether a swap was made.
        """
        kept = [k for k in np.flatnonzero(st.active) if removable[k]]
        out = [k for k in np.flatnonzero(~st.active) if removable[k]]
        if not kept or not out:
            return False
        G = reduced_parameter_rows(problem.blocks(st.X, st.a), self.segments)
        est = {}
        for t in kept:
            for r in out:
                support = st.active.copy()
                support[t], support[r] = False, True
                est[(t, r)] = removal_estimate(G, st.a, np.flatnonzero(~support))
        for (t, r) in sorted(est, key=est.get)[:tries]:
            if est[(t, r)] >= st.cost:
                break
            trial = st.active.copy()
            trial[t], trial[r] = False, True
            refit, new_score = self._refit(problem, st, trial)
            better = new_score < st.score if self.criterion == "cv" else refit.cost < st.cost * (1 - 1e-9)
            self._record(path, PruneStep(f"{names[t]} -> {names[r]}", float(est[(t, r)]), float(refit.cost),
                                         float(new_score), bool(better), [n for n, on in zip(names, trial) if on]))
            if better:
                self._adopt(st, trial, refit, new_score)
                return True
        return False


def log_step(step: PruneStep) -> None:
    """A progress message per step (``BackwardElimination(on_step=log_step)``), logger ``mcl``."""
    what = "dense fit" if step.removed is None else ("accepted: " if step.accepted else "refused: ") + step.removed
    log.info("    %3d terms, cost %.6g  %s", len(step.active), step.cost, what)


@dataclass
class _State:
    """The current support, fit and criterion value of a backward elimination."""

    active: np.ndarray
    X: np.ndarray
    a: np.ndarray
    cost: float
    score: float

    def update(self, active, fit, score) -> None:
        self.active, self.X, self.a, self.cost, self.score = active, fit.X, fit.a, fit.cost, score

