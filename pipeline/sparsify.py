"""Backward elimination: from a dense fitted law to a sparse, readable one (paper 004, sec. V).

Each round estimates, for every remaining candidate parameter, the minimal cost after setting
it to zero (Algorithm 3, :func:`pipeline.lm.removal_estimate`: the state eliminations are
shared), retrains the best candidate with Levenberg-Marquardt, and accepts the removal if the
criterion says so:

- ``threshold``: the cost stays within (1 + tau) of the dense model's;
- ``aic`` / ``bic``: n log(V / n) + 2k, or + k log n, does not increase (n measured values);
- ``cv``: the cost on held-out measurements (a second problem) does not increase.

Which parameters may be removed next is a plugin point (``mcl_prioritisers``): ``all`` offers
every remaining one; ``degree`` offers the highest monomial degree first and moves to the next
degree when a removal there is refused (the stage-wise removal of section VI-A).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import ConfigError
from .lm import IdentificationProblem, levenberg_marquardt, reduced_parameter_rows, removal_estimate, restrict


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

    def terms(self) -> dict[str, float]:
        return {n: float(v) for n, v, on in zip(self.names, self.a, self.active) if on}

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
                 batch: int = 1):
        if criterion not in ("threshold", "aic", "bic", "cv"):
            raise ConfigError(f"criterion '{criterion}': choose threshold, aic, bic or cv")
        if criterion == "cv" and validation is None:
            raise ConfigError("criterion 'cv' needs a validation problem (held-out measurements)")
        self.criterion, self.threshold = criterion, threshold
        self.prioritiser = prioritiser or HighestDegreeFirst()
        self.segments, self.lm_options = segments, dict(lm_options or {})
        self.validation = validation
        self.batch = max(1, int(batch))

    def _score(self, problem, X, a, active, cost, dense_cost) -> float:
        n = max(int(problem.M.sum()), 1)
        k = int(active.sum())
        if self.criterion == "aic":
            return n * np.log(cost / n) + 2 * k
        if self.criterion == "bic":
            return n * np.log(cost / n) + k * np.log(n)
        if self.criterion == "threshold":
            return cost / dense_cost
        Xv = self.validation.initial_states()
        return levenberg_marquardt(self.validation, Xv, a, active, segments=self.segments,
                                   **self.lm_options).cost

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
        X, a, cost = fit.X, fit.a, fit.cost
        dense = cost
        score = self._score(problem, X, a, active, cost, dense)
        path = [PruneStep(None, None, cost, score, True, [n for n, on in zip(names, active) if on])]
        for stage in self.prioritiser.stages(names, degrees):
            size = 1
            while True:
                cand = [k for k in stage if active[k] and removable[k]]
                if not cand or active.sum() <= 1:
                    break
                G = reduced_parameter_rows(restrict(problem.blocks(X, a), active), self.segments)
                idx = list(np.flatnonzero(active))
                a_act = a[active]
                est = {k: removal_estimate(G, a_act, [idx.index(k)]) for k in cand}
                take = sorted(cand, key=est.get)[:min(size, len(cand), int(active.sum()) - 1)]
                trial = active.copy()
                trial[take] = False
                refit = levenberg_marquardt(problem, X, a, trial, segments=self.segments, **self.lm_options)
                new_score = self._score(problem, refit.X, refit.a, trial, refit.cost, dense)
                ok = self._accept(new_score, score)
                joint = removal_estimate(G, a_act, [idx.index(k) for k in take])
                path.append(PruneStep(", ".join(names[k] for k in take), float(joint), refit.cost,
                                      float(new_score), ok, [n for n, on in zip(names, trial) if on]))
                if not ok:
                    if len(take) > 1:       # too many at once: try fewer
                        size = max(1, len(take) // 2)
                        continue
                    break                   # this stage is done: move to the next one
                active, X, a, cost = trial, refit.X, refit.a, refit.cost
                size = min(2 * size, self.batch)
                if self.criterion != "threshold":
                    score = new_score
        return SparseResult(names, active, a, X, cost, path)

