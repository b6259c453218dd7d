"""Index reduction by Pantelides' algorithm: CasADi's ``dae_reduce_index`` written again.

CasADi 3.8's version indexes its list of differentiated variables with positions in its list of
all variables once a variable is differentiated twice (a multibody joint's angle: phi, w, a),
and fails ("complement: out of bounds") or picks the wrong states. This is the same algorithm
(structural: differentiate the equations of each structurally singular subset until every
equation can be matched to a highest derivative) with its result assembled by variable, in the
dictionary ``dae_reduce_index`` returns, so ``dae_map_semi_expl`` takes it as before.
"""
from __future__ import annotations

import sys

import casadi as ca

from ..errors import ModelicaError

MAX_DIFFERENTIATIONS = 500


class _Graph:
    """Equations and variables with their derivative links (Pantelides' bipartite graph)."""

    def __init__(self, incidence: list[list[int]], der: list[int]):
        self.eqs = [list(v) for v in incidence]     # equation -> its variables
        self.der = list(der)                        # variable -> its derivative (or -1)
        self.eq_der = [-1] * len(self.eqs)          # equation -> its derivative (or -1)
        self.assign = [-1] * len(self.der)          # variable -> the equation matched to it

    def new_var(self, v: int) -> int:
        if self.der[v] < 0:
            self.der[v] = len(self.der)
            self.der.append(-1)
            self.assign.append(-1)
        return self.der[v]

    def new_eq(self, e: int) -> int:
        """d/dt of equation e: it reads e's variables and their derivatives."""
        if self.eq_der[e] < 0:
            vs = set(self.eqs[e]) | {self.new_var(v) for v in self.eqs[e]}
            self.eq_der[e] = len(self.eqs)
            self.eqs.append(sorted(vs))
            self.eq_der.append(-1)
        return self.eq_der[e]

    def augment(self, e: int, seen_e: set, seen_v: set) -> bool:
        """An augmenting path from equation e over highest derivatives (Duff's search)."""
        seen_e.add(e)
        top = [v for v in self.eqs[e] if self.der[v] < 0]
        for v in top:
            if self.assign[v] < 0:
                self.assign[v] = e
                return True
        for v in top:
            if v not in seen_v:
                seen_v.add(v)
                if self.augment(self.assign[v], seen_e, seen_v):
                    self.assign[v] = e
                    return True
        return False

    def run(self, n_eqs: int) -> None:
        for k in range(n_eqs):
            e, rounds = k, 0
            while True:
                seen_e, seen_v = set(), set()
                if self.augment(e, seen_e, seen_v):
                    break
                rounds += 1
                if rounds > MAX_DIFFERENTIATIONS:
                    raise ModelicaError("index reduction failed: the model is structurally singular "
                                        "(an equation is missing or a variable over-constrained)")
                for v in seen_v:
                    self.new_var(v)
                for q in seen_e:
                    self.new_eq(q)
                for v in seen_v:
                    self.assign[self.der[v]] = self.eq_der[self.assign[v]]
                e = self.eq_der[e]


def _order(link: list[int]) -> list[int]:
    """How many times each entry is a derivative of another (0: an original)."""
    order = [0] * len(link)
    for i, j in enumerate(link):          # derivatives come after what they differentiate
        if j >= 0:
            order[j] = order[i] + 1
    return order


def reduced(impl: dict):
    """Pantelides' algorithm on ``impl`` (keys x_impl, dx_impl, z, alg, t, p): (the graph, every
    variable's symbol, every equation with its derivatives, whose rows are written)."""
    x_impl, dx_impl, z, alg, t = (impl[k] for k in ("x_impl", "dx_impl", "z", "alg", "t"))
    nx = x_impl.numel()
    V = ca.vertcat(x_impl, dx_impl, z)
    rows, cols = ca.jacobian_sparsity(alg, V).get_triplet()
    incidence = [[] for _ in range(alg.numel())]
    for r, c in zip(rows, cols):
        incidence[r].append(c)
    graph = _Graph(incidence, [i + nx if i < nx else -1 for i in range(V.numel())])
    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10 * len(graph.der) + 1000))
    try:
        graph.run(alg.numel())
    finally:
        sys.setrecursionlimit(limit)

    var = ca.vertsplit(V) + [None] * (len(graph.der) - V.numel())
    for i, j in enumerate(graph.der):     # new derivatives, in order (a derivative's source first)
        if j >= V.numel():
            var[j] = ca.SX.sym("d" + var[i].name())
    pairs = [i for i, j in enumerate(graph.der) if j >= 0]
    j1, j2 = ca.vertcat(*[var[i] for i in pairs], t), ca.vertcat(*[var[graph.der[i]] for i in pairs], 1)
    eqs = ca.vertsplit(alg) + [None] * (len(graph.eqs) - alg.numel())
    eq_order = _order(graph.eq_der)
    for order in range(1, max(eq_order) + 1):
        sources = [e for e, d in enumerate(graph.eq_der) if d >= 0 and eq_order[d] == order]
        derived = ca.vertsplit(ca.jtimes(ca.vertcat(*[eqs[e] for e in sources]), j1, j2))
        for e, de in zip(sources, derived):
            eqs[graph.eq_der[e]] = de
    return graph, var, eqs


def reduce_index(impl: dict) -> tuple[dict, dict]:
    """The index-reduced DAE of ``impl`` (keys x_impl, dx_impl, z, alg, t, p), with the keys and
    meaning of ``casadi.dae_reduce_index``'s result (pole 0: no Baumgarte term)."""
    nx, nv = impl["x_impl"].numel(), 2 * impl["x_impl"].numel() + impl["z"].numel()
    graph, var, eqs = reduced(impl)
    z, t, p = impl["z"], impl["t"], impl["p"]
    pairs = [i for i, j in enumerate(graph.der) if j >= 0]
    xs = [var[i] for i in pairs]
    dxs = [var[graph.der[i]] for i in pairs]
    at = {i: k for k, i in enumerate(pairs)}          # a variable's place among xs (CasADi's slip)
    eq_order = _order(graph.eq_der)
    active = [d < 0 for d in graph.eq_der]
    dropped = [eqs[e] for order in range(max(eq_order)) for e, d in enumerate(graph.eq_der)
               if d >= 0 and eq_order[e] == order]

    var_order = _order(graph.der)
    parent = [-1] * len(graph.der)
    for i, j in enumerate(graph.der):
        if j >= 0:
            parent[j] = i
    explicit = []                          # variables two or more derivatives below another
    for i in range(len(graph.der)):
        if var_order[i] >= 2:
            chain, k = [], parent[i]
            while k >= 0:
                chain.append(k)
                k = parent[k]
            explicit += [at[k] for k in chain[1:]]
    explicit = sorted(set(explicit))
    implicit = sorted(set(range(len(xs))) - set(explicit))
    zs = ca.vertsplit(z)
    z_new = [zs[i - 2 * nx] for i in range(2 * nx, nv) if var_order[i] == 0 and graph.der[i] < 0]
    pick = lambda items, idx: ca.vertcat(*[items[k] for k in idx]) if idx else ca.SX(0, 1)
    red = {"x": pick(xs, explicit), "ode": pick(dxs, explicit), "x_impl": pick(xs, implicit),
           "dx_impl": pick(dxs, implicit), "z": ca.vertcat(*z_new) if z_new else ca.SX(0, 1),
           "alg": ca.vertcat(*[e for e, a in zip(eqs, active) if a]), "I": ca.vertcat(*dropped) if dropped else ca.SX(0, 1),
           "t": t, "p": p}
    return red, {"index": max(eq_order) + 1}
