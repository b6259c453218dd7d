"""The main job (``mcl run``): what the model gets wrong, which component, which law, what gain.

1. Misfit: the nominal model simulated on the training inputs; the residual (where measured)
   against the noise estimated from the data (:func:`mcl.stats.noise_estimate`, any time
   grid), so a correct model comes out not significant; where it exceeds the noise.
2. Candidates: every two-connector component (or the named one) with the law families of its
   role (:mod:`.families`) or the pinned templates, each started from its fit to the nominal
   component's own law (the first simulation is the nominal model); screened by one
   Gauss-Newton step; the promising fitted and pruned by a fitter plugin (:mod:`.fitters`),
   stopped early when they cannot win; then the shape stage (a network distilled into sparse
   laws) for the best law of one variable.
3. Verdict: ranked by the run's :class:`mcl.stats.Criterion` against each other and the
   nominal model; a cause must also improve the validation data (:func:`_decide`).
4. Extend (:mod:`.extend`): the law in the component's words, the extended model as Modelica
   and FMU, gains on training and validation data, another configuration.
5. Report (:mod:`.report`): report.json and report.html.

The run directory is built in ``<output>.partial`` (each candidate's result saved as it
finishes, so an interrupted run resumes) and renamed to ``<output>`` at the end.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..data import TimeSeries
from ..progress import log
from ..simulation import prepare_inputs
from ..errors import ConfigError, MclError, ModelicaError
from ..executor import TaskFailed
from ..stats import criterion as criterion_of, noise_estimate, rms, rss as rss_of
from .fitters import FIT_OPTIONS, residual
from .families import distillations, families, role_of, spec_name
from .extend import explain


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

def probe(model, result, inputs: TimeSeries, params: dict, names: list[str]) -> np.ndarray:
    """Values of named model variables along a simulation, (N, len(names))."""
    ode = model.ode
    N = len(result.time)
    inputs = prepare_inputs(model, inputs)
    u = np.array([np.interp(result.time, inputs.time, inputs.column(n)) for n in ode.u_names]).reshape(-1, N)
    p = model.parameter_vector(params)
    vals = np.array(ode.probe.map(N)(result.states.T, u, np.repeat(p[:, None], N, 1), result.time[None]))
    return vals[[ode.probe_names.index(n) for n in names]].T


def component_variables(comp) -> tuple[str, str]:
    """Names of (potential of a, potential of b) and the flow into a of a two-connector component."""
    a, b = comp.connectors
    return (f"{comp.name}.{a.name}.{a.potential[0]}", f"{comp.name}.{b.name}.{b.potential[0]}",
            f"{comp.name}.{a.name}.{a.flow[0]}")


def law_env(v: np.ndarray, i: np.ndarray, t: np.ndarray) -> dict:
    """A component's law variables along a simulation: v, i and their time derivatives."""
    return {"v": v, "i": i, "dv": np.gradient(v, t), "di": np.gradient(i, t)}


def _candidate_model(ctx, item):
    """(template, w0, swapped model description, compiled model) of one candidate, compiled by
    the parent before the batch (a forked worker must not run the Rust front end: its threads
    do not survive a fork); a candidate that did not compile raises its error here."""
    built = ctx.models[item.key]
    if isinstance(built, Exception):
        raise built
    return built


def build_candidates(graph, train, nominal_probe, items, workdir, libraries=()) -> dict:
    """Every candidate of ``items`` compiled (the template in place of its component); one that
    does not compile (its system refers to variables the template lacks) keeps its error."""
    out = {}
    for it in items:
        try:
            out[it.key] = build_candidate(graph, train, nominal_probe, it, workdir, libraries)
        except MclError as exc:
            out[it.key] = ModelicaError(f"the candidate does not compile: {exc.message}")
    return out


def build_candidate(graph, train, nominal_probe, item, workdir, libraries=()):
    from ..api import compile_model, registry
    from ..swap import swap_component

    comp_name, tpl_index, tpl_spec = item
    template = registry().template(tpl_spec)
    # an explicit start (a distilled law) is where the fit begins; otherwise the template
    # fitted to the nominal component's own law, so the first simulation is the nominal model
    explicit = isinstance(tpl_spec, dict) and "start" in tpl_spec
    w0 = template.start() if explicit else template.start_from(nominal_probe[comp_name])
    tm = swap_component(graph, comp_name, template, Path(workdir) / f"{comp_name}_{tpl_index}",
                        w=w0, package=f"Candidate_{comp_name}_{tpl_index}")
    return template, w0, tm, compile_model(tm.sources, tm.model_name, libraries=libraries).with_outputs(train.names)


def promising(screening: list[dict], limit: int, ratio: float = 10.0) -> list[int]:
    """Indices of the candidates worth a full fit: at most ``limit``, best predicted first, and
    only those whose predicted RSS after one Gauss-Newton step is within ``ratio`` of the best
    prediction (a candidate predicted 10x worse loses by n ln 10 in any criterion unless the
    linearisation is badly wrong; fitting it costs more than all the others)."""
    ok = sorted((s["predicted_rss"], k) for k, s in enumerate(screening) if s.get("predicted_rss") is not None)
    if not ok:
        return []
    floor = max(ok[0][0], 1e-300)
    return [k for pred, k in ok[:limit] if pred <= ratio * floor]


def _screen_task(ctx, item):
    """Executor task: the Gauss-Newton prediction of how much a candidate can explain.

    One simulation with sensitivities at w0 (the template fitted to the nominal law):
    predicted RSS after one Gauss-Newton step = RSS - g^T (S^T S)^+ g with g = S^T r.
    Cheap, and ranks the candidates well enough to fit only the promising ones fully.
    """
    from ..api import simulate

    train = ctx.train
    comp_name, _, tpl_spec = item
    template, w0, tm, model = _candidate_model(ctx, item)
    params = dict(zip(tm.parameter_names, w0))
    res = simulate(model, train, params, sensitivities=tm.parameter_names[1:], options=FIT_OPTIONS)
    if not res.ok:
        return {"component": comp_name, "template": tpl_spec, "predicted_rss": None, "reason": res.reason}
    idx = [model.output_names.index(o) for o in model.output_names if o in train.names]
    r = residual(train, model, res).ravel()
    S = res.sensitivities[:, idx, :].reshape(-1, len(tm.parameter_names) - 1)
    S, r = S[np.isfinite(r)], r[np.isfinite(r)]      # only what was measured
    g = S.T @ r
    gain = float(g @ np.linalg.pinv(S.T @ S) @ g)
    return {"component": comp_name, "template": tpl_spec, "rss0": float(r @ r), "n_params": len(tm.parameter_names),
            "predicted_rss": float(max(r @ r - gain, 0.0))}


def _candidate_task(ctx, item):
    """Executor task: one candidate component with one template, fitted and pruned."""
    from ..api import simulate

    from ..api import registry

    train, validate, criterion = ctx.train, ctx.validate, ctx.criterion
    comp_name, _, tpl_spec = item
    template, w0, tm, model = _candidate_model(ctx, item)
    comp = ctx.graph.components[comp_name]
    # the shape stage (a network, then distilled laws with fitted scales) always simulates: it
    # refines the best law and is not stopped for being behind it; a network has many
    # parameters and one chance, so it gets three fits' budget
    shape = item.index >= NEURAL_INDEX
    fitter = registry().fitter("simulation" if shape else ctx.method)
    fit = fitter.fit(model, train, tm.parameter_names, w0, template, criterion,
                     ctx.budget * (3 if item.index == NEURAL_INDEX else 1), give_up=None if shape else ctx.give_up,
                     prune=bool(getattr(template, "terms", None)))
    w, active = fit.w, fit.active
    params = dict(zip(tm.parameter_names, w))
    out = {"component": comp_name, "class": comp.cls, "template": tpl_spec,
           "family": getattr(template, "family", "") or template.name, "law_variable": template.law_variable,
           "w0": w0.tolist(),
           "w": w.tolist(), "active": active.tolist(), "rss": fit.rss, "score": fit.score,
           "simulations": fit.simulations, "pruning": fit.path, "equation": template.equation(w * active),
           "visited": fit.visited,
           "terms": [str(m) for m in getattr(template, "terms", [])]}
    # the fitter's own simulation of the result on the training data, where it made one
    res = fit.result if fit.result is not None else simulate(model, train, params)
    out["train_rms"] = rms(residual(train, model, res)) if res.ok else None
    if validate is not None:
        rv = simulate(model, validate, params)
        out["validation_rms"] = rms(residual(validate, model, rv)) if rv.ok else None
    if res.ok:
        pv = probe(model, res, train, params, [f"{comp_name}.v", f"{comp_name}.i"])
        env = law_env(pv[:, 0], pv[:, 1], train.time)
        out["v_range"] = [float(pv[:, 0].min()), float(pv[:, 0].max())]
        x = env[template.law_variable]
        out["law_range"] = [float(np.min(x)), float(np.max(x))]
    return out


@dataclass
class Context:
    """What every executor task of a run shares (sent once per worker)."""

    graph: object
    train: TimeSeries
    validate: TimeSeries | None
    budget: int                 # simulations per fit
    criterion: str
    method: str                 # simulation | full-discretisation
    models: dict                # (component, family index) -> built candidate or its error
    best_file: str              # the best finished candidate's RSS, written by the parent

    def give_up(self, reachable_rss: float) -> bool:
        """A fit stops when even its Gauss-Newton model cannot come within a factor of 10 of the
        RSS of a candidate already fitted (n ln 10 in any criterion: it cannot win)."""
        best = _best_rss(Path(self.best_file)) if self.best_file else None
        return best is not None and reachable_rss > 10.0 * best


def context(graph, train, validate, spec, part, models) -> Context:
    return Context(graph, train, validate, spec.max_simulations, spec.criterion, spec.refinement_method,
                   models, str(part / "best.json") if spec.early_stop else "")


class _Batch:
    """Fits candidates (compiled by the parent, fitted by the executor's workers), each saved as
    it finishes so that a rerun skips it."""

    def __init__(self, graph, train, validate, spec, part, models, nominal_probe, rundir, reg):
        self.graph, self.train, self.validate, self.spec, self.part = graph, train, validate, spec, part
        self.models, self.nominal_probe, self.rundir, self.reg = models, nominal_probe, rundir, reg

    def __call__(self, items: list) -> list[dict]:
        part, spec = self.part, self.spec
        todo = [it for it in items if not _done(part / it.file)]
        log.info("      fitting %d candidate(s) (%d already done)", len(items), len(items) - len(todo))
        self.models.update(build_candidates(self.graph, self.train, self.nominal_probe,
                                            [it for it in todo if it.key not in self.models],
                                            part / "work", spec.libraries))
        ctx = context(self.graph, self.train, self.validate, spec, part, self.models)

        def checkpoint(k, r):
            it = todo[k]
            if isinstance(r, TaskFailed):
                r = {"component": it.component, "template": it.spec, "failed": r.reason, "score": None}
            self.rundir.write_json(it.file, r)
            _note_best(part / "best.json", r, self.rundir)

        if todo:
            with self.reg.executor(spec.executor) as ex:
                ex.map(_candidate_task, todo, context=ctx, timeout=3600, label="candidates", on_result=checkpoint)
        return [json.loads((part / it.file).read_text()) for it in items]


#: family indices of the shape stage (after any family list)
NEURAL_INDEX, SHAPE_INDEX = 100, 101


def _shapes(fit: _Batch, cands: list[dict], sigma: float) -> list[dict]:
    """Non-polynomial shapes for the most promising component: a neural law in the variable of
    its best polynomial law, fitted to the data, then distilled into a sparse readable law over
    tanh, sinh, |x| x, x/sqrt(1 + x^2), exp and polynomial terms (:func:`families.distillations`) and
    fitted and pruned like any candidate. Skipped when the polynomial law already fits to the
    noise, or when it is not a law of one variable."""
    done = sorted((c for c in cands if c.get("score") is not None), key=lambda c: c["score"])
    if not done or (done[0].get("train_rms") is not None and done[0]["train_rms"] < 1.2 * sigma):
        return []
    # the best law of one variable (a storage law in v and dv has no single curve to shape)
    one = [c for c in done if c.get("family") in ("static", "rate") and c.get("law_variable") in ("v", "dv")]
    if not one:
        return []
    best, var = one[0], one[0]["law_variable"]
    log.info("      shape of %s's law in %s: neural fit, then a sparse law distilled from it", best["component"], var)
    from ..api import registry

    # the network starts as the best polynomial law (fitted to its curve), so it only has to improve
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


def _best_rss(path: Path) -> float | None:
    """The least RSS of the finished candidates (None before the first finishes)."""
    try:
        return json.loads(path.read_text())["rss"]
    except (OSError, ValueError, KeyError):
        return None


def _note_best(path: Path, result: dict, rundir) -> None:
    """Keep the least RSS of the finished candidates where running fits can read it."""
    rss = result.get("rss")
    if rss is None or result.get("failed"):
        return
    best = _best_rss(path)
    if best is None or rss < best:
        rundir.write_json(path.name, {"rss": rss, "component": result["component"]})


def _done(path: Path) -> bool:
    """A candidate already fitted (a failed one is tried again on resume)."""
    if not path.exists():
        return False
    try:
        return "failed" not in json.loads(path.read_text())
    except ValueError:
        return False


def _helps(after, before: float, margin: float = 0.02) -> bool:
    """Whether the validation error improves by more than ``margin`` (relative): a law that
    only fits the training data is not a cause."""
    return after is not None and np.isfinite(after) and after < (1 - margin) * before


def _fmt(x) -> str:
    return "failed" if x is None else f"{x:.4g}"


def _screen(items, models, reg, spec, ctx) -> list[dict]:
    """The screening prediction of every item. A law family chosen automatically that does not
    fit the component's place (a storage law across a voltage source needs du/dt) is not
    applicable there: recorded as such, not as a failure."""
    auto = [isinstance(it.spec, dict) and "family" in it.spec and isinstance(models.get(it.key), Exception)
            for it in items]
    run = [it for it, a in zip(items, auto) if not a]
    with reg.executor(spec.executor) as ex:
        res = iter(ex.map(_screen_task, run, context=ctx, timeout=3600, label="screening") if run else [])
    out = []
    for it, a in zip(items, auto):
        if a:
            out.append({"component": it.component, "template": it.spec, "predicted_rss": None,
                        "not_applicable": str(models[it.key])})
            continue
        r = next(res)
        out.append(r if not isinstance(r, TaskFailed) else
                   {"component": it.component, "template": it.spec, "predicted_rss": None, "reason": r.reason})
    return out


def _failures(screening: list, cands: list) -> list[dict]:
    """Every candidate that could not be evaluated, with the stage and the reason."""
    out = [{"component": s["component"], "template": s["template"], "stage": "screening",
            "reason": s.get("reason", "failed")} for s in screening
           if s.get("predicted_rss") is None and not s.get("not_applicable")]
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


def _search(spec, graph, nominal, sim0, train, validate, part, rundir, reg, sigma, report):
    """Steps 2-3: every candidate component with its law families (or the pinned templates),
    screened by one linearised step, the promising ones fitted, then the shape stage. Returns
    (candidate results, screening, each component's nominal law variables)."""
    comps = [c for c in graph.two_connector_components() if not c.inputs]
    if spec.unknown != "auto":
        comps = [graph.components[spec.unknown]]
    nominal_probe = {}
    for c in comps:
        va, vb, fa = component_variables(c)
        pv = probe(nominal, sim0, train, {}, [va, vb, fa])
        nominal_probe[c.name] = law_env(pv[:, 0] - pv[:, 1], pv[:, 2], train.time)
    roles = {c.name: role_of(nominal_probe[c.name]) for c in comps}
    report["roles"] = roles
    items = [Item(c.name, k, t) for c in comps
             for k, t in enumerate(spec.templates or families(roles[c.name], nominal_probe[c.name]))]
    screen_file = part / "screening.json"
    models = {}
    if screen_file.exists():
        screening = json.loads(screen_file.read_text())
    else:
        log.info("[2/5] screening %d candidate(s) (components x law families): one linearised step each",
                 len(items))
        models = build_candidates(graph, train, nominal_probe, items, part / "work", spec.libraries)
        screening = _screen(items, models, reg, spec, context(graph, train, validate, spec, part, models))
        rundir.write_json("screening.json", screening)
    keep = promising(screening, spec.screen, ratio=10.0 if spec.early_stop else np.inf)
    for k, s_ in enumerate(screening):
        if k not in keep and s_.get("predicted_rss") is not None:
            s_["not_fitted"] = "screening predicts it cannot compete"
    fit = _Batch(graph, train, validate, spec, part, models, nominal_probe, rundir, reg)
    cands = fit([items[k] for k in keep])
    if spec.templates is None:
        cands += _shapes(fit, cands, sigma)
    return cands, screening, nominal_probe


def _decide(report: dict, spec, resid, val0):
    """Step 4's verdict: the best candidate and its lead (in the criterion) over the best law of
    any other component or the nominal model, or (None, None) with ``report["no_cause"]`` saying
    why: nothing beats the nominal model, or the best does not improve the validation data."""
    n_obs = int(np.isfinite(resid).sum())
    nominal_score = criterion_of(spec.criterion).score(rss_of(resid), n_obs, 0)
    report["nominal_score"] = nominal_score      # the nominal model is a contender too
    scored = [c for c in report["candidates"] if c.get("score") is not None]
    ranked = [c for c in scored if c["score"] < nominal_score]
    if not ranked:
        report["no_cause"] = ("no candidate could be evaluated" if not scored
                              else "no candidate explains the training data better than the nominal model")
        return None, None
    best = ranked[0]
    if val0 is not None and not _helps(best.get("validation_rms"), val0):
        report["no_cause"] = (f"the best candidate, {best['component']} ({spec_name(best['template'])}), "
                              f"does not improve the validation data (RMS {val0:.4g} -> "
                              f"{_fmt(best.get('validation_rms'))})")
        return None, None
    others = [c["score"] for c in ranked if c["component"] != best["component"]]
    return best, min(others + [nominal_score]) - best["score"]


def run_discovery(spec, train: TimeSeries, validate: TimeSeries | None = None, force: bool = False,
                  fingerprint: dict | None = None) -> dict:
    """Execute a validated :class:`mcl.runfile.RunSpec` on ``train`` (and ``validate``) data;
    returns the report dict. :class:`mcl.Discovery` is the public face of this function."""
    from ..api import compile_model, registry, simulate
    from ..graph import build_graph
    from .rundir import RunDirectory

    rundir = RunDirectory(spec.output, force=force)
    part = rundir.partial
    (part / "candidates").mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    reg = registry()
    nominal = compile_model(spec.sources, spec.model_name, libraries=spec.libraries).with_outputs(train.names)
    graph = build_graph(spec.sources, spec.model_name, libraries=spec.libraries)
    outputs = [o for o in nominal.output_names if o in train.names]
    log.info("[1/5] nominal model %s: simulating the training data", spec.model_name)
    sim0 = simulate(nominal, train)
    if not sim0.ok:
        raise ConfigError(f"the nominal model does not simulate the training data: {sim0.reason}")
    y_meas = train.select(outputs).values
    y0 = sim0.outputs[:, [nominal.output_names.index(o) for o in outputs]]
    resid = y_meas - y0
    sigma = float(np.sqrt(np.mean([noise_estimate(y_meas[:, k], train.time) ** 2 for k in range(len(outputs))])))
    train_rms0 = rms(resid)
    significant = bool(train_rms0 > 1.5 * sigma and train_rms0 > 1e-12)
    report = {"model": spec.model_name, "outputs": outputs,
              "misfit": {"significant": significant, "train_rms": train_rms0, "noise_estimate": sigma,
                         "per_output_rms": {o: rms(resid[:, k]) for k, o in enumerate(outputs)}},
              "cause": None, "candidates": [], "gain": None,
              "units": {n: u for n, u in nominal.info.get("units", {}).items() if n in outputs},
              "software": software_versions(), "inputs": fingerprint or {}}
    log.info("      residual RMS %.4g vs noise %.4g: %s", train_rms0, sigma,
             "significant" if significant else "not significant")
    from .report import misfit_in_time

    report["misfit"]["where"] = misfit_in_time(train.time, resid, sigma) if significant else []
    val0, val_y = None, None
    if validate is not None:
        sv = simulate(nominal, validate)
        val0 = rms(residual(validate, nominal, sv, outputs)) if sv.ok else None
        val_y = [sv.outputs[:, [nominal.output_names.index(o) for o in outputs]] if sv.ok else None, None]
    extended_y = None
    if significant:
        cands, screening, nominal_probe = _search(spec, graph, nominal, sim0, train, validate, part, rundir, reg,
                                                  sigma, report)
        report["candidates"] = (sorted([c for c in cands if c.get("score") is not None], key=lambda c: c["score"])
                                + [c for c in cands if c.get("score") is None])
        report["screening"] = screening
        report["failed"] = _failures(screening, cands)
        for f in report["failed"]:
            log.warning("      %s with %s could not be evaluated (%s): %s", f["component"],
                        spec_name(f["template"]), f["stage"], f["reason"])
        best, delta = _decide(report, spec, resid, val0)
        if best is not None:
            report["cause"], extended_y, ext_val = explain(best, delta, graph, spec, part, train, validate,
                                                            outputs, reg, nominal_probe)
            if val_y is not None:
                val_y[1] = ext_val
            _weigh_unevaluated(report["cause"]["evidence"], best, cands, screening, spec,
                               int(np.isfinite(y_meas).sum()))
            report["gain"] = {"train_rms_before": train_rms0, "train_rms_after": best.get("train_rms"),
                              "validation_rms_before": val0, "validation_rms_after": best.get("validation_rms")}
        else:
            log.info("      no convincing cause: %s", report["no_cause"])
    if report["gain"] is None:
        report["gain"] = {"train_rms_before": train_rms0, "train_rms_after": train_rms0,
                          "validation_rms_before": val0, "validation_rms_after": val0}
    report["seconds"] = time.perf_counter() - t_start
    log.info("[5/5] report")
    from .report import write_report

    write_report(part, report, train, outputs, y0, extended_y, validate=validate, validation=val_y, **spec.report)
    rundir.finish()
    log.info("wrote %s/report.html and report.json", spec.output)
    return report


def software_versions() -> dict:
    """Versions of mcl and of what computes its numbers (recorded in report.json)."""
    from ..compile.library import distribution_versions

    return distribution_versions("mcl", "casadi", "fmpy", "numpy", "scipy", "pymoca", "rumoca")
