"""Hidden constraints: equations that solve for their unknowns on paper (one unknown matched to
each) but whose sum cancels every one of them, in every mode.

A DC link that floats between a diode bridge and an inverter is the common case: summing the
currents into the link's every node (Kirchhoff's law, coefficients +-1) cancels all the
currents inside it and leaves i1 + i2 + i3 = 0 for the three grid chokes, a constraint on
states. Pantelides' algorithm reads only which unknowns each equation holds, so it does not see
it; the link's potential is then solved from a singular system (1e16 times the rounding) and the
solver crawls at 1e-8 s steps. Here each block of the system in (x', z) is evaluated at a few
random points (modes included); a block singular at all of them, with the same left null
vectors y at all of them, has one of its equations replaced by y'F, the sum with its unknowns
taken out (they cancel). That equation holds only states and earlier unknowns, and index
reduction then differentiates it, as the linear combination method does (Tan, Nedialkov and
Pryce, "Conversion methods for improving structural analysis of differential-algebraic
equation systems", BIT 2017).
"""
from __future__ import annotations

import dataclasses
import logging
from fractions import Fraction

import casadi as ca
import numpy as np

from .dae import Dae

log = logging.getLogger(__name__)

POINTS = 6             # random points each block is evaluated at (the first two: all modes 0, all 1)
SINGULAR = 1e-10       # a singular value this small against the largest: the block is singular there
BLOCK_MAX = 300        # larger blocks are not looked at (a dense SVD each)
NODES_MAX = 20000      # nor blocks whose equations are larger expressions than this
SEED = 20170311


def revealed(dae: Dae) -> Dae:
    """``dae`` with each hidden constraint made an equation of its own (see the module)."""
    w = ca.vertcat(dae.dx, dae.z)
    n = w.numel()
    if n < 2:
        return dae
    sp = ca.jacobian_sparsity(dae.residual, w)
    blocks = [(R, C) for R, C in _blocks(sp) if 2 <= len(R) <= min(len(C), BLOCK_MAX) and len(C) <= 2 * BLOCK_MAX]
    if not blocks:
        return dae
    residual = ca.vertsplit(dae.residual)
    # (a block of large expressions, a medium's property functions, is left alone: the sums
    # this looks for are Kirchhoff's and d'Alembert's, short rows; differentiating IF97 water
    # in a fluid's block cost 7 s)
    rows_of = [ca.vertcat(*[residual[r] for r in R]) for R, _ in blocks]
    blocks = [(R, C, F) for (R, C), F in zip(blocks, rows_of) if ca.n_nodes(F) <= NODES_MAX]
    if not blocks:
        return dae
    hybrid = ca.vertcat(dae.d, dae.d_pre, dae.x_pre, dae.flags, dae.z_pre)
    args = [dae.x, w, dae.u, dae.p, dae.t, hybrid]
    jacs = [ca.densify(ca.jacobian(F, ca.vertcat(*[w[c] for c in C]))) for _, C, F in blocks]
    jfun = ca.Function("hidden_jac", args, jacs, {"allow_free": True})
    if jfun.has_free():
        return dae
    points = _points(dae, hybrid.numel())
    mats = [[np.array(J, float) for J in jfun.call(pt)] for pt in points]
    changed = []
    for k, (R, C, _) in enumerate(blocks):
        for r, c in _combinations(dae, residual, w, R, C, [M[k] for M in mats], args, points):
            residual[r] = c
            changed.append(r)
    if not changed:
        return dae
    log.info("hidden constraints: %d equation(s) replaced by the sums that cancel their unknowns", len(changed))
    return dataclasses.replace(dae, residual=ca.vertcat(*residual))


def _blocks(sp: ca.Sparsity) -> list[tuple[list, list]]:
    """(rows, unknowns) of the square blocks of ``sp``'s block triangular form, and of the part
    with more unknowns than rows (where the model's index is above 1; its rows still independent
    on paper: a polyphase machine's zero-sequence inductor, m i0 = sum(i), beside its star
    point's sum(i) = 0, hides i0 = 0 there), that part split into its unconnected pieces (a
    model's machines, each its own)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    nb, rp, cp, rb, cb, *_ = sp.btf()
    all_rows, all_cols = (np.asarray(v) for v in sp.get_triplet())
    out = []
    for b in range(nb):
        R, C = list(rp[rb[b]:rb[b + 1]]), list(cp[cb[b]:cb[b + 1]])
        if len(R) >= len(C):
            out.append((R, C))
            continue
        m = len(R)
        row_at, col_at = np.full(sp.size1(), -1), np.full(sp.size2(), -1)
        row_at[R], col_at[C] = np.arange(m), m + np.arange(len(C))
        inside = (row_at[all_rows] >= 0) & (col_at[all_cols] >= 0)
        graph = coo_matrix((np.ones(int(inside.sum())), (row_at[all_rows[inside]], col_at[all_cols[inside]])),
                           shape=(m + len(C),) * 2)
        _, label = connected_components(graph, directed=False)
        rows_in, cols_in = np.asarray(R), np.asarray(C)
        out += [(rows_in[label[:m] == piece].tolist(), cols_in[label[m:] == piece].tolist()) for piece in np.unique(label)]
    return out


def _points(dae: Dae, n_hybrid: int) -> list:
    """Random points around the start values (the first two with every mode 0, then every mode
    1; then random modes): states, unknowns and parameters perturbed by 30 % (a block singular
    only at a parameter's value, a = 0 in a*y + z = x, is not a constraint: a fit may change a)."""
    rng = np.random.default_rng(SEED)
    start = ca.Function("start", [dae.p], [dae.x_start, dae.z_start], {"allow_free": True})
    try:
        x0, z0 = (np.array(v, float).ravel() for v in start(dae.p_values))
    except RuntimeError:
        x0, z0 = np.zeros(dae.x.numel()), np.zeros(dae.z.numel())
    x0, z0 = np.nan_to_num(x0), np.nan_to_num(z0)

    def near(v):
        return v * (1 + 0.3 * rng.standard_normal(v.size)) + 0.3 * rng.standard_normal(v.size)

    out = []
    for k in range(POINTS):
        modes = (np.full(n_hybrid, float(k)) if k < 2 else rng.integers(0, 2, n_hybrid).astype(float))
        w = np.concatenate([near(np.zeros(dae.dx.numel())), near(z0)])
        out.append([near(x0), w, np.asarray(dae.u_start, float), near(np.asarray(dae.p_values, float)),
                    rng.uniform(0.0, 1.0), modes])
    return out


def _combinations(dae, residual, w, R, C, mats, args, points):
    """(row, its new equation) for each hidden constraint of the block of rows ``R`` in the
    unknowns ``C`` (its matrices ``mats`` at ``points``; as many unknowns as rows or more): none
    where the block's rows are independent at any point, or its null vectors differ between
    points (a mode's singularity: a clutch locked at rest), or their sum reads no variable
    (redundant, not a constraint)."""
    mats = [B for B in mats if np.all(np.isfinite(B))]
    if len(mats) < POINTS - 2:
        return []
    U, s, _ = np.linalg.svd(mats[0])
    if s[0] == 0 or s[-1] > SINGULAR * s[0]:
        return []
    Y = U[:, s <= SINGULAR * s[0]]
    for B in mats[1:]:
        sb = np.linalg.svd(B, compute_uv=False)
        if sb[-1] > SINGULAR * sb[0] or np.abs(Y.T @ B).max() > 1e3 * SINGULAR * sb[0]:
            return []
    Y, pivots = _echelon(Y)
    unknowns = ca.vertcat(*[w[c] for c in C])
    others = ca.vertcat(dae.x, dae.u, dae.t, *[w[c] for c in range(w.numel()) if c not in set(C)])
    out = []
    for k in range(Y.shape[1]):
        y = Y[:, k]
        total = sum((_exact(v) * residual[R[i]] for i, v in enumerate(y) if v != 0), ca.SX(0))
        kept = ca.substitute(total, unknowns, ca.SX.zeros(unknowns.sparsity()))
        if not ca.depends_on(kept, others) or not _same(total, kept, args, points):
            continue
        out.append((R[pivots[k]], kept))
    return out


def _echelon(Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The null vectors ``Y`` (columns) recombined so that each is 1 on a row of its own where
    the others are 0 (the rows of largest weight), and those rows: each sum replaces its own."""
    from scipy.linalg import qr

    _, _, piv = qr(Y.T, pivoting=True)
    piv = piv[:Y.shape[1]]
    Y = Y @ np.linalg.inv(Y[piv, :])
    Y[np.abs(Y) < 1e-9] = 0.0
    return Y, piv


def _exact(v: float) -> float:
    """``v`` as the simple fraction it rounds (+-1 from Kirchhoff's sums), else as it is."""
    f = Fraction(v).limit_denominator(64)
    return float(f) if abs(float(f) - v) < 1e-8 * max(1.0, abs(v)) else float(v)


def _same(a: ca.SX, b: ca.SX, args, points) -> bool:
    """Whether ``a`` and ``b`` agree at ``points`` (the unknowns taken out truly cancel)."""
    f = ca.Function("hidden_same", args, [a, b], {"allow_free": True})
    for pt in points:
        va, vb = (float(v) for v in f(*pt))
        if np.isfinite(va) and not abs(va - vb) <= 1e-8 * (1 + abs(va)):
            return False
    return True
