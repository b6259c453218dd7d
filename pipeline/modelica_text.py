"""pymoca AST -> Modelica source text (expressions, modifications, equations).

The connection graph keeps declarations and equations as pymoca AST; rewriting a model (a
component replaced, a component added) prints them back with these functions. Binary operations
are always parenthesised: the text is read by compilers, and it can never change precedence.
"""
from __future__ import annotations

from pymoca import ast

from .errors import UnsupportedConstruct

_INFIX = {"+", "-", "*", "/", "^", "<", ">", "<=", ">=", "==", "<>", "!=", "and", "or"}


def ref(c: ast.ComponentRef) -> str:
    text = c.name
    idx = [i for group in (c.indices or []) for i in group if i is not None
           and not (isinstance(i, ast.Primary) and i.value is None)]
    if idx:
        text += "[" + ", ".join(expr(i) for i in idx) + "]"
    for child in c.child or []:
        text += "." + ref(child)
    return text


def expr(e) -> str:
    if isinstance(e, ast.Primary):
        v = e.value
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace('"', '\\"') + '"'
        return "0" if v is None else repr(v)
    if isinstance(e, ast.ComponentRef):
        return ref(e)
    if isinstance(e, ast.Array):
        return "{" + ", ".join(expr(v) for v in e.values) + "}"
    if isinstance(e, ast.IfExpression):
        parts = [f"if {expr(c)} then {expr(x)}" for c, x in zip(e.conditions, e.expressions)]
        return "(" + " else".join(parts) + f" else {expr(e.expressions[-1])})"
    if isinstance(e, ast.Expression):
        op, args = e.operator, e.operands
        if isinstance(op, ast.ComponentRef):
            op = ref(op)
        if op in _INFIX and len(args) == 2:
            sym = "<>" if op == "!=" else op
            return f"({expr(args[0])} {sym} {expr(args[1])})"
        if op in ("-", "+") and len(args) == 1:
            return f"({op}{expr(args[0])})"
        if op == "not" and len(args) == 1:
            return f"(not {expr(args[0])})"
        return f"{op}({', '.join(expr(a) for a in args)})"
    if isinstance(e, (int, float)):
        return repr(e)
    if isinstance(e, str):
        return e
    raise UnsupportedConstruct(f"cannot print Modelica expression {e!r}")


def modification(m: ast.ClassModification | None) -> tuple[str, str]:
    """A declaration's modification as ("(a = 1, b(start = 2))", "= binding")."""
    if m is None:
        return "", ""
    args, binding = [], ""
    for arg in m.arguments:
        el = arg.value
        if not isinstance(el, ast.ElementModification):
            raise UnsupportedConstruct("cannot rewrite a model with redeclarations or "
                                       "replaceable components in its modifications")
        name = ref(el.component)
        if name == "value":
            binding = " = " + "".join(expr(x) for x in el.modifications)
            continue
        text = name
        for part in el.modifications:
            if isinstance(part, ast.ClassModification):
                inner, inner_binding = modification(part)
                text += inner + inner_binding
            else:
                text += " = " + expr(part)
        args.append(text)
    return ("(" + ", ".join(args) + ")") if args else "", binding


def declaration(sym: ast.Symbol, type_name: str | None = None) -> str:
    """One component or variable declaration, e.g. ``input Real u(unit = "V") "source";``.

    ``type_name`` replaces the declared type (a fully qualified name keeps the text valid when
    the declaration is moved out of its package).
    """
    mods, binding = modification(sym.class_modification)
    prefixes = " ".join(sym.prefixes)
    dims = ""
    if sym.dimensions and any(d is not None and not (isinstance(d, ast.Primary) and d.value is None)
                              for group in sym.dimensions for d in group):
        dims = "[" + ", ".join(expr(d) for group in sym.dimensions for d in group) + "]"
    comment = f' "{sym.comment}"' if sym.comment else ""
    kind = type_name or ref(sym.type)
    return f"{prefixes + ' ' if prefixes else ''}{kind} {sym.name}{dims}{mods}{binding}{comment};"


def equation(eq) -> str:
    if isinstance(eq, ast.ConnectClause):
        return f"connect({ref(eq.left)}, {ref(eq.right)});"
    if isinstance(eq, ast.Equation):
        return f"{expr(eq.left)} = {expr(eq.right)};"
    raise UnsupportedConstruct(f"cannot rewrite a model with a {type(eq).__name__} in its equations")
