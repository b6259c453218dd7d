"""State selection by dummy derivatives (Mattsson and Söderlind 1993).

Pantelides' algorithm differentiates a model's constraints; integrating every variable that
then appears differentiated, with the constraints themselves dropped, lets the states drift off
them. Where the constraints are linear, a linear multistep method keeps them to rounding; where
they are not (a multibody loop's positions, a body's rotation matrix: 120 states for a revolute
constraint between two bodies), the drift grows until the solver stalls. Here every equation and
every derivative Pantelides made is kept, and as many derivatives as there are differentiated
equations are made algebraic ("dummy" derivatives), chosen, order by order from the highest, so
that the differentiated equations determine them: the states left are independent, and the
system is of index 1. Variables declared ``stateSelect = prefer`` or ``always`` are the last
chosen as dummies, ``avoid`` and ``never`` the first.
"""
from __future__ import annotations

import logging
import warnings

import casadi as ca
import numpy as np
import scipy.linalg

from .pantelides import reduced

log = logging.getLogger(__name__)

#: rank of each stateSelect: the higher, the later a derivative of it is made a dummy
RANK = {"Never": -2, "Avoid": -1, "Default": 0, "Prefer": 1, "Always": 2}
#: points (and their seed) where a choice of dummies the declarations leave open is checked to
#: keep its determinant's sign (:func:`_one_sign`)
SIGN_POINTS, SIGN_SEED = 40, 1


def select(impl: dict, names: list[str], rank: dict, start: np.ndarray, p_values: np.ndarray,
           modes: ca.SX = ca.SX(0, 1)):
    """(the index-1 semi-explicit DAE of ``impl`` by dummy derivatives, keys x, z, ode, alg, p,
    t; its map back to ``impl``'s variables); None where no selection of dummies makes it so
    (a differentiated block singular at the start values and at a random point) or where the
    model does not decide it (see :func:`_tied`, :func:`_switching`). ``names`` and ``start``: of impl's x_impl then z; ``rank``: stateSelect by
    name; ``p_values``: of impl's p; ``modes``: the parameters that hold discrete values."""
    graph, var, eqs = reduced(impl)
    nx, nz = impl["x_impl"].numel(), impl["z"].numel()
    n = len(graph.der)
    parent_v, parent_e = [-1] * n, [-1] * len(eqs)
    for i, j in enumerate(graph.der):
        if j >= 0:
            parent_v[j] = i
    for e, d in enumerate(graph.eq_der):
        if d >= 0:
            parent_e[d] = e
    base = list(range(n))                    # each variable's undifferentiated ancestor
    for j in range(n):
        if parent_v[j] >= 0:
            base[j] = base[parent_v[j]]
    base_name = [names[b] if b < nx else names[b - nx] for b in base]    # (no dx is a base)
    # (an original state x is wanted as a state before an algebraic unknown Pantelides differentiated)
    want = [(RANK.get(rank.get(base_name[v], "Default"), 0), base[v] < nx) for v in range(n)]
    H = [e for e in range(len(eqs)) if graph.eq_der[e] < 0 and parent_e[e] >= 0]
    cand = sorted({v for e in H for v in graph.eqs[e] if graph.der[v] < 0 and parent_v[v] >= 0})
    point = np.concatenate([_point(var, nx, nz, start), p_values, [0.0]])
    var_p = [*var, *ca.vertsplit(impl["p"]), impl["t"]]
    dummies, ties = set(), []
    while H:
        rows = ca.vertcat(*[eqs[e] for e in H])
        jac = ca.jacobian(rows, ca.vertcat(*[var[v] for v in cand]))
        if _switching(jac, modes, impl["p"], p_values):
            # (chosen in the mode the model starts in, the states may not determine the
            # others in another: a machine braked by a switch; a reference path's position,
            # piecewise in time, differentiated twice switches only in what no choice reads)
            log.debug("dummy derivatives: a differentiated equation switches with the model's modes")
            return None
        wants = [want[v] for v in cand]
        chosen, Ms = _independent(jac, var_p, point, wants)
        if chosen is None:
            return None
        # (at the start and at the random point: a coefficient 0 at the start, y of a pendulum
        # released level, hides a choice that is there; a dummy that an equation gives with a
        # constant coefficient stays one wherever the run goes: its tie is no choice)
        fixed = _explicit(jac, chosen, ca.vertcat(*var), Ms[0])
        tied = [(cand[d], cand[c]) for M in Ms for d, c in _tied(M, chosen, [w[0] for w in wants])
                if d not in fixed]
        if tied and not _one_sign(jac[:, chosen], var_p, point):
            ties += tied
        picked = [cand[k] for k in chosen]
        dummies.update(v for v in picked if parent_v[v] >= 0)
        H = [parent_e[e] for e in H if parent_e[parent_e[e]] >= 0]
        cand = [parent_v[v] for v in picked if parent_v[v] >= 0]
    states = [v for v in range(n) if graph.der[v] >= 0 and graph.der[v] not in dummies and v not in dummies]
    is_state = set(states)
    # (a derivative left out that could replace a dummy of the same stateSelect, its variable
    # a state: which variables are states is then a choice of the start point, not the model's)
    alias = _aliases(var, eqs)
    tie = next(((d, c) for d, c in ties if parent_v[c] in is_state and alias(d) != alias(c)), None)
    if tie:
        log.debug("dummy derivatives: the stateSelect declarations leave a choice of states "
                  "(%s or %s)", *(base_name[v] for v in tie))
        return None
    appears = {v for row in graph.eqs for v in row}
    alg = [v for v in range(n) if v not in is_state and v in appears]
    if len(alg) != len(eqs):
        log.debug("dummy derivatives: %d equations for %d unknowns", len(eqs), len(alg))
        return None
    g, zs = ca.vertcat(*eqs), ca.vertcat(*[var[v] for v in alg])
    if ca.sprank(ca.jacobian_sparsity(g, zs)) < len(alg):
        return None
    xs = ca.vertcat(*[var[v] for v in states]) if states else ca.SX(0, 1)
    semi = {"x": xs, "z": zs, "p": impl["p"], "t": impl["t"], "alg": g, "selected": True,
            "ode": ca.vertcat(*[var[graph.der[v]] for v in states]) if states else ca.SX(0, 1)}
    to_orig = ca.Function("state_to_orig", [xs, zs], [impl["dx_impl"], impl["x_impl"], impl["z"]],
                          ["xf", "zf"], ["dx_impl", "x_impl", "z"])
    log.debug("dummy derivatives: %d states of %d", len(states), nx + sum(1 for j in graph.der[2 * nx + nz:] if j >= 0))
    return semi, to_orig


def _switching(rows: ca.SX, modes: ca.SX, p: ca.SX, p_values: np.ndarray) -> bool:
    """Do ``rows`` (the differentiated equations' Jacobian in the candidates) read a discrete
    value or hold a branch (if-then-else) on more than the parameters ``p`` (a joint's axis
    normalised by cases of its direction is no branch)?"""
    if modes.numel() and ca.depends_on(rows, modes):
        return True
    rows = ca.substitute(rows, p, ca.DM(p_values))
    f = ca.Function("rows", ca.symvar(rows), [rows])
    return any(f.instruction_id(i) == ca.OP_IF_ELSE_ZERO for i in range(f.n_instructions()))


def _aliases(var: list, eqs: list):
    """variable -> a representative of the variables equal to it up to a constant factor and
    offset by equations of two unknowns (der(s) = v, and its derivatives): keeping one of them
    or the other as a state is no choice."""
    root = list(range(len(var)))

    def find(v):
        while root[v] != v:
            root[v] = root[root[v]]
            v = root[v]
        return v
    at = {v.element_hash(): k for k, v in enumerate(var)}
    for eq in eqs:
        row = [at[v.element_hash()] for v in ca.symvar(eq) if v.element_hash() in at]
        if len(row) == 2 and ca.jacobian(eq, ca.vertcat(*[var[v] for v in row])).is_constant():
            root[find(row[0])] = find(row[1])
    return find


def _explicit(jac: ca.SX, kept: list[int], V: ca.SX, M: np.ndarray) -> set[int]:
    """The columns ``kept`` of ``jac`` that its rows give one after another, each from a row
    where it is the only one of them not yet given and its coefficient a nonzero constant (of
    no unknown; nonzero in ``M``, ``jac`` at the start): a volume's energy U = m*u beside its
    mass m and specific energy u, never the coefficient x of a pendulum's x*x' + y*y' = 0."""
    rows, cols = jac.sparsity().get_triplet()
    open_in = {}
    for r, c in zip(rows, cols):
        if c in kept:
            open_in.setdefault(r, set()).add(c)
    given, progress = set(), True
    while progress:
        progress = False
        for r, open_ in open_in.items():
            rest = open_ - given
            if len(rest) == 1:
                (c,) = rest
                if M[r, c] != 0 and np.isfinite(M[r, c]) and not ca.depends_on(jac[r, c], V):
                    given.add(c)
                    progress = True
    return given


def _point(var: list, nx: int, nz: int, start: np.ndarray) -> np.ndarray:
    """Values of every variable where the selection is made: the start values, derivatives 0."""
    values = np.zeros(len(var))
    values[:nx] = start[:nx]
    values[2 * nx:2 * nx + nz] = start[nx:]
    return values


def _independent(jac: ca.SX, var: list, point: np.ndarray, want: list):
    """(positions of as many columns of the Jacobian ``jac`` (of the differentiated equations in
    the candidates) as it has rows, nonsingular; ``jac`` at the start ``point`` and at a random
    one): chosen at ``point``, else at the random point; None where neither has full rank (see
    :func:`_pivoted`)."""
    V = ca.vertcat(*var)
    J = ca.Function("J", [V], [jac])
    rng = np.random.default_rng(0)
    Ms = [_rows_alike(np.array(J(at))) for at in
          (point, point * rng.uniform(0.5, 1.5, point.size) + rng.uniform(-1, 1, point.size))]
    for M in Ms:
        kept = _pivoted(M, want) if np.all(np.isfinite(M)) else None
        if kept is not None:
            return kept, Ms
    return None, Ms


def _one_sign(jac: ca.SX, var: list, point: np.ndarray) -> bool:
    """Whether the determinant of ``jac`` (the differentiated equations in the dummies chosen)
    keeps one sign at :data:`SIGN_POINTS` points spread widely around ``point``: a choice that
    no run can make singular, though the declarations leave it open. A machine's air-gap flux
    in the rotor's frame, R(phi) times the stator's: a dummy whatever angle the rotor turns
    to. A pendulum's x x' + y y' = 0 changes sign with x (the bottom of its swing): no."""
    J = ca.Function("dummies", [ca.vertcat(*var)], [jac])
    rng = np.random.default_rng(SIGN_SEED)
    signs = set()
    finite = 0
    for _ in range(SIGN_POINTS):
        at = point * rng.uniform(-3.0, 3.0, point.size) + rng.uniform(-10.0, 10.0, point.size)
        M = np.array(J(at), float)
        if not np.all(np.isfinite(M)):
            continue
        sign, logdet = np.linalg.slogdet(_rows_alike(M))
        if sign == 0 or logdet < np.log(1e-12):
            return False
        signs.add(sign)
        finite += 1
    return len(signs) == 1 and finite >= SIGN_POINTS // 2


def _rows_alike(M: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore"):       # (a row holding inf: not finite, judged so later)
        return M / np.maximum(np.max(np.abs(M), axis=1, keepdims=True, initial=0.0), 1e-300)


def _tied(M: np.ndarray, kept: list[int], rank: list) -> list:
    """Each (one kept, one left out) where the column left out could replace the one kept, of
    the same declared ``rank`` (stateSelect).
    Then which variables stay states is a choice of this point, not of the model: a pendulum
    in x and y, released level, keeps y, which cannot tell the left swing from the right one,
    and a static choice there would flip its x silently (choosing again as the run goes on,
    dynamic state selection, is not done)."""
    chosen = set(kept)
    rest = [k for k in range(M.shape[1]) if k not in chosen]
    if not rest or not np.all(np.isfinite(M)):
        return []
    with warnings.catch_warnings():          # (singular: judged below)
        warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)
        lu, piv = scipy.linalg.lu_factor(M[:, kept], check_finite=False)
    if np.min(np.abs(np.diag(lu))) < 1e-10 * np.max(np.abs(np.diag(lu)), initial=1.0):
        return []                                    # (singular there: no swap to judge)
    A = scipy.linalg.lu_solve((lu, piv), M[:, rest], check_finite=False)   # each left out in the kept
    rank = np.asarray(rank)
    same = rank[kept][:, None] == rank[rest][None, :]
    return [(kept[i], rest[j]) for i, j in np.argwhere(same & (np.abs(A) > 1e-8))]


def _pivoted(M: np.ndarray, want: list):
    """Columns of M, as many as its rows and independent, chosen as QR with column pivoting
    chooses them (the largest left once those chosen are projected out), from the least
    ``want``-ed first: a pendulum hanging near the vertical keeps x and x' as states, and y, y'
    (which x and x' determine there) are made algebraic. None where M has not full row rank."""
    R = M.copy()
    tol = np.linalg.norm(M) * max(M.shape) * np.finfo(float).eps * 100
    classes = {w: np.array([x == w for x in want]) for w in sorted(set(want))}
    kept = []
    while len(kept) < M.shape[0]:
        size = np.linalg.norm(R, axis=0)
        size[kept] = 0.0
        usable = next((mask & (size > tol) for mask in classes.values() if np.any(mask & (size > tol))), None)
        if usable is None:
            return None
        best = int(np.argmax(np.where(usable, size, -1.0)))
        q = R[:, best] / size[best]
        R -= np.outer(q, q @ R)
        kept.append(best)
    return kept
