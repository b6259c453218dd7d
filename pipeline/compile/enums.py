"""``Integer()`` of an enumeration variable, written as the comparison rumoca translates.

rumoca 0.10 refuses ``Integer(mode)`` where ``mode`` is a variable of an enumeration type
("expected a numeric expression, found Enumeration"), though it reads ``mode == Mode.Heating``.
:func:`enumerated` writes ``(if mode == Mode.Off then 1 elseif ... else n)`` for each such call
of a variable declared, with its type, in the same text.
"""
from __future__ import annotations

import re

from .sources import masked

_TYPE = re.compile(r"\btype\s+(\w+)\s*=\s*enumeration\s*\(([^()]*)\)")
_CALL = re.compile(r"(?<![\w.])Integer\s*\(\s*([A-Za-z_][\w.]*)\s*\)")


def enumerated(text: str) -> str:
    """``text`` with ``Integer(v)`` of each variable ``v`` of an enumeration declared in it
    written as comparisons with its literals."""
    blank = masked(text)
    literals = {m[1]: [w.split()[0] for w in re.sub(r'"[^"]*"', "", m[2]).split(",") if w.strip()]
                for m in _TYPE.finditer(blank)}
    if not literals:
        return text
    kinds = "|".join(map(re.escape, literals))
    typed = {m[2]: m[1].split(".")[-1] for m in
             re.finditer(rf"(?<![\w.])((?:[A-Za-z_]\w*\.)*(?:{kinds}))\s+(\w+)\b(?!\s*=\s*enumeration)", blank)}
    out, pos = [], 0
    for m in _CALL.finditer(blank):
        kind = typed.get(m[1])
        if kind is None or not literals[kind]:
            continue
        names = literals[kind]
        chain = " ".join(f"{'if' if k == 0 else 'elseif'} {m[1]} == {kind}.{lit} then {k + 1}"
                         for k, lit in enumerate(names[:-1]))
        out += [text[pos:m.start()], f"({chain} else {len(names)})" if chain else "1"]
        pos = m.end()
    return "".join(out) + text[pos:]
