"""Step 4 of a discovery: the winner explained and put back.

The winning candidate's law in the component's own words with its curve over the range the data
visit, the extended model (the learned class in place of the suspect) written as Modelica,
compiled and exported as an FMU, its outputs on the training and validation data, and, with
``second:`` in the run file, the learned law placed into another configuration.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..data import read_csv
from ..progress import log
from ..stats import criterion as criterion_of, rms
from ..swap import class_name_for
from .fitters import residual
from .words import in_words, words

LEARNED_PACKAGE = "Learned"


def explain(best, delta, graph, spec, part, train, validate, outputs, reg, nominal_probe):
    """The winner as a law, the extended model (Modelica + FMU) and its simulated outputs."""
    from ..api import compile_model, simulate
    from ..compile.fmu.export import build_fmu
    from ..swap import swap_component

    template = reg.template(best["template"])
    w = np.asarray(best["w"]) * np.asarray(best["active"])
    comp = graph.components[best["component"]]
    law = in_words(template, w, comp)
    log.info("[3/5] cause: %s (%s): %s", comp.name, comp.cls, law)
    var = template.law_variable
    lo, hi = best.get("law_range") or best.get("v_range") or [-1.0, 1.0]
    xs = np.linspace(lo, hi, 41)
    curve = [[float(x), float(f)] for x, f in zip(xs, template.curve(w, xs))]
    env = nominal_probe[best["component"]]
    x_nom, f_nom = (env["i"], env["v"]) if var == "i" else (env[var], env["i"])
    pick = np.linspace(0, len(x_nom) - 1, min(200, len(x_nom))).astype(int)
    nominal_points = [[float(x_nom[k]), float(f_nom[k])] for k in pick]
    nominal_terms = [t for t, a in zip(best.get("terms", []), np.abs(best["w0"]) > 1e-9 * np.max(np.abs(best["w0"]))) if a]
    new_terms = [t for t, on, w0 in zip(best.get("terms", []), best["active"], best["w0"])
                 if on and t not in nominal_terms]
    effect = (f"{comp.name} follows {law}"
              + (f"; missing from the nominal law: {', '.join(new_terms)}" if new_terms else ""))
    ext_dir = part / "extended"
    name = {"v": "v", "dv": "der(v)", "i": "i"}[var]
    note = f"; learned for {name} in [{lo:.4g}, {hi:.4g}] (the range of the training data)"
    tm = swap_component(graph, comp.name, template, ext_dir, w=w, package=LEARNED_PACKAGE, note=note)
    log.info("[4/5] extended model: compiling to an FMU")
    ext = compile_model(tm.sources, tm.model_name, libraries=spec.libraries)
    fmu = build_fmu(ext, ext_dir / f"{spec.model_name.split('.')[-1]}.fmu")   # the model's own outputs
    ext = ext.with_outputs(train.names)
    pick = lambda r: r.outputs[:, [ext.output_names.index(o) for o in outputs]] if r.ok else None
    y_ext = pick(simulate(ext, train))
    y_val = pick(simulate(ext, validate)) if validate is not None else None
    cause = {"component": comp.name, "class": comp.cls, "effect": effect,
             "evidence": {"criterion": spec.criterion, "delta_to_next": delta,
                          "strength": criterion_of(spec.criterion).strength(delta)},
             "law": {"equation": law, "where": words(comp).definitions,
                     "template_equation": template.equation(w, across="v", flow="i"),
                     "family": best.get("family"),
                     "across": f"{comp.name}.{comp.connectors[0].name}.{comp.connectors[0].potential[0]} - "
                               f"{comp.name}.{comp.connectors[1].name}.{comp.connectors[1].potential[0]}",
                     "flow": f"{comp.name}.{comp.connectors[0].name}.{comp.connectors[0].flow[0]}",
                     # the curve: the law against the variable it is in (der(across) for a law
                     # in the rate; across against flow for a law in the flow), over the visited range
                     "variable": {"v": "across", "dv": "der(across)", "i": "flow"}[var],
                     "range": [float(lo), float(hi)],
                     "curve": curve, "nominal": nominal_points},
             "visited": best.get("visited", []), "parameters": template.parameter_names(),
             "modelica": str(tm.path.relative_to(part)), "fmu": str(fmu.relative_to(part)),
             "learned_class": class_name_for(comp.name, template)}
    if spec.second:
        cause["second_configuration"] = _second(spec, template, w, comp.name, part)
    return cause, y_ext, y_val


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
    nominal = compile_model(sources, name, libraries=spec.libraries).with_outputs(data.names)
    graph = build_graph(sources, name, libraries=spec.libraries)
    tm = swap_component(graph, target, template, part / "second", w=w, package="LearnedSecond")
    learned = compile_model(tm.sources, tm.model_name, libraries=spec.libraries).with_outputs(data.names)
    outs = [o for o in nominal.output_names if o in data.names]
    before, after = simulate(nominal, data), simulate(learned, data)
    return {"model": name, "component": target,
            "rms_before": rms(residual(data, nominal, before, outs)) if before.ok else None,
            "rms_after": rms(residual(data, learned, after, outs)) if after.ok else None}
