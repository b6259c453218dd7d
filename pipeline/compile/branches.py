"""Branches of if-expressions evaluated only when taken.

CasADi's SX writes ``if c then a else b`` as ``(c ? a : 0) + (!c ? b : 0)`` and evaluates
both ``a`` and ``b`` on every call. Where a branch is a large computation of its own (IF97's
water properties compute each region's equations of state, tens of thousands of instructions,
where one region is taken) this costs several times what is needed. :func:`short_circuited`
moves each such branch into a function called through a CasADi switch: an SX call node whose
branch runs only when its condition holds, and gives zeros otherwise, as the if-expression does.
Derivatives, code generation and serialisation go through CasADi's own Switch.
"""
from __future__ import annotations

import hashlib
from collections import OrderedDict

import casadi as ca

SMALLEST = 400          # instructions: a branch below this is left inline (a call costs about as much)
_IEZ, _IN, _OUT, _CONST, _CALL = ca.OP_IF_ELSE_ZERO, ca.OP_INPUT, ca.OP_OUTPUT, ca.OP_CONST, ca.OP_CALL
#: the switches made, by their branch's serialised form: a medium's function inlined at every
#: pipe segment gives each block the same branches on other inputs (PumpingSystem: 123 blocks
#: of 30 000-70 000 instructions, mostly IF97's regions), each made and split once
_SWITCHES: OrderedDict = OrderedDict()
_KEPT = 256
#: the same switches by their branch's form in the program (see :meth:`_Program._shape`)
_SHAPES: OrderedDict = OrderedDict()


def short_circuited(f: ca.Function, smallest: int = SMALLEST, depth: int = 0) -> ca.Function:
    """``f`` (an SX function) with each branch of ``smallest`` instructions or more evaluated
    only when taken; ``f`` itself where there is none (or it is not an SX function)."""
    if not f.is_a("SXFunction") or f.n_instructions() < 2 * smallest or depth > 8 or \
            not any(f.instruction_id(k) == _IEZ for k in range(f.n_instructions())):
        return f
    # (equal conditions made one node: each if-expression on ``region == 1`` writes its own;
    # a branch is rebuilt from nodes made so, and needs it no more)
    outs = f.call(f.sx_in())
    g = ca.Function(f.name(), f.sx_in(), ca.cse(outs) if depth == 0 else outs, {"live_variables": False})
    prog = _Program(g)
    if prog.calls or not prog.cones(smallest):
        return f
    return prog.rebuilt(f.name(), smallest, depth, f.name_in(), f.name_out())


class _Program:
    """An SX function's instructions, each node named by the work slot it writes (one slot per
    node, the function made without reusing slots)."""

    def __init__(self, g: ca.Function):
        self.g = g
        n = g.n_instructions()
        ops = [g.instruction_id(k) for k in range(n)]
        self.calls = _CALL in ops
        self.op, self.ins, self.outputs, self.consts, self.inputs, self.order = {}, {}, [], {}, {}, []
        for k, op in enumerate(ops):
            if op == _OUT:
                self.outputs.append((g.instruction_output(k), g.instruction_input(k)[0]))
                continue
            s = g.instruction_output(k)[0]
            self.op[s] = op
            self.order.append(s)
            if op == _IN:
                self.inputs[s] = g.instruction_input(k)
            elif op == _CONST:
                self.consts[s] = g.instruction_constant(k)
            else:
                self.ins[s] = tuple(g.instruction_input(k))

    def reads(self, s: int) -> tuple:
        return self.ins.get(s, ())

    def cones(self, smallest: int) -> dict:
        """condition slot -> (its branch's nodes, in order; its roots ``c ? x : 0``): the nodes
        used only under that condition, outermost conditions first. Branches smaller than
        ``smallest`` are left out."""
        # guard: the outermost condition (its slot) that every use of a node is under; None:
        # needed outside any branch. Set from the uses, which come later: in reverse order
        guard: dict[int, int | None] = {s: None for _, s in self.outputs}
        ins = self.ins
        for s in reversed(self.order):
            mine = guard.setdefault(s, None)
            r = ins.get(s, ())
            taken = self.op[s] == _IEZ and r[1] != r[0]     # c ? x : 0, x under c
            for j, d in enumerate(r):
                v = r[0] if taken and j == 1 and mine is None else mine
                guard[d] = v if d not in guard or guard[d] == v else None
        nodes: dict[int, list] = {}
        for s in self.order:
            if guard[s] is not None and self.reads(s):      # (inputs and constants: passed in)
                nodes.setdefault(guard[s], []).append(s)
        roots: dict[int, list] = {}
        for s in self.order:
            if guard[s] is None and self.op[s] == _IEZ:
                c, x = self.ins[s]
                if guard.get(x) == c:
                    roots.setdefault(c, []).append(s)
        self.big = {c: (nodes[c], roots[c]) for c in roots if len(nodes.get(c, ())) >= smallest}
        self._acyclic()
        return self.big

    def _acyclic(self) -> None:
        """Leave inline each branch whose inputs depend on its own or another branch's result
        in a cycle (two if-expressions on one condition, the second reading the first)."""
        while self.big:
            bit = {c: 1 << i for i, c in enumerate(self.big)}
            root_of = {r: c for c, (_, rs) in self.big.items() for r in rs}
            dep: dict[int, int] = {}
            for s in self.order:
                m = 0
                for d in self.reads(s):
                    m |= dep.get(d, 0)
                if s in root_of:
                    m |= bit[root_of[s]]
                dep[s] = m
            self.frontier = {c: _frontier(self, nodes, roots) for c, (nodes, roots) in self.big.items()}
            needs = {c: dep.get(c, 0) for c in self.big}
            for c, reads in self.frontier.items():
                for d in reads:
                    needs[c] |= dep.get(d, 0)
            cyclic = [c for c in self.big if _reaches(c, needs, bit)]
            if not cyclic:
                return
            for c in cyclic:
                del self.big[c]

    def rebuilt(self, name: str, smallest: int, depth: int, names_in, names_out) -> ca.Function:
        sx_in = self.g.sx_in()
        root_of = {r: (c, i) for c, (_, rs) in self.big.items() for i, r in enumerate(rs)}
        frontier = self.frontier        # (:meth:`_acyclic`'s, of the branches kept)
        w: dict[int, ca.SX] = {}
        calls: dict[int, list] = {}

        def deps(s):
            if s in root_of:
                c = root_of[s][0]
                return [c, *frontier[c]]
            return self.reads(s)

        def make(s):
            if s in root_of:
                c, i = root_of[s]
                if c not in calls:
                    calls[c] = self._branch(c, frontier[c], w, smallest, depth)
                return calls[c][i]
            return self.node(s, w, sx_in)

        outs = []
        for o in range(self.g.n_out()):
            outs.append([ca.SX(0)] * self.g.sparsity_out(o).nnz())
        for (o, nz), s in self.outputs:
            outs[o][nz] = _built(s, w, deps, make)
        res = [ca.SX(self.g.sparsity_out(o), ca.vertcat(*v) if v else ca.SX(0, 1)) for o, v in enumerate(outs)]
        return ca.Function(name, sx_in, res, names_in, names_out)

    def node(self, s: int, w: dict, sx_in) -> ca.SX:
        """Node ``s`` built from the nodes it reads, ``w`` (an input from ``sx_in``)."""
        if s in self.consts:
            return ca.SX(self.consts[s])
        if s in self.inputs:
            i, nz = self.inputs[s]
            return sx_in[i].nz[nz]
        r, op = self.ins[s], self.op[s]
        return ca.SX.unary(op, w[r[0]]) if len(r) == 1 else ca.SX.binary(op, w[r[0]], w[r[1]])

    def _branch(self, c: int, frontier: list, w: dict, smallest: int, depth: int) -> list:
        """The branch under condition slot ``c``, called through a switch: its roots' values."""
        nodes, roots = self.big[c]
        shape = (self._shape(nodes, roots, frontier), smallest, depth)
        call = _SHAPES.get(shape)
        if call is None:
            f_in = ca.SX.sym("f", len(frontier))
            local = {s: f_in[i] for i, s in enumerate(frontier)}
            for s in nodes:
                local[s] = self.node(s, local, None)
            taken = ca.vertcat(*[local[self.ins[r][1]] for r in roots])
            call = _kept(_SHAPES, shape, _switch(f_in, taken, smallest, depth))
        got = call(w[c], ca.vertcat(*[w[s] for s in frontier]) if frontier else ca.SX(0, 1))
        return ca.vertsplit(got)

    def _shape(self, nodes: list, roots: list, frontier: list) -> str:
        """The branch's form as a digest of its operations and how they are wired, from the
        program alone: an equal branch met in another block (the same medium function at
        another pipe segment) is then found without building its expression to serialise it."""
        at = {s: i for i, s in enumerate(frontier)}
        n = len(at)
        for k, s in enumerate(nodes):
            at[s] = n + k
        ins, op = self.ins, self.op
        form = [len(frontier), *[(op[s], *[at[d] for d in ins[s]]) for s in nodes],
                *[at[ins[r][1]] for r in roots]]
        return hashlib.sha1(repr(form).encode()).hexdigest()


def _switch(f_in: ca.SX, taken: ca.SX, smallest: int, depth: int) -> ca.Function:
    """(c, f) -> c ? taken(f) : 0, the branch's own branches short-circuited; made once per
    distinct branch (named by its form: equal branches are one function in generated code)."""
    key = hashlib.sha1(ca.Function("branch", [f_in], [taken]).serialize().encode()).hexdigest()
    if key in _SWITCHES:
        _SWITCHES.move_to_end(key)
        return _SWITCHES[key]
    name = f"branch_{key[:16]}"
    body = short_circuited(ca.Function(name, [f_in], [taken]), smallest, depth + 1)
    zero = ca.Function(name + "_0", [f_in], [ca.SX.zeros(taken.sparsity())])
    c_mx, f_mx = ca.MX.sym("c"), ca.MX.sym("f", f_in.numel())
    switch = ca.Function.if_else(name + "_if", body, zero)
    return _kept(_SWITCHES, key, ca.Function(name + "_call", [c_mx, f_mx], [switch(c_mx, f_mx)], {"never_inline": True}))


def _kept(cache: OrderedDict, key, value):
    """``value``, kept in ``cache`` under ``key`` (the oldest dropped past :data:`_KEPT`)."""
    cache[key] = value
    while len(cache) > _KEPT:
        cache.popitem(last=False)
    return value


def _frontier(prog: _Program, nodes: list, roots: list) -> list:
    """The nodes outside a branch that it reads (its values' included), in order."""
    mine, tops = set(nodes), set(roots)
    seen, out = set(), []
    for s in [*nodes, *roots]:
        for d in (prog.ins[s][1:] if s in tops else prog.reads(s)):
            if d not in mine and d not in seen:
                seen.add(d)
                out.append(d)
    return out


def _reaches(c: int, needs: dict, bit: dict) -> bool:
    """Does branch ``c`` need, through the branches it needs, its own result?"""
    seen, todo = 0, needs[c]
    while todo & ~seen:
        seen |= todo
        for d, b in bit.items():
            if todo & b:
                todo |= needs[d]
    return bool(seen & bit[c])


def _built(s: int, w: dict, deps, make) -> ca.SX:
    """Node ``s``'s value, its inputs built first (iteratively: chains run deep)."""
    stack = [s]
    while stack:
        k = stack[-1]
        if k in w:
            stack.pop()
            continue
        todo = [d for d in deps(k) if d not in w]
        if todo:
            stack.extend(todo)
            continue
        w[k] = make(k)
        stack.pop()
    return w[s]
