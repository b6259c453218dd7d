"""Singular operations inside if-branches made finite where their branch is not taken.

SX evaluates both branches of ``if c then a else b`` and masks the one not taken. Its value is
then right, but its derivatives need not be: reverse mode (and a Jacobian computed by it, as
CasADi does for a function of one output) passes each node of the branch not taken an adjoint
of 0, and multiplies it by the node's partial derivative. Where that partial is infinite (a
wall-friction law's ``dp/|m_flow|`` in its turbulent branch, evaluated at zero flow), 0 * inf
is NaN, and every entry the branch's inputs reach is NaN: a heating circuit started at rest had
a NaN Jacobian in every row of its initial system, its finite differences finite.

:func:`guarded` gives each such operation, where every use of it is under some conditions, the
operand ``if conds then operand else safe``: the same value and derivatives where the branch is
taken, a finite operation (division by 1, sqrt(1), log(1), asin(0)) where it is not.

The same 0 x inf comes from values that comparisons read outside any branch, and only branches
differentiate (or nothing does): IF97 water picks its region by comparing the temperature with
``572.5 + sqrt((p/1e6 - 13.92)/0.00102)``, NaN below 13.9 MPa (and the comparison false, as
meant). A branch's guard would change the value the comparison reads; such an operation is
instead given its operand where that lies inside its domain and, outside, the value it takes
there as a constant (NaN, or at the domain's edge 0, inf, asin(1)): every value and comparison
as before, and an adjoint of 0 stays 0 (an open tank of IF97 water draining through a pipe had
a NaN Jacobian in every row, its directional derivatives finite). At the edge, in a branch
taken, the derivative is then 0 where it was infinite.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .branches import _IEZ, _Program

#: operation -> {operand: a value where it and its partial derivatives are finite} (the
#: operations with a singularity; not those that only overflow, exp(800))
SAFE = {ca.OP_DIV: {1: 1.0}, ca.OP_INV: {0: 1.0}, ca.OP_SQRT: {0: 1.0}, ca.OP_LOG: {0: 1.0},
        ca.OP_POW: {0: 1.0}, ca.OP_CONSTPOW: {0: 1.0}, ca.OP_ASIN: {0: 0.0}, ca.OP_ACOS: {0: 0.0},
        ca.OP_ATANH: {0: 0.0}, ca.OP_ACOSH: {0: 2.0}, ca.OP_ATAN2: {0: 0.0, 1: 1.0}}
_EMPTY: frozenset = frozenset()


def guarded(parts: list[ca.SX]) -> list[ca.SX]:
    """``parts`` (SX expressions) with each singular operation used only inside if-branches
    given safe operands where those branches are not taken; ``parts`` themselves where none is
    (or where the expressions hold calls)."""
    if not parts:
        return parts
    syms = ca.symvar(ca.vertcat(*[ca.vec(e) for e in parts]))
    g = ca.Function("guarded", [ca.vertcat(*syms)] if syms else [ca.SX(0, 1)], parts,
                    {"live_variables": False, "allow_free": True})
    ops = [g.instruction_id(k) for k in range(g.n_instructions())]
    if _IEZ not in ops or not any(op in SAFE for op in ops):
        return parts
    prog = _Program(g)
    if prog.calls:
        return parts
    guard, need = _guards(prog), _guards(prog, differentiated=True)
    singular = {s: safe for s in prog.order
                if (guard.get(s) or need.get(s) != _EMPTY) and (safe := _singular(prog, s))}
    if not singular:
        return parts
    # (where no branch guards the value, but the derivative is needed only in branches, or never)
    return _rebuilt(prog, guard, singular, g, {s for s in singular if not guard.get(s)})


def _singular(prog: _Program, s: int) -> dict:
    """{operand: its safe value} of node ``s``, where it can be singular (not x / 2, x^2)."""
    safe = SAFE.get(prog.op[s])
    if not safe:
        return {}
    r = prog.reads(s)
    if prog.op[s] == ca.OP_CONSTPOW and r[1] in prog.consts:
        n = float(prog.consts[r[1]])
        if n >= 0 and n == int(n):
            return {}
    return {j: v for j, v in safe.items() if r[j] not in prog.consts}


#: comparisons and logic: their results have no derivative, and neither do their operands' uses
_LOGIC = {ca.OP_LT, ca.OP_LE, ca.OP_EQ, ca.OP_NE, ca.OP_NOT, ca.OP_AND, ca.OP_OR}


def _guards(prog: _Program, differentiated: bool = False) -> dict[int, frozenset]:
    """slot -> the conditions (their slots) every use of the node is under (empty: needed
    unconditionally). Set from the uses, which come later: in reverse order. ``differentiated``:
    only the uses that differentiate it count (not comparisons, logic, if-conditions); a node
    then absent is never differentiated."""
    guard: dict[int, frozenset] = {s: _EMPTY for _, s in prog.outputs}
    for s in reversed(prog.order):
        if differentiated and (s not in guard or prog.op[s] in _LOGIC):
            continue
        mine = guard.setdefault(s, _EMPTY)
        r = prog.reads(s)
        taken = prog.op[s] == _IEZ and r[1] != r[0]     # c ? x : 0, x under c
        for j, d in enumerate(r):
            if differentiated and taken and j == 0:
                continue                # the condition: no derivative
            v = mine | {r[0]} if taken and j == 1 else mine
            guard[d] = v if d not in guard else guard[d] & v
    return guard


#: unary operation -> (its operand's open domain, where values and derivatives are finite; a point
#: inside it; [(operand at an edge, the value there)]; elsewhere the value is NaN)
_DOMAIN = {ca.OP_SQRT: (lambda x: x > 0, 1.0, [(0.0, 0.0)]),
           ca.OP_LOG: (lambda x: x > 0, 1.0, [(0.0, -np.inf)]),
           ca.OP_ASIN: (lambda x: ca.fabs(x) < 1, 0.0, [(1.0, np.pi / 2), (-1.0, -np.pi / 2)]),
           ca.OP_ACOS: (lambda x: ca.fabs(x) < 1, 0.0, [(1.0, 0.0), (-1.0, np.pi)]),
           ca.OP_ATANH: (lambda x: ca.fabs(x) < 1, 0.0, [(1.0, np.inf), (-1.0, -np.inf)]),
           ca.OP_ACOSH: (lambda x: x > 1, 2.0, [(1.0, 0.0)])}


def _detached(op: int, x: ca.SX, n=None) -> ca.SX | None:
    """``op(x)`` (``x^n`` for a constant ``n``) with the same value everywhere, computed from a
    finite operand outside the operation's domain: None where ``op`` is not one of those."""
    if op == ca.OP_CONSTPOW:
        if n is None:
            return None
        n = float(n)
        whole = n == int(n)          # (a negative whole power: finite for x < 0, inf at 0)
        inside = x != 0 if whole else x > 0
        edges = [(0.0, np.inf if n < 0 else 0.0 if n > 0 else 1.0)]
        f = lambda a: ca.constpow(a, n)        # noqa: E731
        safe = 1.0
    elif op in _DOMAIN:
        domain, safe, edges = _DOMAIN[op]
        inside = domain(x)
        f = lambda a: ca.SX.unary(op, a)       # noqa: E731
    else:
        return None
    outside = ca.SX(np.nan)
    for at, value in edges:
        outside = ca.if_else(x == at, value, outside)
    return ca.SX.binary(_IEZ, inside, f(ca.if_else(inside, x, safe))) + ca.SX.binary(_IEZ, ca.logic_not(inside), outside)


def _rebuilt(prog: _Program, guard: dict, singular: dict, g: ca.Function, detached: set = frozenset()) -> list[ca.SX]:
    """``g``'s outputs rebuilt, each node of ``singular`` (slot -> {operand: safe value}) with
    its operands guarded by the conditions ``guard`` gives it, or, where its value is read
    outside them and its derivative only inside or never (``detached``), computed from an
    operand inside its domain (:func:`_detached`)."""
    sx_in = g.sx_in()
    w: dict[int, ca.SX] = {}
    taken: dict[frozenset, ca.SX] = {}          # the conditions together
    other: dict[tuple, ca.SX] = {}              # (conditions, value): the value where they fail
    made: dict[tuple, ca.SX] = {}               # (conditions, operand, value): the operand guarded
    for s in prog.order:
        op, r = prog.op[s], prog.reads(s)
        if s in detached:
            alone = _detached(op, w[r[0]], prog.consts.get(r[1]) if op == ca.OP_CONSTPOW else None)
            if alone is not None:
                w[s] = alone
                continue
        # (only conditions computed before the node: a condition that reads it guards nothing)
        conds = frozenset(c for c in guard.get(s, _EMPTY) if c in w)
        safe = singular.get(s) if conds else None
        if not safe:
            w[s] = prog.node(s, w, sx_in)
            continue
        if conds not in taken:
            taken[conds] = _all([w[c] for c in sorted(conds)])
        for v in safe.values():
            if (conds, v) not in other:
                other[conds, v] = ca.SX.binary(_IEZ, ca.logic_not(taken[conds]), ca.SX(v)) if v else ca.SX(0)
        # (c ? x : 0) + (!c ? safe : 0), each made once (a branch divides by |m_flow| often)
        for j in safe:
            key = conds, r[j], safe[j]
            if key not in made:
                made[key] = ca.SX.binary(_IEZ, taken[conds], w[r[j]]) + other[conds, safe[j]]
        args = [made[conds, d, safe[j]] if j in safe else w[d] for j, d in enumerate(r)]
        w[s] = ca.SX.unary(op, args[0]) if len(args) == 1 else ca.SX.binary(op, args[0], args[1])
    outs = [[ca.SX(0)] * g.sparsity_out(o).nnz() for o in range(g.n_out())]
    for (o, nz), s in prog.outputs:
        outs[o][nz] = w[s]
    return [ca.SX(g.sparsity_out(o), ca.vertcat(*v) if v else ca.SX(0, 1)) for o, v in enumerate(outs)]


def _all(cs: list[ca.SX]) -> ca.SX:
    out = cs[0]
    for c in cs[1:]:
        out = ca.logic_and(out, c)
    return out
