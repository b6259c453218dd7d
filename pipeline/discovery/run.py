"""The main job (``mcl run``): what the model gets wrong, which components, which laws, what gain.

The user's model is compiled once, exactly as written; everything below works on that compiled
model (its DAE and component structure), never on rewritten Modelica.

1. Misfit: the nominal model simulated on the training inputs; the residual (where measured)
   against the noise estimated from the data, so a correct model comes out not significant;
   where it exceeds the noise.
2. Search (:func:`_search`): every candidate component (or the named one) with the law families
   of its role (:mod:`.families`) or the pinned templates. Screening is one simulation of the
   model with a deviation at every component (:mod:`.screen`), which predicts what one
   Gauss-Newton step of each law at each component would reach; the promising laws are put into
   the compiled DAE (:mod:`.inject`), fitted and pruned by a fitter plugin (:mod:`.fitters`),
   stopped when they cannot win; then the shape stage (a network distilled into sparse laws).
3. Verdict (:func:`_decide`): ranked by the run's :class:`mcl.stats.Criterion` against each
   other and the model without the law; a cause must also improve the validation data; of
   laws that explain the data equally well on parallel components, the one whose role fits
   the learned effect is named and the others listed as equivalent.
4. Several faults: the cause is put into the model and steps 1-3 repeat on the extended model
   until the misfit is at the noise level or no further cause convinces.
5. Extend and report (:mod:`.extend`, :mod:`.report`): the laws in the components' words, the
   extended model written as Modelica, compiled and exported as an FMU, gains on training and
   validation data (and another configuration); report.json and report.html.

The run directory is built in ``<output>.partial`` (each candidate's result saved as it finishes,
so an interrupted run resumes) and renamed to ``<output>`` at the end.
"""
from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..data import TimeSeries
from ..errors import ConfigError, MclError
from ..executor import TaskFailed
from ..progress import log
from ..stats import criterion as criterion_of, noise_estimate, rms
from .families import distillations, families, role_of, spec_name
from .fitters import FIT_OPTIONS, residual
from .inject import NominalForm, compiled, mode_of, nominal_form, rate_variables, with_injections, with_law
from ..sensitivity import fine_grid
from .screen import law_signals, linear_response, predicted_rss

#: at most this many causes are searched one after the other
MAX_CAUSES = 3
#: family indices of the shape stage (after any family list)
NEURAL_INDEX, SHAPE_INDEX = 100, 101


class Item(NamedTuple):
    """One candidate: a component with one law (family index ``index`` of its list, or of the
    shape stage) given by a template spec."""

    component: str
    index: int
    spec: object

    @property
    def key(self) -> tuple[str, int]:
        return (self.component, self.index)

    @property
    def file(self) -> str:
        return f"candidates/{self.component}_{self.index}.json"


@dataclass
class Base:
    """The model a search round works on: the compiled model with the causes found so far."""

    model: object              # CompiledModel (outputs include the measured variables)
    result: object             # its simulation of the training data
    excluded: set = field(default_factory=set)   # components already named as causes

    @property
    def dae(self):
        return self.model.dae

    @property
    def structure(self):
        return self.model.structure


@dataclass
class Context:
    """What every executor task of a round shares (inherited by forked workers)."""

    base: Base
    signals: dict               # component -> nominal law variables at the data points
    rates: dict                 # component -> its across value and flow as functions of the states
    train: TimeSeries
    validate: TimeSeries | None
    budget: int                 # simulations per fit
    criterion: str
    method: str                 # simulation | full-discretisation
    progress_dir: str           # running and finished fits publish their RSS here ('' = no early stop)
    n_obs: int = 0

    def give_up(self, reachable: float, current: float, item: "Item") -> bool:
        """A fit stops when it cannot win: its Gauss-Newton model (trusted by the fit) cannot come
        within a factor 10 of the least RSS another candidate has reached (n ln 10 in any
        criterion), or the fit is near its own optimum (its RSS within 1.5x of what it can
        reach) and that cannot improve on the other's RSS by what one more parameter costs
        (ln n / n of the RSS)."""
        best = best_rss(Path(self.progress_dir), exclude=item) if self.progress_dir else None
        if best is None:
            return False
        n = max(self.n_obs, 2)
        near = current <= 1.5 * reachable
        return reachable > 10.0 * best or (near and reachable > best * (1.0 - np.log(n) / n))


# -- candidates built in the compiled DAE --------------------------------------------------------
@dataclass
class Built:
    template: object
    w0: np.ndarray
    names: list[str]           # the law's parameters in the candidate model
    model: object              # CompiledModel
    nominal: NominalForm | None


def build(ctx: Context, item: Item) -> Built:
    """The candidate model: the base model's DAE with ``item``'s law at its component, started
    at its fit to the nominal law (or the spec's own ``start``)."""
    from ..api import registry

    template = registry().template(item.spec)
    comp = ctx.base.structure.components[item.component]
    env = ctx.signals[item.component].env()
    explicit = isinstance(item.spec, dict) and "start" in item.spec
    w0 = template.start() if explicit else template.start_from(env)
    nominal = None
    if template.explicit is not None:
        series = mode_of(template) == "series"
        law_vars = [v for v in (("i", "di") if series else ("v", "dv")) if v in template.uses]
        nominal = nominal_form(env, law_vars, "v" if series else "i")
    dae, names = with_law(ctx.base.dae, comp, template, w0, nominal, ctx.rates.get(item.component))
    base = ctx.base.model
    model = compiled(dae, base.name, outputs=ctx.train.names, info=base.info, structure=base.structure)
    return Built(template, np.asarray(w0, float), names, model, nominal)


def _candidate_task(ctx: Context, item: Item) -> dict:
    """Executor task: one component with one law, built, fitted and pruned."""
    from ..api import registry, simulate

    try:
        built = build(ctx, item)
    except MclError as exc:
        return {"component": item.component, "template": item.spec, "score": None,
                "not_applicable": f"the law cannot be put there: {exc.message}"}
    template, model, names = built.template, built.model, built.names
    # the shape stage (a network, then distilled laws with fitted scales) always simulates: it
    # refines the best law and is not stopped for being behind it; a network has many
    # parameters and one chance, so it gets three fits' budget
    shape = item.index >= NEURAL_INDEX
    fitter = registry().fitter("simulation" if shape else ctx.method)
    progress = None if not ctx.progress_dir else (lambda rss: publish(Path(ctx.progress_dir), item, rss))
    fit = fitter.fit(model, ctx.train, names, built.w0, template, ctx.criterion,
                     ctx.budget * (3 if item.index == NEURAL_INDEX else 1),
                     give_up=None if shape or not ctx.progress_dir else (lambda reach, now: ctx.give_up(reach, now, item)),
                     prune=bool(getattr(template, "terms", None)),
                     progress=progress)
    w, active = fit.w, fit.active
    params = dict(zip(names, w))
    comp = ctx.base.structure.components[item.component]
    out = {"component": item.component, "class": comp.cls, "template": item.spec,
           "family": getattr(template, "family", "") or template.name, "law_variable": template.law_variable,
           "mode": mode_of(template), "parameter_names": names,
           "nominal_form": built.nominal.coefficients if built.nominal else None,
           "nominal_exact": bool(built.nominal.exact) if built.nominal else None,
           "w0": built.w0.tolist(), "w": w.tolist(), "active": active.tolist(), "rss": fit.rss, "score": fit.score,
           "simulations": fit.simulations, "pruning": fit.path, "equation": template.equation(w * active),
           "visited": fit.visited, "terms": [str(m) for m in getattr(template, "terms", [])]}
    res = fit.result if fit.result is not None else simulate(model, ctx.train, params)
    out["train_rms"] = rms(residual(ctx.train, model, res)) if res.ok else None
    if ctx.validate is not None:
        rv = simulate(model, ctx.validate, params)
        out["validation_rms"] = rms(residual(ctx.validate, model, rv)) if rv.ok else None
    if res.ok:
        sig = law_signals(model, res.states, res.time, ctx.train, [comp])[comp.name]
        env = sig.env()
        out["v_range"] = [float(np.min(env["v"])), float(np.max(env["v"]))]
        x = env[template.law_variable]
        out["law_range"] = [float(np.min(x)), float(np.max(x))]
    return out


def publish(directory: Path, item: Item, rss: float) -> None:
    """A running or finished fit's RSS, where the other fits (in any worker) read it."""
    if rss is None or not np.isfinite(rss):
        return
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{item.component}_{item.index}.json"
    tmp = path.with_suffix(f".{id(path)}.tmp")
    tmp.write_text(json.dumps({"rss": float(rss)}))
    tmp.replace(path)


def best_rss(directory: Path, exclude: Item | None = None) -> float | None:
    """The least RSS any fit of this round (but ``exclude``) has reached so far (None before any)."""
    best = None
    own = f"{exclude.component}_{exclude.index}.json" if exclude is not None else None
    for f in directory.glob("*.json") if directory.is_dir() else []:
        if f.name == own:
            continue
        try:
            rss = json.loads(f.read_text())["rss"]
        except (OSError, ValueError, KeyError):
            continue
        best = rss if best is None else min(best, rss)
    return best


def _balanced(base: Base, train: TimeSeries, comp) -> bool:
    """Whether what flows into one connector of ``comp`` flows out of the other along the run
    (a one-port: resistor, spring, damper, capacitor); a mass or an inertia stores it."""
    from ..simulation import prepare_inputs

    ode, res = base.model.ode, base.result
    fa, fb = comp.flow()
    idx = [ode.probe_names.index(n) for n in (fa, fb)]
    u = prepare_inputs(base.model, train)
    N = len(res.time)
    U = np.array([np.interp(res.time, u.time, u.values[:, j]) for j in range(len(u.names))]).reshape(-1, N)
    p = base.model.parameter_vector()
    vals = np.array(ode.probe.map(N)(res.states.T, U, np.repeat(p[:, None], N, 1), res.time[None]))[idx]
    scale = float(np.max(np.abs(vals))) or 1.0
    return float(np.max(np.abs(vals[0] + vals[1]))) <= 1e-6 * scale


# -- screening -----------------------------------------------------------------------------------
def promising(screening: list[dict], limit: int, ratio: float = 10.0) -> list[int]:
    """Indices of the candidates worth a full fit: at most ``limit``, best predicted first, and
    only those whose predicted RSS after one Gauss-Newton step is within ``ratio`` of the best
    prediction (a candidate predicted 10x worse loses by n ln 10 in any criterion unless the
    linearisation is badly wrong). Laws that could not be screened are always fitted."""
    ok = sorted((s["predicted_rss"], k) for k, s in enumerate(screening) if s.get("predicted_rss") is not None)
    unscreened = [k for k, s in enumerate(screening) if s.get("unscreened")]
    if not ok:
        return unscreened
    floor = max(ok[0][0], 1e-300)
    return [k for pred, k in ok[:limit] if pred <= ratio * floor] + unscreened


def _screen(items: list[Item], base: Base, train: TimeSeries, resid: np.ndarray) -> tuple[list[dict], dict]:
    """The screening prediction of every item (one simulation of the model with a deviation at
    every component, :mod:`.screen`); also each component's law variables at the data points."""
    from ..api import registry

    reg = registry()
    comps = [base.structure.components[c] for c in dict.fromkeys(it.component for it in items)]
    templates = {it.key: reg.template(it.spec) for it in items}
    modes = {}
    for it in items:
        modes.setdefault(it.component, mode_of(templates[it.key]))
    sdae, j_names = with_injections(base.dae, comps, modes)
    model = compiled(sdae, base.model.name, outputs=train.names, info=base.model.info, structure=base.structure)
    from ..api import simulate
    from ..simulation import SimulationOptions

    fine, at_data = fine_grid(train.time, _substeps(model, train))
    nominal = simulate(model, train, t_out=fine, options=SimulationOptions(rtol=1e-7, atol=1e-9))
    if not nominal.ok:
        raise ConfigError(f"the model does not simulate the training data: {nominal.reason}")
    sig = law_signals(model, nominal.states, fine, train, comps)
    phis, owners = {}, []
    for it in items:
        tpl = templates[it.key]
        if tpl.explicit is None:      # an implicit law has no deviation terms to screen
            continue
        try:   # d D / d w_k: the law's right-hand terms (features are signed, lhs first)
            phi = -tpl.features(sig[it.component].env())[:, 1:len(tpl.terms)].T
        except (NotImplementedError, KeyError, AttributeError):
            continue
        phis[f"{it.component}#{it.index}"] = phi
        owners.append(it)
    # one deviation parameter per component; every law at it shares that parameter's response
    j_of = {c.name: n for c, n in zip(comps, j_names)}
    cols = {k: j_of[k.split("#")[0]] for k in phis}
    resp = linear_response(model, [cols[k] for k in phis], train, nominal, at_data, phis) if phis else None
    outputs = [o for o in model.output_names if o in train.names]
    o_idx = [model.output_names.index(o) for o in outputs]
    r = resid.ravel()
    out = []
    for it in items:
        key = f"{it.component}#{it.index}"
        entry = {"component": it.component, "template": it.spec}
        if key not in phis or resp is None:
            entry.update(predicted_rss=None, unscreened=True)
        else:
            j = [k for k, (c, _) in enumerate(resp.columns) if c == key]
            S = resp.S[:, o_idx, :][:, :, j].reshape(-1, len(j))
            entry.update(rss0=float(np.nansum(r**2)), n_params=len(j) + 1, predicted_rss=predicted_rss(S, r))
        out.append(entry)
    data_sig = {c: type(s)(*(getattr(s, f)[at_data] for f in ("v", "i", "dv", "di"))) for c, s in sig.items()}
    return out, data_sig


def _substeps(model, train: TimeSeries) -> int:
    """Points per data interval for the linearised response (:mod:`mcl.sensitivity`): enough
    that the model's fastest mode moves little in one step."""
    from ..api import simulate
    from ..sensitivity import MAX_STEP, SUBSTEPS, Linearisation

    res = simulate(model, train)
    if not res.ok:
        return SUBSTEPS
    lin = Linearisation(model, res.states, res.time, train, model.parameter_vector(), [])
    h = float(np.max(np.diff(train.time)))
    return int(np.clip(np.ceil(lin.rate() * h / MAX_STEP), SUBSTEPS, 24))


# -- fitting batches -----------------------------------------------------------------------------
class _Batch:
    """Fits candidates in the executor's workers (each builds its own candidate model from the
    compiled DAE), each saved as it finishes so that a rerun skips it."""

    def __init__(self, ctx: Context, part: Path, rundir, reg, executor: dict):
        self.ctx, self.part, self.rundir, self.reg, self.executor = ctx, part, rundir, reg, executor

    def __call__(self, items: list[Item]) -> list[dict]:
        part = self.part
        todo = [it for it in items if not _done(part / it.file)]
        log.info("      fitting %d candidate(s) (%d already done)", len(items), len(items) - len(todo))

        def checkpoint(k, r):
            it = todo[k]
            if isinstance(r, TaskFailed):
                r = {"component": it.component, "template": it.spec, "failed": r.reason, "score": None}
            self.rundir.write_json(str((part / it.file).relative_to(self.rundir.partial)), r)
            if self.ctx.progress_dir and r.get("rss") is not None and not r.get("failed"):
                publish(Path(self.ctx.progress_dir), it, r["rss"])

        if todo:
            with self.reg.executor(self.executor) as ex:
                ex.map(_candidate_task, todo, context=self.ctx, timeout=3600, label="candidates",
                       on_result=checkpoint)
        return [json.loads((part / it.file).read_text()) for it in items]


def _done(path: Path) -> bool:
    """A candidate already fitted (a failed one is tried again on resume)."""
    if not path.exists():
        return False
    try:
        return "failed" not in json.loads(path.read_text())
    except ValueError:
        return False


def _shapes(fit: _Batch, cands: list[dict], sigma: float) -> list[dict]:
    """Non-polynomial shapes for the most promising component: a neural law in the variable of
    its best polynomial law, fitted to the data, then distilled into a sparse readable law over
    tanh, sinh, |x| x, x/sqrt(1 + x^2), exp and polynomial terms (:func:`families.distillations`)
    and fitted and pruned like any candidate. Skipped when the polynomial law already fits to
    the noise, or when it is not a law of one variable."""
    from ..api import registry

    done = sorted((c for c in cands if c.get("score") is not None), key=lambda c: c["score"])
    if not done or (done[0].get("train_rms") is not None and done[0]["train_rms"] < 1.2 * sigma):
        return []
    one = [c for c in done if c.get("family") in ("static", "rate") and c.get("law_variable") in ("v", "dv")]
    if not one:
        return []
    best, var = one[0], one[0]["law_variable"]
    log.info("      shape of %s's law in %s: neural fit, then a sparse law distilled from it", best["component"], var)
    poly = registry().template(best["template"])
    xs = np.linspace(*(best.get("law_range") or [-1.0, 1.0]), 201)
    spec = {"name": "neural", "hidden": 4, "x": var, "coupled": False}
    start = registry().template(spec).fit_curve(xs, poly.curve(np.asarray(best["w"]) * np.asarray(best["active"]), xs))
    neural = fit([Item(best["component"], NEURAL_INDEX, {**spec, "start": start.tolist()})])
    out = list(neural)
    n = neural[0]
    if n.get("score") is None or not n.get("law_range"):
        return out
    template = registry().template(n["template"])
    xs = np.linspace(*n["law_range"], 201)
    laws = distillations(xs, template.curve(np.asarray(n["w"]), xs), var)
    items = [Item(best["component"], SHAPE_INDEX + k,
                  {"name": "polynomial", "lhs": ["i"], "rhs": law["terms"], "scales": law["scales"],
                   "start": [1.0, *map(float, law["c"])], "family": "shape"})
             for k, law in enumerate(laws)]
    return out + fit(items)


def _search(spec, base: Base, train, validate, part: Path, rundir, reg, sigma: float, resid, report: dict):
    """Steps 2-3 of one round: the candidate components with their law families (or the pinned
    templates), screened in one pass, the promising ones fitted, then the shape stage. Returns
    (candidate results, screening, each component's nominal law variables, roles)."""
    comps = [c for c in base.structure.candidates() if c.name not in base.excluded]
    if spec.unknown != "auto":
        comps = [base.structure.components[spec.unknown]]
    if not comps:
        return [], [], {}, {}, None
    stores = [c.name for c in comps if not _balanced(base, train, c)]
    if stores:
        log.info("      not one-ports (their flows do not balance: masses, inertias): %s", ", ".join(stores))
        comps = [c for c in comps if c.name not in stores]
    signals = law_signals(base.model, base.result.states, base.result.time, train, comps)
    roles = {c.name: role_of(signals[c.name].env()) for c in comps}
    items = [Item(c.name, k, t) for c in comps
             for k, t in enumerate(spec.templates or families(roles[c.name], signals[c.name].env()))]
    templates = {it.key: reg.template(it.spec) for it in items}
    modes = {}
    for it in items:
        modes.setdefault(it.component, mode_of(templates[it.key]))
    rates = rate_variables(base.dae, comps, modes)
    blocked = {it.key: _blocked(templates[it.key], rates[it.component], it.component) for it in items}
    screen_file = part / "screening.json"
    if screen_file.exists():
        screening = json.loads(screen_file.read_text())
    else:
        log.info("[2/5] screening %d law(s) on %d component(s) in one simulation", len(items), len(comps))
        screening, _ = _screen([it for it in items if not blocked[it.key]], base, train, resid)
        screening = iter(screening)
        screening = [{"component": it.component, "template": it.spec, "predicted_rss": None,
                      "not_applicable": blocked[it.key]} if blocked[it.key] else next(screening) for it in items]
        rundir.write_json(str(screen_file.relative_to(rundir.partial)), screening)
    keep = promising(screening, spec.screen, ratio=10.0 if spec.early_stop else np.inf)
    for k, s_ in enumerate(screening):
        if k not in keep and s_.get("predicted_rss") is not None:
            s_["not_fitted"] = "screening predicts it cannot compete"
    n_obs = int(np.isfinite(resid).sum())
    ctx = Context(base, signals, rates, train, validate, spec.max_simulations, spec.criterion,
                  spec.refinement_method, str(part / "progress") if spec.early_stop else "", n_obs)
    fit = _Batch(ctx, part, rundir, reg, spec.executor)
    cands = fit([items[k] for k in keep])
    for c in cands:       # a law that cannot sit at its component is not applicable, not a failure
        if c.get("not_applicable"):
            s_ = next((s for s in screening if s["component"] == c["component"] and s["template"] == c["template"]), None)
            if s_ is not None:
                s_["not_applicable"] = c["not_applicable"]
    cands = [c for c in cands if not c.get("not_applicable")]
    if spec.templates is None:
        cands += [c for c in _shapes(fit, cands, sigma) if not c.get("not_applicable")]
    return cands, screening, signals, roles, fit


def _blocked(template, rates: dict, component: str) -> str | None:
    """Why a law cannot sit at a component (it is in the rate of a variable the model's states
    do not set there: it would add a state), or None."""
    for var, d in (("v", "dv"), ("i", "di")):
        if d in template.uses and rates.get(var) is None:
            what = "across value" if var == "v" else "flow"
            return f"the {what} of {component} is not set by the model's states: a law in its rate would add a state"
    return None


# -- the verdict ---------------------------------------------------------------------------------
#: a lead below this (in the criterion) does not separate two laws: they explain the data alike
EQUAL = 2.0


def effect_kind(c: dict) -> str | None:
    """Which role the learned law's additions to the nominal law point to: ``static`` (terms in
    the across value only), ``rate`` (its rate only), ``integral`` (the flow and its rate),
    ``storage`` (both); None when nothing is added."""
    nominal = set((c.get("nominal_form") or {}))
    extra = []
    for term, on, w in zip(c.get("terms", [])[1:], c.get("active", [])[1:], c.get("w", [])[1:]):
        if on and w != 0 and term not in nominal:
            extra.append(term)
    if not extra:
        return None
    from ..templates import Monomial

    used = set()
    for t in extra:
        try:
            used |= Monomial.parse(t, (c.get("template") or {}).get("scales", {}) if isinstance(c.get("template"), dict) else ()).variables
        except MclError:
            return None
    if used <= {"v"}:
        return "static"
    if used <= {"dv"}:
        return "rate"
    if used <= {"i", "di"}:
        return "integral"
    return "storage"


def _equivalents(best: dict, ranked: list[dict], structure) -> list[dict]:
    """The other components that explain the data as well as ``best``, each with the reason the
    data cannot separate them: every component in parallel with it (a law in the across value
    or its rate gives the same flow whichever of two parallel parts carries it), and any other
    whose best law scores within :data:`EQUAL` of it."""
    out, seen = [], {best["component"]}
    if best.get("mode", "parallel") == "parallel" and structure is not None:
        for p in structure.parallel(best["component"]):
            seen.add(p)
            out.append({"component": p, "class": structure.components[p].cls,
                        "reason": f"parallel to {best['component']}: the data cannot separate them"})
    for c in ranked:
        if c["component"] in seen or c["score"] - best["score"] > EQUAL:
            continue
        seen.add(c["component"])
        out.append({"component": c["component"], "class": c.get("class"), "equation": c.get("equation"),
                    "score_difference": c["score"] - best["score"],
                    "reason": f"explains the data as well ({c['score'] - best['score']:+.2g} in the criterion)"})
    return out


def _decide(cands: list[dict], spec, resid, val0, roles: dict, structure, rss0: float):
    """The verdict of one round: the best candidate, its lead (in the criterion) over the best law
    of any component it is not equivalent to, or over the model without it, and its
    equivalents; or (None, reason). Of laws that explain the data equally well, the one at the
    component whose role fits the learned effect is named (a force in the position belongs to
    the spring, in the speed to the damper)."""
    n_obs = int(np.isfinite(resid).sum())
    nominal_score = criterion_of(spec.criterion).score(rss0, n_obs, 0)
    scored = sorted((c for c in cands if c.get("score") is not None), key=lambda c: c["score"])
    ranked = [c for c in scored if c["score"] < nominal_score]
    if not ranked:
        return None, ("no candidate could be evaluated" if not scored
                      else "no candidate explains the training data better than the model without it"), nominal_score
    close = [c for c in ranked if c["score"] - ranked[0]["score"] <= EQUAL]
    fits = [c for c in close if effect_kind(c) is not None and roles.get(c["component"]) == effect_kind(c)]
    best = fits[0] if fits else ranked[0]
    if val0 is not None and not _helps(best.get("validation_rms"), val0):
        return None, (f"the best candidate, {best['component']} ({spec_name(best['template'])}), does not improve "
                      f"the validation data (RMS {val0:.4g} -> {_fmt(best.get('validation_rms'))})"), nominal_score
    equivalents = _equivalents(best, ranked, structure)
    same = {best["component"], *(e["component"] for e in equivalents)}
    others = [c["score"] for c in ranked if c["component"] not in same]
    best = {**best, "delta": min(others + [nominal_score]) - best["score"], "equivalents": equivalents,
            "effect_kind": effect_kind(best), "role": roles.get(best["component"])}
    return best, None, nominal_score


def _helps(after, before: float, margin: float = 0.02) -> bool:
    """Whether the validation error improves by more than ``margin`` (relative): a law that
    only fits the training data is not a cause."""
    return after is not None and np.isfinite(after) and after < (1 - margin) * before


def _fmt(x) -> str:
    return "failed" if x is None else f"{x:.4g}"


def _role_fit(fit: _Batch, best: dict, roles: dict, structure, cands: list[dict], signals) -> list[dict]:
    """When the best law's additions do not fit its component's role (a storage law on a damper
    whose new terms are in the position), the components in parallel with it whose role does fit
    get that kind of law too, so that the verdict can name the part whose physics it is."""
    kind = effect_kind(best)
    if kind is None or roles.get(best["component"]) == kind or structure is None:
        return []
    tried = {(c["component"], c.get("family")) for c in cands
             if not any(str(step.get("message", "")).startswith("stopped") for step in c.get("pruning", []))}
    items = []
    for other in structure.parallel(best["component"]):
        if roles.get(other) != kind or other not in signals:
            continue
        for k, spec_ in enumerate(families(kind, signals[other].env())):
            if spec_.get("family") == kind and (other, kind) not in tried:
                items.append(Item(other, 50 + k, spec_))
    if not items:
        return []
    # fitted to the end: the verdict compares it with the law it may be equivalent to
    patient = _Batch(dataclasses.replace(fit.ctx, progress_dir=""), fit.part, fit.rundir, fit.reg, fit.executor)
    return [c for c in patient(items) if not c.get("not_applicable")]


def _failures(screening: list, cands: list) -> list[dict]:
    """Every candidate that could not be evaluated, with the stage and the reason."""
    out = [{"component": s["component"], "template": s["template"], "stage": "screening",
            "reason": s.get("reason", "failed")} for s in screening
           if s.get("predicted_rss") is None and not s.get("not_applicable") and not s.get("unscreened")]
    out += [{"component": c["component"], "template": c["template"], "stage": "fitting",
             "reason": c["failed"]} for c in cands if c.get("failed")]
    return out


def _weigh_unevaluated(evidence: dict, best: dict, cands: list, screening: list, spec, n_obs: int) -> None:
    """A contender that failed in fitting can only be excluded by its screening prediction:
    its predicted score (one linearised step) must lose by the criterion's 'decisive' margin;
    otherwise the cause is at most 'undecided'."""
    score_of = criterion_of(spec.criterion).score
    open_ = []
    for c in (c for c in cands if c.get("failed")):
        pred = next((s for s in screening if s["component"] == c["component"] and s["template"] == c["template"]), {})
        k = pred.get("n_params", 3)
        if pred.get("predicted_rss") is None or score_of(pred["predicted_rss"], n_obs, k - 1) - best["score"] <= 10:
            open_.append(c["component"])
    if open_:
        evidence["unevaluated"] = open_
        evidence["strength"] = f"undecided: {', '.join(open_)} could not be evaluated"


# -- the run -------------------------------------------------------------------------------------
def _outputs_of(model, data: TimeSeries, result, outputs) -> np.ndarray | None:
    return result.outputs[:, [model.output_names.index(o) for o in outputs]] if result.ok else None


def _with_cause(base: Base, best: dict, train: TimeSeries, rates: dict) -> Base:
    """The base model with ``best``'s law put in at its fitted values (pruned terms at 0)."""
    import dataclasses

    from ..api import registry, simulate

    template = registry().template(best["template"])
    comp = base.structure.components[best["component"]]
    nominal = NominalForm(best["nominal_form"], 0.0) if best.get("nominal_form") is not None else None
    w = np.asarray(best["w"]) * np.asarray(best["active"])
    dae, names = with_law(base.dae, comp, template, w, nominal, rates.get(comp.name))
    model = compiled(dae, base.model.name, outputs=train.names, info=base.model.info, structure=base.structure)
    result = simulate(model, train)
    if not result.ok:
        raise ConfigError(f"the model with {best['component']}'s learned law does not simulate the training "
                          f"data: {result.reason}")
    return dataclasses.replace(base, model=model, result=result, excluded=base.excluded | {best["component"]})


def run_discovery(spec, train: TimeSeries, validate: TimeSeries | None = None, force: bool = False,
                  fingerprint: dict | None = None) -> dict:
    """Execute a validated :class:`mcl.runfile.RunSpec` on ``train`` (and ``validate``) data;
    returns the report dict. :class:`mcl.Discovery` is the public face of this function."""
    from ..api import compile_model, registry, simulate
    from .extend import describe, extend
    from .rundir import RunDirectory

    rundir = RunDirectory(spec.output, force=force)
    part = rundir.partial
    t_start, cpu_start = time.perf_counter(), cpu_seconds()
    reg = registry()
    nominal = compile_model(spec.sources, spec.model_name, libraries=spec.libraries).with_outputs(train.names)
    if nominal.dae is None or nominal.structure is None:
        raise ConfigError(f"the compiler '{nominal.info.get('compiler')}' keeps no DAE of {spec.model_name}: "
                          "discovery needs the default compiler (casadi, on rumoca)")
    if spec.unknown != "auto" and spec.unknown not in nominal.structure.components:
        from ..registry import did_you_mean

        raise ConfigError(f"no component '{spec.unknown}' in {spec.model_name}"
                          f"{did_you_mean(spec.unknown, list(nominal.structure.components))}", where="unknown")
    outputs = [o for o in nominal.output_names if o in train.names]
    log.info("[1/5] nominal model %s: simulating the training data", spec.model_name)
    sim0 = simulate(nominal, train)
    if not sim0.ok:
        raise ConfigError(f"the nominal model does not simulate the training data: {sim0.reason}")
    y_meas = train.select(outputs).values
    y0 = _outputs_of(nominal, train, sim0, outputs)
    resid = y_meas - y0
    sigma = float(np.sqrt(np.mean([noise_estimate(y_meas[:, k], train.time) ** 2 for k in range(len(outputs))])))
    train_rms0 = rms(resid)
    significant = _significant(train_rms0, sigma)
    report = {"model": spec.model_name, "outputs": outputs,
              "misfit": {"significant": significant, "train_rms": train_rms0, "noise_estimate": sigma,
                         "per_output_rms": {o: rms(resid[:, k]) for k, o in enumerate(outputs)}},
              "cause": None, "causes": [], "candidates": [], "gain": None,
              "units": {n: u for n, u in nominal.info.get("units", {}).items() if n in outputs},
              "components": len(nominal.structure.components), "software": software_versions(),
              "inputs": fingerprint or {}}
    log.info("      residual RMS %.4g vs noise %.4g: %s", train_rms0, sigma,
             "significant" if significant else "not significant")
    from .report import misfit_in_time

    report["misfit"]["where"] = misfit_in_time(train.time, resid, sigma) if significant else []
    val0, val_y = None, None
    if validate is not None:
        sv = simulate(nominal, validate)
        val0 = rms(residual(validate, nominal, sv, outputs)) if sv.ok else None
        val_y = [_outputs_of(nominal, validate, sv, outputs), None]
    base = Base(nominal, sim0)
    rss_base, val_base, rounds = float(np.nansum(resid**2)), val0, []
    while significant and len(report["causes"]) < MAX_CAUSES:
        r = len(rounds) + 1
        rpart = part / f"round{r}"
        (rpart / "candidates").mkdir(parents=True, exist_ok=True)
        resid_base = y_meas - _outputs_of(base.model, train, base.result, outputs)
        cands, screening, signals, roles, fit = _search(spec, base, train, validate, rpart, rundir, reg, sigma,
                                                        resid_base, report)
        best, why, nominal_score = _decide(cands, spec, resid_base, val_base, roles, base.structure, rss_base)
        if best is not None:
            extra = _role_fit(fit, best, roles, base.structure, cands, signals)
            if extra:
                cands += extra
                best, why, nominal_score = _decide(cands, spec, resid_base, val_base, roles, base.structure, rss_base)
        rounds.append({"round": r, "screening": screening, "candidates": cands, "roles": roles,
                       "nominal_score": nominal_score, "no_cause": why})
        report["failed"] = report.get("failed", []) + _failures(screening, cands)
        for f in _failures(screening, cands):
            log.warning("      %s with %s could not be evaluated (%s): %s", f["component"],
                        spec_name(f["template"]), f["stage"], f["reason"])
        if best is None:
            log.info("      %s: %s", "no convincing cause" if not report["causes"] else "no further cause", why)
            break
        cause = describe(best, base, spec, train, signals)
        _weigh_unevaluated(cause["evidence"], best, cands, screening, spec, int(np.isfinite(y_meas).sum()))
        report["causes"].append(cause)
        base = _with_cause(base, best, train, fit.ctx.rates)
        resid_after = y_meas - _outputs_of(base.model, train, base.result, outputs)
        rss_base, val_base = float(np.nansum(resid_after**2)), best.get("validation_rms")
        significant = _significant(rms(resid_after), sigma)
        cause["after"] = {"train_rms": rms(resid_after), "validation_rms": val_base,
                          "misfit_left": "significant" if significant else "at the noise level"}
    _summarise_rounds(report, rounds)
    extended_y = None
    if report["causes"]:
        report["cause"] = report["causes"][0]
        extended_y, ext_val, files = extend(report["causes"], base, spec, part, train, validate, outputs)
        report["extended"] = files
        if val_y is not None:
            val_y[1] = ext_val
        report["gain"] = {"train_rms_before": train_rms0, "train_rms_after": rms(y_meas - extended_y) if extended_y is not None else None,
                          "validation_rms_before": val0, "validation_rms_after": val_base}
    if report["gain"] is None:
        report["gain"] = {"train_rms_before": train_rms0, "train_rms_after": train_rms0,
                          "validation_rms_before": val0, "validation_rms_after": val0}
    report["seconds"] = time.perf_counter() - t_start
    report["cpu_seconds"] = cpu_seconds() - cpu_start
    log.info("[5/5] report")
    from .report import write_report

    write_report(part, report, train, outputs, y0, extended_y, validate=validate, validation=val_y, **spec.report)
    rundir.finish()
    log.info("wrote %s/report.html and report.json", spec.output)
    return report


def cpu_seconds() -> float:
    """CPU seconds of this process and its finished workers (user + system)."""
    import resource

    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def _significant(train_rms: float, sigma: float) -> bool:
    return bool(train_rms > 1.5 * sigma and train_rms > 1e-12)


def _summarise_rounds(report: dict, rounds: list[dict]) -> None:
    """report.json's candidates, screening and verdict: every round's, in order (the first round
    is the search for the first cause)."""
    report["rounds"] = [{"round": r["round"], "no_cause": r["no_cause"], "roles": r["roles"]} for r in rounds]
    report["candidates"] = []
    report["screening"] = []
    for r in rounds:
        ranked = sorted((c for c in r["candidates"] if c.get("score") is not None), key=lambda c: c["score"])
        report["candidates"] += [{**c, "round": r["round"]} for c in ranked]
        report["candidates"] += [{**c, "round": r["round"]} for c in r["candidates"] if c.get("score") is None]
        report["screening"] += [{**s, "round": r["round"]} for s in r["screening"]]
    if rounds:
        report["nominal_score"] = rounds[0]["nominal_score"]
        report["roles"] = rounds[0]["roles"]
        if not report["causes"]:
            report["no_cause"] = rounds[0]["no_cause"]


def software_versions() -> dict:
    """Versions of mcl and of what computes its numbers (recorded in report.json)."""
    from ..compile.library import distribution_versions

    return distribution_versions("mcl", "casadi", "fmpy", "numpy", "scipy", "rumoca")
