"""Parameters bound to a bare function call, restated so that rumoca counts them as parameters.

rumoca 0.10 counts the binding of a scalar parameter to a call of a function with an array
argument (``parameter Real L = Modelica.Math.Vectors.length(r)``, a gear's efficiency
interpolated in its loss table) as an equation of the model, while the parameter is not an
unknown: the model is refused as unbalanced (2 equations for 1 unknown). The same call inside an
expression is a parameter's binding as it should be. :func:`restated` writes ``f(...) + 0`` for
each such binding of a Real or Integer parameter (the value and type unchanged, the line count
kept); the compile tries it only after rumoca refused the model as written as unbalanced.
"""
from __future__ import annotations

import re

#: a scalar Real or Integer parameter's declaration, up to its name (a Complex-valued SI type is
#: a record: a call there is its constructor, and a record plus 0 is no Modelica)
_HEAD = re.compile(r"\bparameter\s+(?P<type>Real|Integer|(?:Modelica\.Units\.|Modelica\.SIunits\.)?SI\.(?!Complex)\w+"
                   r"|Modelica\.SIunits\.(?!Complex)\w+)\s+(?P<name>\w+)\s*")
_CALL = re.compile(r"[A-Za-z_][\w.]*\s*\(")
_AFTER = re.compile(r"\s*(;|\"|annotation\b)")


def restated(text: str) -> str:
    """``text`` with every scalar Real or Integer parameter bound to a bare call bound to
    ``call + 0`` instead (the rest of the text as it was)."""
    out, pos = [], 0
    for head in _HEAD.finditer(text):
        if head.start() < pos:
            continue
        k = head.end()
        if text.startswith("(", k):                      # its modifiers: (unit = "m", min = 0)
            k = closing(text, k)
            if k is None:
                continue
            k = _skip_space(text, k)
        if not text.startswith("=", k) or text.startswith("==", k):
            continue
        k = _skip_space(text, k + 1)
        call = _CALL.match(text, k)
        if call is None or text[k:call.end()].split("(")[0].strip() in ("if", "Real", "Integer"):
            continue
        end = closing(text, call.end() - 1)
        if end is None or _AFTER.match(text, end) is None:
            continue
        out.append(text[pos:end])
        out.append(" + 0")
        pos = end
    out.append(text[pos:])
    return "".join(out)


def closing(text: str, k: int) -> int | None:
    """The index just past the parenthesis that closes the one at ``k`` (strings skipped)."""
    depth, i, n = 0, k, len(text)
    while i < n:
        c = text[i]
        if c == '"':
            i = text.find('"', i + 1)
            while i > 0 and text[i - 1] == "\\":
                i = text.find('"', i + 1)
            if i < 0:
                return None
        elif c == "(":
            depth += 1
        elif c == ")":
            depth -= 1
            if depth == 0:
                return i + 1
        elif c == ";":
            return None
        i += 1
    return None


def _skip_space(text: str, k: int) -> int:
    while k < len(text) and text[k].isspace():
        k += 1
    return k
