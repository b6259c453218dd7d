"""``Integer()`` of an enumeration variable, written as the comparison rumoca translates.

rumoca 0.10 refuses ``Integer(mode)`` where ``mode`` is a variable of an enumeration type
("expected a numeric expression, found Enumeration"), though it reads ``mode == Mode.Heating``.
:func:`enumerated` writes ``(if mode == Mode.Off then 1 elseif ... else n)`` for each such call
of a variable declared, with its type, in the same text.

rumoca refuses an initial equation that sets such a variable (``mode = Mode.Off``) for the same
reason: it is written as an equation of numbers, ``1.0*Integer(mode) = 1.0*(1)``, the
literals as their positions, which the front end solves for the mode's start
(``rumoca_frontend._solved_for``).
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
    text = _initial_set(text, literals, typed)
    blank = masked(text)
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


#: an initial equation section, up to the next section or the class's end (not an if's or a for's)
_INITIAL = re.compile(r"\binitial\s+equation\b(.*?)(?=\b(?:initial\s+)?(?:equation|algorithm|public|protected)\b"
                      r"|\bend\s+(?!if\b|for\b|when\b|while\b)\w+\s*;|\Z)", re.S)


def _initial_set(text: str, literals: dict, typed: dict) -> str:
    """``text`` with each initial equation ``v = expr;`` that sets an enumeration variable ``v``
    written in numbers: ``1.0*Integer(v) = 1.0*(expr)``, a literal in ``expr`` as its position."""
    blank = masked(text)
    out, pos = [], 0
    for sec in _INITIAL.finditer(blank):
        for m in re.finditer(r"(?<![\w.])(\w+)\s*=(?!=)([^;]*);", sec[1]):
            kind = typed.get(m[1])
            if kind is None:
                continue
            start, end = sec.start(1) + m.start(), sec.start(1) + m.end()
            rhs = text[sec.start(1) + m.start(2):sec.start(1) + m.end(2)]
            for k, lit in enumerate(literals[kind]):
                rhs = re.sub(rf"(?<![\w.])(?:[A-Za-z_]\w*\.)*{re.escape(kind)}\.{re.escape(lit)}\b", f"{k + 1}", rhs)
            out += [text[pos:start], f"1.0*Integer({m[1]}) = 1.0*({rhs.strip()});"]
            pos = end
    return "".join(out) + text[pos:]
