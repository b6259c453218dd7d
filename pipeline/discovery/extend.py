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

import dataclasses
import re
import shutil
from pathlib import Path

import numpy as np

from ..data import read_csv
from ..progress import log
from ..stats import criterion as criterion_of, rms
from .fitters import residual
from .words import in_words, words

LEARNED_PACKAGE = "Learned"


def class_name_for(component: str, template) -> str:
    return re.sub(r"\W", "_", f"{component}_{template.name}")


def describe(best: dict, base, spec, train, signals) -> dict:
    """A cause: the winning law in the component's words, its curve, what it adds to the nominal
    law, the evidence and the equivalent components."""
    from ..api import registry

    template = registry().template(best["template"])
    w = np.asarray(best["w"]) * np.asarray(best["active"])
    comp = base.structure.components[best["component"]]
    law = in_words(template, w, comp)
    log.info("[3/5] cause: %s (%s): %s", comp.name, comp.cls, law)
    var = template.law_variable
    lo, hi = best.get("law_range") or best.get("v_range") or [-1.0, 1.0]
    xs = np.linspace(lo, hi, 41)
    curve = [[float(x), float(f)] for x, f in zip(xs, template.curve(w, xs))]
    env = signals[comp.name].env()
    x_nom, f_nom = (env["i"], env["v"]) if var == "i" else (env[var], env["i"])
    pick = np.linspace(0, len(x_nom) - 1, min(200, len(x_nom))).astype(int)
    nominal_points = [[float(x_nom[k]), float(f_nom[k])] for k in pick]
    nominal_terms = set(best.get("nominal_form") or {})
    new_terms = [t for t, on in zip(best.get("terms", [])[1:], best["active"][1:]) if on and t not in nominal_terms]
    effect = f"{comp.name} follows {law}" + (f"; missing from the nominal law: {', '.join(new_terms)}" if new_terms else "")
    if best.get("nominal_exact") is False:
        effect += " (its nominal law is not linear: the learned terms are a deviation from it)"
    equivalents = best.get("equivalents", [])
    if equivalents:
        effect += "; equivalent: " + ", ".join(f"{e['component']} ({e['reason']})" for e in equivalents)
    name = {"v": "v", "dv": "der(v)", "i": "i"}[var]
    wd = words(comp)
    return {"component": comp.name, "class": comp.cls, "effect": effect, "template": best["template"],
            "w": w.tolist(), "mode": best.get("mode"), "nominal_form": best.get("nominal_form"),
            "evidence": {"criterion": spec.criterion, "delta_to_next": best["delta"],
                         "strength": criterion_of(spec.criterion).strength(best["delta"]),
                         "role": best.get("role"), "effect_kind": best.get("effect_kind")},
            "equivalents": equivalents,
            "law": {"equation": law, "where": wd.definitions,
                    "template_equation": template.equation(w, across="v", flow="i"),
                    "family": best.get("family"), "across": wd.across, "flow": wd.flow,
                    # the curve: the law against the variable it is in (der(across) for a law in
                    # the rate; across against flow for a law in the flow), over the visited range
                    "variable": {"v": "across", "dv": "der(across)", "i": "flow"}[var],
                    "range": [float(lo), float(hi)], "curve": curve, "nominal": nominal_points,
                    "note": f"learned for {name} in [{lo:.4g}, {hi:.4g}] (the range of the training data)"},
            "visited": best.get("visited", []), "parameters": template.parameter_names(),
            "learned_class": class_name_for(comp.name, template),
            "train_rms": best.get("train_rms"), "validation_rms": best.get("validation_rms")}


# -- Modelica ------------------------------------------------------------------------------------
def connector_classes(comp, libraries=(), sources=()) -> dict[str, str]:
    """The class of each of ``comp``'s connectors, read from its class's declarations (through
    what it extends), in the libraries on the path and the user's own files."""
    from ..compile.classes import LibraryClasses
    from ..compile.library import available, library_path
    from ..compile.sources import checked, expand, top_level_names

    libs = dict(available(library_path(libraries)))
    try:
        files = expand(checked(sources))
    except Exception:  # noqa: BLE001 - the sources compiled; this is only for naming
        files = []
    for f in files:
        if f.name == "package.mo":
            libs.setdefault(f.parent.name.split(" ")[0], f.parent)
        else:
            for n in top_level_names([f], {f: f.read_text(errors="replace")}):
                libs.setdefault(n, f)
    lib = LibraryClasses(libs)
    info = lib.find(comp.cls) if comp.cls else None
    out = {}
    if info is not None:
        for _prefixes, cls, _type, member, _cond in lib.members(info):
            if cls is not None and cls.kind == "connector":
                out[member] = cls.name
    return out


def learned_class(cause: dict, comp, libraries=(), sources=()) -> str:
    """The learned law as a Modelica class with the component's own connector classes."""
    from ..api import registry

    template = registry().template(cause["template"])
    classes = connector_classes(comp, libraries, sources)
    conns = [dataclasses.replace(c, cls=classes.get(c.name, c.cls)) for c in comp.connectors]
    unresolved = [c.name for c in conns if c.cls.startswith("connector(")]
    if unresolved:
        raise ValueError(f"the connector classes of {comp.name} ({comp.cls or 'class unknown'}) are not found")
    note = "; " + cause["law"]["note"]
    return template.modelica_class(cause["learned_class"], dataclasses.replace(comp, connectors=conns),
                                   np.asarray(cause["w"]), note)


def _statement_end(text: str, start: int) -> int:
    """Index just past the ';' that ends the statement starting at ``start`` (strings and
    parentheses skipped)."""
    depth, k, n = 0, start, len(text)
    while k < n:
        ch = text[k]
        if ch == '"':
            k += 1
            while k < n and text[k] != '"':
                k += 2 if text[k] == "\\" else 1
        elif ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
        elif ch == ";" and depth == 0:
            return k + 1
        k += 1
    return n


def _arguments(text: str) -> list[str]:
    """The top-level comma-separated arguments of a modification."""
    out, depth, cur = [], 0, ""
    for ch in text:
        depth += {"(": 1, ")": -1, "{": 1, "}": -1, "[": 1, "]": -1}.get(ch, 0)
        if ch == "," and depth == 0:
            out.append(cur)
            cur = ""
        else:
            cur += ch
    return [a for a in [*out, cur] if a.strip()]


def redeclared(text: str, model_short: str, component: str, new_class: str, keep=("v", "i")) -> str | None:
    """``text`` with the declaration of ``component`` inside class ``model_short`` changed to
    ``new_class``: of its modification only what modifies the learned class's own variables
    ``keep`` stays (a start value, fixed = true; the nominal class's parameters go), its
    comment and annotation stay. None when that declaration is not in the class."""
    head = re.search(rf"(?m)(?:^|[\s;])(?:(?:partial|encapsulated|final)\s+)*(?:model|block|class)\s+{re.escape(model_short)}\b",
                     text)
    if not head:
        return None
    end = re.search(rf"\bend\s+{re.escape(model_short)}\s*;", text[head.end():])
    body_end = head.end() + (end.start() if end else len(text) - head.end())
    decl = re.compile(rf"(?m)(^|;|\n)([ \t]*)((?:(?:inner|outer|final|replaceable|redeclare)\s+)*)"
                      rf"([A-Za-z_][\w.]*)(\s+){re.escape(component)}\b")
    for m in decl.finditer(text, head.end(), body_end):
        if m.group(4) in ("connect", "end", "equation", "import", "extends", "parameter", "constant"):
            continue
        stop = _statement_end(text, m.end())
        rest = text[m.end():stop]
        if rest.lstrip().startswith("("):          # the modification, nested parentheses and all
            k0, depth = rest.index("("), 0
            for k in range(k0, len(rest)):
                depth += {"(": 1, ")": -1}.get(rest[k], 0)
                if depth == 0:
                    break
            kept = [a for a in _arguments(rest[k0 + 1:k]) if re.match(rf"\s*(?:each\s+|final\s+)*({'|'.join(keep)})\b", a)]
            rest = (f"({', '.join(a.strip() for a in kept)})" if kept else "") + rest[k + 1:]
        return text[:m.start(4)] + new_class + m.group(5) + component + rest + text[stop:]
    return None


def write_extended(causes: list[dict], base, spec, directory: Path) -> tuple[list[Path], str, Path, list[str]]:
    """The extended model as Modelica in ``directory``: the package ``Learned`` with the learned
    classes, and a copy of the user's sources (or of the model's class) in which each learned
    component is declared with its learned class. Returns (sources, model name, the Learned
    package file, notes on what could not be written)."""
    from ..compile.library import uses_annotation

    directory.mkdir(parents=True, exist_ok=True)
    notes, classes, swaps = [], [], []
    for cause in causes:
        comp = base.structure.components[cause["component"]]
        if "." in comp.name:
            notes.append(f"{comp.name} is inside a component: its learned class is in the package, "
                         "the model is not rewritten for it")
        try:
            classes.append(learned_class(cause, comp, spec.libraries, spec.sources))
        except ValueError as exc:
            notes.append(str(exc))
            continue
        if "." not in comp.name:
            swaps.append((comp.name, f"{LEARNED_PACKAGE}.{cause['learned_class']}"))
    short = spec.model_name.split(".")[-1]
    sources, model_name, extra = [], spec.model_name, ""
    if spec.sources:
        for src in spec.sources:
            target = directory / src.name
            if src.is_dir():
                shutil.copytree(src, target, dirs_exist_ok=True)
            else:
                shutil.copyfile(src, target)
            sources.append(target)
        files = [f for s in sources for f in ([s] if s.is_file() else sorted(s.rglob("*.mo")))]
    else:
        text = _library_class_text(spec.model_name, spec.libraries)
        if text is None:
            notes.append(f"the class {spec.model_name} is not found as text: the model is not rewritten")
        else:
            extra, model_name = text, f"{LEARNED_PACKAGE}.{short}"
        files = []
    for name, cls in swaps:
        done = False
        for owner in _class_and_bases(short, [f.read_text(errors="replace") for f in files] + [extra]):
            for f in files:
                new = redeclared(f.read_text(errors="replace"), owner, name, cls)
                if new is not None:
                    f.write_text(new)
                    done = True
                    break
            if extra and not done:
                new = redeclared(extra, owner, name, cls)
                if new is not None:
                    extra, done = new, True
            if done:
                break
        if not done:
            notes.append(f"the declaration of {name} is not in {spec.model_name}'s own text: the model is not rewritten for it")
    body = "\n".join(classes) + (f"\n{extra}" if extra else "")
    indented = "\n".join(("  " + line) if line.strip() else "" for line in body.splitlines())
    uses = uses_annotation(body, spec.libraries)
    package = directory / f"{LEARNED_PACKAGE}.mo"
    package.write_text(f'package {LEARNED_PACKAGE} "Components learned by mcl"\n{indented}\n'
                       + (f"  {uses};\n" if uses else "") + f"end {LEARNED_PACKAGE};\n")
    return [*sources, package], model_name, package, notes


def _class_and_bases(short: str, texts: list[str]) -> list[str]:
    """``short`` and the classes it extends, transitively (short names, as found in ``texts``):
    where a component may be declared. (The copy of a base class declares the learned class
    for every model of the copy that extends it.)"""
    out, todo = [], [short]
    while todo:
        name = todo.pop(0)
        if name in out:
            continue
        out.append(name)
        for text in texts:
            head = re.search(rf"(?:^|[\s;])(?:model|block|class)\s+{re.escape(name)}\b", text or "")
            if not head:
                continue
            end = re.search(rf"\bend\s+{re.escape(name)}\s*;", text[head.end():])
            body = text[head.end(): head.end() + (end.start() if end else 0)]
            todo += [b.split(".")[-1] for b in re.findall(r"\bextends\s+([\w.]+)", body)]
            break
    return out


def _library_class_text(model: str, libraries=()) -> str | None:
    """The text of class ``model`` from the library it is in (for a model given by name only)."""
    from ..compile.library import available, library_path

    parts = model.split(".")
    where = available(library_path(libraries)).get(parts[0])
    if where is None:
        return None
    path = where
    rest = parts[1:]
    if where.is_dir():
        while rest and (path / rest[0]).is_dir():
            path, rest = path / rest[0], rest[1:]
        path = path / f"{rest[0]}.mo" if rest and (path / f"{rest[0]}.mo").is_file() else path / "package.mo"
    text = path.read_text(errors="replace")
    short = parts[-1]
    m = re.search(rf"(?m)^[ \t]*(?:(?:partial|encapsulated)\s+)?(model|block|class)\s+{re.escape(short)}\b", text)
    end = m and re.search(rf"\bend\s+{re.escape(short)}\s*;", text[m.end():])
    if not m or not end:
        return None
    return text[m.start(): m.end() + end.end()].strip() + "\n"


def extend(causes: list[dict], base, spec, part: Path, train, validate, outputs):
    """The extended model: simulated from the compiled DAE with every learned law (what was
    fitted), written as Modelica, compiled again and exported as an FMU; the cause of each
    round records the files. Returns (training outputs, validation outputs, files)."""
    from ..api import compile_model, simulate
    from ..compile.fmu.export import build_fmu

    model = base.model
    pick = lambda r: r.outputs[:, [model.output_names.index(o) for o in outputs]] if r.ok else None
    y_train = pick(simulate(model, train))
    y_val = pick(simulate(model, validate)) if validate is not None else None
    ext_dir = part / "extended"
    log.info("[4/5] extended model: Modelica, compiled again, and an FMU")
    sources, name, package, notes = write_extended(causes, base, spec, ext_dir)
    files = {"modelica": str(package.relative_to(part)), "sources": [str(s.relative_to(part)) for s in sources],
             "model": name, "notes": notes}
    try:
        ext = compile_model(sources, name, libraries=spec.libraries)
        fmu = build_fmu(ext, ext_dir / f"{spec.model_name.split('.')[-1]}.fmu")
        files["fmu"] = str(fmu.relative_to(part))
        check = simulate(ext.with_outputs(train.names), train)
        if check.ok and y_train is not None:
            y_check = check.outputs[:, [ext.with_outputs(train.names).output_names.index(o) for o in outputs]]
            files["recompiled_difference"] = float(np.max(np.abs(y_check - y_train)))
    except Exception as exc:  # noqa: BLE001 - the learned laws stand; the written model is reported
        files["error"] = f"the written extended model does not compile: {getattr(exc, 'message', exc)}"
        log.warning("      %s", files["error"])
    for cause in causes:
        cause["modelica"], cause["fmu"] = files["modelica"], files.get("fmu")
    if spec.second:
        causes[0]["second_configuration"] = _second(spec, causes[0], base)
    return y_train, y_val, files


def _second(spec, cause: dict, base) -> dict:
    """The first learned law placed into another configuration (``second:`` in the run file):
    that model compiled as written, the law put into its DAE at the same component (or the
    one ``second.component`` names)."""
    from ..api import compile_model, registry, simulate
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
    before = simulate(nominal, data)
    outs = [o for o in nominal.output_names if o in data.names]
    out = {"model": sec["model"]["name"], "component": target,
           "rms_before": rms(residual(data, nominal, before, outs)) if before.ok else None, "rms_after": None}
    if not before.ok:
        return out
    env = law_signals(nominal, before.states, before.time, data, [comp])[target].env()
    series = mode_of(template) == "series"
    law_vars = [v for v in (("i", "di") if series else ("v", "dv")) if v in template.uses]
    rates = rate_variables(nominal.dae, [comp], {comp.name: mode_of(template)})[comp.name]
    dae, _ = with_law(nominal.dae, comp, template, np.asarray(cause["w"]),
                      nominal_form(env, law_vars, "v" if series else "i"), rates)
    learned = compiled(dae, nominal.name, outputs=data.names, info=nominal.info, structure=nominal.structure)
    after = simulate(learned, data)
    out["rms_after"] = rms(residual(data, learned, after, outs)) if after.ok else None
    return out
