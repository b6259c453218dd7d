"""A model's text restated, with the same meaning, where rumoca misreads it as written: bindings
to a bare function call, a component array's array modifiers, a record array sized by its
sibling (here), while loops (:mod:`.loops`), Integer() of an enumeration (:mod:`.enums`), a
replaceable component's own modifiers (:func:`.redeclares.defaults_lifted`).
:func:`restated` applies them all; the compile tries it only after rumoca refused the model.

rumoca 0.10 counts the binding of a scalar parameter to a call of a function with an array
argument (``parameter Real L = Modelica.Math.Vectors.length(r)``, a gear's efficiency
interpolated in its loss table) as an equation of the model, while the parameter is not an
unknown: the model is refused as unbalanced (2 equations for 1 unknown). A variable bound so
(``Real q = f({0, 1, 2}, time)``) is miscounted the same way. The same call inside an
expression is a parameter's binding as it should be. :func:`restated` writes ``f(...) + 0`` for
each such binding of a Real or Integer parameter (the value and type unchanged, the line count
kept).

rumoca 0.10 also fails on a component array modified by an array expression other than a
literal or a reference, ``HeatCapacitor cap[n](C = linspace(10, 30, n))`` (unbalanced, or
"expression shape mismatch"): :func:`distributed` writes the value element by element,
``C = {(linspace(10, 30, n))[i] for i in 1:n}``, which it reads. A record's bound parameter
array sized by a sibling (``head[size(q, 1)] = {...}``) is declared ``[:]`` (:func:`unsized`).
"""
from __future__ import annotations

import re

from .enums import enumerated
from .loops import bounded, unrolled
from .redeclares import defaults_lifted
from .records import copied
from .sources import KEYWORDS, arguments, closing, masked, statement_end

#: a scalar Real or Integer parameter's declaration, up to its name (a Complex-valued SI type is
#: a record: a call there is its constructor, and a record plus 0 is no Modelica)
_HEAD = re.compile(r"(?:\bparameter\s+|\boutput\s+|\bdiscrete\s+|(?<![\w.])(?=(?:Real|Integer|Modelica|SI)\b))(?P<type>Real|Integer|(?:Modelica\.Units\.|Modelica\.SIunits\.)?SI\.(?!Complex)\w+"
                   r"|Modelica\.SIunits\.(?!Complex)\w+)\s+(?P<name>\w+)\s*")
_CALL = re.compile(r"[A-Za-z_][\w.]*\s*\(")
_AFTER = re.compile(r"\s*(;|\"|annotation\b)")


def restated(text: str) -> str:
    """``text`` with the restatements rumoca reads (:func:`called`, :func:`distributed`,
    :func:`unsized`, :func:`.loops.bounded`, :func:`.enums.enumerated`,
    :func:`.redeclares.defaults_lifted`, :func:`.records.copied`, :func:`.loops.unrolled`)."""
    return unrolled(defaults_lifted(enumerated(bounded(unsized(distributed(called(copied(text))))))))


#: a bound parameter array sized by another's size: ``parameter Real head[size(q, 1)] = {...}``
_SIZED = re.compile(r"(\bparameter\s+[A-Za-z_][\w.]*\s+\w+\s*\[)((?:\s*size\s*\([^()]*\)\s*,)*\s*size\s*\([^()]*\)\s*)"
                    r"(\]\s*=)")


def unsized(text: str) -> str:
    """``text`` with each bound parameter array sized by ``size(...)`` of another declared
    ``[:]`` (its binding gives its size): rumoca cannot resolve the other name where a record
    holding both is passed to a function."""
    return _SIZED.sub(lambda m: m[1] + ", ".join([":"] * m[2].count("size")) + m[3], text)


def called(text: str) -> str:
    """``text`` with every scalar Real or Integer parameter or variable bound to a bare call
    bound to ``call + 0`` instead (the rest of the text as it was)."""
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


def _skip_space(text: str, k: int) -> int:
    while k < len(text) and text[k].isspace():
        k += 1
    return k


#: a component array with a modification: ``cap[n](`` or ``Capacitor[n] cap(`` (in an expression
#: an index is never followed by a parenthesis)
_ARRAY_MODIFIED = re.compile(r"(?<![\w.])(?:(?P<name>[A-Za-z_]\w*)\s*\[(?P<dims>[^\[\]]*)\]"
                             r"|[A-Za-z_][\w.]*\s*\[(?P<tdims>[^\[\]]*)\]\s+(?P<tname>[A-Za-z_]\w*))\s*\(")
#: a reference, which rumoca takes for a component array as it is
_REFERENCE = re.compile(r"[A-Za-z_][\w.]*(?:\s*\[[^\[\]]*\])?")
#: the openings of a literal array, fill(...) or a string: taken as they are where they are all
_LITERAL = re.compile(r"\{|fill\s*\(|\"")
#: a value's end that is a description string, not part of it
_DESCRIBED = re.compile(r"(?<=[\w)\]}.])\s*\"[^\"]*\"$")
_ARGUMENT = re.compile(r"\s*(?P<prefix>(?:final\s+)*)(?P<path>[A-Za-z_][\w.]*)\s*")


def distributed(text: str) -> str:
    """``text`` with each modifier value of a component array that is an array expression
    written element by element (``{(e)[i] for i in 1:n}``); ``each`` and ``redeclare``
    arguments, literals, fill(...) and references as they were.

    A component array sized by another component's parameter (``heat[pipe.nNodes]``) takes
    its size from its one array-valued modifier (rumoca 0.10): with none (``each`` values
    only), or with an expression (even written element by element), it loses all but its first
    element's values, one equation short per element. There the first ``each`` value of a
    modification with no array value is written ``fill(v, dims)``, and an array expression is
    bound to a parameter array declared after the component (``mcl_heat_Q_flow``), which the
    modifier names. (Two array values stay as they are: rumoca reads neither.)"""
    blank, edits = masked(text), []
    for m in _ARRAY_MODIFIED.finditer(blank):
        name = m["name"] or m["tname"]
        if name in KEYWORDS:
            continue
        dims = [d.strip() for d in (m["dims"] or m["tdims"]).split(",")]
        if any(not d or d == ":" for d in dims):
            continue
        end = closing(blank, m.end() - 1)
        if end is None:
            continue
        literal = _literal_dims(blank, dims)
        if literal != dims:
            span = m.span("dims") if m["dims"] is not None else m.span("tdims")
            edits.append((*span, ", ".join(literal) + "\n" * text[span[0]:span[1]].count("\n")))   # (lines kept)
            dims = literal
        if not any(_of_component(blank, d) for d in dims):
            edits += [(a, b, _elementwise(text[a:b], dims)) for a, b, _, each, as_is in _values(blank, m.end(), end - 1)
                      if each is None and not as_is]
            continue
        stop = statement_end(blank, end)
        values = _values(blank, m.end(), end - 1, each=True)
        arrays = [v for v in values if v[3] is None]
        if not arrays and values:      # (one each value as the array)
            a, b, _, each, _ = values[0]
            edits.append((each, b, f"{text[each:a].replace('each', '', 1).lstrip()}fill({text[a:b]}, {', '.join(dims)})"))
        hoisted = [(a, b, "mcl_" + "_".join([name, *path])) for a, b, path, _, as_is in arrays if not as_is]
        if stop is not None and hoisted:
            edits += hoisted
            edits.append((stop, stop, "".join(f" final parameter Real {h}[{', '.join([':'] * len(dims))}] = {text[a:b]};"
                                              for a, b, h in hoisted)))
    for a, b, new in sorted(edits, key=lambda e: (e[0], e[1]), reverse=True):
        text = text[:a] + new + text[b:]
    return text


def _of_component(masked: str, dim: str) -> bool:
    """Whether array dimension ``dim`` reads a parameter of a component the text declares
    (``pipe.nNodes``, ``DynamicPipe pipe(...)``); a record parameter's field (``cellData.nRC``)
    rumoca reads as any other size."""
    ref = re.match(r"\s*([A-Za-z_]\w*)\s*\.\s*[A-Za-z_]", dim)
    if ref is None:
        return False
    for decl in re.finditer(rf"(?<![\w.])[A-Za-z_][\w.]*\s+{ref[1]}\s*[(;\[\"]", masked):
        if decl[0].split()[0] not in KEYWORDS and not re.search(
                r"\b(parameter|constant|redeclare)\b[\w\s]*$", masked[max(0, decl.start() - 80):decl.start()]):
            return True
    return False


def _literal_dims(masked: str, dims: list[str]) -> list[str]:
    """``dims`` with each ``c.p`` that the text's one declaration of component ``c`` modifies
    to a whole number (``DynamicPipe pipe2(nNodes = 5, ...)``) written as that number: a
    component array sized so is read as any other."""
    out = []
    for d in dims:
        ref = re.fullmatch(r"([A-Za-z_]\w*)\s*\.\s*([A-Za-z_]\w*)", d)
        decls = list(re.finditer(rf"(?<![\w.])[A-Za-z_][\w.]*\s+{ref[1]}\s*\(", masked)) if ref else []
        end = closing(masked, decls[0].end() - 1) if len(decls) == 1 else None
        value = None
        for a, b in arguments(masked, decls[0].end(), end - 1) if end is not None else []:
            arg = re.fullmatch(rf"\s*(?:final\s+)?{ref[2]}\s*=\s*(\d+)\s*", masked[a:b])
            value = arg[1] if arg else value
        out.append(value or d)
    return out


def _values(masked: str, start: int, stop: int, each: bool = False, path: tuple = ()) -> list[tuple]:
    """The values of the modification ``masked[start:stop]`` (inside its parentheses), its
    nested modifications' included: (start, end, the member's path, where its ``each`` starts
    or None, whether rumoca reads it for a component array as it is). ``each``: values of
    ``each`` modifiers too."""
    edits = []
    for a, b in arguments(masked, start, stop):
        arg = _ARGUMENT.match(masked, a, b)
        skip = re.match(r"\s*(each|redeclare|replaceable|extends)\b", masked[a:b])
        if arg is None or (skip and not (each and skip[1] == "each")):
            continue
        if skip:           # each: the argument after it
            arg = _ARGUMENT.match(masked, a + skip.end(), b)
            if arg is None:
                continue
        member = (*path, *arg["path"].split("."))
        k = arg.end()
        if masked.startswith("(", k):
            inner = closing(masked, k)
            if inner is None or inner > b:
                continue
            if not skip:      # (an each on the outer applies to all inside: left as it is)
                edits += _values(masked, k + 1, inner - 1, each, member)
            k = _skip_space(masked, inner)
        if masked.startswith("=", k) or masked.startswith(":=", k):
            k = _skip_space(masked, k + (1 if masked[k] == "=" else 2))
            value = _DESCRIBED.sub("", masked[k:b].rstrip())
            if value:
                edits.append((k, k + len(value), member, a + skip.start(1) if skip else None, _as_is(value)))
    return edits


def _as_is(value: str) -> bool:
    """Whether rumoca reads ``value`` for a component array as it is: a reference, or one
    literal array, fill(...) or string."""
    if _REFERENCE.fullmatch(value):
        return True
    opening = _LITERAL.match(value)
    if opening is None:
        return False
    if value[0] == '"':
        return value.find('"', 1) == len(value) - 1
    return closing(value, opening.end() - 1) == len(value)


def _elementwise(value: str, dims: list[str]) -> str:
    """``value`` (an array of the component array's ``dims``) built element by element."""
    its = [f"mcl_i{k}" for k in range(1, len(dims) + 1)]
    out = f"({value})[{', '.join(its)}]"
    for it, d in reversed(list(zip(its, dims))):
        out = f"{{{out} for {it} in 1:{d}}}"
    return out
