"""The learned laws written as Modelica: classes that look native, and the user's model with them.

:func:`learned_class` writes a learned law as a class of the package ``Learned``: it extends the
nominal class's own two-connector interface (MSL's ``OnePort``, ``PartialCompliant``...; the
law then reads in that interface's variables, orientation and units; a law in the connectors'
own potentials reads them by name, ``port_a.T``), its coefficients are
parameters with units and descriptions (terms the pruning removed are left out), its icon is the
nominal class's, and a Documentation annotation gives the law, the range it was learned on, the
data, the evidence and the confidence. Where no such interface is found, the class declares the
component's own connectors and its law in v (across a - b) and i (the flow into a).

:func:`write_extended` copies the user's sources and changes, in the copy, each learned
component's declaration to its learned class (nothing else the user wrote changes: imports,
initial equations, modifiers, annotations).
"""
from __future__ import annotations

import bisect
import dataclasses
import html
import re
import shutil
from pathlib import Path

import numpy as np

from ..compile.components import top_level_parts
from ..compile.sources import statement_end

LEARNED_PACKAGE = "Learned"


def _library(libraries=(), sources=()):
    """Class lookup (:class:`mcl.compile.classes.LibraryClasses`) in the libraries on the path and
    the user's own files."""
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
    return LibraryClasses(libs)


def connector_classes(comp, libraries=(), sources=(), scope: str = "") -> dict[str, str]:
    """The class of each of ``comp``'s connectors, read from its class's declarations (through
    what it extends), in the libraries on the path and the user's own files; named as seen from
    ``scope`` (the model's class: a connector of the user's own package, ``Port``, is
    ``Tanks.Port`` from the package ``Learned``)."""
    lib = _library(libraries, sources)
    info = lib.find(comp.cls) if comp.cls else None
    out = {}
    if info is not None:
        for _prefixes, cls, _type, member, _cond in lib.members(info):
            if cls is not None and cls.kind == "connector":
                seen = lib.resolve(cls.name, scope) if scope else None
                out[member] = seen.name if seen is not None and seen.kind == "connector" else cls.name
    return out


#: where a library's components take their law from a partial class they need not extend: a
#: Modelica.Fluid pipe's momentum law is that of a transport between two ports (the MSL's
#: valves and orifices extend it: dp = port_a.p - port_b.p, m_flow = port_a.m_flow, the
#: medium carried through unchanged), which leaves m_flow = f(dp) to the class, and the
#: enthalpy carried through without loss (as the MSL's valves write it)
TRANSPORTS = {"Modelica.Fluid.": "Modelica.Fluid.Interfaces.PartialTwoPortTransport"}
TRANSPORT_EQUATIONS = {"Modelica.Fluid.Interfaces.PartialTwoPortTransport": [
    "port_a.h_outflow = inStream(port_b.h_outflow);", "port_b.h_outflow = inStream(port_a.h_outflow);"]}


def interface_of(comp, lib) -> str | None:
    """The partial class the nominal class extends that declares both its connectors and the
    domain's law variables (MSL's OnePort, PartialCompliant, Element1D; MCL's TwoPin), else
    its library's transport class where that declares them (:data:`TRANSPORTS`), or None."""
    from .words import words

    info = lib.find(comp.cls) if comp.cls else None
    if info is None:
        return None
    wd = words(comp)
    need = {c.name for c in comp.connectors} | {wd.across.split(".", 1)[1], wd.flow.split(".", 1)[1]}
    own = _interface_in_bases(info, lib, need)
    if own is not None:
        return own
    transport = next((t for prefix, t in TRANSPORTS.items() if comp.cls.startswith(prefix)), None)
    return transport if transport is not None and need <= _declared(transport, lib) else None


def _interface_in_bases(info, lib, need: set) -> str | None:
    """The first class ``info`` extends (breadth first) that declares every name of ``need``."""
    todo, seen = list(info.extends), set()
    scope = info.name.rsplit(".", 1)[0]
    while todo:
        name = todo.pop(0)
        base = lib.resolve(name, scope) or lib.resolve(name, info.name)
        if base is None or base.name in seen:
            continue
        seen.add(base.name)
        members = {m for *_rest, m, _c in lib.members(base)}
        if need <= members:
            return base.name
        todo += base.extends
        scope = base.name.rsplit(".", 1)[0]
    return None


def _declared(qualified: str, lib) -> set[str]:
    """The names class ``qualified`` declares, itself and through what it extends."""
    info = lib.find(qualified)
    return {m for *_rest, m, _c in lib.members(info)} if info is not None else set()


def _class_text(qualified: str, lib) -> str | None:
    """The raw text of class ``qualified`` (annotations included), from its file."""
    located = lib.file_of(qualified)
    if located is None:
        return None
    try:
        text = located[0].read_text(errors="replace")
    except OSError:
        return None
    short = qualified.split(".")[-1]
    m = re.search(rf"(?m)^[ \t]*(?:(?:partial|encapsulated|final|replaceable|redeclare)\s+)*(model|block|class)\s+"
                  rf"{re.escape(short)}\b", text)
    end = m and re.search(rf"\bend\s+{re.escape(short)}\s*;", text[m.end():])
    return text[m.start(): m.end() + end.end()] if m and end else None


def _balanced(text: str, start: int) -> str:
    """``text[start:]`` up to the parenthesis that closes the one at ``start``."""
    depth = 0
    for k in range(start, len(text)):
        depth += {"(": 1, ")": -1}.get(text[k], 0)
        if depth == 0:
            return text[start:k + 1]
    return text[start:]


def icon_of(qualified: str, lib) -> str | None:
    """The ``Icon(...)`` of a class's annotation (what OMEdit and Dymola draw), or None."""
    text = _class_text(qualified, lib)
    if not text:
        return None
    m = re.search(r"\bIcon\s*\(", text)
    if not m:
        return None
    icon = "Icon" + _balanced(text, text.index("(", m.start()))
    # the nominal class's parameters are not the learned class's: no visibility by them, and a
    # label that showed one (R=%R) names the law instead
    icon = re.sub(r"\bvisible\s*=\s*[A-Za-z_]\w*\s*,", "", icon)
    return re.sub(r'textString\s*=\s*"[^"]*%(?!name\b)\w+[^"]*"', 'textString="learned"', icon)


def _unit_power(unit: str, power: int) -> str | None:
    """``unit`` raised to ``power`` in Modelica's unit syntax, for a plain unit (V, m, K, rad)."""
    if not unit or not re.fullmatch(r"[A-Za-z]+", unit):
        return None
    return unit if power == 1 else f"{unit}{power}"


def coefficient_unit(term, units: dict) -> str | None:
    """The unit of a coefficient of ``term`` in a law y = sum c_k term_k (``units``: y, v, i,
    va, vb's units; dv's is v's per second): y's unit over the term's; None where a unit is not
    plain or the term not a monomial (tanh(dv/s) has no unit: its coefficient takes y's)."""
    y = units.get("y")
    if not y or not re.fullmatch(r"[A-Za-z]+", y):
        return None
    powers = getattr(term, "powers", None)
    if str(term) == "z":        # a hysteresis' z is in v's units (:mod:`mcl.hysteresis`)
        powers = (("v", 1),)
    if powers is None or not isinstance(powers, tuple):
        return y if not getattr(term, "variables", None) or term.degree == 0 else None
    num, den = [y], []
    for var, p in powers:
        base = units.get("v" if var == "dv" else "i" if var == "di" else var)
        part = _unit_power(base, p)
        if part is None:
            return None
        den.append(part)
        if var in ("dv", "di"):
            num.append("s" if p == 1 else f"s{p}")
    if not den:
        return y
    return f"{'.'.join(num)}/{'.'.join(den) if len(den) == 1 else '(' + '.'.join(den) + ')'}"


def learned_class(cause: dict, comp, libraries=(), sources=(), units: dict | None = None, data: str = "",
                  scope: str = "") -> str:
    """The learned law as a Modelica class that looks native: it extends the nominal class's
    interface when one is found (else it declares the component's own connectors), its
    coefficients are parameters with units and descriptions, zero terms are left out, its icon
    is the nominal class's and its documentation says what was learned, on what, how surely.
    ``scope``: the model's class, where the component's classes are named from."""
    from ..services import registry

    template = registry().template(cause["template"])
    if (comp.equation or comp.term) and template.explicit == "i" and hasattr(template, "terms"):
        lib = _library(libraries, sources)
        return _equation_block(cause, comp, template, units or {}, data, lib.find(SISO) is not None)
    lib = _library(libraries, sources)
    if comp.sensor and template.explicit == "i" and hasattr(template, "terms"):
        return _sensor_class(cause, comp, template, lib, libraries, sources, scope, units or {}, data)
    if comp.ports:
        if template.explicit != "i" or not hasattr(template, "terms") or hasattr(template, "hidden_modelica"):
            raise ValueError(f"{comp.name} has {', '.join(p.name for p in comp.ports)} beside "
                             f"{' and '.join(c.name for c in comp.connectors)}: a law of this form is not written "
                             "into its class (the law is in the report)")
        return _wrapper_class(cause, comp, template, lib, libraries, sources, scope, units or {}, data)
    interface = interface_of(comp, lib) if template.explicit == "i" and hasattr(template, "terms") else None
    if interface is None:
        return _template_class(cause, comp, template, libraries, sources, scope)
    from .words import parity, words

    wd = words(comp)
    local = lambda q: q.split(".", 1)[-1] if not q.startswith("der(") else f"der({q[4:-1].split('.', 1)[-1]})"
    names = {"v": local(wd.across), "dv": local(wd.rate), "i": local(wd.flow),
             "va": local(wd.potentials[0]), "vb": local(wd.potentials[1])}
    if names["dv"] not in _declared(interface, lib):      # MCL's TwoFlange has s_rel, no v_rel
        names["dv"] = f"der({names['v']})"
    w = np.asarray(cause["w"], float)
    if wd.flipped:        # the interface's orientation (b - a): odd terms change sign
        signs = np.array([parity(t, getattr(template, "scales", None)) for t in template.terms])
        if (signs == 0).any():
            return _template_class(cause, comp, template, libraries, sources, scope)
        w = w.copy()
        w[:len(signs)] *= signs * signs[0]
    u = {"y": (units or {}).get(wd.flow), "v": (units or {}).get(wd.across), "i": (units or {}).get(wd.flow)}
    u["va"] = u["vb"] = (units or {}).get(wd.potentials[0]) or u["v"]
    params, rhs = _terms(template, w, names, u)
    law = f"{names['i']} = {' + '.join(rhs) or '0'};"
    if hasattr(template, "hidden_modelica"):      # the law's own state (a hysteresis' z) and its equation
        decls, eqs = template.hidden_modelica(w, names["dv"])
        params, law = params + decls, "\n  ".join([law, *eqs])
    icon = icon_of(comp.cls, lib)
    doc = _documentation(cause, data)
    annotation = f"  annotation({icon + ', ' if icon else ''}Documentation(info=\"{doc}\"));"
    return (f'{"block" if comp.signal else "model"} {cause["learned_class"]} "{comp.cls.split(".")[-1]} {comp.name} as learned by mcl: '
            f'{html.escape(cause["law"]["equation"])}"\n  extends {interface};\n' + "\n".join(params)
            + f"\nequation\n  {law}\n" + "".join(f"  {e}\n" for e in TRANSPORT_EQUATIONS.get(interface, []))
            + f"{annotation}\nend {cause['learned_class']};\n")


#: the nominal component inside the learned class of a component with a heat port
WRAPPED = "nominal"


def _wrapper_class(cause: dict, comp, template, lib, libraries, sources, scope: str, units: dict, data: str) -> str:
    """The learned class of a component with a heat port beside its pair (a resistor, a pipe
    with ``useHeatPort = true``): the nominal component inside (:data:`WRAPPED`, which the
    model's modifiers go to), its own equations and heat port kept, and beside it a flow of the
    learned law less the nominal one (what the discovery simulated: the extra flow carries what
    the connectors' further pairs carry, as :func:`mcl.discovery.inject._carried` has it)."""
    classes = connector_classes(comp, libraries, sources, scope)
    ports = [c.name for c in [*comp.connectors, *comp.ports]]
    if any(n not in classes for n in ports):
        raise ValueError(f"the connector classes of {comp.name} ({comp.cls or 'class unknown'}) are not found")
    nominal = lib.resolve(comp.cls, scope) if scope else None
    nominal = nominal.name if nominal is not None else comp.cls
    a, b = comp.connectors
    va, vb = f"{WRAPPED}.{a.name}.{a.potential[0]}", f"{WRAPPED}.{b.name}.{b.potential[0]}"
    names = {"v": f"({va} - {vb})", "dv": f"der({va} - {vb})", "va": va, "vb": vb}
    (xa, xb), (fa, _) = comp.across(), comp.flow()
    u = {"y": units.get(fa), "v": units.get(xa), "i": units.get(fa), "va": units.get(xa), "vb": units.get(xb)}
    params, rhs = _terms(template, np.asarray(cause["w"], float), names, u)
    name, short = cause["learned_class"], comp.cls.split(".")[-1]
    decls = [f"  {classes[n]} {n};" for n in ports]
    decls += [f'  {nominal} {WRAPPED} "the nominal {short}: its own equations, its heat included";',
              f'  {name}_deviation deviation "the learned law\'s flow less the nominal one\'s, beside it";']
    equations = [f"  connect({n}, {WRAPPED}.{n});" for n in ports]
    equations += [f"  connect({c.name}, deviation.{c.name});" for c in comp.connectors]
    equations.append(f"  deviation.f = {' + '.join(rhs) or '0'} - {WRAPPED}.{a.name}.{a.flow[0]};")
    icon = icon_of(comp.cls, lib)
    return (f'model {name} "{short} {comp.name} as learned by mcl: {html.escape(cause["law"]["equation"])}"\n'
            + "\n".join(decls + params) + "\nequation\n" + "\n".join(equations)
            + f"\n  annotation({icon + ', ' if icon else ''}Documentation(info=\"{_documentation(cause, data)}\"));"
            f"\nend {name};\n" + _flow_between(f"{name}_deviation", comp, classes))


def _flow_between(name: str, comp, classes: dict) -> str:
    """A class that sets the flow ``f`` from its connector a to b (the pair of ``comp``), with
    the further pairs the connectors carry taken along from the side the flow comes from."""
    a, b = comp.connectors
    eqs = [f"  0 = {a.name}.{a.flow[0]} + {b.name}.{b.flow[0]};", f"  {a.name}.{a.flow[0]} = f;"]
    for x, g in zip(a.potential[1:], a.flow[1:]):
        eqs += [f"  0 = {a.name}.{g} + {b.name}.{g};",
                f"  {a.name}.{g} = semiLinear(f, {a.name}.{x}, {b.name}.{x});"]
    return (f'model {name} "a flow set from outside, between the connectors of {comp.cls.split(".")[-1]}"\n'
            f"  {classes[a.name]} {a.name};\n  {classes[b.name]} {b.name};\n"
            f'  input Real f "the flow into {a.name}";\nequation\n' + "\n".join(eqs) + f"\nend {name};\n")


def _terms(template, w, names: dict, u: dict) -> tuple[list[str], list[str]]:
    """(parameter declarations, terms c_k*x_k) of a law in the class's own variable ``names``
    (for v, dv, i, va, vb), its coefficients ``w`` (then its scales), units by ``u``."""
    from ..templates import Monomial, scaled_power

    scales = dict(zip(template.scales, w[len(template.terms):])) if getattr(template, "scales", None) else {}
    params, rhs = [], []
    for k, (term, c) in enumerate(zip(template.terms[1:], w[1:len(template.terms)]), start=1):
        if c == 0:
            continue
        folded = scaled_power(term)
        if folded is not None:     # (x/s)^p, fitted in units of s: c/s^p on x^p
            x, s_, p = folded
            term, c = Monomial(((x, p),)), c / s_**p
        text = term.modelica()
        for s_name, s_val in scales.items():      # a scale is a parameter too: a calibration sets it
            if re.search(rf"\b{s_name}\b", text) and not any(p.startswith(f"  parameter Real {s_name} ") for p in params):
                params.append(f'  parameter Real {s_name} = {float(s_val)!r} "a scale inside the law";')
        text = re.sub(r"\b(va|vb|dv|di|v|i)\b", lambda m: names.get(m.group(1), m.group(1)), text)
        pname = f"c{len(rhs) + 1}"
        unit = coefficient_unit(term, u)
        unit_mod = f'(unit="{unit}")' if unit else ""
        params.append(f'  parameter Real {pname}{unit_mod} = {float(c)!r} "coefficient of {html.escape(text)}";')
        rhs.append(f"{pname}*{text}" if text != "1" else pname)
    return params, rhs


SISO = "Modelica.Blocks.Interfaces.SISO"


def _equation_block(cause: dict, comp, template, units: dict, data: str, siso: bool = True) -> str:
    """The law learned for the user's own equation y = g(x) as a block: y = f(u), u the x the
    equation read (or xa - xb); the model's equation is rewritten to read it (:func:`rewritten`).
    The block extends the MSL's SISO where the MSL is found (its icon and connectors), else
    declares its input and output (a model of plain equations needs no library)."""
    w = np.asarray(cause["w"], float)
    xa, xb = comp.across()
    u = {"y": units.get(comp.flow()[0]), "v": units.get(xa), "i": units.get(comp.flow()[0])}
    if comp.term:
        u["y"] = u["i"] = None
    params, rhs = _terms(template, w, {"v": "u", "i": "y"}, {**u, "va": u["v"], "vb": u["v"]})
    doc = _documentation(cause, data)
    reads = f"{xa} - {xb}" if xb else xa
    return (f'block {cause["learned_class"]} "{comp.flow()[0]} = f({reads}) as learned by mcl: '
            f'{html.escape(cause["law"]["equation"])}"\n'
            + (f'  extends {SISO};\n' if siso else
               '  input Real u "what the equation reads";\n  output Real y "what it gives";\n')
            + "\n".join(params)
            + f"\nequation\n  y = {' + '.join(rhs) or '0'};\n  annotation(Documentation(info=\"{doc}\"));\n"
            f"end {cause['learned_class']};\n")


def law_instance(comp) -> str:
    """The instance of the learned block that a rewritten equation of ``comp`` reads."""
    return re.sub(r"\W", "_", f"{comp.name}_law")       # (q[2]: q_2__law)


def _class_span(text: str, model_short: str):
    """(the match of class ``model_short``'s head in ``text``, or None; where its body ends)."""
    head = re.search(rf"(?m)(?:^|[\s;])(?:(?:partial|encapsulated|final)\s+)*(?:model|block|class)\s+{re.escape(model_short)}\b",
                     text)
    if not head:
        return None, len(text)
    end = re.search(rf"\bend\s+{re.escape(model_short)}\s*;", text[head.end():])
    return head, head.end() + (end.start() if end else len(text) - head.end())


def rewritten(text: str, model_short: str, comp, new_class: str, unknowns) -> str | None:
    """``text`` with ``comp``'s equation in class ``model_short`` (the one statement that names
    its variable and what it reads, and no other unknown of ``unknowns``) given by an instance of
    the learned block ``new_class``, declared before the equation section; None when that
    equation is not found there."""
    head, body_end = _class_span(text, model_short)
    if not head:
        return None
    quoted = _quoted(text)
    sections = [m for m in re.finditer(r"(?<![\w.])(initial\s+)?equation\b", text[:body_end])
                if m.start() > head.end() and not quoted(m.start())]
    xa, xb = comp.across()
    needs = {comp.name, xa, *([xb] if xb else [])} if comp.equation else {xa}
    others = set(unknowns) - needs
    # a term of a balance: its text, whatever the spacing (k*x, k * x)
    pattern = (r"(?<![\w.])" + r"\s*".join(re.escape(t) for t in re.findall(r"\w+(?:\.\w+)*|\S", comp.inputs[1]))
               + r"(?![\w.(\[])") if comp.term else None
    found = []          # a term's balances: (section, start, stop, the statement rewritten)
    for sec in (m for m in sections if not m.group(1)):
        start = sec.end()
        while start < body_end:
            stop = min(statement_end(text, start) or len(text), body_end)
            statement = re.sub(r'"(?:\\.|[^"\\])*"|//[^\n]*|/\*.*?\*/', " ", text[start:stop], flags=re.S)
            if re.match(r"\s*(?:initial\s+)?(?:equation|algorithm|protected|public)\b", statement):
                break
            words = set(re.sub(r"\s+(?=\[)|(?<=\[)\s+|\s+(?=\])", "", w) for w in re.findall(
                r"(?<![\w.])[A-Za-z_]\w*(?:\s*\[[^\]]*\])?(?:\.[A-Za-z_]\w*(?:\s*\[[^\]]*\])?)*", statement))
            inst = law_instance(comp)
            original = text[start:stop]
            if pattern and "der" in words and len(re.findall(pattern, statement)) == 1 == len(re.findall(pattern, original)):
                indent = re.match(r"\s*", original).group(0).split("\n")[-1] or "  "
                new = re.sub(pattern, f"{inst}.y", original) + (f"\n{indent}{inst}.u = {xa};" if not found else "")
                found.append((sec, start, stop, new, indent))
            if comp.equation and needs <= words and not words & others and "der" not in words and "=" in statement:
                reads = f"{xa} - {xb}" if xb else xa
                indent = re.match(r"\s*", text[start:stop]).group(0).split("\n")[-1] or "  "
                new = f"\n{indent}{inst}.u = {reads};\n{indent}{comp.name} = {inst}.y;"
                return _declared_before(text, head, sec, quoted, indent,
                                        f'{new_class} {inst} "the law of {comp.name} learned by mcl"', start, new, stop)
            start = stop
    if not found or len(found) != len(comp.rows):     # (each balance the term is in, or none)
        return None
    for _sec, start, stop, new, _ in reversed(found[1:]):
        text = text[:start] + new + text[stop:]
    sec, start, stop, new, indent = found[0]
    return _declared_before(text, head, sec, quoted, indent,
                            f'{new_class} {inst} "the law of {comp.inputs[1]} learned by mcl"', start, new, stop)


def _declared_before(text, head, sec, quoted, indent, declaration, start, new, stop) -> str:
    """``text`` with the statement at ``start:stop`` replaced by ``new`` and ``declaration``
    added where the class's declarations end (before its first section)."""
    first = next(m.start() for m in re.finditer(r"(?<![\w.])(?:initial\s+)?(?:equation|algorithm)\b", text[:sec.end()])
                 if m.start() > head.end() and not quoted(m.start()))
    line = text.rfind("\n", 0, first) + 1
    return text[:line] + f"{indent}{declaration};\n" + text[line:start] + new + text[stop:]


def _sensor_class(cause: dict, comp, template, lib, libraries, sources, scope: str, units: dict, data: str) -> str:
    """A sensor's learned law as a class with the nominal sensor's connectors, in which the
    nominal sensor (``measured``) measures and the output is the law of its reading: the
    nominal class's own equations stay as written, whatever the sensor measures."""
    classes = connector_classes(comp, libraries, sources, scope)
    out = comp.inputs[0].split(".")[-1]
    ports = [c.name for c in comp.connectors]
    missing = [n for n in (*ports, out) if n not in classes]
    if missing:
        raise ValueError(f"the connector classes of {comp.name} ({comp.cls or 'class unknown'}) are not found")
    nominal = lib.resolve(comp.cls, scope) if scope else None
    nominal = nominal.name if nominal is not None else comp.cls
    unit = units.get(comp.inputs[0])
    params, rhs = _terms(template, np.asarray(cause["w"], float), {"v": f"measured.{out}", "i": out},
                         {"y": unit, "v": unit, "i": unit})
    icon = icon_of(comp.cls, lib)
    doc = _documentation(cause, data)
    decls = [f'  {classes[n]} {n} "as the nominal sensor\'s";' for n in ports]
    decls.append(f'  {classes[out]} {out} "the reading, by the learned law";')
    decls.append(f'  {nominal} measured "what the sensor measures (the nominal sensor)";')
    equations = [f"  connect({n}, measured.{n});" for n in ports] + [f"  {out} = {' + '.join(rhs) or '0'};"]
    return (f'model {cause["learned_class"]} "{comp.cls.split(".")[-1]} {comp.name} as learned by mcl: '
            f'{html.escape(cause["law"]["equation"])}"\n' + "\n".join(decls + params) + "\nequation\n"
            + "\n".join(equations) + f"\n  annotation({icon + ', ' if icon else ''}Documentation(info=\"{doc}\"));"
            f"\nend {cause['learned_class']};\n")


def _documentation(cause: dict, data: str) -> str:
    """The Documentation annotation's HTML: the law, where it holds, the data, the evidence, how sure."""
    law, ev = cause["law"], cause["evidence"]
    rows = [f"<p>Learned by mcl for <b>{html.escape(cause['component'])}</b> "
            f"({html.escape(cause.get('class') or '')}):</p>",
            f"<pre>{html.escape(law['equation'])}</pre><p>where {html.escape(law.get('where', ''))}.</p>",
            f"<p>{html.escape(law.get('note', ''))}.</p>"]
    if data:
        rows.append(f"<p>Data: {html.escape(data)}.</p>")
    rows.append(f"<p>Evidence: {html.escape(str(ev.get('strength')))} "
                f"(&Delta;{html.escape(str(ev.get('criterion', '')).upper())} {ev.get('delta_to_next', 0):.3g} "
                f"to the next explanation).</p>")
    params = law.get("parameters") or []
    names, terms = cause.get("parameters") or [], cause.get("terms") or []
    from ..templates import unscaled

    term_of = {n: unscaled(t) for n, t in zip(names, terms)}    # (va/550)^4 reads va^4

    def interval(p):
        term, k = term_of.get(p["name"].split(".")[-1], (p["name"], 1.0))
        return f"{html.escape(term)}: {k * p['value']:.4g} [{k * p['ci95'][0]:.4g}, {k * p['ci95'][1]:.4g}]"

    if params:
        rows.append("<p>95% intervals of the coefficients: " + "; ".join(interval(p) for p in params) + ".</p>")
    return "".join(rows).replace('"', "'")


def _template_class(cause: dict, comp, template, libraries, sources, scope: str = "") -> str:
    """The law as a class declaring the component's own connectors, in v (a - b), i (into a) and
    the connectors' potentials va, vb where it reads them."""
    classes = connector_classes(comp, libraries, sources, scope)
    conns = [dataclasses.replace(c, cls=classes.get(c.name, c.cls)) for c in comp.connectors]
    unresolved = [c.name for c in conns if c.cls.startswith("connector(")]
    if unresolved:
        raise ValueError(f"the connector classes of {comp.name} ({comp.cls or 'class unknown'}) are not found")
    note = "; " + cause["law"]["note"]
    return template.modelica_class(cause["learned_class"], dataclasses.replace(comp, connectors=conns),
                                   np.asarray(cause["w"]), note, learned=True)


def _quoted(text: str):
    """Whether a position of ``text`` is inside a string or a comment."""
    spans = [m.span() for m in re.finditer(r'"(?:\\.|[^"\\])*"|//[^\n]*|/\*.*?\*/', text, re.S)]
    starts = [a for a, _ in spans]

    def inside(k: int) -> bool:
        j = bisect.bisect_right(starts, k) - 1
        return j >= 0 and k < spans[j][1]
    return inside


#: a declaration's start: its line, indent, prefixes, type and the space before its names
_DECLARATION = r"(?m)(^|;|\n)([ \t]*)((?:(?:inner|outer|final|replaceable|redeclare)\s+)*)([A-Za-z_][\w.]*)(\s+)"
_NOT_DECLARED = ("connect", "end", "equation", "import", "extends", "parameter", "constant")


def retyped(text: str, model_short: str, inst: str, new_class: str) -> str | None:
    """``text`` with instance ``inst`` of class ``model_short`` declared of ``new_class``, its
    modification and comment kept; one of several declared together (``Tank t1, t2;``) gets a
    declaration of its own. None when its declaration is not in the class."""
    head, body_end = _class_span(text, model_short)
    if not head:
        return None
    quoted = _quoted(text)
    for m in re.compile(_DECLARATION).finditer(text, head.end(), body_end):
        if m.group(4) in _NOT_DECLARED or quoted(m.start(4)):
            continue
        stop = statement_end(text, m.end()) or len(text)
        items = top_level_parts(text[m.end():stop - 1])
        k = next((j for j, a in enumerate(items) if re.match(rf"\s*{re.escape(inst)}\b(?!\.)", a)), None)
        if k is None:
            continue
        if len(items) == 1:
            return text[:m.start(4)] + new_class + text[m.end(4):]
        rest = ", ".join(a.strip() for j, a in enumerate(items) if j != k)
        return (text[:m.end()] + rest + f";\n{m.group(2)}{m.group(3)}{new_class} {items[k].strip()};" + text[stop:])
    return None


def with_instance_class(text: str, cls_short: str, copy_short: str) -> str | None:
    """``text`` with a copy of class ``cls_short`` named ``copy_short`` right after it (in the
    same scope, so that its names resolve as the original's): one instance's class, for a law
    learned in that instance's own equation. None when the class is not in ``text``."""
    head, body_end = _class_span(text, cls_short)
    if not head:
        return None
    end = re.compile(rf"end\s+{re.escape(cls_short)}\s*;").match(text, body_end)
    if end is None:
        return None
    start = text.rfind("\n", 0, head.end()) + 1
    body = text[start:end.start()]
    body = re.sub(rf"\b(model|block|class)(\s+){re.escape(cls_short)}\b", rf"\g<1>\g<2>{copy_short}", body, count=1)
    return text[:end.end()] + "\n" + body + f"end {copy_short};" + text[end.end():]


def local_component(comp, inst: str):
    """``comp`` (an equation or a term inside instance ``inst``) in the names of ``inst``'s class."""
    strip = (lambda s: re.sub(rf"(?<![\w.]){re.escape(inst)}\.", "", s))
    return dataclasses.replace(comp, name=strip(comp.name), cls=strip(comp.cls),
                               connectors=[dataclasses.replace(c, name=strip(c.name)) for c in comp.connectors],
                               parameters=[strip(n) for n in comp.parameters], inputs=[strip(n) for n in comp.inputs])


def redeclared(text: str, model_short: str, component: str, new_class: str, keep=("v", "i")) -> str | None:
    """``text`` with the declaration of ``component`` inside class ``model_short`` changed to
    ``new_class``: of its modification only what modifies the learned class's own variables
    ``keep`` stays (a start value, fixed = true; the nominal class's parameters go), or where
    ``keep`` is a name, all of it goes to that component inside the learned class; its
    comment and annotation stay. None when that declaration is not in the class."""
    head, body_end = _class_span(text, model_short)
    if not head:
        return None
    decl = re.compile(rf"{_DECLARATION}{re.escape(component)}\b")
    quoted = _quoted(text)
    for m in decl.finditer(text, head.end(), body_end):
        if m.group(4) in _NOT_DECLARED:
            continue
        if quoted(m.start(4)):      # (a class's description: "... a counter reads ...")
            continue
        stop = statement_end(text, m.end()) or len(text)
        rest = text[m.end():stop]
        if rest.lstrip().startswith("("):          # the modification, nested parentheses and all
            k0, depth = rest.index("("), 0
            for k in range(k0, len(rest)):
                depth += {"(": 1, ")": -1}.get(rest[k], 0)
                if depth == 0:
                    break
            if isinstance(keep, str):      # all of it, to the component inside (:func:`_wrapper_class`)
                rest = f"({keep}{rest[k0:k + 1]})" + rest[k + 1:]
            else:
                kept = [a for a in top_level_parts(rest[k0 + 1:k])
                        if re.match(rf"\s*(?:each\s+|final\s+|redeclare\s+|package\s+)*({'|'.join(keep)})\b", a)]
                rest = (f"({', '.join(a.strip() for a in kept)})" if kept else "") + rest[k + 1:]
        return text[:m.start(4)] + new_class + m.group(5) + component + rest + text[stop:]
    return None


def _kept(text: str, spec) -> tuple[str, ...]:
    """What of a declaration's modification the learned class ``text`` takes: its own law's
    variables, and where it extends an interface, what that declares and the medium (a
    Modelica.Fluid pipe's ``redeclare package Medium``, ``m_flow_start``)."""
    m = re.search(r"^\s*extends\s+([\w.]+)\s*;", text, re.M)
    if m is None:
        return ("v", "i")
    return ("v", "i", "Medium", *sorted(_declared(m.group(1), _library(spec.libraries, spec.sources))))


def write_extended(causes: list[dict], base, spec, directory: Path, data: str = "",
                   calibrated: dict | None = None) -> tuple[list[Path], str, Path, list[str]]:
    """The extended model as Modelica in ``directory``: the package ``Learned`` with the learned
    classes, and a copy of the user's sources (or of the model's class) in which each learned
    component is declared with its learned class; with a calibration (``calibrated``: the laws'
    calibrated ``w`` per cause, the nominal ``values`` and all ``params``), also the class
    :func:`calibrated_class` (named :func:`calibrated_name`). Returns (sources, the extended
    model's name, the Learned package file, notes on what could not be written)."""
    from ..compile.library import uses_annotation

    directory.mkdir(parents=True, exist_ok=True)
    notes, classes, swaps, law_values = [], [], [], {}
    for k, cause in enumerate(causes):
        comp = base.structure.components[cause["component"]]
        own = comp.equation or comp.term      # (a user's equation may be its instance's: t1.qout = t1.h/t1.R)
        if "." in comp.name and not own:
            notes.append(f"{comp.name} is inside a component: its learned class is in the package, "
                         "the model is not rewritten for it")
        write = lambda c: learned_class(c, comp, spec.libraries, spec.sources, base.model.info.get("units", {}),
                                        data, scope=spec.model_name)
        try:
            classes.append(write(cause))
            if calibrated and ("." not in comp.name or own):     # the class's own parameters at their calibrated values
                before, after = _parameter_values(classes[-1]), _parameter_values(write({**cause, "w": calibrated["w"][k]}))
                law_values[comp.name] = {n: v for n, v in after.items() if before.get(n) != v}
        except ValueError as exc:
            notes.append(str(exc))
            continue
        if "." not in comp.name or own:
            swaps.append((comp, f"{LEARNED_PACKAGE}.{cause['learned_class']}",
                          WRAPPED if comp.ports else _kept(classes[-1], spec)))
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
    swapped = {}        # component -> the instance path its learned class is declared with
    copies = {}         # instance -> the copy of its class its own laws are written in
    dae = base.model.dae
    unknowns = [*dae.x_names, *dae.z_names, *dae.u_names] if dae is not None else []
    for comp, cls, keep in swaps:
        name = comp.name
        change = ((lambda text, owner: rewritten(text, owner, comp, cls, unknowns)) if comp.equation or comp.term
                  else (lambda text, owner: redeclared(text, owner, name, cls, keep)))
        done = False
        for owner in _class_and_bases(short, [f.read_text(errors="replace") for f in files] + [extra]):
            for f in files:
                new = change(f.read_text(errors="replace"), owner)
                if new is not None:
                    f.write_text(new)
                    done = True
                    break
            if extra and not done:
                new = change(extra, owner)
                if new is not None:
                    extra, done = new, True
            if done:
                break
        path = (law_instance(comp) if comp.equation or comp.term else name) if done else None
        if not done and (comp.equation or comp.term) and files:     # the equation of an instance's class
            path = _rewritten_in_instance(comp, cls, files, spec.model_name, unknowns, copies)
            done = path is not None
        if done:
            swapped[name] = path
        else:
            what = "equation" if comp.equation or comp.term else "declaration"
            notes.append(f"the {what} of {name} is not in {spec.model_name}'s own text: the model is not rewritten for it")
    if calibrated:
        # (a learned class's values only where the model declares the component with it)
        law_values = {f"{swapped[c]}.{n}": v for c, values in law_values.items() if c in swapped
                      for n, v in values.items()}
        text, more = calibrated_class(short, model_name, {**calibrated["values"], **law_values}, calibrated["params"],
                                      calibrated["free"])
        classes.append(text)
        notes += more + [f"{n} is not written into {short}Calibrated: its class keeps it from modifiers (protected or final)"
                         for n in calibrated.get("unwritable", ())]
    body = "\n".join(classes) + (f"\n{extra}" if extra else "")
    indented = "\n".join(("  " + line) if line.strip() else "" for line in body.splitlines())
    uses = uses_annotation(body, spec.libraries)
    package = directory / f"{LEARNED_PACKAGE}.mo"
    package.write_text(f'package {LEARNED_PACKAGE} "Components learned by mcl"\n{indented}\n'
                       + (f"  {uses};\n" if uses else "") + f"end {LEARNED_PACKAGE};\n")
    return [*sources, package], model_name, package, notes


def _rewritten_in_instance(comp, cls: str, files: list[Path], model: str, unknowns, made: dict) -> str | None:
    """``comp``'s equation or term written in its instance's class (``t1.qout = t1.h/t1.R`` is
    ``qout = h/R`` in class Tank) rewritten in a copy of that class for that instance alone
    (``Tank_t1``, beside Tank), which the model then declares the instance of. Returns the
    learned block's instance path (``t1.qout_law``), None where not done. ``made``: the copies
    made so far, by instance (a second law of the same instance goes into the same copy)."""
    from ..compile.components import declared_classes, split_name

    path = split_name(comp.inputs[0])
    if len(path) != 2 or "[" in path[0]:
        return None
    inst = path[0]
    texts = {str(f): f.read_text(errors="replace") for f in files}
    local = local_component(comp, inst)
    mine = [n[len(inst) + 1:] for n in unknowns if n.startswith(inst + ".")]
    if inst in made:
        for f in files:
            new = rewritten(texts[str(f)], made[inst], local, cls, mine)
            if new is not None:
                f.write_text(new)
                return f"{inst}.{law_instance(local)}"
        return None
    owner = declared_classes([inst], model, texts).get(inst)
    if owner is None:
        return None
    short = owner.split(".")[-1]
    copy = re.sub(r"\W", "_", f"{short}_{inst}")
    for f in files:
        text = with_instance_class(texts[str(f)], short, copy)
        new = rewritten(text, copy, local, cls, mine) if text is not None else None
        if new is None:
            continue
        now = {**texts, str(f): new}
        owners = _class_and_bases(model.split(".")[-1], list(now.values()))
        for g in files:         # the model (or a class it extends) declares the instance
            for where in owners:
                changed = retyped(now[str(g)], where, inst, copy)
                if changed is not None:
                    f.write_text(new)
                    g.write_text(changed)       # (the same file: new, retyped)
                    made[inst] = copy
                    return f"{inst}.{law_instance(local)}"
        return None
    return None


def _parameter_values(text: str) -> dict[str, float]:
    """The Real parameters a class ``text`` declares with a number, by name."""
    return {m.group(1): float(m.group(2)) for m in
            re.finditer(r'parameter Real (\w+)(?:\(unit="[^"]*"\))? = ([-+\d.eE]+)[ ;]', text)}


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


def internal_parameters(model: str, names, libraries=(), sources=()) -> list[str]:
    """Of the parameters ``names`` (a.b.c, x[2]) of class ``model``, those no modifier can set:
    an element on the path is protected or final in its class (a TransferFunction's bb, a
    Filter's coefficients). They are the classes' own workings: ``free: auto`` leaves them, and
    a calibrated model could not be written with them. A path not found is taken as settable."""
    lib = _library(libraries, sources)
    top = lib.find(model)
    members = {}

    def member(info, part):
        if info.name not in members:
            members[info.name] = {m[3]: m for m in lib.members(info)}
        return members[info.name].get(part)

    out = []
    for name in names:
        info, hidden = top, False
        for part in re.sub(r"\[[^\]]*\]", "", name).split("."):
            m = member(info, part) if info is not None else None
            if m is None:
                break
            if {"protected", "final"} & m[0]:
                hidden = True
                break
            info = m[1]
        if hidden:
            out.append(name)
    return out


def _modification(values: dict, params: dict) -> tuple[str, list[str]]:
    """The modification (``f1 = 5050.3, G1(A_ripple = 0.559), G2(a = {1, 2e4, ...})``) that sets
    ``values`` (dotted names, array elements as x[2]: the whole array is written, its other
    elements at their ``params`` value); returns it and the names it cannot write (an element
    of an array of more than one dimension, or one whose elements are not all known)."""
    tree, skipped, arrays = {}, [], set()
    for name, value in values.items():
        if not np.isfinite(value):
            skipped.append(name)
            continue
        m = re.fullmatch(r"(.+)\[(\d+)\]", name)
        if m is None:
            path, leaf = name.split("."), repr(float(value))
        else:
            base = m.group(1)
            if base in arrays:
                continue
            elements = sorted((int(k.group(1)), n) for n in params if (k := re.fullmatch(re.escape(base) + r"\[(\d+)\]", n)))
            if [k for k, _ in elements] != list(range(1, len(elements) + 1)):
                skipped.append(name)
                continue
            arrays.add(base)
            path, whole = base.split("."), [float(values.get(n, params[n])) for _, n in elements]
            if not np.all(np.isfinite(whole)):
                skipped.append(name)
                continue
            leaf = "{" + ", ".join(map(repr, whole)) + "}"
        if "[" in ".".join(path):
            skipped.append(name)
            continue
        node = tree
        for part in path[:-1]:
            node = node.setdefault(part, {})
        node[path[-1]] = leaf

    def text(node) -> str:
        return ", ".join(f"{k} = {v}" if isinstance(v, str) else f"{k}({text(v)})" for k, v in node.items())

    return text(tree), skipped


def calibrated_name(model: str) -> str:
    """The name of the calibrated model :func:`write_extended` writes for model ``model``."""
    return f"{LEARNED_PACKAGE}.{model.split('.')[-1]}Calibrated"


def calibrated_class(short: str, extended: str, values: dict, params: dict, free) -> tuple[str, list[str]]:
    """The model delivered with ``free:``: class ``{short}Calibrated`` extends the extended
    model ``extended`` with the calibrated ``values`` (the nominal parameters and the learned
    classes' own parameters, by their dotted names) as its modification. Returns the class and
    notes on the values it cannot write."""
    mod, skipped = _modification(values, params)
    how = free if isinstance(free, str) else ", ".join(free)
    notes = [f"{n} is not written into {short}Calibrated (not a finite number, or an element of an array it cannot "
             "write whole)" for n in skipped]
    return (f'model {short}Calibrated "{extended} with the learned laws and the parameters calibrated with them '
            f'(free: {how})"\n  extends {extended}' + (f"({mod})" if mod else "") + f";\nend {short}Calibrated;\n"), notes
