"""The causes explained and put back.

:func:`describe` words a cause: the law in the component's own words with its curve over the
range the data visit, what it adds to the nominal law, the evidence and the equivalent
components. :func:`extend` puts the learned laws back as Modelica: each learned law becomes a
class of a package ``Learned``, and the user's model is copied with each such component's
declaration changed to its learned class (nothing else of what the user wrote changes: imports,
initial equations, modifiers, annotations); that Modelica is compiled again, exported as an FMU
and simulated on the training and validation data (and, with ``second:``, the learned law is put
into another configuration).
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..data import read_csv
from ..progress import log
from ..stats import criterion as criterion_of, rms
from ..templates import unscaled
from .families import shape_words
from .fitters import WHOLE_RUN, residual
from .modelica import write_extended
from .report import short_number
from .words import in_words, said, words

def class_name_for(component: str, template) -> str:
    return re.sub(r"\W", "_", f"{component}_{template.name}")


def _as_good(alt: dict, comp) -> dict:
    """An equally good law of the component (:func:`.verdict.alternatives`) in its own words."""
    from ..services import registry

    out = {k: alt[k] for k in ("equation", "family", "score_difference")}
    if alt.get("template") is not None and alt.get("w") is not None:
        out["equation"] = said(registry().template(alt["template"]), np.asarray(alt["w"]), comp)
    return out


def _named(said: str, var: str, name: str) -> str:
    """A term's words (``shape_words``) with the law's variable in the component's own name, as
    the law is written: "sinh(x/s1)" for the term k*x, not the template's "sinh(v/s1)"."""
    if not re.fullmatch(r"[A-Za-z_][\w.]*", name or ""):
        return said          # (a negated or indexed name: the template's own)
    head, sep, term = said.rpartition(": ")
    return head + sep + re.sub(rf"\b{re.escape(var)}\b", name, term)


def describe(best: dict, base, spec, train, signals) -> dict:
    """A cause: the winning law in the component's words, its curve, what it adds to the nominal
    law, the evidence and the equivalent components."""
    from ..services import registry

    template = registry().template(best["template"])
    w = np.asarray(best["w"]) * np.asarray(best["active"])
    comp = base.structure.components[best["component"]]
    law = in_words(template, w, comp)
    log.info("[3/5] cause: %s (%s): %s", comp.name, comp.cls, law)
    var = template.law_variable
    lo, hi = best.get("law_range") or best.get("v_range") or [-1.0, 1.0]
    xs = np.linspace(lo, hi, 201)      # (a Coulomb-like tanh at 1 % of the range, drawn smooth)
    wd = words(comp)
    # the curve in the equation's own words and sign (a mechanical element's s_rel and f are
    # b - a and the force at b: the template's v and i negated; a connector's own potential
    # keeps its sign)
    sign = -1.0 if wd.flipped else 1.0
    x_sign = 1.0 if var in ("va", "vb") else sign
    env = signals[comp.name].env()
    names = wd.names
    # a law that also reads a connector's own potential is drawn with the other one held (at the
    # template's own value, else its mean along the nominal run)
    other = "va" if var == "vb" else "vb"
    held = ({other: float(template.at.get(other, np.mean(env[other])))}
            if (template.uses & {"va", "vb"}) - {var} else {})
    curve = [[x_sign * float(x), sign * float(f)] for x, f in zip(xs, template.curve(w, xs, at=held))]
    # a law that remembers its path (a hysteresis) is a loop: its falling branch too
    falling = ([[x_sign * float(x), sign * float(f)] for x, f in zip(xs, template.branch(w, xs, rising=False))]
               if hasattr(template, "branch") else None)
    x_nom, f_nom = (env["i"], env["v"]) if var == "i" else (env[var], env["i"])
    pick = np.linspace(0, len(x_nom) - 1, min(200, len(x_nom))).astype(int)
    nominal_points = sorted([x_sign * float(x_nom[k]), sign * float(f_nom[k])] for k in pick)
    x_name, y_name = names[var], (wd.across if var == "i" else wd.flow)
    units = base.model.info.get("units", {})
    nominal_terms = set(best.get("nominal_form") or {})
    speed = var == "dv" and bool(comp.connectors) and comp.connectors[0].potential[:1] in (("s",), ("phi",))
    new_terms = [_named(shape_words(unscaled(t)[0], comp.signal, speed), var, x_name) if t != "1" else "a constant"
                 for t, on in zip(best.get("terms", [])[1:], best["active"][1:]) if on and t not in nominal_terms]
    effect = f"{comp.name} follows {law}" + (f"; missing from the nominal law: {', '.join(new_terms)}" if new_terms else "")
    if best.get("nominal_exact") is False:
        effect += " (in place of its nominal law, which is not linear in the law's variables)"
    equivalents = best.get("equivalents", [])
    if equivalents:
        effect += "; equivalent: " + ", ".join(f"{e['component']} ({e['reason']})" for e in equivalents)
    alternatives = [_as_good(a, comp) for a in best.get("alternatives", [])]
    if alternatives:
        effect += "; as good for the data: " + "; ".join(f"{a['equation']} ({a['score_difference']:+.2g})"
                                                        for a in alternatives)
    plainer = _as_good(best["plainer"], comp) if best.get("plainer") else None
    if plainer:
        plainer.update({k: best["plainer"].get(k) for k in ("train_rms", "validation_rms")})
        effect += (f"; a plainer law (training RMS {short_number(plainer['train_rms'])}, this law {short_number(best.get('train_rms'))}): "
                   f"{plainer['equation']}")
    name = {"v": "v", "dv": "der(v)", "i": "i", "va": _local(wd.potentials[0]), "vb": _local(wd.potentials[1])}[var]
    return {"component": comp.name, "class": comp.cls, "effect": effect, "template": best["template"],
            "w": w.tolist(), "mode": best.get("mode"), "nominal_form": best.get("nominal_form"),
            "evidence": {"criterion": criterion_of(spec.criterion).name, "delta_to_next": best["delta"],
                         "strength": criterion_of(spec.criterion).strength(best["delta"]),
                         "role": best.get("role"), "effect_kind": best.get("effect_kind")},
            "equivalents": equivalents, "alternatives": alternatives, **({"plainer": plainer} if plainer else {}),
            "law": {"equation": law, "where": wd.definitions,
                    "template_equation": template.equation(w, across="v", flow="i"),
                    "family": best.get("family"), "across": wd.across, "flow": wd.flow,
                    # the curve: the law against the variable it is in (der(across) for a law in
                    # the rate; across against flow for a law in the flow; a connector's own
                    # potential), over the visited range, the other potential held at "held"
                    "variable": {"v": "across", "dv": "der(across)", "i": "flow", "va": "potential at a",
                                 "vb": "potential at b"}[var],
                    "range": sorted([x_sign * float(lo), x_sign * float(hi)]), "curve": curve,
                    **({"falling": falling} if falling else {}),
                    "nominal": nominal_points,
                    "x": x_name, "y": y_name, "x_unit": unit_of(x_name, units), "y_unit": unit_of(y_name, units),
                    "sign": sign,          # the equation's orientation against the template's (v = a - b, i into a)
                    "x_sign": x_sign,      # the curve's x against the template's (a potential keeps its sign)
                    "held": {names[p]: value for p, value in held.items()},
                    "at": held,            # the same, by the template's names (Template.curve's at)
                    "along": _along(template, w, env, wd, sign),
                    "nominal_is_function": _nominal_is_function(best, var),
                    "note": f"learned for {name} in [{lo:.4g}, {hi:.4g}] (the range of the training data)"},
            "visited": best.get("visited", []), "parameters": template.parameter_names(),
            "terms": best.get("terms") or template.parameter_names(),
            "learned_class": class_name_for(comp.name, template),
            "train_rms": best.get("train_rms"), "validation_rms": best.get("validation_rms")}


def _local(name: str) -> str:
    """A component's variable without the component's name (Outlet1.a.h: a.h)."""
    return name.split(".", 1)[-1]


def _along(template, w, env: dict, wd, sign: float, points: int = 200) -> dict | None:
    """A law in more than one of v, va, vb (radiation: G (T_a^4 - T_b^4)) is no curve: the law
    at points along the nominal run, each [variables..., flow] in the equation's words and sign
    (v and the flow flipped for a mechanical element, the potentials not); None for a law of
    one variable."""
    terms = [m for m, c in zip(getattr(template, "terms", []), w) if c != 0]
    reads = set().union(*(m.variables for m in terms)) - {"i"} if terms else template.uses - {"i"}
    used = [x for x in ("v", "va", "vb") if x in reads]
    if not {"va", "vb"} & reads or len(used) < 2 or reads & {"dv", "di"}:
        return None
    n = len(np.asarray(env["v"]))
    pick = np.linspace(0, n - 1, min(points, n)).astype(int)
    va, vb = np.asarray(env["va"], float)[pick], np.asarray(env["vb"], float)[pick]
    f = template.flow_of(w, va - vb, va=va, vb=vb)
    columns = {"v": sign * (va - vb), "va": va, "vb": vb}
    return {"variables": [wd.names[x] for x in used],
            "points": [[*(float(columns[x][k]) for x in used), sign * float(f[k])] for k in range(len(pick))]}


def _nominal_is_function(best: dict, var: str) -> bool:
    """Whether the nominal law is a function of the law's variable alone (a line to draw)."""
    form = best.get("nominal_form") or {}
    if var == "i" or not best.get("nominal_exact") or not form:
        return False
    other = "dv" if var == "v" else "v"
    return abs(form.get(other, 0.0)) <= 1e-9 * (abs(form.get(var, 0.0)) + 1e-300)


def unit_of(name: str, units: dict) -> str | None:
    """The unit of a variable of the model (``der(x)``: x's per second)."""
    if name.startswith("der(") and name.endswith(")"):
        inner = units.get(name[4:-1])
        return f"{inner}/s" if inner else None
    return units.get(name)


def extend(causes: list[dict], base, spec, part: Path, train, validate, outputs, calibrated: dict | None = None):
    """The extended model: simulated from the compiled DAE with every learned law (what was
    fitted), written as Modelica, compiled again and exported as an FMU; the cause of each
    round records the files. With a calibration (``free:``), the model written and exported is
    the calibrated one, and it is checked against the calibrated run. Returns (training
    outputs, validation outputs, files)."""
    from ..services import simulate
    from ..compile.fmu.export import build_fmu

    model = base.model
    pick = lambda r: r.outputs[:, [model.output_names.index(o) for o in outputs]] if r.ok else None
    y_train = pick(simulate(model, train, options=WHOLE_RUN))
    y_val = pick(base.validation or simulate(model, validate, options=WHOLE_RUN)) if validate is not None else None
    ext_dir = part / "extended"
    log.info("[4/5] extended model: Modelica, compiled again, and an FMU")
    sources, name, package, notes = write_extended(causes, base, spec, ext_dir, _data_words(spec, train), calibrated)
    files = {"modelica": str(package.relative_to(part)), "sources": [str(s.relative_to(part)) for s in sources],
             "model": name, "notes": notes}
    try:
        ext, calibrated_run = _delivered(files, sources, spec, calibrated)
        y_ref = pick(calibrated_run) if calibrated_run is not None else y_train
        # the FMU's default experiment is the training data's span and sampling
        fmu = build_fmu(ext, ext_dir / f"{spec.model_name.split('.')[-1]}.fmu", experiment=train)
        files["fmu"] = str(fmu.relative_to(part))
        check = simulate(ext.with_outputs(train.names), train, options=WHOLE_RUN)
        if not check.ok:      # a stiff learned law: the tolerance its fit simulated it at (as with_causes)
            from .fitters import FIT_OPTIONS

            check = simulate(ext.with_outputs(train.names), train, options={**FIT_OPTIONS, **WHOLE_RUN})
        if check.ok and y_ref is not None:
            y_check = check.outputs[:, [ext.with_outputs(train.names).output_names.index(o) for o in outputs]]
            files["recompiled_difference"] = float(np.max(np.abs(y_check - y_ref)))
        elif not check.ok:
            files["error"] = f"the written extended model does not simulate the training data: {check.reason}"
            log.warning("      %s", files["error"])
    except Exception as exc:  # noqa: BLE001 - the learned laws stand; the written model is reported
        files["error"] = f"the written extended model does not compile: {getattr(exc, 'message', exc)}"
        log.warning("      %s", files["error"])
    for cause in causes:
        cause["modelica"], cause["fmu"] = files["modelica"], files.get("fmu")
    if spec.second:
        causes[0]["second_configuration"] = _second(spec, causes[0], base)
    return y_train, y_val, files


def _delivered(files: dict, sources, spec, calibrated):
    """The model delivered, compiled, and the calibrated run it must reproduce: the calibrated
    one (with ``calibrated``) when it compiles, else the extended model with the laws alone
    (None: the run with the laws alone; a note says why); ``files["model"]`` names it."""
    from ..services import compile_model
    from .modelica import calibrated_name

    if calibrated:
        try:
            ext = compile_model(sources, calibrated_name(spec.model_name), libraries=spec.libraries)
            files["model"] = calibrated_name(spec.model_name)
            return ext, calibrated["run"]
        except Exception as exc:  # noqa: BLE001 - the laws alone are still a model to deliver
            files["notes"].append(f"the calibrated model does not compile ({getattr(exc, 'message', exc)}): "
                                  "the model with the laws alone is delivered")
    return compile_model(sources, files["model"], libraries=spec.libraries), None


def _data_words(spec, train) -> str:
    """Which data a law was learned from, in words (the file and its span)."""
    where = spec.train.name if getattr(spec, "train", None) else "the training data given"
    return f"{where}, {len(train.time)} samples over t = {train.time[0]:g}..{train.time[-1]:g} s"


def _second(spec, cause: dict, base) -> dict:
    """The first learned law placed into another configuration (``second:`` in the run file):
    that model compiled as written, the law put into its DAE at the same component (or the
    one ``second.component`` names)."""
    from ..services import compile_model, registry, simulate
    from .inject import compiled, mode_of, nominal_form, rate_variables, with_law
    from .screen import law_signals

    sec = spec.second
    root = spec.path.parent if spec.path else Path.cwd()
    sources = [root / s for s in sec["model"].get("sources", [])]
    data = read_csv(root / sec["data"])
    nominal = compile_model(sources, sec["model"]["name"], libraries=spec.libraries).with_outputs(data.names)
    target = sec.get("component", cause["component"])
    comp = nominal.structure.components[target]
    template = registry().template(cause["template"])
    before = simulate(nominal, data, options=WHOLE_RUN)
    outs = [o for o in nominal.output_names if o in data.names]
    out = {"model": sec["model"]["name"], "component": target,
           "rms_before": rms(residual(data, nominal, before, outs)) if before.ok else None, "rms_after": None}
    if not before.ok:
        return out
    env = law_signals(nominal, before.states, before.time, data, [comp])[target].env()
    series = mode_of(template) == "series"
    w = np.asarray(cause["w"], float)
    active = w != 0
    law_vars = [v for v in (("i", "di") if series else ("v", "dv")) if v in template.uses_where(active)]
    rates = rate_variables(nominal.dae, [comp], {comp.name: mode_of(template)})[comp.name]
    dae, _ = with_law(nominal.dae, comp, template, w, nominal_form(env, law_vars, "v" if series else "i"),
                      rates, active=active)
    learned = compiled(dae, nominal.name, outputs=data.names, info=nominal.info, structure=nominal.structure)
    after = simulate(learned, data)
    out["rms_after"] = rms(residual(data, learned, after, outs)) if after.ok else None
    return out
