"""Complex arithmetic written in the forms rumoca 0.10 reads.

rumoca 0.10.2 translates an infix operator on an operator record (``a + b``, ``2*a``, ``-a``)
as if it were on Reals: ``b = a + a`` is one equation where it should be two, and the model is
'unbalanced'. The MSL's QuasiStatic, FundamentalWave and ComplexBlocks libraries are written
so. What rumoca does read, and what each Complex statement is rewritten to:

- an operator as the record's call: ``Complex.'+'(a, b)``, ``Complex.'*'.multiply(a, b)``, a Real
  operand as ``Complex(x)``;
- an equation with a component reference on its left and the record's constructor on its
  right (rumoca equates two records only of one class: ``v = a`` with v a ComplexVoltage and a
  a Complex is refused): ``v = Complex(a.re, a.im)``, a value that is not a reference through
  ``Modelica.ComplexMath.real``/``imag``. An equation with no reference on either side is
  solved for a reference that is a term of a sum (``p.i + n.i = Complex(0)`` -> ``p.i = -n.i``),
  or a term's factor where that divides by no variable; any other is written as two Real
  equations of its parts (``-sqrt(2)*v = j*omega*Phi``: solved for Phi it would divide by omega);
- an element chosen by an array's element (``x[index[k]]``) through its members: rumoca resolves
  no record equation of one;
- a record-valued if-expression as the constructor of its parts' if-expressions;
- an equation of whole arrays as a for-loop over their elements, a scalar product of two
  vectors as the sum of its terms' parts, ``fill(c, n)`` as a comprehension;
- an imported Complex function whose short name is a built-in's (``abs``) named in full.

The operands' types come from the classes' declarations (:mod:`.classes`): a component
reference is followed member by member, a function call has its output's type. A statement
this module cannot read is left as written. The rewrite keeps the file's line count.
"""
from __future__ import annotations

import functools
import hashlib
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

from .classes import ClassInfo, LibraryClasses
from .sources import masked

#: the digest's mark of a document compiled with its Complex operators as calls (the rewrite's version)
MARK = "+complex" + hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:8]
#: the MSL's packages that write their equations in Complex arithmetic, and the record itself
MENTIONS = re.compile(r"\b(?:Complex|FundamentalWave|QuasiStatic|ComplexBlocks|ComplexMath)\b")

_TOKEN = re.compile(r"""
    (?P<skip>\s+|//[^\n]*|/\*.*?\*/)
  | (?P<str>"(?:\\.|[^"\\])*")
  | (?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)
  | (?P<id>'(?:\\.|[^'\\])*'|[A-Za-z_]\w*)
  | (?P<op>:=|==|<>|<=|>=|\.[-+*/^]|[-+*/^=<>()\[\]{},;.:])
""", re.DOTALL | re.VERBOSE)

_CLASS = {"model", "block", "connector", "record", "package", "class", "type", "function", "operator"}
_OPS = {"+": "Complex.'+'", "-": "Complex.'-'.subtract", "*": "Complex.'*'.multiply", "/": "Complex.'/'",
        "^": "Complex.'^'", "==": "Complex.'=='", "<>": "Complex.'<>'"}
#: built-ins whose value has their (first) argument's type
_SAME = {"pre", "noEvent", "smooth", "homotopy", "delay", "sum", "previous", "hold", "semiLinear", "fill"}
#: the built-in functions a Complex function imported by its short name hides (rumoca takes the built-in)
_BUILTIN = {"abs", "sqrt", "exp", "log", "log10", "sin", "cos", "tan", "sinh", "cosh", "tanh", "asin", "acos",
            "atan", "sign", "max", "min", "sum", "product"}
#: the other built-in functions of Real values
_REAL_BUILTIN = {"atan2", "floor", "ceil", "mod", "rem", "div", "integer", "cross", "skew", "transpose", "identity",
                 "diagonal", "zeros", "ones", "linspace", "scalar", "vector", "matrix", "cardinality", "sample",
                 "edge", "change", "terminal"}
C, R, U = "C", "R", "U"   # a Complex value; any other; a call of a function not found (taken as Complex beside one)


@dataclass
class Tok:
    """A token of Modelica text and its place."""

    kind: str
    text: str
    start: int
    end: int


def tokens(text: str) -> list[Tok]:
    """The tokens of ``text``, comments and white space left out."""
    out = []
    for m in _TOKEN.finditer(text):
        if m.lastgroup != "skip":
            out.append(Tok(m.lastgroup, m.group(), m.start(), m.end()))
    return out


@dataclass
class Node:
    """An expression's node, its place in the text and its type."""

    kind: str                  # num str ref call bin un paren array if other
    start: int
    end: int
    kids: list = field(default_factory=list)
    op: str = ""               # bin/un: the operator; call/ref: the name
    type: str = R
    rewrite: str | None = None  # the node's new text (a Complex operator as its call)
    variable: bool = False     # a reference to a variable of the class (one an equation may be solved for)
    member: bool = False       # a reference to a component of the class (not an imported or a package's constant)
    qualified: str = ""        # a call's function named in full (an imported ComplexMath.abs is not the built-in)
    head: int = 0              # where a call's name ends
    array_at: int | None = None  # a reference to a whole array: where its array part's name ends
    iterator: str = ""         # an array comprehension's iterator
    function: str = ""         # a call's function, resolved (Modelica.ComplexMath.real)
    whole: bool = False        # a call of a function whose output is an array (symmetricOrientation(m))


@dataclass(frozen=True)
class _Element:
    """An array equation written element by element: the loop's index, and the comprehensions'
    iterators it stands for."""

    index: str
    iterators: frozenset = frozenset()


class _Unread(Exception):
    """A statement this module does not read: it is left as written."""


class _Parser:
    """Modelica expressions over tokens ``toks[i:j]``, each node with its place in the text."""

    def __init__(self, toks: list[Tok], typer):
        self.t, self.i, self.typer = toks, 0, typer

    def peek(self, k=0):
        return self.t[self.i + k].text if self.i + k < len(self.t) else None

    def take(self, want=None) -> Tok:
        if self.i >= len(self.t) or (want is not None and self.t[self.i].text != want):
            raise _Unread(want)
        self.i += 1
        return self.t[self.i - 1]

    def node(self, kind, first, kids=(), op="", type_=R):
        return Node(kind, first.start, self.t[self.i - 1].end, list(kids), op, type_)

    def expression(self) -> Node:
        if self.peek() == "if":
            first = self.take()
            kids = [self.expression()]
            self.take("then")
            kids.append(self.expression())
            while self.peek() == "elseif":
                self.take()
                kids.append(self.expression())
                self.take("then")
                kids.append(self.expression())
            self.take("else")
            kids.append(self.expression())
            node = self.node("if", first, kids, type_=C if any(k.type == C for k in kids[1::2] + kids[-1:]) else R)
            if node.type == C:          # rumoca reads no record-valued if-expression: its parts' are
                node.rewrite = "if"
            return node
        first = self.t[self.i] if self.i < len(self.t) else None
        e = self.binary(0)
        if self.peek() == ":":              # a range
            while self.peek() == ":":
                self.take()
                self.binary(0)
            return Node("other", first.start, self.t[self.i - 1].end, [e])
        return e

    _LEVELS: ClassVar = [("or",), ("and",), ("<", "<=", ">", ">=", "==", "<>"), ("+", "-", ".+", ".-"),
               ("*", "/", ".*", "./"), ("^", ".^")]

    def binary(self, level: int) -> Node:
        if level == len(self._LEVELS):
            return self.primary()
        first = self.t[self.i] if self.i < len(self.t) else None
        if first is None:
            raise _Unread("end")
        if level == 0 and self.peek() == "not":
            self.take()
        if level == 3 and self.peek() in ("-", "+", ".-", ".+"):     # unary
            op = self.take().text
            x = self.binary(level + 1)
            left = self.node("un", first, [x], op.lstrip("."), x.type)
            if x.type == C:
                left.rewrite = "call"
        else:
            left = self.binary(level + 1)
        while self.peek() in self._LEVELS[level]:
            op = self.take().text.lstrip(".")
            right = self.binary(level + 1)
            complex_ = (left.type == C or right.type == C) and (level > 2 or op in ("==", "<>"))
            left = self.node("bin", first, [left, right], op, C if complex_ and level > 2 else R)
            if complex_:
                left.rewrite = "call"
        return left

    def primary(self) -> Node:
        tok = self.t[self.i] if self.i < len(self.t) else None
        if tok is None:
            raise _Unread("end")
        if tok.kind in ("num", "str") or tok.text in ("true", "false", "end", ":"):
            self.take()
            return self.node("num", tok)
        if tok.text == "(":
            self.take()
            kids = [self.expression()] if self.peek() != ")" else []
            while self.peek() == ",":
                self.take()
                kids.append(self.expression())
            self.take(")")
            return self.node("paren", tok, kids, type_=kids[0].type if len(kids) == 1 else R)
        if tok.text in ("{", "["):
            close = "}" if tok.text == "{" else "]"
            self.take()
            kids, iterators = [], []
            while self.peek() != close:
                kids.append(self.expression())
                if self.peek() == "for":
                    iterators = self.iterators()
                if self.peek() in (",", ";"):
                    self.take()
                elif self.peek() != close:
                    raise _Unread(close)
            self.take(close)
            node = self.node("array", tok, kids, type_=C if any(k.type == C for k in kids) else R)
            if len(kids) == 1 and len(iterators) == 1:
                node.iterator = iterators[0]
            return node
        if tok.kind == "id" or tok.text in ("der", "initial", "pre"):
            return self.reference()
        raise _Unread(tok.text)

    def iterators(self) -> list[str]:
        """A comprehension's iterators' names."""
        names = []
        while self.peek() in ("for", ","):
            self.take()
            names.append(self.take().text)
            if self.peek() == "in":
                self.take()
                self.expression()
        return names

    def reference(self) -> Node:
        first = self.t[self.i]
        parts, ends, subscripted = [], [], []
        while True:
            name = self.take()
            if name.kind != "id":
                raise _Unread(name.text)
            parts.append(name.text)
            ends.append(name.end)
            subscripted.append(self.peek() == "[")
            if self.peek() == "[":
                self.take()
                while self.peek() != "]":
                    self.expression()
                    if self.peek() == ",":
                        self.take()
                self.take("]")
            if self.peek() == "." and self.i + 1 < len(self.t) and self.t[self.i + 1].kind == "id":
                self.take()
                continue
            break
        name, head = ".".join(parts), self.t[self.i - 1].end
        if self.peek() != "(":
            type_, whole = self.typer.reference(parts, subscripted)
            ref = self.node("ref", first, op=name, type_=R if type_ in ("re", "im") else type_)
            ref.variable = self.typer.variable(parts[0])
            ref.member = parts[0] in self.typer.env
            ref.array_at = ends[whole] if whole is not None else None
            if type_ in ("re", "im"):       # bw.re of a Complex array bw: rumoca reads no such slice
                ref.rewrite, ref.head = type_, ends[-2]
            return ref
        self.take("(")
        kids = []
        while self.peek() != ")":
            if self.t[self.i].kind == "id" and self.peek(1) == "=":      # a named argument
                self.take()
                self.take()
            kids.append(self.expression())
            if self.peek() == "for":
                self.iterators()
            if self.peek() == ",":
                self.take()
            elif self.peek() != ")":
                raise _Unread(")")
        self.take(")")
        call = self.node("call", first, kids, op=name)
        call.type = self.typer.call(name, kids)
        call.whole = self.typer.array_valued(name)
        if name.split(".")[-1] in _PARTS:
            call.function = self.typer.qualified(name) or (name if name.startswith("Modelica.ComplexMath.") else "")
        if name in _BUILTIN and any(k.type == C for k in kids):
            call.qualified, call.head = self.typer.qualified(name), head
        return call


def _emit(node: Node, text: str, el: _Element | None = None) -> str:
    """``node``'s text with its Complex operators written as calls; with ``el``, the element
    ``el.index`` of an array expression."""
    if node.rewrite in ("re", "im"):
        # bw[k].re, not real(bw[k]): rumoca resolves no comprehension's iterator in a record
        # function's call inside sum()
        inner = _Element(el.index if el is not None else "mcl_s")
        x = f"{text[node.start:node.array_at]}[{inner.index}]{text[node.array_at:node.head]}.{node.rewrite}"
        return x if el is not None else f"{{{x} for {inner.index} in 1:size({text[node.start:node.array_at]}, 1)}}"
    if el is not None:
        if node.kind == "ref" and node.op in el.iterators:
            return el.index
        if node.kind == "ref" and node.array_at is not None:
            return f"{text[node.start:node.array_at]}[{el.index}]{text[node.array_at:node.end]}"
        if node.kind == "array" and node.iterator:          # {f(k) for k in 1:m}: f(index)
            return _emit(node.kids[0], text, _Element(el.index, el.iterators | {node.iterator}))
        if node.kind == "call" and node.op == "fill":
            return _emit(node.kids[0], text, el)
        if node.kind == "call" and node.whole:          # f(m)[k] of an array-valued f
            return f"({_emit(node, text)})[{el.index}]"
        if node.kind in ("array", "other") or node.kind == "call" and node.op in _SAME | {"size", "ndims"}:
            raise _Unread("an array expression read element by element")
    if node.rewrite == "if":
        conds = [_emit(k, text, el) for k in node.kids[0:-1:2]]
        values = [_parts(k, text, el) for k in node.kids[1::2] + node.kids[-1:]]

        def chain(part):
            arms = [f"{'if' if k == 0 else 'elseif'} {c} then {v[part]}" for k, (c, v) in enumerate(zip(conds, values))]
            return f"({' '.join(arms)} else {values[-1][part]})"
        return f"Complex({chain(0)}, {chain(1)})"
    if node.function in _OF_PARTS and len(node.kids) == 1:
        parts = _expanded(node.kids[0], text, el)
        if parts is not None:
            return _OF_PARTS[node.function].format(*parts)
    if node.kind == "call" and node.op == "fill" and node.type == C and len(node.kids) == 2:
        # rumoca's shapes miss fill(Complex(1, 0), n); the comprehension it reads
        return f"{{{_emit(node.kids[0], text)} for mcl_j in 1:{_emit(node.kids[1], text)}}}"
    if _dot(node):          # a scalar product of two Complex vectors: the sum of its terms' parts
        term = _Element("mcl_i")
        a, b = (_emit(k, text, term) for k in node.kids)
        whole = next(n for n in _walk(node.kids[0]) if n.kind == "ref" and n.array_at is not None)
        over = f"for {term.index} in 1:size({text[whole.start:whole.array_at]}, 1)"
        return "Complex({})".format(", ".join(f"sum({part}({_OPS['*']}({a}, {b})) {over})" for part in (REAL, IMAG)))
    if node.rewrite == "call":
        args = [_emit(k, text, el) for k in node.kids]
        args = [a if k.type != R else f"Complex({a})" for a, k in zip(args, node.kids)]
        if node.kind == "un":
            return f"Complex.'-'.negate({args[0]})" if node.op == "-" else args[0]
        return f"{_OPS[node.op]}({args[0]}, {args[1]})"
    out, at = [], node.start
    if node.qualified:
        out, at = [node.qualified], node.head
    for k in node.kids:
        if _changed(k) or el is not None and _arrayed(k):
            out += [text[at:k.start], _emit(k, text, el)]
            at = k.end
    out.append(text[at:node.end])
    return "".join(out)


#: the functions of Complex values whose parts :func:`_expanded` writes out
_PARTS = {"real", "imag", "conj", "abs", "arg"}
#: Real functions of a Complex value, written on its parts (re, im)
_OF_PARTS = {"Modelica.ComplexMath.real": "({0})", "Modelica.ComplexMath.imag": "({1})",
             "Modelica.ComplexMath.abs": "sqrt(({0})^2 + ({1})^2)", "Modelica.ComplexMath.arg": "atan2({1}, {0})"}


def _expanded(node: Node, text: str, el: _Element | None = None, depth: int = 0) -> tuple[str, str] | None:
    """The real and imaginary parts of a Complex value written in Real arithmetic on its
    operands' members (``real(v[j]*conj(i[j]))`` -> ``v[j].re*i[j].re - ...``), or None where
    it holds another call or a division, or grows deep. rumoca resolves no comprehension's
    iterator in a call of a record function inside ``sum({... for j in 1:m})``."""
    if node.type == R:
        return _emit(node, text, el), "0"
    if depth > 3:
        return None
    if node.kind == "ref" and node.rewrite is None and (node.array_at is None or el is not None):
        x = _emit(node, text, el)       # (rumoca resolves no member of an imported constant: j.re)
        return (f"{x}.re", f"{x}.im") if node.member else (f"{REAL}({x})", f"{IMAG}({x})")
    if node.kind == "paren" and len(node.kids) == 1:
        return _expanded(node.kids[0], text, el, depth)
    if node.kind == "call" and node.op == "Complex" and 1 <= len(node.kids) <= 2 and "=" not in text[node.start:node.end]:
        kids = [_emit(k, text, el) for k in node.kids]
        return kids[0], kids[1] if len(kids) > 1 else "0"
    conj = node.kind == "call" and node.function == "Modelica.ComplexMath.conj" and len(node.kids) == 1
    if not (conj or node.kind == "un" and node.op in ("+", "-") or node.kind == "bin" and node.op in ("+", "-", "*")):
        return None
    kids = [_expanded(k, text, el, depth + 1) for k in node.kids]
    if any(k is None for k in kids):
        return None
    if conj:
        return kids[0][0], f"-({kids[0][1]})"
    if node.kind == "un":
        return kids[0] if node.op == "+" else (_sum("0", "-", kids[0][0]), _sum("0", "-", kids[0][1]))
    (a, b), (c, d) = kids
    if node.op in ("+", "-"):
        return _sum(a, node.op, c), _sum(b, node.op, d)
    return _sum(_product(a, c), "-", _product(b, d)), _sum(_product(a, d), "+", _product(b, c))


def _product(a: str, b: str) -> str:
    return "0" if "0" in (a, b) else f"({a})*({b})"


def _sum(a: str, op: str, b: str) -> str:
    if b == "0":
        return a
    return (b if op == "+" else f"-({b})") if a == "0" else f"({a}) {op} ({b})"


def _changed(node: Node) -> bool:
    return node.rewrite is not None or bool(node.qualified) or node.kind == "call" and node.op == "fill" \
        and node.type == C or node.function in _OF_PARTS or any(_changed(k) for k in node.kids)


def _arrayed(node: Node) -> bool:
    """Whether ``node`` holds a whole array (a reference, a comprehension, a fill) outside a
    scalar product."""
    if node.kind == "ref" and node.array_at is not None or node.kind == "array" and node.iterator \
            or node.kind == "call" and (node.op == "fill" or node.whole):
        return True
    if node.kind == "call" and node.op in ("sum", "product", "max", "min", "size", "ndims"):
        return False        # a scalar of an array
    return not _dot(node) and any(_arrayed(k) for k in node.kids)


def _dot(node: Node) -> bool:
    """Whether ``node`` is ``a*b`` of two Complex vectors (references to whole arrays)."""
    return node.kind == "bin" and node.op == "*" and node.rewrite == "call" and all(
        any(n.kind == "ref" and n.array_at is not None for n in _walk(k)) for k in node.kids)


def _terms(node: Node, sign: int = 1):
    """The signed terms of a top-level sum."""
    if node.kind == "bin" and node.op in ("+", "-"):
        yield from _terms(node.kids[0], sign)
        yield from _terms(node.kids[1], sign if node.op == "+" else -sign)
    elif node.kind == "un" and node.op in ("+", "-"):
        yield from _terms(node.kids[0], sign if node.op == "+" else -sign)
    elif node.kind == "paren" and len(node.kids) == 1:
        yield from _terms(node.kids[0], sign)
    else:
        yield sign, node


def _zero(node: Node, text: str) -> bool:
    """``Complex(0)``, ``Complex(0, 0)`` or ``fill(Complex(0), n)``."""
    if node.kind == "call" and node.op == "fill" and node.kids:
        return _zero(node.kids[0], text)
    return node.kind == "call" and node.op == "Complex" and \
        all(re.fullmatch(r"0\.?0*", text[k.start:k.end]) for k in node.kids)


def _equation(lhs: Node, rhs: Node, text: str, el: _Element | None = None):
    """(a Complex equation written with a component reference on its left and a record
    constructor on its right, its operators as calls; the reference), or None where neither
    side is a reference nor a sum holding one (times or over a factor)."""
    for ref, value in ((lhs, rhs), (rhs, lhs)):
        if ref.kind != "ref":
            continue
        x = _emit(ref, text, el)
        if _INDIRECT.search(x):      # x[index[k]]: rumoca reads the element's members only
            return "; ".join(f"{x}.{m} = {v}" for m, v in zip(("re", "im"), _parts(value, text, el))), ref
        right = _record(value, text, el=el)
        unchanged = ref is lhs and el is None and right == text[value.start:value.end]
        return (None if unchanged else f"{x} = {right}"), ref
    terms = [(s, n) for s, n in _terms(lhs)] + [(-s, n) for s, n in _terms(rhs)]
    k = next((k for k, (_, n) in enumerate(terms) if _solvable(n) is not None), None)
    if k is None:
        return _split(lhs, rhs, text, el)
    sign, term = terms.pop(k)
    ref, op, factor = _solvable(term)
    if factor is not None and (factor.type != R or any(n.kind == "ref" and n.variable for n in _walk(factor))):
        return _split(lhs, rhs, text, el)     # solved for, the term would divide by a variable (omega)
    out = None                # term = -sign * (the other terms)
    for s, n in terms:
        if _zero(n, text):
            continue
        arg = _emit(n, text, el) if n.type != R else f"Complex({_emit(n, text, el)})"
        if out is None:
            out = arg if -sign * s > 0 else f"Complex.'-'.negate({arg})"
        else:
            out = f"{_OPS['+' if -sign * s > 0 else '-']}({out}, {arg})"
    out = out or "Complex(0)"
    if factor is not None:    # term = ref * factor, factor * ref or ref / factor
        f = _emit(factor, text, el) if factor.type != R else f"Complex({_emit(factor, text, el)})"
        out = f"{_OPS['/' if op == '*' else '*']}({out}, {f})"
    return f"{_emit(ref, text, el)} = {_record(None, text, out)}", ref


#: a subscript that is itself an array's element (``x[index[k]]``)
_INDIRECT = re.compile(r"\[[^\]]*\[")


def _split(lhs: Node, rhs: Node, text: str, el: _Element | None = None):
    """(the equation as two Real equations of its parts, a whole-array reference in it): the
    form for an equation no reference can be solved for without a division by a variable."""
    left, right = _parts(lhs, text, el), _parts(rhs, text, el)
    whole = next((n for n in [*_walk(lhs), *_walk(rhs)] if n.kind == "ref" and n.array_at is not None), None)
    return f"{left[0]} = {right[0]}; {left[1]} = {right[1]}", whole


def _solvable(term: Node):
    """(reference, operator, factor) where ``term`` is a Complex reference (factor None), or
    one times or over a factor; else None."""
    if term.kind == "ref" and term.type == C and term.variable:
        return term, "", None
    if term.kind == "paren" and len(term.kids) == 1:
        return _solvable(term.kids[0]) if term.kids[0].kind == "ref" else None
    if term.kind != "bin" or term.op not in ("*", "/"):
        return None
    a, b = term.kids
    if a.kind == "ref" and a.type == C and a.variable:
        return a, term.op, b
    if term.op == "*" and b.kind == "ref" and b.type == C and b.variable:
        return b, "*", a
    return None


#: the parts of a Complex value that is not a reference (rumoca equates two records only where
#: their types are the same class, or the right-hand side is the record's constructor)
REAL, IMAG = "Modelica.ComplexMath.real", "Modelica.ComplexMath.imag"


def _parts(node: Node, text: str, el: _Element | None = None) -> tuple[str, str]:
    """The real and imaginary parts of a value as text."""
    parts = _expanded(node, text, el)
    if parts is None:
        x = _emit(node, text, el)
        parts = f"{REAL}({x})", f"{IMAG}({x})"
    return parts


def _record(node: Node | None, text: str, written: str | None = None, el: _Element | None = None) -> str:
    """A Complex value (``node``, or the text ``written``) as ``Complex(re, im)``: rumoca
    refuses ``v = a`` where v is a ComplexVoltage and a a Complex ('distinct resolved type
    identities'), and reads ``v = Complex(a.re, a.im)``."""
    if node is not None and (node.kind == "call" and node.op == "Complex" or _dot(node)):
        return _emit(node, text, el)
    if node is not None:
        return "Complex({}, {})".format(*_parts(node, text, el))
    if written.startswith("Complex(") and _closing_at_end(written):
        return written
    return f"Complex({REAL}({written}), {IMAG}({written}))"


def _closing_at_end(x: str) -> bool:
    """Whether the parenthesis opened after ``Complex`` closes at the end of ``x``."""
    depth = 0
    for k, ch in enumerate(x[len("Complex"):]):
        depth += {"(": 1, ")": -1}.get(ch, 0)
        if depth == 0:
            return k == len(x) - len("Complex") - 1
    return False


class _Typer:
    """The types of the names written inside one class."""

    def __init__(self, lc: LibraryClasses, info: ClassInfo | None):
        self.lc, self.info, self.locals = lc, info, set()     # locals: a statement's for-loop iterators
        self.functions: dict[str, ClassInfo | None] = {}
        self.scope = info.name if info else ""
        self.env = {}
        if info is not None:
            for prefixes, cls, type_name, name, _c in lc.members(info):
                self.env[name] = (cls, type_name, prefixes)

    def complex_class(self, cls, type_name="") -> bool:
        return _is_complex(self.lc, cls.name) if cls is not None else type_name.split(".")[-1] == "Complex"

    def variable(self, name: str) -> bool:
        """Whether ``name`` is a variable of the class (not a parameter, a constant or an import)."""
        return name in self.env and not self.env[name][2] & {"parameter", "constant"}

    def reference(self, parts: list[str], subscripted=None) -> tuple[str, int | None]:
        """The type of the reference ``parts``, and which of its parts is a whole array (None:
        an element); one reference through two whole arrays is not read."""
        subscripted = subscripted or [False] * len(parts)
        if parts[0] in self.locals:
            return R, None
        wholes = []
        if parts[0] in self.env:
            cls, type_name, _prefixes = self.env[parts[0]]
            if self.info is not None and parts[0] in _arrays(self.lc, self.info.name) and not subscripted[0]:
                wholes.append(0)
            rest = parts[1:]
        else:
            cls, type_name, rest = self._global(parts)
        owner = cls
        for k, name in enumerate(rest, start=len(parts) - len(rest)):
            if cls is not None and self.complex_class(cls) and wholes and k == len(parts) - 1 \
                    and name in ("re", "im"):              # the parts of a whole array: a slice
                return ("re" if name == "re" else "im"), wholes[0]
            if cls is None or self.complex_class(cls):     # .re, .im of a Complex: Real
                return R, None
            found = _members(self.lc, cls.name).get(name)
            if found is None:
                return R, None
            if name in _arrays(self.lc, owner.name) and not subscripted[k]:
                wholes.append(k)
            cls, type_name = found
            owner = cls
        if len(wholes) > 1:
            raise _Unread("an array of arrays")
        return (C if self.complex_class(cls, type_name) else R), (wholes[0] if wholes else None)

    def _global(self, parts):
        """(class, type name, members left) of a name not declared in the class: an imported
        constant (``j``), or a package's constant (``Modelica.ComplexMath.j``)."""
        info = self.info
        if info is not None and parts[0] in info.imports:
            parts = info.imports[parts[0]].split(".") + parts[1:]
        for k in range(len(parts) - 1, 0, -1):
            pkg = self.lc.resolve(".".join(parts[:k]), self.scope, info)
            if pkg is not None:
                found = _members(self.lc, pkg.name).get(parts[k])
                if found is not None:
                    return (*found, parts[k + 1:])
                return None, "", []
        return None, "", []

    def function(self, name: str) -> ClassInfo | None:
        """The class ``name`` written in this class resolves to (once per name: a call's type,
        its output's shape and its full name each ask)."""
        if name not in self.functions:
            self.functions[name] = self.lc.resolve(name, self.scope, self.info)
        return self.functions[name]

    def qualified(self, name: str) -> str:
        """The full name of the function ``name`` is imported as (or "")."""
        fn = self.function(name)
        return fn.name if fn is not None and "." in fn.name else ""

    def array_valued(self, name: str) -> bool:
        """Whether the function ``name`` returns an array."""
        if name in _SAME or name in _BUILTIN or name in _REAL_BUILTIN or name.startswith("Complex"):
            return False
        fn = self.function(name)
        if fn is None:
            return False
        outputs = [n for p, _c, _t, n, _k in self.lc.members(fn) if "output" in p]
        return bool(outputs) and outputs[0] in _arrays(self.lc, fn.name)

    def call(self, name: str, args: list[Node]) -> str:
        if name == "Complex" or name.startswith("Complex.'") and not name.startswith(("Complex.'=='", "Complex.'<>'")):
            return C
        if name in _SAME:
            return args[0].type if args else R
        if name in ("der", "initial", "terminal", "size", "ndims", "integer", "String"):
            return R
        fn = self.function(name)
        if fn is None:
            return R if name in _BUILTIN | _REAL_BUILTIN else U
        outputs = [(c, t) for p, c, t, _n, _k in self.lc.members(fn) if "output" in p]
        return C if outputs and self.complex_class(*outputs[0]) else R


@functools.lru_cache(maxsize=4096)
def _members(lc: LibraryClasses, name: str) -> dict:
    """{member: (its class, its type's name)} of class ``name``, inherited ones too."""
    info = lc.find(name)
    return {} if info is None else {n: (c, t) for _p, c, t, n, _k in lc.members(info)}


@functools.lru_cache(maxsize=4096)
def _arrays(lc: LibraryClasses, name: str) -> set:
    info = lc.find(name)
    return set() if info is None else lc.arrays(info)


def _walk(node: Node):
    yield node
    for k in node.kids:
        yield from _walk(k)


@functools.lru_cache(maxsize=4096)
def _is_complex(lc: LibraryClasses, name: str) -> bool:
    if name.split(".")[-1] == "Complex" and "." not in name:
        return True
    info = lc.find(name)
    if info is None:
        return False
    scope = name.rsplit(".", 1)[0] if "." in name else ""
    if info.short is not None:
        head = re.sub(r"^(?:input|output|flow|stream|parameter|constant|discrete)\s+", "", info.short)
        head = re.match(r"[\w.]+", head)
        if head is None:
            return False
        base = lc.resolve(head.group(), scope, info) or lc.resolve(head.group(), name)
        return base is not None and _is_complex(lc, base.name) or head.group().split(".")[-1] == "Complex"
    return any(_is_complex(lc, b.name) for b in lc.bases(info))


def _statements(toks: list[Tok]):
    """(class path, section, statement tokens) of each statement of a file's tokens; section is
    'decl', 'equation' or 'algorithm'."""
    stack: list[list] = []          # [name, section]
    within: list[str] = []
    i, n = 0, len(toks)
    while i < n:
        t = toks[i].text
        if t == "within":
            j = i + 1
            while j < n and toks[j].text != ";":
                j += 1
            within = "".join(x.text for x in toks[i + 1:j]).split(".") if j > i + 1 else []
            i = j + 1
            continue
        if t == "end" and i + 1 < n and stack and toks[i + 1].text == stack[-1][0]:
            stack.pop()
            i += 3
            continue
        head = _class_head(toks, i)
        if head is not None:
            name, j, short = head
            if short:
                while j < n and toks[j].text != ";":
                    j += 1
                i = j + 1
                continue
            stack.append([name, "decl"])
            i = j
            while i < n and toks[i].kind == "str":      # its description (a nested class may follow)
                i += 1
            continue
        if t in ("equation", "algorithm") and stack:
            stack[-1][1] = t
            i += 1
            continue
        if t in ("public", "protected") and stack:
            stack[-1][1] = "decl"
            i += 1
            continue
        if t == "initial" and i + 1 < n and toks[i + 1].text in ("equation", "algorithm"):
            i += 1
            continue
        j, depth = i, 0
        while j < n and not (toks[j].text == ";" and depth == 0):
            depth += {"(": 1, "[": 1, "{": 1, ")": -1, "]": -1, "}": -1}.get(toks[j].text, 0)
            j += 1
        if stack:
            yield [*within, *(s[0] for s in stack)], stack[-1][1], toks[i:j]
        i = j + 1


_PREFIX = {"partial", "encapsulated", "final", "replaceable", "redeclare", "expandable", "pure", "impure",
           "inner", "outer"}


def _class_head(toks, i):
    """(name, index after the head, short) where a class definition starts at ``toks[i]``."""
    j = i
    while j < len(toks) and toks[j].text in _PREFIX:
        j += 1
    if j >= len(toks) or toks[j].text not in _CLASS:
        return None
    if toks[j].text == "operator" and j + 1 < len(toks) and toks[j + 1].text in ("record", "function"):
        j += 1
    if j + 1 >= len(toks) or toks[j + 1].kind != "id":
        return None
    name, k = toks[j + 1].text, j + 2
    if k < len(toks) and toks[k].text == "=":
        return name, k, True
    if name == "extends" and k < len(toks) and toks[k].kind == "id":     # model extends X
        return toks[k].text, k + 1, False
    return name, k, False


def uses_complex(text: str) -> bool:
    """Whether ``text``'s code (not its comments and strings) names Complex or a library built on it."""
    return MENTIONS.search(text) is not None and MENTIONS.search(masked(text)) is not None


def rewrite(text: str, lc: LibraryClasses) -> str:
    """``text`` (a file of Modelica classes) with its Complex operators written as calls."""
    if not uses_complex(text):
        return text
    toks = tokens(text)
    edits = []
    typers, branches = {}, {}     # branches: the if-equations open in each class's equations
    for path, section, st in _statements(toks):
        key = ".".join(path)
        if section == "equation":
            try:
                branches[key] = branches.get(key, 0) + _headers(st, section)[2]
            except IndexError:
                pass
        if not st or not any(t.text in ("+", "-", "*", "/", "^", "=", ".*", "./") for t in st):
            continue
        if key not in typers:
            typers[key] = _Typer(lc, lc.find(key))
        typer = typers[key]
        if typer.info is None:
            continue
        if section == "decl":
            edits += _modifiers(st, typer, text)
        try:
            edit = _statement(st, section, typer, text, branches.get(key, 0) > 0)
        except (_Unread, IndexError, RecursionError):
            continue
        if edit is not None:
            edits.append(edit)
    return applied(text, edits)


def applied(text: str, edits: list[tuple[int, int, str]]) -> str:
    """``text`` with each (start, end, new text) edit made, its line count kept."""
    out, at = [], 0
    for start, end, new in sorted(edits):
        lines, new = text.count("\n", start, end), new.replace("\n", " ")
        out += [text[at:start], new + "\n" * max(0, lines - new.count("\n"))]
        at = end
    out.append(text[at:])
    return "".join(out)


def _comprehension(e: Node, text: str) -> str:
    """A Complex array's value computed on whole arrays (``plug_p.pin.v - plug_n.pin.v``) as
    the comprehension of its elements' constructors (rumoca reads no arithmetic on whole record
    arrays); any other value (a comprehension, a fill) as it is written after the rewrite."""
    whole = next((n for n in _walk(e) if n.kind == "ref" and n.array_at is not None), None)
    if whole is None:
        return _emit(e, text)
    el = _Element("mcl_k")
    return f"{{{_record(e, text, el=el)} for {el.index} in 1:size({text[whole.start:whole.array_at]}, 1)}}"


def _complex_equation(lhs: Node, rhs: Node, text: str, parts: bool = False):
    """(start, end, new text) of a Complex equation; an equation of whole arrays as a for-loop
    over their elements (rumoca reads no record array's equation). ``parts``: as two Real
    equations always (in an if-equation's branch: rumoca counts a record equation as one, and
    the branches' counts must agree)."""
    solve = _split if parts else _equation
    if not (_arrayed(lhs) or _arrayed(rhs)):
        new, _ = solve(lhs, rhs, text)
        return (lhs.start, rhs.end, new) if new is not None else None
    comprehension = next((n.iterator for n in (rhs, lhs) if n.kind == "array" and n.iterator), "")
    el = _Element(comprehension or "mcl_k")
    new, ref = solve(lhs, rhs, text, el)
    if new is None or ref is None or ref.array_at is None:
        return None
    return lhs.start, rhs.end, f"for {el.index} in 1:size({text[ref.start:ref.array_at]}, 1) loop {new}; end for"


def _modifiers(st: list[Tok], typer: _Typer, text: str) -> list:
    """The edits of a declaration's modifiers' values (``powerBalance(power1 = sum({real(v[j]*i[j])
    for j in 1:m}))``): the class's own names, its operators as calls, a Complex value as the
    record's constructor."""
    edits, depth = [], 0
    for k, t in enumerate(st):
        depth += {"(": 1, "[": 1, "{": 1, ")": -1, "]": -1, "}": -1}.get(t.text, 0)
        if t.text == "=" and depth == 0:
            break           # the binding: the statement's own (named arguments in it are not modifiers)
        if t.text != "=" or st[k - 1].kind != "id":
            continue
        try:
            e = _Parser(st[k + 1:], typer).expression()
        except (_Unread, IndexError, RecursionError):
            continue
        if e.type == C and not _arrayed(e):
            new = _record(e, text)
        elif _changed(e) and not _arrayed(e):
            new = _emit(e, text)
        else:
            continue
        if new != text[e.start:e.end]:
            edits.append((e.start, e.end, new))
    return edits


def _headers(st: list[Tok], section: str) -> tuple[int, set, int, int]:
    """(where the statement's own part starts, the iterators of the for-loops it opens, the
    if-equations it opens less those it closes, the same of for-loops) past its structured
    headers: ``for ... loop``, ``if ... then``, ``else``, ``end if``, ``when ... then``."""
    k, locals_, opened, loops = 0, set(), 0, 0
    while k < len(st):
        t = st[k].text
        if t == "for":
            locals_.add(st[k + 1].text)
            loops += 1
            while st[k].text != "loop":
                k += 1
            k += 1
        elif t in ("if", "elseif", "when", "elsewhen", "while") and section in ("equation", "algorithm"):
            opened += t == "if"
            while st[k].text not in ("then", "loop"):
                k += 1
            k += 1
        elif t == "else":
            k += 1
        elif t == "end" and k + 1 < len(st) and st[k + 1].text in ("for", "if", "when", "while"):
            opened -= st[k + 1].text == "if"
            loops -= st[k + 1].text == "for"
            k += 2
        else:
            break
    return k, locals_, opened, loops


def trimmed(st: list[Tok], section: str) -> list[Tok]:
    """A statement's tokens without a class's description before it, nor an equation's
    description and annotation after it."""
    while st and st[0].kind == "str":      # a class's description
        st = st[1:]
    for k, t in enumerate(st):             # an equation's description and annotation
        if t.text == "annotation" or (t.kind == "str" and section != "decl" and k and st[k - 1].text not in "(,="):
            return st[:k]
    return st


def _statement(st: list[Tok], section: str, typer: _Typer, text: str, branch: bool = False):
    """(start, end, new text) of one statement's rewritten part, or None; ``branch``: the
    statement is inside an if-equation."""
    st = trimmed(st, section)
    if not st:
        return None
    if section == "decl":
        if st[0].text in ("extends", "import", "annotation"):
            return None
        depth = 0
        for k, t in enumerate(st):
            depth += {"(": 1, "[": 1, "{": 1, ")": -1, "]": -1, "}": -1}.get(t.text, 0)
            if t.text == "=" and depth == 0:
                break
        else:
            return None
        p = _Parser(st[k + 1:], typer)
        e = p.expression()
        array = any(t.text == "[" for t in st[:k]) or _arrayed(e)
        if e.type == C and array and _arrayed(e):
            new = _comprehension(e, text)
        else:
            new = _record(e, text) if e.type == C and not array else _emit(e, text)     # a binding is an equation too
        return (e.start, e.end, new) if new != text[e.start:e.end] else None
    k, locals_, _, _ = _headers(st, section)
    rest = st[k:]
    if not rest or rest[0].text in ("connect", "annotation"):
        return None
    typer.locals = locals_
    p = _Parser(rest, typer)
    lhs = p.expression()
    if p.peek() in ("=", ":="):
        assign = p.take().text
        rhs = p.expression()
        if p.i != len(rest):
            raise _Unread("trailing")
        if assign == "=" and (lhs.type == C or rhs.type == C):
            return _complex_equation(lhs, rhs, text, parts=branch)
        if not _changed(rhs) and not _changed(lhs):
            return None
        return lhs.start, rhs.end, f"{_emit(lhs, text)} {assign} {_emit(rhs, text)}"
    if p.i != len(rest) or not _changed(lhs):
        return None
    return lhs.start, lhs.end, _emit(lhs, text)
