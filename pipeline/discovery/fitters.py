"""Candidate fitters: how a candidate's law is fitted to the data and pruned.

Two built-in routes, registered through the hook ``mcl_fitters`` like any third-party one and
chosen in the run file by ``refinement: {method: ...}``:

- ``simulation`` (:class:`SimulationFitter`): the low-budget Levenberg-Marquardt of the fit
  stage on simulations with exact sensitivities (paper 000's cost J of eq. 3), then backward
  elimination of terms (the RSS increase of removing a term estimated from the sensitivities,
  the best removal refitted, kept if the criterion improves);
- ``full-discretisation`` (:class:`FullDiscretisationFitter`): paper 004's least squares over
  states and parameters (eq. 12) with stage-wise backward elimination (:mod:`mcl.refine`).

Both are scored the same way: the RSS of a simulation of the result on the training data and
the run's :class:`mcl.stats.Criterion`, so candidates from either route compare.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..data import TimeSeries
from ..errors import MclError
from ..simulation import RUN_TIME_LIMIT
from ..stats import criterion as criterion_of, effective_samples, gram_inverse, rms, rss as rss_of

#: solver tolerances while fitting: a Gauss-Newton step needs the sensitivities to a few digits,
#: and measured inputs (linear between samples) make CVODES stop at every kink; 10x looser
#: tolerances take 3x fewer steps. Scores are computed again at the default tolerances.
FIT_OPTIONS = {"rtol": 1e-5, "atol": 1e-7}
#: a run of a whole record by a model known to simulate it (the nominal model, the model with the
#: laws found): the time a run the user asks for may take, not a candidate's 60 s (a model of
#: hundreds of components, or a loaded machine, needs more for one run)
WHOLE_RUN = {"time_limit": RUN_TIME_LIMIT}
#: a fit stops when a step lowers the cost (or is predicted to) by less than this fraction: a
#: change in RSS of 1e-5 moves a criterion by n 1e-5, far below the differences that rank candidates
FIT_TOL = 1e-5


def residual(data: TimeSeries, model, result, outputs=None) -> np.ndarray:
    """Measured minus simulated outputs (N, n_outputs), NaN where a value was not measured;
    ``outputs`` default to every model output the data measures."""
    outputs = [o for o in model.output_names if o in data.names] if outputs is None else outputs
    measured = data.select(outputs).values
    return (measured - result.outputs[:, [model.output_names.index(o) for o in outputs]]) * data.weight_of(outputs)


def rms_both(data: TimeSeries, model, result, outputs) -> tuple[float | None, float | None]:
    """The RMS of a run's residual in the data's units (reported) and weighted as the fits
    weigh it (``data.weights``: compared); (None, None) for a failed run."""
    if not result.ok:
        return None, None
    r = residual(data, model, result, outputs)
    return rms(r / data.weight_of(outputs)), rms(r)


def rms_each(data: TimeSeries, model, result, outputs) -> dict:
    """Each output's RMS of a run's residual in the data's units ({} for a failed run)."""
    if not result.ok:
        return {}
    r = residual(data, model, result, outputs) / data.weight_of(outputs)
    return {o: rms(r[:, k]) for k, o in enumerate(outputs)}



@dataclass
class FitOutcome:
    """A fitted candidate: the parameters, which terms survive, the RSS and criterion on the
    training data, the simulations spent, the pruning path and the points visited."""

    w: np.ndarray
    active: np.ndarray
    rss: float
    score: float
    simulations: int
    path: list = field(default_factory=list)
    visited: list = field(default_factory=list)
    result: object = None       # the simulation of the result on the training data, if made


class CandidateFitter:
    """Base of candidate fitters (hook ``mcl_fitters``): ``fit`` a compiled candidate model whose
    template parameters are ``names`` (``names[0]`` the law's scale), started at ``w0``."""

    name = ""
    description = ""

    def fit(self, model, data: TimeSeries, names: list[str], w0, template, criterion, budget: int,
            give_up=None, prune: bool = True, progress=None, algorithm: str = "levenberg-marquardt",
            limits: dict | None = None) -> FitOutcome:
        """``give_up(reachable_rss, current_rss, k, dictionary)`` stops a fit that cannot win;
        ``progress(rss, k, dictionary)`` is told the RSS of each better point reached (so that
        other fits can compare), ``k`` being the parameters the fit has free among ``dictionary``;
        ``algorithm`` names the optimiser (:data:`mcl.fit.FITTERS`), ``limits`` are simulation
        options that bound each run (``max_work``, ``state_bound``: a law that makes the model
        crawl or blow up fails instead)."""
        raise NotImplementedError


class SimulationFitter(CandidateFitter):
    name = "simulation"
    description = "Levenberg-Marquardt on simulations with sensitivities, then backward elimination"

    def fit(self, model, data, names, w0, template, criterion, budget, give_up=None, prune=True, progress=None,
            algorithm="levenberg-marquardt", limits=None):
        n_terms = len(getattr(template, "terms", names))
        return FitOutcome(*fit_and_prune(model, data, names, w0, budget, criterion, give_up=give_up,
                                         prune=prune, n_terms=n_terms, progress=progress, algorithm=algorithm,
                                         limits=limits, follows=getattr(template, "follows", {})))


class FullDiscretisationFitter(CandidateFitter):
    name = "full-discretisation"
    description = "paper 004: least squares over states and parameters, stage-wise backward elimination"

    def fit(self, model, data, names, w0, template, criterion, budget, give_up=None, prune=True, progress=None,
            algorithm="levenberg-marquardt", limits=None):
        if not getattr(template, "terms", None) or getattr(template, "scales", None):
            # a network, or a law with fitted scales, has no terms to prune stage-wise by degree
            return SimulationFitter().fit(model, data, names, w0, template, criterion, budget, give_up, prune,
                                          progress, algorithm, limits)
        return FitOutcome(*refine_candidate(model, data, names, w0, criterion, template))


def _followed(active: np.ndarray, follows: dict | None) -> np.ndarray:
    """``active`` with the parameters that act only through a removed term removed with it
    (``follows``: a term's index -> theirs; a hysteresis' shape parameters go with z's
    coefficient: left free with no effect, they drifted to 5e13 and made the model too stiff
    to run on the validation data). Removed, they are 0."""
    out = np.array(active, bool)
    for k, others in (follows or {}).items():
        if not out[k]:
            out[list(others)] = False
    return out


def fit_and_prune(model, data: TimeSeries, names: list[str], w0, budget: int, criterion,
                  give_up=None, prune: bool = True, n_terms: int | None = None, progress=None,
                  held=None, prunable=None, algorithm: str = "levenberg-marquardt", limits: dict | None = None,
                  follows: dict | None = None):
    """LM fit of the law parameters, then backward elimination of terms.

    ``held`` marks the parameters kept at their start value (each law's scale: G(w) = 0 and
    G(k w) = 0 are one law; default the first), ``prunable`` the terms backward elimination may
    remove (default the first ``n_terms`` but the held); ``prune=False`` keeps every parameter (a
    network has no terms to remove). ``give_up`` (see :class:`mcl.fit.LevenbergMarquardt`)
    stops a candidate that cannot win (and its ``settled()``, where it has one, skips the refits
    on growing windows once another law fits to the noise); ``progress`` hears of each better RSS."""
    from ..fit import FitProblem, fitter

    n = len(names)
    w0 = np.asarray(w0, float)
    held = np.zeros(n, bool) if held is None else np.asarray(held, bool)
    if not held.any() and prunable is None:
        held[0] = True
    if prunable is None:
        prunable = np.arange(n) < (n_terms or n)
    prunable = np.asarray(prunable, bool) & ~held
    score_of = criterion_of(criterion).score
    n_obs = int(np.isfinite(data.select([o for o in model.output_names if o in data.names]).values).sum())
    dictionary = int((~held).sum())
    active = np.ones(n, bool)

    def fit(active_mask, start, window=data, limit=budget, restore=24):
        free = active_mask & ~held
        params = [nm for nm, on in zip(names, free) if on]
        fixed = {nm: (float(w0[k]) if held[k] else 0.0) for k, nm in enumerate(names) if not free[k]}
        problem = FitProblem(model, window, params, fixed=fixed, options={**FIT_OPTIONS, **(limits or {})})
        whole = window is data      # only a fit to all the data compares with other candidates
        # the other fits compare with this one counting its free parameters (a larger law's
        # lower RSS does not stop a smaller one that the criterion may prefer)
        k = len(params)
        report = None if progress is None or not whole else (lambda cost: progress(cost * len(data.time), k, dictionary))
        stop = None if give_up is None or not whole else (lambda reach, now: give_up(reach, now, k, dictionary))
        algo = fitter(algorithm, limit, tol=FIT_TOL, give_up=stop, progress=report, restore=restore)
        res = algo.fit(problem, np.asarray(start)[free])
        w = np.where(held, w0, 0.0)
        w[free] = res.w
        rss = res.cost * len(window.time)   # J of eq. (3) is the mean over samples of the RSS
        return w, rss, problem, res

    visited = []

    def record(problem, active_mask):
        free = active_mask & ~held
        for e in problem.recorder.evaluations:
            full = np.where(held, w0, 0.0)
            full[free] = e.w
            visited.append([*full.tolist(), bool(e.feasible)])

    def score_for(rss, active_mask):
        return score_of(rss, n_obs, int((active_mask & ~held).sum()), dictionary)

    # terms are removed by the criterion counting the samples the full law's residual is worth
    # (:func:`mcl.stats.effective_samples`, from pruning's first run), the score the fit reports
    # counts them all: sampled far faster than its error changes (a friction at 1 kHz), every
    # sample counted kept a cubic that fits its slow wiggles; a law that leaves white noise is
    # pruned as before
    n_worth = n_obs

    def pruning(rss, kept: int):
        return score_of(rss * n_worth / n_obs, n_worth, kept, dictionary)

    def worth(sim) -> float:
        # (at least the dictionary's square: below it the extended BIC's cost of the choice,
        # 2 log C(D, k), largest at half the dictionary, outweighs a term's own log n, and a
        # full law would be kept whole for counting few samples)
        return min(float(n_obs), max(effective_samples(problem.residual_and_cost(sim)[0]), dictionary ** 2))

    w, rss, problem, res = fit(active, w0)
    record(problem, active)
    sims = res.simulations
    start = next((e.cost for e in problem.recorder.evaluations if e.feasible), None)
    # (a switched system's ladder starts shorter: its phase drifts from its first switches on;
    # the room of a thermostat fitted from its first quarter, two dozen switches, stalled)
    windows = moving(horizons(data, **(SWITCHED_LADDER if problem.switched else {})), model.output_names)
    # (not when another law already fits to the noise: this one could at best tie with it)
    settled = getattr(give_up, "settled", None)
    if (len(windows) > 1 and start is not None and rss > (SWITCHED_STALL if problem.switched else STALL) * start * len(data.time)
            and not res.message.startswith("stopped") and not (settled and settled())):
        # hardly better than where it started: a law far from the nominal one moves resonances,
        # and a fit to the whole record falls into the local minima phase drift makes; fitted
        # first to its first eighth, quarter and half, each start is close enough for the next
        # (a window's fit that cannot start, from where the last one ended, ends the ladder:
        # the fit to the whole record stands)
        w_c, rss_c = w0, np.inf
        for window in windows:
            try:
                w_c, rss_c, problem_c, res_c = fit(active, w_c, window, max(budget - sims, 5))
            except MclError:
                rss_c = np.inf
                break
            record(problem_c, active)
            sims += res_c.simulations
        if rss_c < rss:
            w, rss, problem, res = w_c, rss_c, problem_c, res_c
    path = []
    score = pruning(rss, int((active & ~held).sum()))
    path.append({"removed": None, "rss": rss, "score": score, "accepted": True, "message": res.message})
    last = {}      # the previous estimates, by parameter: for a point whose sensitivities fail
    grouping = True

    def judged(trial, refit, removed: str, estimate: float):
        """A removal's refit scored against the current law and put on the path: (accepted,
        the state it would give: active, w, rss, score, problem)."""
        nonlocal sims
        w_t, rss_t, problem_t, res_t = refit
        record(problem_t, trial)
        sims += res_t.simulations
        score_t = pruning(rss_t, int((trial & ~held).sum()))
        ok = score_t < score
        path.append({"removed": removed, "estimate": float(estimate), "rss": rss_t,
                     "score": score_t, "accepted": bool(ok)})
        return ok, (trial, w_t, rss_t, score_t, problem_t)

    while prune and (active & prunable).sum() > 1 and not res.message.startswith("stopped"):
        sim = problem.simulate(w[active & ~held], gradient=True)
        sims += 1
        free = np.flatnonzero(active & ~held)
        if sim.ok and not path[1:]:      # (the full law's run, nothing removed yet: its residual's worth)
            n_worth = worth(sim)
            score = path[0]["score"] = pruning(rss, len(free))
        if sim.ok:
            S = problem.output_sensitivities(sim).reshape(-1, len(free))
            H_inv = gram_inverse(S.T @ S)
            with np.errstate(over="ignore"):       # (a huge coefficient's estimate is inf: removed last)
                est = w[free] ** 2 / np.maximum(np.diag(H_inv), 1e-300)      # increase of RSS
        elif last:
            # a law near the edge of what simulates (a capacitance term crossing zero at the
            # end of the range) may fail on the finer grid of the sensitivities: the removals
            # are tried in the previous order (removing the culprit is what makes it robust)
            est = np.array([last.get(k, np.inf) for k in free])
        else:
            break
        est = np.where(prunable[free], est, np.inf)                  # a scale is not a term
        last = dict(zip(free, est))
        if sim.ok and grouping:
            # the terms the criterion would drop together, by the same estimate, in one refit
            # (a six-term law pruned to two: one refit, not four); refused, one at a time
            group = _group_to_drop(w[free], H_inv, est, rss, score,
                                   lambda r, m: pruning(r, len(free) - m))
            if len(group) > 1:
                trial = active.copy()
                trial[free[group]] = False
                trial = _followed(trial, follows)
                try:
                    refit = fit(trial, w, restore=1)
                except MclError:
                    refit = None
                if refit is not None:
                    ok, state = judged(trial, refit, ", ".join(names[free[j]] for j in group),
                                       rss + _joint_increase(w[free], H_inv, group))
                    if ok:
                        active, w, rss, score, problem = state
                        continue
                grouping = False
        refit = None
        # the cheapest removal first; one the model cannot do without (a capacitor's own
        # capacitance: its state would vanish) does not simulate, and the next is tried
        for j in np.argsort(est)[:3]:
            if not np.isfinite(est[j]):
                break
            trial = active.copy()
            trial[free[j]] = False
            trial = _followed(trial, follows)
            try:
                refit = fit(trial, w, restore=1)
            except MclError:
                path.append({"removed": names[free[j]], "accepted": False, "message": "does not simulate without it"})
                continue
            k, e_k = free[j], est[j]
            break
        if refit is None:
            break
        ok, state = judged(trial, refit, names[k], rss + e_k)
        if not ok:
            break
        active, w, rss, score, problem = state
    from ..services import simulate

    final = simulate(model, data, dict(zip(names, w)))    # the score at the default tolerances
    sims += 1
    if final.ok:
        rss = rss_of(residual(data, model, final))
    return w, active, rss, score_for(rss, active), sims, path, visited, final


def _joint_increase(w: np.ndarray, H_inv: np.ndarray, group) -> float:
    """The increase of RSS from setting the parameters ``group`` to zero and refitting the
    others, to first order: w_G^T (H^-1_GG)^-1 w_G (a single term's is w^2 / H^-1_jj)."""
    g = np.asarray(group)
    return float(w[g] @ np.linalg.pinv(H_inv[np.ix_(g, g)]) @ w[g])


def _group_to_drop(w: np.ndarray, H_inv: np.ndarray, est: np.ndarray, rss: float, score: float,
                   score_without) -> list[int]:
    """The largest set of the cheapest terms (by their single ``est``) whose joint removal the
    criterion is estimated to prefer (``score_without(rss, how many removed)`` below ``score``),
    leaving at least one term."""
    order = [int(j) for j in np.argsort(est) if np.isfinite(est[j])]
    best: list[int] = []
    for m in range(2, len(order)):
        group = order[:m]
        if score_without(rss + _joint_increase(w, H_inv, group), m) < score:
            best = group
    return best


#: a fit to the whole record that leaves more than this share of its start's RSS is refitted
#: on growing windows (it hardly moved: a local minimum of phase drift); a switched system's
#: fit is, unless it left less than :data:`SWITCHED_STALL`: its sawtooth's phase drifts past
#: each switch, and a furnished room's air-to-furniture law, fitted to the whole record, left
#: 49 % (0.50 K against 0.05 K of noise) in a local minimum that its first windows avoid
STALL, SWITCHED_STALL = 0.5, 0.02
#: the refits on growing windows of a switched system (FitProblem.switched): from its first
#: 32nd, windows of 20 samples or more (a thermostat's room: its first 16th, one switch, fits
#: from the nominal law to the truth; its first quarter does not)
SWITCHED_LADDER = {"first": 1 / 32, "min_samples": 20}


def horizons(data: TimeSeries, first: float = 1 / 8, min_samples: int = 100) -> list[TimeSeries]:
    """The data's first eighth, quarter, half and all of it (windows shorter than
    ``min_samples`` samples left out)."""
    n, out, frac = len(data.time), [], first
    while frac < 1:
        k = int(n * frac)
        if k >= min_samples:
            out.append(data.head(k))
        frac *= 2
    return [*out, data]


#: a window of the refits on growing windows that holds less than this share of the outputs'
#: movement teaches the fit nothing: the Wiener-Hammerstein record is quiet for its first half
#: (its first eighth, quarter and half hold 0.26 % of it; the tanks' first eighth 2.6 %), and
#: a fit to it wandered to costs of 1e7, 100 simulations a candidate, all thrown away
QUIET = 0.01


def moving(windows: list[TimeSeries], outputs) -> list[TimeSeries]:
    """``windows`` (:func:`horizons`: the last is the whole record) without the partial ones
    in which the measured ``outputs`` have made less than :data:`QUIET` of their movement (the
    sum of their squared steps, each output's share, averaged over them)."""
    whole = windows[-1]
    cols = [whole.names.index(o) for o in outputs if o in whole.names]
    steps = np.nan_to_num(np.diff(whole.values[:, cols], axis=0)) ** 2
    total = steps.sum(axis=0)
    if not cols or not np.all(total > 0):
        return windows
    share = lambda w: float(np.mean(steps[:len(w.time) - 1].sum(axis=0) / total))
    return [w for w in windows[:-1] if share(w) >= QUIET] + [whole]


def refine_candidate(model, data: TimeSeries, names: list[str], w0, criterion: str, template):
    """Paper 004's refinement (:func:`mcl.refine.refine`), scored like :func:`fit_and_prune`:
    RSS and BIC/AIC of a simulation of the refined law on the training data."""
    from ..services import simulate
    from ..refine import refine

    w, active, path = refine(model, data, names, w0, criterion, terms=getattr(template, "terms", None))
    res, sims = simulate(model, data, dict(zip(names, w * active))), 2   # and refine's start
    if not res.ok:   # the refined law does not simulate: keep the start (nominal) law
        w, active = np.asarray(w0, float), np.ones(len(names), bool)
        res, sims = simulate(model, data, dict(zip(names, w))), 3
    r = residual(data, model, res)
    rss = rss_of(r)
    score = criterion_of(criterion).score(rss, int(np.isfinite(r).sum()), int(active.sum()) - 1, len(names) - 1)
    return w * active, active, rss, score, sims, path, [], res


