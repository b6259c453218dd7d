"""Full-discretisation Levenberg-Marquardt for ODE identification (paper 004, sections II-IV).

The unknowns are the states at every discretisation point and the parameters,
b = [x(t_1); ...; x(t_Nd); a] (eq. 15), and the cost is ||g(b)||^2 with the residual blocks of
eqs. (16)-(19): for j < N_d

    p_x,j = [ S_x^-1 ((x_{j+1} - x_j)/dt - f(t_{j+1/2}, (x_j + x_{j+1})/2, a)) sqrt(dt)   (midpoint)
              sqrt(mu_x / 2) x_j sqrt(dt) ;  sqrt(mu_x / 2) x_{j+1} sqrt(dt)             (trapezoid)
              S_y^-1 (y(t_j) - h(t_j, x_j))   where t_j is a measurement time ]

p_x,Nd = S_y^-1 (y - h) at the last point, and p_a = sqrt(mu_a) a. Every block couples only
x_j, x_{j+1} and a, which is what the structured solver exploits.

The linear LM step (eq. 23) is solved by :func:`structured_step`: the dynamic-programming
recursion of section IV / Algorithm 2 with the QR formulas of Appendix B (eqs. 82-83),
min_r ||[M_r M_s M_1][r; s; 1]||^2 = ||R22 [s; 1]||^2 at r = -R11^-1 R12 [s; 1], where
R = qr([M_r M_s M_1]) — no Q is ever formed. The N_d states are split in N_s segments whose
inner eliminations are independent (Algorithm 2, lines 3-10 and 22-27); they run here as one
batched QR per step across all segments, so the Python work is O(N_d / N_s + N_s).
:func:`direct_step` solves the same step with a sparse factorisation, as the reference.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


class BlockEvaluationFailed(RuntimeError):
    """f, h or their derivatives are not finite at some discretisation point."""


@dataclass
class Blocks:
    """Linearised residual blocks at b_k, padded to a common row count m.

    For j = 0..N-1: ``g[j]`` (m,), ``X[j]`` = dp_j/dx_j (m, n), ``Z[j]`` = dp_j/dx_{j+1}
    (m, n; zero for the last block), ``A[j]`` = dp_j/da (m, p). ``ga`` (p,) and ``Aa`` (p, p)
    are p_a and its Jacobian.
    """

    g: np.ndarray
    X: np.ndarray
    Z: np.ndarray
    A: np.ndarray
    ga: np.ndarray
    Aa: np.ndarray

    @property
    def shape(self):
        N, m, n = self.X.shape
        return N, m, n, self.A.shape[2]

    def cost(self) -> float:
        return float(np.sum(self.g**2) + np.sum(self.ga**2))

    def gradient(self) -> np.ndarray:
        """2 (dg/db)^T g, block by block (no sparse matrix is formed)."""
        gx = np.einsum("jmn,jm->jn", self.X, self.g)
        gx[1:] += np.einsum("jmn,jm->jn", self.Z[:-1], self.g[:-1])
        ga = np.einsum("jmp,jm->p", self.A, self.g) + self.Aa.T @ self.ga
        return 2 * np.concatenate([gx.ravel(), ga])


def direct_step(blocks: Blocks, lam: float) -> np.ndarray:
    """gamma of eq. (24) by a sparse solve of the normal equations (reference for tests)."""
    N, m, n, p = blocks.shape
    J = jacobian_matrix(blocks)
    g = np.concatenate([blocks.g.ravel(), blocks.ga])
    H = (J.T @ J + lam * sp.identity(J.shape[1])).tocsc()
    return -spla.spsolve(H, J.T @ g)


def jacobian_matrix(blocks: Blocks) -> sp.csr_matrix:
    """dg/db as a sparse matrix (rows: blocks in order, then p_a; columns: x_1..x_N, a)."""
    N, m, n, p = blocks.shape
    parts = [(blocks.X, np.arange(N) * n, n), (blocks.Z[:-1], np.arange(1, N) * n, n),
             (blocks.A, np.full(N, N * n), p)]
    rows, cols, vals = [], [], []
    for mats, col0, width in parts:
        k = len(mats)
        r = np.arange(k)[:, None, None] * m + np.arange(m)[None, :, None]
        c = col0[:k, None, None] + np.arange(width)[None, None, :]
        rows.append(np.broadcast_to(r, mats.shape).ravel())
        cols.append(np.broadcast_to(c, mats.shape).ravel())
        vals.append(mats.ravel())
    rows.append(np.repeat(N * m + np.arange(p), p))
    cols.append(np.tile(N * n + np.arange(p), p))
    vals.append(blocks.Aa.ravel())
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(N * m + p, N * n + p))


try:  # LAPACK dgeqrf on a stack of matrices, in place, without np.linalg.qr's copies and triu
    from numpy.linalg import _umath_linalg

    def _geqrf(M: np.ndarray) -> np.ndarray:
        _umath_linalg.qr_r_raw(M, signature="d->d")
        return M
except (ImportError, AttributeError):  # pragma: no cover - other numpy layouts
    def _geqrf(M: np.ndarray) -> np.ndarray:
        k = min(M.shape[-2:])
        M[..., :k, :] = np.linalg.qr(M, mode="r")
        return M


def _r_factor(M: np.ndarray, own: bool = False) -> np.ndarray:
    """R of a (batched) QR decomposition, padded with zero rows to be square.

    ``own``: M is a scratch array that may be overwritten (saves a copy)."""
    M = M if own and M.dtype == np.float64 and M.flags.c_contiguous else np.array(M, dtype=float)
    rows, k = M.shape[-2:]
    _geqrf(M)
    if rows < k:  # fewer rows than columns: pad with zero rows (they add nothing)
        M = np.concatenate([M, np.zeros(M.shape[:-2] + (k - rows, k))], axis=-2)
    return M[..., :k, :] * _upper(k)


_UPPER: dict[int, np.ndarray] = {}


def _upper(k: int) -> np.ndarray:
    if k not in _UPPER:
        _UPPER[k] = np.triu(np.ones((k, k)))
    return _UPPER[k]


def _eliminate(F: np.ndarray, k: int):
    """Appendix B: F holds rows [M_r | M_s | M_1] with r the first k columns.

    Returns (R11, R12, R22): r = -R11^-1 R12 [s; 1] and min = ||R22 [s; 1]||^2 (eqs. 82-83).
    """
    R = _r_factor(F, own=True)
    return R[..., :k, :k], R[..., :k, k:], R[..., k:, k:]


def _solve_upper(R11, rhs):
    """R11^-1 rhs for (batched) upper-triangular R11; pseudo-inverse where R11 is singular."""
    try:
        return np.linalg.solve(R11, rhs)
    except np.linalg.LinAlgError:
        return np.linalg.pinv(R11) @ rhs


def _damped(block: np.ndarray, n_first: int, lam: float, offset: int = 0) -> np.ndarray:
    """Append sqrt(lam) I rows on columns [offset, offset + n_first) (the damping of eq. 23)."""
    if lam <= 0 or n_first == 0:
        return block
    shape = block.shape[:-2] + (n_first, block.shape[-1])
    rows = np.zeros(shape)
    idx = np.arange(n_first)
    rows[..., idx, offset + idx] = np.sqrt(lam)
    return np.concatenate([block, rows], axis=-2)


def _workers() -> int:
    return max(1, int(os.environ.get("MCL_LM_THREADS", os.cpu_count() or 1)))


def _in_parallel(fn, groups: list) -> list:
    """fn over the groups, one thread each: the QRs release the GIL (Algorithm 2's parallel loops)."""
    if len(groups) == 1:
        return [fn(groups[0])]
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(len(groups)) as pool:
        return list(pool.map(fn, groups))


def _inner(blocks: Blocks, lam: float, seqs: list, F: np.ndarray):
    """Lines 3-10 of Algorithm 2 for some segments: eliminate their inner states (eq. 35).

    F[s] is segment s's factor on (left boundary, current state, delta, 1); the segments take
    their i-th step together as one batched QR of [F[s] (columns reordered); q_j; sqrt(lam) I]
    on (x_j | left, x_{j+1}, delta, 1). Returns the laws r = -R11^-1 R12 [...] per step and the
    final factors (F is updated in place).
    """
    N, m, n, p = blocks.shape
    C, K = 3 * n + p + 1, 2 * n + p + 1
    lengths = np.array([len(q) for q in seqs])
    first = np.array([q[0] if len(q) else 0 for q in seqs])
    damp = n if lam > 0 else 0
    # one scratch stack for all steps (LAPACK works in place); at least C rows so R is square
    buf = np.empty((len(seqs), max(K + m + damp, C), C))
    upper = _upper(K)
    laws = []
    for i in range(int(lengths.max(initial=0))):
        act = np.flatnonzero(lengths > i)
        j = first[act] + i
        M = buf[:len(act)]
        M.fill(0.0)
        Fa = F[act]
        M[:, :K, :n] = Fa[:, :, n:2 * n]
        M[:, :K, n:2 * n] = Fa[:, :, :n]
        M[:, :K, 3 * n:] = Fa[:, :, 2 * n:]
        q = M[:, K:K + m]
        q[:, :, :n] = blocks.X[j]
        q[:, :, 2 * n:3 * n] = blocks.Z[j]
        q[:, :, 3 * n:3 * n + p] = blocks.A[j]
        q[:, :, -1] = blocks.g[j]
        if damp:                           # the damping of eq. (23) on x_j
            M[:, K + m + np.arange(n), np.arange(n)] = np.sqrt(lam)
        _geqrf(M)                          # R in the upper triangle (eqs. 82-83)
        F[act] = M[:, n:C, n:C] * upper
        laws.append((act, j, np.triu(M[:, :n, :n]), M[:, :n, n:].copy()))
    return laws, F


def _groups(Ns: int) -> list[np.ndarray]:
    return [g for g in np.array_split(np.arange(Ns), min(_workers(), Ns)) if len(g)]


def _forward(blocks: Blocks, lam: float, segments: int):
    """Lines 3-14 of Algorithm 2: eliminate every state; returns G on (delta, 1) and the laws.

    The segments' inner eliminations (eq. 35) run in parallel, a thread per group of segments;
    then the boundary states are eliminated in order (eq. 38).
    """
    N, m, n, p = blocks.shape
    Ns = int(max(1, min(segments, N // 2)))
    bounds = np.linspace(0, N, Ns + 1).round().astype(int)
    starts, ends = bounds[:-1], bounds[1:]
    # blocks each segment eliminates: segment 0 from its first state, the others after their
    # left boundary state x_start (which the boundary recursion eliminates)
    seqs = [np.arange(starts[s] + (s > 0), ends[s]) for s in range(Ns)]
    K = 2 * n + p + 1                      # carried factor columns (left, x_j, delta, 1)
    F = np.zeros((Ns, K, K))
    for s in range(1, Ns):                 # H_{s,1} = q_{zeta(s)} on (x_start, x_start+1, delta, 1)
        j = starts[s]
        q = np.hstack([blocks.X[j], blocks.Z[j], blocks.A[j], blocks.g[j][:, None]])
        F[s] = _r_factor(_damped(q[None], n, lam)[0])[:K]
    groups = _groups(Ns)
    per_group = _in_parallel(lambda g: _inner(blocks, lam, [seqs[s] for s in g], F[g]), groups)
    laws = []                              # (global segment numbers, j, R11, R12) per step and group
    for g, (group_laws, Fg) in zip(groups, per_group):
        F[g] = Fg
        laws.append([(g[act], j, R11, R12) for act, j, R11, R12 in group_laws])
    # boundary recursion (eq. 38): G in columns (b_s, delta, 1); w_s = F[s] on (b_s, b_{s+1}, delta, 1)
    G = F[0][:, n:]
    boundary = []
    for s in range(1, Ns):
        Gx = np.zeros((G.shape[0], K))
        Gx[:, :n] = G[:, :n]
        Gx[:, 2 * n:] = G[:, n:]
        R11, R12, G = _eliminate(np.vstack([Gx, F[s]]), n)
        boundary.append((R11, R12))
    # after the last segment G's state columns are all zero (there is no x_{N+1})
    return G[:, n:], laws, boundary, starts


def structured_step(blocks: Blocks, lam: float, segments: int = 1) -> np.ndarray:
    """gamma of eq. (23) by the segment recursion of Algorithm 2 (Appendix B QR formulas).

    delta is solved from r_k + G (eq. 37), then the boundary states (eq. 40) and the inner
    states of all segments together (eq. 39) are recovered backwards.
    Returns gamma = [beta_1; ...; beta_N; delta], ordered as :func:`direct_step`.
    """
    N, m, n, p = blocks.shape
    G, laws, boundary, starts = _forward(blocks, lam, segments)
    Ns = len(starts)
    ra = _damped(np.hstack([blocks.Aa, blocks.ga[:, None]])[None], p, lam)[0]
    R11, R12, _ = _eliminate(np.vstack([G, ra]), p)
    delta = -_solve_upper(R11, R12[:, -1])
    b = np.zeros((Ns + 1, n))
    for s in range(Ns - 1, 0, -1):
        R11, R12 = boundary[s - 1]
        b[s] = -_solve_upper(R11, R12 @ np.concatenate([b[s + 1], delta, [1.0]]))
    beta = np.zeros((N + 1, n))            # row N: the non-existent x_{N+1} (zero columns)
    beta[starts[1:]] = b[1:Ns]

    def back(group_laws):                  # eq. (39), a thread per group of segments
        for act, j, R11, R12 in reversed(group_laws):
            rest = np.concatenate([b[act], beta[j + 1], np.broadcast_to(delta, (len(act), p)),
                                   np.ones((len(act), 1))], axis=1)
            beta[j] = -_solve_upper(R11, np.einsum("sij,sj->si", R12, rest)[..., None])[..., 0]

    _in_parallel(back, laws)
    return np.concatenate([beta[:N].ravel(), delta])


def reduced_parameter_rows(blocks: Blocks, segments: int = 1) -> np.ndarray:
    """Lines 1-13 of Algorithm 3: every state eliminated (lambda = 0, eq. 46), leaving rows on
    (delta, 1) whose squared norm is the linearised cost; shared by every removal candidate."""
    G, _, _, _ = _forward(blocks, 0.0, segments)
    return np.vstack([G, np.hstack([blocks.Aa, blocks.ga[:, None]])])


def removal_estimate(rows: np.ndarray, a_active: np.ndarray, removed) -> float:
    """V_e after setting the parameters ``removed`` (indices into the active ones) to zero:
    delta_k = -a_k (eq. 45) moves into the constant column, the rest of delta is minimised."""
    removed = list(removed)
    p = rows.shape[1] - 1
    keep = [c for c in range(p) if c not in removed]
    const = rows[:, -1] - rows[:, removed] @ a_active[removed]
    _, _, R22 = _eliminate(np.hstack([rows[:, keep], const[:, None]]), len(keep))
    return float(np.sum(R22**2))


def removal_estimates(blocks: Blocks, a_active: np.ndarray, segments: int = 1) -> np.ndarray:
    """Algorithm 3 (paper 004): the minimal cost V_e after setting each parameter to zero.

    Linearised at the optimum with lambda = 0 (eq. 46). Eliminating the states (lines 1-13) is
    shared by every candidate; only the final small problem over delta differs: with the k-th
    element of delta fixed at -a_k (eq. 45), min over the rest of ||[G; r] [delta; 1]||^2.
    """
    rows = reduced_parameter_rows(blocks, segments)
    return np.array([removal_estimate(rows, a_active, [k]) for k in range(blocks.shape[3])])


# -- the discretised identification problem (eqs. 12-19) ------------------------------------------
def discretisation_grid(t_meas: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Appendix A: N_r^(i) = ceil((t_m^(i+1) - t_m^(i)) / dt) equal steps between measurements.

    Returns (t_d, index of each measurement time in t_d). The text writes floor brackets, but
    steps no longer than dt need the ceiling.
    """
    t_meas = np.asarray(t_meas, dtype=float)
    pieces, idx = [], []
    for a, b in zip(t_meas[:-1], t_meas[1:]):
        k = max(1, int(np.ceil((b - a) / dt - 1e-9)))
        idx.append(sum(len(x) for x in pieces))
        pieces.append(a + (b - a) * np.arange(k) / k)
    idx.append(sum(len(x) for x in pieces))
    pieces.append(t_meas[-1:])
    return np.concatenate(pieces), np.array(idx)


@dataclass
class Measurements:
    """Measurements at arbitrary times; NaN marks an output not measured at that time."""

    time: np.ndarray
    values: np.ndarray           # (N_m, n_y)

    @classmethod
    def merge(cls, series: list[tuple[np.ndarray, np.ndarray, int]], n_y: int) -> "Measurements":
        """From (times, values, output index) triples: each output on its own time grid."""
        times = np.unique(np.concatenate([np.asarray(t, float) for t, _, _ in series]))
        vals = np.full((len(times), n_y), np.nan)
        for t, v, k in series:
            vals[np.searchsorted(times, t), k] = v
        return cls(times, vals)


class IdentificationProblem:
    """min ||g(b)||^2 of eq. (14) for x' = f(t, x, a), y = h(t, x) (paper 004, eq. 12).

    ``f(t, x, a)`` and ``h(t, x)`` are Python functions written with CasADi or NumPy operations
    (or CasADi Functions), traced once on symbols; every derivative comes from CasADi.
    ``Sx``/``Sy`` are the factors of W_x = S_x S_x^T and W_y = S_y S_y^T (eqs. 7-8), as vectors
    (diagonal) or matrices.
    """

    def __init__(self, f, h, n_x: int, n_a: int, meas: Measurements, dt: float,
                 Sx=None, Sy=None, mu_x: float = 1e-8, mu_a: float = 1e-3):
        import casadi as ca

        self.n, self.p, self.meas = n_x, n_a, meas
        self.t, self.j_meas = discretisation_grid(meas.time, dt)
        N, n_y = len(self.t), meas.values.shape[1]
        self.n_y = n_y
        Sx_inv = np.linalg.inv(np.diag(np.broadcast_to(Sx if Sx is not None else 1.0, n_x)) if np.ndim(Sx) < 2
                               else np.asarray(Sx))
        Sy_inv = np.linalg.inv(np.diag(np.broadcast_to(Sy if Sy is not None else 1.0, n_y)) if np.ndim(Sy) < 2
                               else np.asarray(Sy))
        sym = ca.MX if getattr(f, "needs_mx", False) else ca.SX
        x, z, a = sym.sym("x", n_x), sym.sym("z", n_x), sym.sym("a", n_a)
        tm, dtj, tj = sym.sym("tm"), sym.sym("dt"), sym.sym("tj")
        y, mask = sym.sym("y", n_y), sym.sym("mask", n_y)
        dyn = ca.mtimes(ca.DM(Sx_inv), (z - x) / dtj - _traced(f, tm, (x + z) / 2, a)) * ca.sqrt(dtj)
        reg = np.sqrt(mu_x / 2) * ca.sqrt(dtj)
        h_x = _traced(h, tj, x, a) if _arity(h) == 3 else _traced(h, tj, x)   # h may use the parameters
        meas_res = ca.mtimes(ca.DM(Sy_inv), mask * (y - h_x))  # S_y^-1 (y - h) where measured
        res = ca.vertcat(dyn, reg * x, reg * z, meas_res)
        last = ca.vertcat(sym.zeros(3 * n_x), meas_res)
        args = [x, z, a, tm, dtj, tj, y, mask]
        jac = [ca.densify(ca.jacobian(res, v)) for v in (x, z, a)]
        blk = ca.Function("blk", args, [ca.densify(res)] + jac)
        blk_last = ca.Function("blk_last", args, [last, ca.jacobian(last, x), ca.jacobian(last, z),
                                                  ca.jacobian(last, a)])
        # "thread" map: the per-block residuals and Jacobians are independent (Algorithm 2, line 3).
        # Evaluated through buffers: no DM copies.
        self._blk = blk.map(N - 1, "thread", _workers())
        self._blk_last = blk_last
        self.m = 3 * n_x + n_y
        self.mu_a = mu_a
        # measurements on the grid (zero and masked where there is none)
        Y = np.zeros((N, n_y))
        M = np.zeros((N, n_y))
        ok = ~np.isnan(meas.values)
        Y[self.j_meas] = np.where(ok, meas.values, 0.0)
        M[self.j_meas] = ok
        self.Y, self.M = Y, M
        self.dt_mid = np.diff(self.t)
        self.t_mid = self.t[:-1] + self.dt_mid / 2

    @property
    def N(self) -> int:
        return len(self.t)

    def blocks(self, X: np.ndarray, a: np.ndarray) -> Blocks:
        """Residual blocks and their Jacobians at states X (N, n) and parameters a."""
        from .simulation import quiet_native_output

        N, m, n, p = self.N, self.m, self.n, self.p
        out = [np.zeros((N, m)), np.zeros((N, n, m)), np.zeros((N, n, m)), np.zeros((N, p, m))]
        with quiet_native_output():        # a failed Newton solve prints a dump (and leaves NaN)
            self._inner_blocks(X, a, out)
            out[0][-1], out[1][-1] = self._last_block(X, a)
        if not all(np.isfinite(np.sum(v)) for v in out):   # one pass: a NaN or inf spoils the sum
            raise BlockEvaluationFailed("the model could not be evaluated at these states and parameters "
                                        "(an algebraic loop did not converge or a value is not finite)")
        G, X_, Z_, A_ = out[0], *(v.transpose(0, 2, 1) for v in out[1:])
        sa = np.sqrt(self.mu_a)
        return Blocks(G, X_, Z_, A_, sa * a, sa * np.eye(p))

    def _inner_blocks(self, X, a, out) -> None:
        """Blocks 0..N-2 by the threaded map, written through buffers into the first N-1 rows of
        ``out`` (column-major (rows, (N-1) cols) results are C-order (N-1, cols, rows) arrays)."""
        N, p = self.N, self.p
        args = [X[:-1], X[1:], np.broadcast_to(a, (N - 1, p)), self.t_mid, self.dt_mid, self.t[:-1],
                self.Y[:-1], self.M[:-1]]
        args = [np.ascontiguousarray(v, dtype=float) for v in args]
        buf, run = self._blk.buffer()
        for k, v in enumerate(args):
            buf.set_arg(k, memoryview(v))
        for k, v in enumerate(out):
            buf.set_res(k, memoryview(v[:N - 1]))
        run()

    def _last_block(self, X, a):
        """(residual, d/dx) of the measurement-only block at the last point; NaN if it fails."""
        try:
            g, Jx, _, _ = self._blk_last(X[-1], X[-1], a, self.t[-1], 1.0, self.t[-1], self.Y[-1], self.M[-1])
            return np.array(g, float).ravel(), np.array(Jx, float).T
        except RuntimeError:
            return np.nan, np.nan

    def cost(self, X, a) -> float:
        return self.blocks(X, a).cost()

    def initial_states(self, guess=None) -> np.ndarray:
        """Measured outputs interpolated onto the grid where h is the identity, else ``guess``."""
        X = np.zeros((self.N, self.n)) if guess is None else np.array(guess, dtype=float)
        for k in range(min(self.n, self.n_y)):
            ok = ~np.isnan(self.meas.values[:, k])
            if ok.sum() >= 2 and guess is None:
                X[:, k] = np.interp(self.t, self.meas.time[ok], self.meas.values[ok, k])
        return X


def _traced(fn, *args):
    """fn evaluated on CasADi symbols. Plain NumPy code works too: NumPy's elementwise functions
    dispatch to CasADi's, and a list or object array of results is stacked into a column."""
    import warnings

    import casadi as ca

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)   # CasADi's notice on NumPy calls
        out = fn(*args)
    if isinstance(out, (list, tuple, np.ndarray)):
        out = ca.vertcat(*np.asarray(out, dtype=object).ravel())
    return out


def _arity(fn) -> int:
    import inspect

    try:
        return len(inspect.signature(fn).parameters)
    except (TypeError, ValueError):
        return 2


class CompiledRhs:
    """f(t, x, a) and h(t, x, a) from a compiled model, with a template's parameters as a.

    ``parameters`` (names of free parameters, e.g. 'Rx.w2') become a; every other parameter keeps
    the value in ``fixed`` or its nominal one; the measured inputs enter as a linear interpolant
    of time. The model's states are x (its semi-explicit states, as the compile stage made them).
    """

    needs_mx = True  # the model's functions are CasADi MX (they may hold Newton solvers)

    def __init__(self, model, inputs, parameters: list[str], fixed: dict | None = None):
        import casadi as ca

        self.model, self.names = model, list(parameters)
        self.p0 = model.parameter_vector(fixed or {})
        self.idx = [model.ode.p_names.index(n) for n in self.names]
        u = inputs.select(model.input_names) if model.input_names else None
        self.u = (ca.interpolant("U", "linear", [u.time], u.values.ravel(order="C"))
                  if u is not None else None)

    def _p(self, a):
        import casadi as ca

        p = ca.MX(ca.DM(self.p0))
        for k, i in enumerate(self.idx):
            p[i] = a[k]
        return p

    def _u(self, t):
        import casadi as ca

        return self.u(t) if self.u is not None else ca.MX(0, 1)

    def __call__(self, t, x, a):
        return self.model.ode.ode(x, self._u(t), self._p(a), t)

    def output(self, t, x, a):
        return self.model.ode.out(x, self._u(t), self._p(a), t)


@dataclass
class LMResult:
    X: np.ndarray
    a: np.ndarray
    cost: float
    iterations: int
    history: list
    message: str


def levenberg_marquardt(problem: IdentificationProblem, X0, a0, active=None, lam0: float = 1e-2,
                        rho1: float = 3.0, rho2: float = 5.0, sigma: float = 1e-9,
                        max_iter: int = 200, rtol: float = 1e-12, segments: int = 1,
                        step=structured_step) -> LMResult:
    """Algorithm 1 (paper 004) with the structured linear step; ``active`` masks parameters.

    Parameters outside ``active`` stay at zero (a removed network edge); the step is computed
    with their columns dropped. Stops when the gradient norm ||2 J^T g|| <= sigma, when the
    relative decrease falls below ``rtol``, or after ``max_iter`` iterations.
    """
    X, a = np.array(X0, dtype=float), np.array(a0, dtype=float)
    active = np.ones(len(a), bool) if active is None else np.asarray(active, bool)
    a[~active] = 0.0
    lam, history, message = lam0, [], "max_iter reached"
    blocks = restrict(problem.blocks(X, a), active)
    cost = blocks.cost()
    for k in range(max_iter):
        if np.linalg.norm(blocks.gradient()) <= sigma:
            message = "gradient below sigma"
            break
        gamma = step(blocks, lam, segments) if step is structured_step else step(blocks, lam)
        Xn = X + gamma[: X.size].reshape(X.shape)
        an = a.copy()
        an[active] += gamma[X.size:]
        try:
            new = restrict(problem.blocks(Xn, an), active)
            new_cost = new.cost()
        except BlockEvaluationFailed:      # outside the model's domain: a rejected step (larger lambda)
            new, new_cost = None, np.inf
        history.append((k, cost, lam))
        if new_cost < cost:
            done = (cost - new_cost) <= rtol * cost
            X, a, blocks, cost, lam = Xn, an, new, new_cost, lam / rho1
            if done:
                message = "relative decrease below rtol"
                break
        else:
            lam *= rho2
            if lam > 1e16:
                message = "no decrease possible"
                break
    return LMResult(X, a, cost, len(history), history, message)


def restrict(blocks: Blocks, active) -> Blocks:
    """The blocks with only the ``active`` parameters (the others are fixed at zero)."""
    if np.all(active):
        return blocks
    return Blocks(blocks.g, blocks.X, blocks.Z, blocks.A[:, :, active], blocks.ga[active],
                  blocks.Aa[np.ix_(active, active)])
