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
"""
from __future__ import annotations

import casadi as ca

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
    guard = _guards(prog)
    singular = {s: safe for s in prog.order if guard.get(s) and (safe := _singular(prog, s))}
    if not singular:
        return parts
    return _rebuilt(prog, guard, singular, g)


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


def _guards(prog: _Program) -> dict[int, frozenset]:
    """slot -> the conditions (their slots) every use of the node is under (empty: needed
    unconditionally). Set from the uses, which come later: in reverse order."""
    guard: dict[int, frozenset] = {s: _EMPTY for _, s in prog.outputs}
    for s in reversed(prog.order):
        mine = guard.setdefault(s, _EMPTY)
        r = prog.reads(s)
        taken = prog.op[s] == _IEZ and r[1] != r[0]     # c ? x : 0, x under c
        for j, d in enumerate(r):
            v = mine | {r[0]} if taken and j == 1 else mine
            guard[d] = v if d not in guard else guard[d] & v
    return guard


def _rebuilt(prog: _Program, guard: dict, singular: dict, g: ca.Function) -> list[ca.SX]:
    """``g``'s outputs rebuilt, each node of ``singular`` (slot -> {operand: safe value}) with
    its operands guarded by the conditions ``guard`` gives it."""
    sx_in = g.sx_in()
    w: dict[int, ca.SX] = {}
    taken: dict[frozenset, ca.SX] = {}          # the conditions together
    other: dict[tuple, ca.SX] = {}              # (conditions, value): the value where they fail
    made: dict[tuple, ca.SX] = {}               # (conditions, operand, value): the operand guarded
    for s in prog.order:
        op, r = prog.op[s], prog.reads(s)
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
