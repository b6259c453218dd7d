"""The main job (``mcl run``): what the model gets wrong, which component, which law, what gain.

1. Misfit: simulate the nominal model on the training inputs; the residual RMS is compared with
   the measurement noise estimated from the data (second differences of a smooth signal are
   noise: Var(d2 y) = 6 sigma^2), so a correct model comes out not significant.
2. Cause: every candidate two-connector component (or the named one) is replaced by each
   template, started from the template's fit to the nominal component's own law (so the first
   simulation reproduces the nominal model), fitted with the low-budget Levenberg-Marquardt of
   the fit stage, and pruned by backward elimination (the cost increase of removing a term is
   estimated from the sensitivities, the best removal refitted, kept if the criterion improves).
   Candidates are ranked by BIC on the training data.
3. Extend: the learned class and the extended system as a Modelica package, compiled to an FMU.
4. Gain: RMS before and after on training and validation data.
5. Report: report.json and report.html with plots.

The run directory is built in ``<output>.partial`` (each candidate's result saved as it
finishes, so an interrupted run resumes) and renamed to ``<output>`` at the end.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..data import TimeSeries, read_csv
from ..progress import log
from ..errors import ConfigError, MclError, ModelicaError
from ..executor import TaskFailed
from ..stats import aic, bic, noise_estimate, rms
from ..swap import class_name_for

LEARNED_PACKAGE = "Learned"


def probe(model, result, inputs: TimeSeries, params: dict, names: list[str]) -> np.ndarray:
    """Values of named model variables along a simulation, (N, len(names))."""
    ode = model.ode
    N = len(result.time)
    u = np.array([np.interp(result.time, inputs.time, inputs.column(n)) for n in ode.u_names]).reshape(-1, N)
    p = model.parameter_vector(params)
    vals = np.array(ode.probe.map(N)(result.states.T, u, np.repeat(p[:, None], N, 1), result.time[None]))
    return vals[[ode.probe_names.index(n) for n in names]].T


def component_variables(comp) -> tuple[str, str]:
    """Names of (potential of a, potential of b) and the flow into a of a two-connector component."""
    a, b = comp.connectors
    return (f"{comp.name}.{a.name}.{a.potential[0]}", f"{comp.name}.{b.name}.{b.potential[0]}",
            f"{comp.name}.{a.name}.{a.flow[0]}")


def nominal_start(template, v, i, t) -> np.ndarray:
    """w0: the template's least-squares fit to the nominal component's law (lhs weight 1)."""
    env = {"v": v, "i": i, "dv": np.gradient(v, t), "di": np.gradient(i, t)}
    phi = template.features(env)
    w_rest, *_ = np.linalg.lstsq(phi[:, 1:], -phi[:, 0], rcond=None)
    return np.concatenate([[1.0], w_rest])


def fit_and_prune(model, data: TimeSeries, names: list[str], w0, budget: int, criterion: str):
    """LM fit of the template parameters, then backward elimination of terms (w1 anchors the scale)."""
    from ..fit import FitProblem, LevenbergMarquardt

    score_of = bic if criterion == "bic" else aic
    n_obs = len(data.time) * len([o for o in model.output_names if o in data.names])
    active = np.ones(len(names), bool)

    def fit(active_mask, start):
        params = [n for n, on in zip(names, active_mask) if on]
        fixed = {n: 0.0 for n, on in zip(names, active_mask) if not on}
        problem = FitProblem(model, data, params, fixed=fixed)
        res = LevenbergMarquardt(max_simulations=budget).fit(problem, np.asarray(start)[active_mask])
        w = np.zeros(len(names))
        w[active_mask] = res.w
        rss = res.cost * len(data.time)   # J of eq. (3) is the mean over samples of the RSS
        return w, rss, problem, res

    visited = []

    def record(problem, active_mask):
        for e in problem.recorder.evaluations:
            full = np.zeros(len(names))
            full[active_mask] = e.w
            visited.append([*full.tolist(), bool(e.feasible)])

    w, rss, problem, res = fit(active, w0)
    record(problem, active)
    sims, path = res.simulations, []
    score = score_of(rss, n_obs, int(active.sum()) - 1)
    path.append({"removed": None, "rss": rss, "score": score, "accepted": True})
    while active.sum() > 2:
        sim = problem.simulate(w[active], gradient=True)
        sims += 1
        if not sim.ok:
            break
        S = sim.sensitivities[:, problem.idx, :].reshape(-1, int(active.sum()))[:, 1:]
        H_inv = np.linalg.pinv(S.T @ S)
        idx = np.flatnonzero(active)[1:]
        est = w[idx] ** 2 / np.maximum(np.diag(H_inv), 1e-300)      # increase of RSS
        k = idx[int(np.argmin(est))]
        trial = active.copy()
        trial[k] = False
        w_t, rss_t, problem_t, res_t = fit(trial, w)
        record(problem_t, trial)
        sims += res_t.simulations
        score_t = score_of(rss_t, n_obs, int(trial.sum()) - 1)
        ok = score_t < score
        path.append({"removed": names[k], "estimate": float(rss + est.min()), "rss": rss_t,
                     "score": score_t, "accepted": bool(ok)})
        if not ok:
            break
        active, w, rss, score, problem = trial, w_t, rss_t, score_t, problem_t
    return w, active, rss, score, sims, path, visited


def refine_candidate(model, data: TimeSeries, names: list[str], w0, criterion: str, template):
    """Paper 004's refinement (:func:`mcl.refine.refine`), scored like :func:`fit_and_prune`:
    RSS and BIC/AIC of a simulation of the refined law on the training data."""
    from ..api import simulate
    from ..refine import refine

    w, active, path = refine(model, data, names, w0, criterion, terms=getattr(template, "terms", None))
    outs = [o for o in model.output_names if o in data.names]
    res, sims = simulate(model, data, dict(zip(names, w * active))), 2   # and refine's start
    if not res.ok:   # the refined law does not simulate: keep the start (nominal) law
        w, active = np.asarray(w0, float), np.ones(len(names), bool)
        res, sims = simulate(model, data, dict(zip(names, w))), 3
    r = data.select(outs).values - res.outputs[:, [model.output_names.index(o) for o in outs]]
    rss = float(np.sum(r**2))
    score = (bic if criterion == "bic" else aic)(rss, r.size, int(active.sum()) - 1)
    return w * active, active, rss, score, sims, path, []


def _candidate_model(ctx, item):
    """(template, w0, swapped model description, compiled model) of one candidate, compiled by
    the parent before the batch (a forked worker must not run the Rust front end: its threads
    do not survive a fork); a candidate that did not compile raises its error here."""
    built = ctx[8][(item[0], item[1])]
    if isinstance(built, Exception):
        raise built
    return built


def build_candidates(graph, train, nominal_probe, items, workdir, libraries=()) -> dict:
    """Every candidate of ``items`` compiled (the template in place of its component); one that
    does not compile (its system refers to variables the template lacks) keeps its error."""
    out = {}
    for it in items:
        try:
            out[(it[0], it[1])] = build_candidate(graph, train, nominal_probe, it, workdir, libraries)
        except MclError as exc:
            out[(it[0], it[1])] = ModelicaError(f"the candidate does not compile: {exc.message}")
    return out


def build_candidate(graph, train, nominal_probe, item, workdir, libraries=()):
    from ..api import compile_model, registry
    from ..swap import swap_component

    comp_name, tpl_index, tpl_spec = item
    template = registry().template(tpl_spec)
    v, i = nominal_probe[comp_name]
    w0 = nominal_start(template, v, i, train.time)
    tm = swap_component(graph, comp_name, template, Path(workdir) / f"{comp_name}_{tpl_index}",
                        w=w0, package=f"Candidate_{comp_name}_{tpl_index}")
    return template, w0, tm, compile_model(tm.sources, tm.model_name, libraries=libraries)


def _screen_task(ctx, item):
    """Executor task: the Gauss-Newton prediction of how much a candidate can explain.

    One simulation with sensitivities at w0 (the template fitted to the nominal law):
    predicted RSS after one Gauss-Newton step = RSS - g^T (S^T S)^+ g with g = S^T r.
    Cheap, and ranks the candidates well enough to fit only the promising ones fully.
    """
    from ..api import simulate

    train = ctx[1]
    comp_name, _, tpl_spec = item
    template, w0, tm, model = _candidate_model(ctx, item)
    params = dict(zip(tm.parameter_names, w0))
    res = simulate(model, train, params, sensitivities=tm.parameter_names[1:])
    if not res.ok:
        return {"component": comp_name, "template": tpl_spec, "predicted_rss": None, "reason": res.reason}
    idx = [model.output_names.index(o) for o in model.output_names if o in train.names]
    r = (train.select([model.output_names[k] for k in idx]).values - res.outputs[:, idx]).ravel()
    S = res.sensitivities[:, idx, :].reshape(-1, len(tm.parameter_names) - 1)
    g = S.T @ r
    gain = float(g @ np.linalg.pinv(S.T @ S) @ g)
    return {"component": comp_name, "template": tpl_spec, "rss0": float(r @ r), "n_params": len(tm.parameter_names),
            "predicted_rss": float(max(r @ r - gain, 0.0))}


def _candidate_task(ctx, item):
    """Executor task: one candidate component with one template, fitted and pruned."""
    from ..api import simulate

    graph, train, validate, _, budget, criterion, _, method, _ = ctx
    comp_name, _, tpl_spec = item
    template, w0, tm, model = _candidate_model(ctx, item)
    comp = graph.components[comp_name]
    if method == "full-discretisation":
        w, active, rss, score, sims, path, visited = refine_candidate(model, train, tm.parameter_names, w0,
                                                                      criterion, template)
    else:
        w, active, rss, score, sims, path, visited = fit_and_prune(model, train, tm.parameter_names, w0,
                                                                   budget, criterion)
    params = dict(zip(tm.parameter_names, w))
    out = {"component": comp_name, "class": comp.cls, "template": tpl_spec, "w0": w0.tolist(),
           "w": w.tolist(), "active": active.tolist(), "rss": rss, "score": score,
           "simulations": sims, "pruning": path, "equation": template.equation(w * active),
           "visited": visited,
           "terms": [str(m) for m in getattr(template, "terms", [])]}
    res = simulate(model, train, params)
    out["train_rms"] = rms(train.select(model.output_names).values - res.outputs) if res.ok else None
    if validate is not None:
        rv = simulate(model, validate, params)
        out["validation_rms"] = (rms(validate.select(model.output_names).values - rv.outputs)
                                 if rv.ok else None)
    if res.ok:
        pv = probe(model, res, train, params, [f"{comp_name}.v"])[:, 0]
        out["v_range"] = [float(pv.min()), float(pv.max())]
    return out


def ctx_of(graph, train, validate, nominal_probe, spec, part, models):
    return (graph, train, validate, nominal_probe, spec.max_simulations, spec.criterion, str(part / "work"),
            spec.refinement_method, models)


def _done(path: Path) -> bool:
    """A candidate already fitted (a failed one is tried again on resume)."""
    if not path.exists():
        return False
    try:
        return "failed" not in json.loads(path.read_text())
    except ValueError:
        return False


def _template_name(spec) -> str:
    return spec if isinstance(spec, str) else spec.get("name", "?")


def _failures(screening: list, cands: list) -> list[dict]:
    """Every candidate that could not be evaluated, with the stage and the reason."""
    out = [{"component": s["component"], "template": s["template"], "stage": "screening",
            "reason": s.get("reason", "failed")} for s in screening if s.get("predicted_rss") is None]
    out += [{"component": c["component"], "template": c["template"], "stage": "fitting",
             "reason": c["failed"]} for c in cands if c.get("failed")]
    return out


def _weigh_unevaluated(evidence: dict, best: dict, cands: list, screening: list, spec, n_obs: int) -> None:
    """A contender that failed in fitting can only be excluded by its screening prediction:
    its predicted score (one linearised step) must lose by the criterion's 'decisive' margin;
    otherwise the cause is at most 'undecided'."""
    score_of = bic if spec.criterion == "bic" else aic
    open_ = []
    for c in (c for c in cands if c.get("failed")):
        pred = next((s for s in screening if s["component"] == c["component"] and s["template"] == c["template"]), {})
        k = pred.get("n_params", 3)
        if pred.get("predicted_rss") is None or score_of(pred["predicted_rss"], n_obs, k - 1) - best["score"] <= 10:
            open_.append(c["component"])
    if open_:
        evidence["unevaluated"] = open_
        evidence["strength"] = f"undecided: {', '.join(open_)} could not be evaluated"


def strength(delta: float) -> str:
    """Kass & Raftery's reading of a BIC difference."""
    return ("decisive" if delta > 10 else "strong" if delta > 6 else
            "positive" if delta > 2 else "weak")


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
    nominal = compile_model(spec.sources, spec.model_name, libraries=spec.libraries)
    graph = build_graph(spec.sources, spec.model_name, libraries=spec.libraries)
    outputs = [o for o in nominal.output_names if o in train.names]
    log.info("[1/5] nominal model %s: simulating the training data", spec.model_name)
    sim0 = simulate(nominal, train)
    if not sim0.ok:
        raise ConfigError(f"the nominal model does not simulate the training data: {sim0.reason}")
    y_meas = train.select(outputs).values
    y0 = sim0.outputs[:, [nominal.output_names.index(o) for o in outputs]]
    resid = y_meas - y0
    sigma = float(np.sqrt(np.mean([noise_estimate(y_meas[:, k]) ** 2 for k in range(len(outputs))])))
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
    val0 = None
    if validate is not None:
        sv = simulate(nominal, validate)
        val0 = rms(validate.select(outputs).values - sv.outputs[:, [nominal.output_names.index(o) for o in outputs]])
    extended_y = None
    if significant:
        comps = [c for c in graph.two_connector_components() if not c.inputs]
        if spec.unknown != "auto":
            comps = [graph.components[spec.unknown]]
        nominal_probe = {}
        for c in comps:
            va, vb, fa = component_variables(c)
            pv = probe(nominal, sim0, train, {}, [va, vb, fa])
            nominal_probe[c.name] = (pv[:, 0] - pv[:, 1], pv[:, 2])
        items = [(c.name, k, t) for c in comps for k, t in enumerate(spec.templates)]
        screen_file = part / "screening.json"
        models = {}
        if screen_file.exists():
            screening = json.loads(screen_file.read_text())
        else:
            log.info("[2/5] screening %d candidate(s): one linearised step each", len(items))
            models = build_candidates(graph, train, nominal_probe, items, part / "work", spec.libraries)
            with reg.executor(spec.executor) as ex:
                res = ex.map(_screen_task, items, context=ctx_of(graph, train, validate, nominal_probe, spec,
                                                                  part, models),
                             timeout=3600, label="screening")
            screening = [r if not isinstance(r, TaskFailed) else
                         {"component": it[0], "template": it[2], "predicted_rss": None, "reason": r.reason}
                         for it, r in zip(items, res)]
            rundir.write_json("screening.json", screening)
        order = sorted(range(len(items)), key=lambda k: (screening[k]["predicted_rss"] is None,
                                                         screening[k]["predicted_rss"] or 0.0))
        items = [items[k] for k in order[: spec.screen]]
        todo = [it for it in items if not _done(part / "candidates" / f"{it[0]}_{it[1]}.json")]
        log.info("      fitting the %d most promising (%d already done)", len(items), len(items) - len(todo))
        models.update(build_candidates(graph, train, nominal_probe, [it for it in todo if it[:2] not in models],
                                       part / "work", spec.libraries))
        ctx = ctx_of(graph, train, validate, nominal_probe, spec, part, models)

        def checkpoint(k, r):  # each candidate is saved as it finishes: a rerun skips it
            it = todo[k]
            if isinstance(r, TaskFailed):
                r = {"component": it[0], "template": it[2], "failed": r.reason, "score": None}
            rundir.write_json(f"candidates/{it[0]}_{it[1]}.json", r)

        with reg.executor(spec.executor) as ex:
            ex.map(_candidate_task, todo, context=ctx, timeout=3600, label="candidates", on_result=checkpoint)
        cands = [json.loads((part / "candidates" / f"{n}_{k}.json").read_text()) for n, k, _ in items]
        ranked = sorted([c for c in cands if c.get("score") is not None], key=lambda c: c["score"])
        report["candidates"] = ranked + [c for c in cands if c.get("score") is None]
        report["screening"] = screening
        report["failed"] = _failures(screening, cands)
        for f in report["failed"]:
            log.warning("      %s with %s could not be evaluated (%s): %s", f["component"],
                        _template_name(f["template"]), f["stage"], f["reason"])
        # the nominal model is a contender too: a cause must explain the data better than it
        n_obs = y_meas.size
        nominal_score = (bic if spec.criterion == "bic" else aic)(float(np.sum(resid**2)), n_obs, 0)
        report["nominal_score"] = nominal_score
        ranked = [c for c in ranked if c["score"] < nominal_score]
        if not ranked:
            log.info("      no candidate explains the data better than the nominal model")
        if ranked:
            best = ranked[0]
            delta = min([c["score"] for c in ranked[1:]] + [nominal_score]) - best["score"]
            report["cause"], extended_y = _explain(best, delta, graph, spec, part, train, validate,
                                                   outputs, reg, nominal_probe)
            _weigh_unevaluated(report["cause"]["evidence"], best, cands, screening, spec, n_obs)
            report["gain"] = {"train_rms_before": train_rms0, "train_rms_after": best.get("train_rms"),
                              "validation_rms_before": val0, "validation_rms_after": best.get("validation_rms")}
    if report["gain"] is None:
        report["gain"] = {"train_rms_before": train_rms0, "train_rms_after": train_rms0,
                          "validation_rms_before": val0, "validation_rms_after": val0}
    report["seconds"] = time.perf_counter() - t_start
    log.info("[5/5] report")
    from ..report import write_report

    write_report(part, report, train, outputs, y0, extended_y, **spec.report)
    rundir.finish()
    log.info("wrote %s/report.html and report.json", spec.output)
    return report


def software_versions() -> dict:
    """Versions of mcl and of what computes its numbers (recorded in report.json)."""
    from ..compile.library import distribution_versions

    return distribution_versions("mcl", "casadi", "fmpy", "numpy", "scipy", "pymoca", "rumoca")


def _explain(best, delta, graph, spec, part, train, validate, outputs, reg, nominal_probe):
    """The winner as a law, the extended model (Modelica + FMU) and its simulated outputs."""
    from ..api import compile_model, simulate
    from ..compile.fmu.export import build_fmu
    from ..swap import swap_component

    template = reg.template(best["template"])
    w = np.asarray(best["w"]) * np.asarray(best["active"])
    comp = graph.components[best["component"]]
    log.info("[3/5] cause: %s (%s): %s", comp.name, comp.cls, template.equation(w))
    lo, hi = best.get("v_range") or [-1.0, 1.0]
    xs = np.linspace(lo, hi, 41)
    curve = [[float(x), float(f)] for x, f in zip(xs, template.flow_of(w, xs))]
    v_nom, i_nom = nominal_probe[best["component"]]
    pick = np.linspace(0, len(v_nom) - 1, min(200, len(v_nom))).astype(int)
    nominal_points = [[float(v_nom[k]), float(i_nom[k])] for k in pick]
    nominal_terms = [t for t, a in zip(best.get("terms", []), np.abs(best["w0"]) > 1e-9 * np.max(np.abs(best["w0"]))) if a]
    new_terms = [t for t, on, w0 in zip(best.get("terms", []), best["active"], best["w0"])
                 if on and t not in nominal_terms]
    effect = (f"{comp.name} follows {template.equation(w)}"
              + (f"; missing from the nominal law: {', '.join(new_terms)}" if new_terms else ""))
    ext_dir = part / "extended"
    tm = swap_component(graph, comp.name, template, ext_dir, w=w, package=LEARNED_PACKAGE)
    log.info("[4/5] extended model: compiling to an FMU")
    ext = compile_model(tm.sources, tm.model_name, libraries=spec.libraries)
    fmu = build_fmu(ext, ext_dir / f"{spec.model_name.split('.')[-1]}.fmu")
    res = simulate(ext, train)
    y_ext = res.outputs[:, [ext.output_names.index(o) for o in outputs]] if res.ok else None
    cause = {"component": comp.name, "class": comp.cls, "effect": effect,
             "evidence": {"delta_bic_to_next": delta, "strength": strength(delta)},
             "law": {"equation": template.equation(w, across="v", flow="i"),
                     "across": f"{comp.name}.{comp.connectors[0].name}.{comp.connectors[0].potential[0]} - "
                               f"{comp.name}.{comp.connectors[1].name}.{comp.connectors[1].potential[0]}",
                     "flow": f"{comp.name}.{comp.connectors[0].name}.{comp.connectors[0].flow[0]}",
                     "curve": curve, "nominal": nominal_points},
             "visited": best.get("visited", []), "parameters": template.parameter_names(),
             "modelica": str(tm.path.relative_to(part)), "fmu": str(fmu.relative_to(part)),
             "learned_class": class_name_for(comp.name, template)}
    if spec.second:
        cause["second_configuration"] = _second(spec, template, w, comp.name, part)
    return cause, y_ext


def _second(spec, template, w, component: str, part: Path) -> dict:
    """The learned law placed into another configuration (``second:`` in the run file)."""
    from ..api import compile_model, simulate
    from ..graph import build_graph
    from ..swap import swap_component

    sec = spec.second
    base = spec.path.parent if spec.path else Path.cwd()
    sources = [base / s for s in sec["model"]["sources"]]
    name = sec["model"]["name"]
    target = sec.get("component", component)
    data = read_csv(base / sec["data"])
    nominal = compile_model(sources, name, libraries=spec.libraries)
    graph = build_graph(sources, name, libraries=spec.libraries)
    tm = swap_component(graph, target, template, part / "second", w=w, package="LearnedSecond")
    learned = compile_model(tm.sources, tm.model_name, libraries=spec.libraries)
    outs = [o for o in nominal.output_names if o in data.names]
    meas = data.select(outs).values
    before, after = simulate(nominal, data), simulate(learned, data)
    pick = (lambda m, r: r.outputs[:, [m.output_names.index(o) for o in outs]])
    return {"model": name, "component": target,
            "rms_before": rms(meas - pick(nominal, before)) if before.ok else None,
            "rms_after": rms(meas - pick(learned, after)) if after.ok else None}
