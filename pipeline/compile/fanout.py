"""A discrete signal fanned out to elements of vector inputs, written as equations for rumoca.

rumoca 0.10.2 cannot lower one Boolean or Integer output connected to elements of two or more
vector inputs (``connect(p.y, a.u[2]); connect(p.y, b.u[2])``, as the MSL's logic networks and
any engineer's do): its ToDae stage stops with "invalid Appendix B discrete solved form". The
same connection written as equations, ``a.u[2] = p.y; b.u[2] = p.y``, is the same model (a
connection of causal signals is their equality) and compiles.

:func:`rewritten_entry` makes that rewrite on a copy of the model's class, placed in the same
package under another name, so that every name in it resolves as in the original. Neither the
user's file nor the library is touched, and only sets of signal connectors whose types are
read from their declarations, with exactly one source, are rewritten.
"""
from __future__ import annotations

import re

from .classes import LibraryClasses, _strip
from .components import _declared_type, _qualified
from .sources import COMMENT_OR_STRING, CONNECT, class_body

_SIGNAL = re.compile(r"^(input|output)\s+(Boolean|Integer)\b")


def rewritten_entry(model: str, text: str, entry: str, lib: LibraryClasses) -> str | None:
    """The source of class ``entry`` in ``model``'s package: ``model``'s class (from ``text``,
    the file defining it) with its fanned-out discrete connections written as equations; None
    when it has none or its class is not found."""
    found = class_body(text, model.split(".")[-1])
    if found is None:
        return None
    head, body = found[0], text[found[1]:found[2]]
    stripped = _strip(body)
    edits = _edits(body, stripped, model, lib)
    if not edits:
        return None
    for start, stop, equation in sorted(edits, reverse=True):
        body = body[:start] + equation + "\n" * body.count("\n", start, stop) + body[stop:]
    package = model.rsplit(".", 1)[0] if "." in model else ""
    return f"within {package};\n{head.group(2)} {entry}{body}end {entry};\n"


def _edits(body: str, stripped: str, model: str, lib: LibraryClasses) -> list[tuple[int, int, str]]:
    """(start, stop, equation) replacing each connect statement of a fanned-out signal set."""
    statements = [(m.group(1).replace(" ", ""), m.group(2).replace(" ", ""), m.start(), _statement_end(body, m.end()))
                  for m in CONNECT.finditer(body) if "//" not in body[body.rfind("\n", 0, m.start()) + 1: m.start()]]
    parent: dict[str, str] = {}

    def root(x):
        while parent.setdefault(x, x) != x:
            x = parent[x]
        return x

    for a, b, *_ in statements:
        parent[root(a)] = root(b)
    sets: dict[str, list] = {}
    for st in statements:
        sets.setdefault(root(st[0]), []).append(st)
    edits = []
    for group in sets.values():
        members = sorted({x for a, b, *_ in group for x in (a, b)})
        if len(members) < 3 or len(group) != len(members) - 1 or not any(m.endswith("]") for m in members):
            continue
        roles = [_role(m, stripped, model, lib) for m in members]
        if None in roles or roles.count("source") != 1:
            continue
        source = members[roles.index("source")]
        sinks = [m for m in members if m != source]
        edits += [(start, stop, f"{sink} = {source};") for (*_, start, stop), sink in zip(group, sinks)]
    return edits


def _statement_end(body: str, at: int) -> int:
    """Index just past the ';' that ends the statement going on at ``at`` (an annotation's
    parentheses and strings skipped)."""
    depth, i = 0, at
    while i < len(body):
        ch = body[i]
        if ch == '"':
            string = COMMENT_OR_STRING.match(body, i)
            i = string.end() - 1 if string else len(body)
        elif ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
        elif ch == ";" and depth <= 0:
            return i + 1
        i += 1
    return len(body)


def _role(ref: str, body: str, model: str, lib: LibraryClasses) -> str | None:
    """"source" or "sink" for a Boolean or Integer signal connector ``ref`` of the class
    (``comp.port[i]``, or the class's own ``port[i]``, whose causality is reversed inside);
    None for anything else or what cannot be read."""
    parts = [re.sub(r"\[.*\]$", "", p) for p in ref.split(".")]
    if len(parts) == 1:
        own = lib.parse(model, "model", body).declarations
        decl = next(((prefixes, type_name) for prefixes, type_name, name, _c in own if name == parts[0]), None)
        kind = _signal(*decl, body, lib, model) if decl else None
        return {"input": "source", "output": "sink"}.get(kind)
    if len(parts) != 2:
        return None
    written = _declared_type(body, parts[0])
    info = lib.find(_qualified(written, body, model, lib)) if written else None
    if info is None:
        return None
    port = next((cls for _p, cls, _t, name, _c in lib.members(info) if name == parts[1]), None)
    kind = _signal_class(port)
    return {"output": "source", "input": "sink"}.get(kind)


def _signal(prefixes: set, type_name: str, body: str, lib: LibraryClasses, model: str) -> str | None:
    """"input" or "output" for the class's own connector declared ``input Boolean`` (or
    Integer), or with a signal connector class."""
    causal = prefixes & {"input", "output"}
    if causal and type_name in ("Boolean", "Integer"):
        return causal.pop()
    return _signal_class(lib.find(_qualified(type_name, body, model, lib)))


def _signal_class(info) -> str | None:
    """"input" or "output" for a connector class ``connector X = input Boolean`` (or Integer)."""
    m = _SIGNAL.match(info.short) if info is not None and info.short else None
    return m.group(1) if m else None
