"""For-equations on arrays written element by element, where rumoca cannot lower them.

rumoca 0.10.2 refuses a for-equation whose body is an array equation when the array has one
element ("canonical DAE construction rejected an invalid operation: expected a scalar
expression"): ``for i in 1:nPorts loop ports[i].Xi_outflow = medium.Xi; end for;`` with a
medium of one independent mass fraction (moist air), or ``mC_flows[i, :] = ...`` with one trace
substance (CO2 in a room). Of two or more elements, and of none, it reads them.

:func:`scalarised` writes each such equation as a loop over its elements,
``for mcl_j in 1:size(ports[i].Xi_outflow, 1) loop ports[i].Xi_outflow[mcl_j] = (medium.Xi)[mcl_j];
end for;``: the same equations, of any number of elements. An equation is taken for an array
equation where one side is a reference to a whole array member (a declared array, not
subscripted) or has one ``:`` subscript, or is der() of one; other equations are left as written.
"""
from __future__ import annotations

import re

from .classes import LibraryClasses
from .complexops import C, Node, _Parser, _statements, _Typer, _Unread, _headers, applied, tokens, trimmed

#: a file that may hold a for-equation (cheap test before the parse)
_LOOPS = re.compile(r"\bfor\b[^;]*\bloop\b")
_INDEX = "mcl_j"


def scalarised(text: str, lc: LibraryClasses) -> str:
    """``text`` (a file of Modelica classes) with its for-equations on arrays written element by element."""
    if not _LOOPS.search(text):
        return text
    edits, depth, typers = [], {}, {}
    for path, section, st in _statements(tokens(text)):
        key = ".".join(path)
        if section != "equation":
            continue
        own = trimmed(st, section)
        try:
            k, _locals, _ifs, loops = _headers(own, section)
        except IndexError:
            continue
        inside = depth.get(key, 0) + max(loops, 0) > 0
        depth[key] = depth.get(key, 0) + loops
        if not inside:
            continue
        if key not in typers:
            typers[key] = _Typer(lc, lc.find(key))
        if typers[key].info is None:
            continue
        edit = _element_loop(own, k, typers[key], text, st[-1].end)
        if edit is not None:
            edits.append(edit)
    return applied(text, edits)


def _element_loop(st, k: int, typer: _Typer, text: str, end: int):
    """(start, ``end``, new text) of one equation in a for-loop as a loop over its elements (its
    description dropped), or None."""
    rest = st[k:]
    if not rest or rest[0].text in ("connect", "annotation", "assert", "if", "when", "for", "end", "reinit"):
        return None
    try:
        p = _Parser(rest, typer)
        lhs = p.expression()
        if p.peek() != "=":
            return None
        p.take()
        rhs = p.expression()
    except (_Unread, IndexError, RecursionError):
        return None
    if p.i != len(rest) or C in (lhs.type, rhs.type):      # (Complex equations: complexops)
        return None
    sides = [_element(side, text) for side in (lhs, rhs)]
    whole = next((s for s in sides if s is not None), None)
    if whole is None:
        return None
    j = _INDEX
    while re.search(rf"\b{j}\b", text[lhs.start:rhs.end]):
        j += "_"
    left, right = ((s[1] if s is not None else f"({text[n.start:n.end]})[{{j}}]")
                   for s, n in zip(sides, (lhs, rhs)))
    new = f"for {j} in 1:{whole[0]} loop {left.format(j=j)} = {right.format(j=j)}; end for"
    return lhs.start, end, new


def _element(node: Node, text: str) -> tuple[str, str] | None:
    """(the number of elements, the element at ``{j}``) where ``node`` is a reference to a whole
    array, one whose last subscript has a single ``:``, or der() of one; else None."""
    if node.kind == "call" and node.op == "der" and len(node.kids) == 1:
        inner = _element(node.kids[0], text)
        return (inner[0], f"der({inner[1]})") if inner is not None else None
    if node.kind != "ref":
        return None
    written = text[node.start:node.end]
    if node.array_at is not None and node.array_at == node.end:
        return f"size({written}, 1)", written + "[{j}]"
    if "(" in written or "{" in written or not written.endswith("]"):
        return None
    # size() of the array's dimension, not of the slice: rumoca sizes x[i, :] as 1 where x has none
    base = written[:written.rindex("[")]
    if "]" in base[base.rfind(".") + 1:] or ":" in base:
        return None
    subscripts = [s.strip() for s in written[len(base) + 1:-1].split(",")]
    if subscripts.count(":") != 1 or any("[" in s for s in subscripts):
        return None
    at = subscripts.index(":")
    return (f"size({base}, {at + 1})",
            f"{base}[{', '.join('{j}' if n == at else s for n, s in enumerate(subscripts))}]")
