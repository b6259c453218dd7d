"""How sure the learned laws are, and the model calibrated with them (grey-box refit).

:func:`uncertainty`: the learned laws' parameters at the optimum, with standard errors from the
Jacobian of the outputs (cov = s^2 (J^T J)^-1, s^2 = RSS / (n - k)), checked by a bootstrap over
blocks of the residual (the Gauss-Newton step each resampled residual asks for: blocks keep the
residual's correlation, which the Jacobian's errors assume away); and a band around each learned
curve (the delta method: Var f(x) = g(x)^T cov g(x), g the law's gradient in its parameters).

:func:`calibrate`: the learned laws refitted together with the nominal parameters the user frees
(``free: [M.m, D.d]``) or those the data determine (``free: auto``: each parameter whose standard
error, with the others, is small against its value); a parameter the data cannot determine is
reported as such and left at its value, not fitted to noise.
"""
from __future__ import annotations

import numpy as np

from ..data import TimeSeries
from ..progress import log
from ..runfile import unknown_free
from ..stats import gram_inverse
from .fitters import FIT_OPTIONS, WHOLE_RUN, residual, rms_both, rms_each

#: a parameter is determined by the data when its standard error is below this share of its
#: value: two standard errors from 0. (At 1.0 a servo drive's load inertia, 0.83 of its value,
#: was freed beside the motor constant and the gear ratio, which together with it the data
#: determine only as a product and a sum, and all three ended at +-110 %)
DETERMINED = 0.5
#: ... and an initial state when below this share: a nuisance the fit needs, whose standard
#: error, measured at the start of the fit, counts the misfit the fit then removes (the tanks'
#: second level at 0.83 of its value: left out, the refit ended at 1.39 V against 0.35)
DETERMINED_STATE = 1.0
#: simulations of the calibration's fit
REFIT_BUDGET = 60
#: the calibration's fit stops once its last few simulations gained less than this share of the
#: RSS (half a percent of the RMS): on the Silverbox, 57 of the first stage's 60 simulations
#: gained 3 %, stepping and stepping back along the valley where kf, ks and M.m trade off
SETTLED = 0.01
#: a calibration's start may cost this many times the best start's RSS (see :func:`_first_good`)
START_SPREAD = 10.0
#: resamples of the block bootstrap
RESAMPLES = 200


def jacobian(model, data: TimeSeries, params: dict, names: list[str]):
    """(residual vector over measured entries, its Jacobian in ``names``) at ``params``."""
    from ..fit import FitProblem

    fixed = {k: v for k, v in params.items() if k not in names}
    problem = FitProblem(model, data, names, fixed=fixed, options=FIT_OPTIONS)
    res = problem.simulate([params[n] for n in names], gradient=True)
    if not res.ok:
        return None, None
    r = residual(data, model, res, problem.outputs)
    S = problem.output_sensitivities(res)
    ok = np.isfinite(r)
    return r[ok], S[ok]


def covariance(r: np.ndarray, J: np.ndarray) -> np.ndarray:
    """s^2 (J^T J)^+ with s^2 = RSS / (n - k): the parameters' covariance at a least-squares fit."""
    n, k = J.shape
    return float(r @ r) / max(n - k, 1) * gram_inverse(J.T @ J)


def bootstrap(r: np.ndarray, J: np.ndarray, blocks: int = 40, seed: int = 0) -> np.ndarray:
    """Standard errors from the spread of the Gauss-Newton steps (J^T J)^+ J^T r* over residuals
    r* resampled in blocks (``blocks`` of them, drawn with replacement: each block keeps the
    residual's correlation within it)."""
    n = len(r)
    H = gram_inverse(J.T @ J)
    size = max(n // blocks, 1)
    pieces = [np.arange(s, min(s + size, n)) for s in range(0, n, size)]
    centred = r - r.mean()
    rng = np.random.default_rng(seed)
    steps = []
    for _ in range(RESAMPLES):
        rs = np.concatenate([centred[pieces[c]] for c in rng.integers(0, len(pieces), len(pieces))])[:n]
        steps.append(H @ (J.T @ np.pad(rs, (0, n - len(rs)))))
    return np.std(steps, axis=0)


def uncertainty(model, data: TimeSeries, params: dict, laws: list[dict]) -> None:
    """Standard errors, 95% intervals and curve bands of the learned laws ``laws`` (each with
    ``names``: its parameters in ``model``, ``active``, ``held``, ``template``, ``curve_x``),
    written into each law dict (``parameters`` and ``band``)."""
    from ..services import registry

    names = [n for law in laws for n, on, held in zip(law["names"], law["active"], law["held"]) if on and not held]
    if not names:
        return
    r, J = jacobian(model, data, params, names)
    if r is None:
        return
    cov, boot = covariance(r, J), bootstrap(r, J)
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    at = {n: k for k, n in enumerate(names)}
    for law in laws:
        rows = []
        for n, on, held in zip(law["names"], law["active"], law["held"]):
            if on and not held:
                k = at[n]
                v = params[n]
                rows.append({"name": n, "value": v, "std_error": float(se[k]), "bootstrap_std_error": float(boot[k]),
                             "ci95": [v - 1.96 * float(se[k]), v + 1.96 * float(se[k])]})
        law["parameters"] = rows
        template = registry().template(law["template"])
        xs = np.asarray(law["curve_x"], float)
        own = [at[n] for n, on, held in zip(law["names"], law["active"], law["held"]) if on and not held]
        g = _gradient(template, np.asarray(law["w"], float), np.asarray(law["active"], bool), xs)
        if g is not None and len(own) == g.shape[1]:
            C = cov[np.ix_(own, own)]
            law["band"] = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", g, C, g), 0.0)).tolist()


def _gradient(template, w, active, xs):
    """d curve / d w_k at ``xs`` for the active, non-held parameters (numerically: the curve of
    any template, explicit or solved)."""
    base = template.curve(w * active, xs)
    if not np.all(np.isfinite(base)):
        return None
    cols = []
    for k in np.flatnonzero(active)[1:]:
        h = 1e-6 * max(abs(w[k]), 1e-3)
        wp = (w * active).copy()
        wp[k] += h
        cols.append((template.curve(wp, xs) - base) / h)
    return np.column_stack(cols) if cols else None


def calibrate(model, train: TimeSeries, validate: TimeSeries | None, params: dict, laws: list[str],
              free, outputs, held=(), judged_on: TimeSeries | None = None, own_start: int | None = None,
              starts: list[dict] = ()) -> dict:
    """The laws' parameters ``laws`` refitted together with the nominal parameters ``free``
    (names, or "auto": those the data determine). Returns what was freed, what the data cannot
    determine, the values with standard errors, and the training and validation RMS (the
    training RMS on ``judged_on`` when given: the whole record of which ``train`` is the head);
    also the calibrated ``params`` and their ``run`` on that record.
    Where the initial state is calibrated, the validation run starts from its own, fitted on
    the first ``own_start`` samples of ``validate`` (default: as many as ``train`` has; at most
    a quarter of the record): the initial-state parameters ``free`` allows, not ``held``.
    ``starts``: values the fit may start from instead of ``params`` (calibrations of the same
    laws on fewer samples: the Wiener-Hammerstein's final one then settles in a few steps), in
    order of preference, ``params`` last: the first not far behind the best on ``train`` is
    taken (:func:`_first_good`)."""
    from ..services import simulate

    nominal = [n for n in model.ode.p_names if n not in laws and n not in held and np.isfinite(params[n])]
    asked = nominal if free == "auto" else list(free)
    unknown = unknown_free(asked, model.ode.p_names, model.name)      # (a run file's are checked before)
    if unknown:
        from ..errors import ConfigError

        raise ConfigError(f"free: {unknown[0]}")
    candidates = [n for n in asked if n not in laws]
    r, J = jacobian(model, train, params, laws + candidates)
    if r is None:
        return {"error": "the extended model does not simulate the training data"}
    if free == "auto":     # flags and parameters no equation reads any more (a law replaced it): not candidates
        keep = [k for k in range(len(candidates)) if np.any(J[:, len(laws) + k] != 0.0)]
        candidates, J = [candidates[k] for k in keep], J[:, list(range(len(laws))) + [len(laws) + k for k in keep]]
    # (the parameters only the initial equations read: a sparsity sweep of the model's functions)
    initial_states = list(getattr(model, "initial_parameters", ()))
    determined, undetermined = _determined(r, J, laws, candidates, params, strict=free == "auto",
                                           states=set(initial_states))
    log.info("      calibration: %s refitted with the laws%s", ", ".join(determined) or "nothing",
             f"; not determined by the data: {', '.join(undetermined)}" if undetermined else "")
    names = laws + determined
    # (only what this fit frees: a value held here stays the model's)
    begins = [{**params, **{n: float(s[n]) for n in names if n in s and np.isfinite(s[n])}} for s in starts]
    begins = [b for k, b in enumerate(begins) if b != params and b not in begins[:k]]
    begin = _first_good([*begins, params], lambda b: _rss(model, train, b, outputs)) if begins else params
    # the initial state is a nuisance: the laws and the physical parameters are fitted first
    # from the start as given, then everything from there. Fitted together from the start, a
    # long record's initial state can lead the fit into a worse optimum that absorbs drift
    # (EMPS: 1.9 against 1.5 mm on training, 8.3 against 5.2 mm on the test record)
    # (the second fit starts next to its optimum: a third of the first's simulations). A start
    # calibrated on fewer samples had its initial state fitted so: the first fit is skipped
    # (on the Wiener-Hammerstein it gained 0.2 % of the RSS in 11 simulations of 32 768 samples)
    initial = set(initial_states) & set(determined)
    calibrated = begin is not params
    first = (_refit(model, train, begin, [n for n in names if n not in initial]) if initial and not calibrated
             else begin)
    new = _refit(model, train, first, names, REFIT_BUDGET // 3 if initial else REFIT_BUDGET)
    # a physical parameter the fit drove through zero (a hydraulic resistance of 1e7 Pa s/m3
    # calibrated to -1.4e8 beside a learned pipe law) stands in for the law, not for the
    # system: held at the model's value, the rest refitted from there
    flipped = _flipped(names, laws, params, new, set(initial_states))
    if flipped:
        log.info("      calibration: %s changed sign in the fit: held at the model's value%s",
                 ", ".join(f"{n} ({params[n]:.3g} -> {new[n]:.3g})" for n in flipped), "s" * (len(flipped) > 1))
        names = [n for n in names if n not in flipped]
        determined = [n for n in determined if n not in flipped]
        # (from where the fit began: the others had followed the flipped one, and from their
        # values with it reset the hose case's refit ended at 2.4x the laws' own RMS)
        new = _refit(model, train, {**first, **{n: params[n] for n in flipped}}, names)
    se = _std_errors(model, train, new, names)
    # judged before the fit they looked determined; at the optimum some may trade off with the
    # laws (the tanks written as equations: the pump's gain, the sensor's and an initial level,
    # each at more than half its value). Fixed back at their values, the refit ended at 1.68 V
    # on training instead of 0.3: the outputs need them, only their split with the laws is
    # loose. They stay fitted and are reported so.
    loose = _loose(names, laws, new, se, set(initial_states))
    if loose:
        log.info("      calibration: %s trade off with the laws at the optimum (standard error above %g of "
                 "the value): one of many equally good sets", ", ".join(loose), DETERMINED)
    out = {"freed": determined, "not_determined": undetermined, "loose": loose, "sign_changed": flipped,
           "values": {n: {"before": params[n], "after": new[n], "std_error": float(se[k])} for k, n in enumerate(names)
                      if n in determined},
           "laws": {n: new[n] for n in laws}}      # the laws' parameters refitted with them
    whole = judged_on if judged_on is not None else train
    sim = simulate(model, whole, new, options=WHOLE_RUN)
    # (reported in the data's units; the calibrations of several laws are compared on the
    # residual weighted as it was fitted)
    out["train_rms"], out["_fit_rms"] = rms_both(whole, model, sim, outputs)
    out["per_output"] = {o: {"train": v} for o, v in rms_each(whole, model, sim, outputs).items()}
    if validate is not None:
        # (at most a quarter of the record: the rest is judged on what was not fitted to it)
        head = validate.head(min(own_start or len(train.time), max(len(validate.time) // 4, 1)))
        states = [n for n in initial_states if n not in held and np.isfinite(params[n])
                  and (free == "auto" or n in free)]
        own, seen = _own_start(model, head, new, states) if initial else (new, [])
        sv = simulate(model, validate, own, options=WHOLE_RUN)
        if not sv.ok and seen:         # a start fitted on the head that fails later: the training's
            sv, seen = simulate(model, validate, new, options=WHOLE_RUN), []
        out["validation_rms"] = rms_both(validate, model, sv, outputs)[0]
        for o, v in rms_each(validate, model, sv, outputs).items():
            out["per_output"].setdefault(o, {})["validation"] = v
        if seen:
            out["validation_initial_state"] = seen
    out["params"], out["run"] = new, sim
    return out


def _std_errors(model, data: TimeSeries, params: dict, names: list[str]) -> np.ndarray:
    """Standard errors of ``names`` at ``params`` (NaN where the run fails)."""
    r, J = jacobian(model, data, params, names)
    if r is None:
        return np.full(len(names), np.nan)
    return np.sqrt(np.maximum(np.diag(covariance(r, J)), 0.0))


def _limit(name: str, states) -> float:
    """The share of its value a parameter's standard error must stay below to count as determined."""
    return DETERMINED_STATE if name in states else DETERMINED


def _loose(names: list[str], laws: list[str], params: dict, se: np.ndarray, states) -> list[str]:
    """The nominal parameters among ``names`` whose standard error at the optimum is not below
    :data:`DETERMINED` of their value (:data:`DETERMINED_STATE` for initial ``states``)."""
    out = []
    for n, s in zip(names, se):
        if n not in laws and np.isfinite(s) and params[n] != 0.0 and s > _limit(n, states) * abs(params[n]):
            out.append(n)
    return out


def _flipped(names: list[str], laws: list[str], before: dict, after: dict, states) -> list[str]:
    """The nominal parameters among ``names`` (not the laws', not the initial ``states``, which
    may cross zero) whose value changed sign from ``before`` to ``after``."""
    return [n for n in names if n not in laws and n not in states and before[n] != 0.0
            and np.sign(after[n]) == -np.sign(before[n])]


def _first_good(starts: list[dict], rss) -> dict:
    """The first of ``starts`` whose ``rss`` is within :data:`START_SPREAD` of the least of them,
    in their order of preference: a start calibrated with other parameters free can be far worse
    than the laws as found (the coupled drives' start merged from three rounds' calibrations cost
    2000x theirs), but the start of least RSS is not the best start for the fit (the tanks'
    merged start cost 2.3x the laws as found; from the laws the joint refit reached 0.47 V on
    the test record, from it 0.31)."""
    values = [rss(s) for s in starts]
    best = min(values)
    return next(s for s, v in zip(starts, values) if v <= START_SPREAD * best)


def _rss(model, data: TimeSeries, params: dict, outputs) -> float:
    """The residual sum of squares of a run of ``model`` with ``params`` on ``data`` (inf when
    it fails)."""
    from ..services import simulate

    run = simulate(model, data, params, options=FIT_OPTIONS)
    return float(np.nansum(residual(data, model, run, outputs) ** 2)) if run.ok else np.inf


def _own_start(model, head: TimeSeries, params: dict, states: list[str]) -> tuple[dict, list[str]]:
    """``params`` with the initial state ``states`` refitted on the ``head`` of a held-out record
    (where the calibration fitted the training record's), and the states the head moved: that
    record starts where the system happened to be, not where the training record did (the
    Wiener-Hammerstein test record starts mid-signal: its first 20 samples alone made the test
    error 2.8 mV, not 0.85). The laws and the physical parameters stay as calibrated; a state
    the head does not see stays as well."""
    r, J = jacobian(model, head, params, states)
    if r is None:
        return params, []
    seen = [n for k, n in enumerate(states) if np.any(J[:, k] != 0.0)]
    if not seen:
        return params, []
    own = _refit(model, head, params, seen, REFIT_BUDGET // 3)
    log.info("      validation: its own initial state (%s) fitted on its first %d samples",
             ", ".join(seen), len(head.time))
    return own, seen


def _refit(model, data: TimeSeries, params: dict, names: list[str], budget: int = REFIT_BUDGET) -> dict:
    """``params`` with ``names`` refitted on ``data`` (Levenberg-Marquardt from their values, in
    at most ``budget`` simulations), stopped once it has settled (:data:`SETTLED`). The
    damping follows each step's gain: with the rule that only shrinks it after a step taken,
    every other step of the Silverbox's calibration was rejected, a simulation each; with it,
    not one of the second stage's. Its final calibration took 126 CPU-s instead of 163, with
    the same test errors."""
    from ..fit import FitProblem, LevenbergMarquardt

    fixed = {k: v for k, v in params.items() if k not in names}
    problem = FitProblem(model, data, names, fixed=fixed, options=FIT_OPTIONS)
    lm = LevenbergMarquardt(max_simulations=budget, axis=None, tol=1e-6, settle=SETTLED, by_gain=True)
    res = lm.fit(problem, [params[n] for n in names])
    log.debug("      refit of %d parameters on %d samples: %s after %d simulations, RSS %.4g",
              len(names), len(data.time), res.message, res.simulations, res.cost)
    return {**params, **dict(zip(names, map(float, res.w)))}


def _determined(r, J, laws, candidates, params, strict: bool, states=frozenset()) -> tuple[list[str], list[str]]:
    """Which of ``candidates`` the data determine together with the laws: added in order of how
    much the outputs depend on them, each kept while its relative standard error stays below
    :data:`DETERMINED` (:data:`DETERMINED_STATE` for the initial ``states``) (with ``strict``;
    asked-for ones only need a finite one) and its column is
    not a combination of the others'. A parameter at 0 (an offset, a rest length, an initial
    state) is measured against the value one Gauss-Newton step gives it: determined when the
    data move it clearly away from 0."""
    n_law = len(laws)
    size = lambda k: abs(params[candidates[k]]) or 1.0
    order = sorted(range(len(candidates)), key=lambda k: -np.linalg.norm(J[:, n_law + k]) * size(k))
    chosen, left = [], []
    for k in order:
        cols = list(range(n_law)) + [n_law + j for j in chosen] + [n_law + k]
        cov = covariance(r, J[:, cols])
        se = np.sqrt(np.maximum(np.diag(cov), 0.0))
        value = abs(params[candidates[k]])
        if value == 0.0:
            value = abs(float(np.linalg.lstsq(J[:, cols], r, rcond=None)[0][-1]))
        rel = se[-1] / max(value, 1e-300)
        if np.isfinite(rel) and _independent(J[:, cols]) and (rel < _limit(candidates[k], states) or not strict):
            chosen.append(k)
        else:
            left.append(k)
    return [candidates[k] for k in chosen], [candidates[k] for k in left]


def _independent(J: np.ndarray, tol: float = 1e-3) -> bool:
    """Whether the last column is not (nearly) a combination of the others, all scaled to unit
    norm (a coefficient of 1e11, a cubic in millimetres, is not ill-determined for its size
    alone; laws that share a term among themselves do not make every nominal parameter so). The
    tolerance is well above the sensitivities' integration error: two parameters that trade off
    exactly (a gain in and a gain out) differ by that error alone."""
    Jc = J / np.maximum(np.linalg.norm(J, axis=0), 1e-300)
    last, others = Jc[:, -1], Jc[:, :-1]
    if not np.linalg.norm(J[:, -1]) > 0:
        return False
    if others.shape[1] == 0:
        return True
    left = last - others @ np.linalg.lstsq(others, last, rcond=None)[0]
    return float(np.linalg.norm(left)) > tol
