"""Output sensitivities from the model linearised along a run.

The sensitivity S = dx/dq of the states to a parameter (or to a signal injected into the model)
obeys the linear, time-varying equation S' = A(t) S + F(t), with A = df/dx along the run and F
the parameter's (or signal's) direct effect; the outputs move by C(t) S + G(t), C = dy/dx. Given
the run on a grid finer than the data's, the trapezoidal rule integrates S for every parameter at
once, and the run itself is one plain simulation. Forward sensitivities carried by the integrator
cost several simulations each; these cost a fraction of one, and are accurate to the rule's
second order (ample for a Gauss-Newton step, whose Jacobian need not be exact; the residual comes
from the solver).

The rule's recursion S_k = P_k S_(k-1) + G_k is solved a block of steps at a time
(:func:`affine_scan`): a Python loop per grid point cost more than the simulation itself on long
records of small models.
"""
from __future__ import annotations

from collections import OrderedDict

import casadi as ca
import numpy as np

from .compile import parametric
from .simulation import crossed, prepare_inputs

#: points per data interval on the grid the rule integrates on (at least, and at most)
SUBSTEPS, MAX_SUBSTEPS = 1, 24
#: the rule's step is shortened until every mode the data can show (up to their Nyquist rate)
#: moves by at most this in one step (h |lambda|: for oscillations the turn in radians, for
#: decays the fraction lost) ...
MAX_STEP = 0.3
#: ... and a faster mode by at most this: the rule then damps it by (1 - x/2)/(1 + x/2) = -0.2
#: or more a step, and gives its quasi-static response exactly (the rule's fixed point for a
#: constant forcing is -A^-1 F); finer steps for modes the samples cannot see only cost time
MAX_STIFF_STEP = 3.0
#: numbers held per chunk of the run (the Jacobians are evaluated a chunk at a time)
CHUNK_NUMBERS = 4_000_000
#: linearisation functions kept (a fit builds one Linearisation per Gauss-Newton step of the
#: same model and parameters: the Jacobians' CasADi functions are made once)
_FUNCTIONS: OrderedDict = OrderedDict()
_KEEP = 8


def fine_grid(t: np.ndarray, substeps: int = SUBSTEPS) -> tuple[np.ndarray, np.ndarray]:
    """The data grid ``t`` with ``substeps`` points in each interval, and where the data points are."""
    t = np.asarray(t, float)
    substeps = max(1, int(substeps))
    inner = t[:-1, None] + np.diff(t)[:, None] * (np.arange(substeps) / substeps)
    fine = np.concatenate([inner.ravel(), t[-1:]])
    return fine, np.arange(0, len(fine), substeps)


def substeps_for(rate: float, h: float) -> int:
    """Points per data interval of spacing ``h`` for a model whose fastest mode is ``rate``."""
    seen = min(rate, np.pi / h) if h > 0 else rate
    need = max(rate * h / MAX_STIFF_STEP, seen * h / MAX_STEP)
    return int(np.clip(np.ceil(need), SUBSTEPS, MAX_SUBSTEPS))


def _expand(f: ca.Function) -> ca.Function:
    try:
        return f.expand()
    except RuntimeError:      # holds a rootfinder or a run-time linear solver
        return f


class _Mapped:
    """A CasADi function mapped over n points, evaluated on NumPy arrays through a
    :class:`casadi.FunctionBuffer` (no conversion to and from DM: on long runs that conversion
    cost more than the evaluation)."""

    def __init__(self, fun: ca.Function, n: int):
        self.f = fun.map(n)
        self.buffer, self.call = self.f.buffer()
        self.out = [np.zeros(self.f.nnz_out(k)) for k in range(self.f.n_out())]
        for k, o in enumerate(self.out):
            self.buffer.set_res(k, memoryview(o))

    def __call__(self, *args) -> list[np.ndarray]:
        ins = [np.ascontiguousarray(np.asarray(a, float).ravel(order="F")) for a in args]
        for k, a in enumerate(ins):
            self.buffer.set_arg(k, memoryview(a))
        self.call()
        if self.buffer.ret() != 0:
            raise RuntimeError(f"evaluating {self.f.name()} failed")
        return [o.reshape(self.f.size_out(k), order="F").copy() for k, o in enumerate(self.out)]


def _functions(ode, idx: list[int]):
    """(df/dx, df/dq, dy/dx, dy/dq as one dense CasADi function, its maps by size and the initial
    state's derivative, made on first use), once per model and parameter selection. A model with algebraic loops is differentiated through their
    Newton form (:func:`mcl.compile.structure.causalise`): the function then takes the loops'
    solutions as a fifth argument."""
    key = (id(ode.ode), id(ode.out), id(ode.init), tuple(idx))
    entry = _FUNCTIONS.get(key)
    if entry is None:
        X, U, P, T = ode.ode.mx_in()
        args = [X, U, P, T]
        where = {n: k for k, n in enumerate(ode.probe_names)}
        split = parametric.split(ode)
        if split is not None:      # the parametric parts q(p) as arguments, and dq/dp (QP)
            Q, QP = ca.MX.sym("q", split.nq), ca.MX.sym("qp", split.nq, len(idx))
            f, y = split.ode(X, U, P, Q, T), split.out(X, U, P, Q, T)
            jac = [ca.densify(J) for J in (ca.jacobian(f, X), split.d_dp(f, P, Q, QP, idx),
                                           ca.jacobian(y, X), split.d_dp(y, P, Q, QP, idx))]
            args += [Q, QP]
        elif getattr(ode, "given", None) is not None and all(n in where for n in ode.y_names):
            ZL = ca.MX.sym("zl", ode.given.size1_in(4))
            f, probe = ode.given(X, U, P, T, ZL)
            y = probe[[where[n] for n in ode.y_names]] if ode.y_names else ca.MX(0, 1)
            args.append(ZL)
        else:
            f, y = ode.ode(X, U, P, T), ode.out(X, U, P, T)
        if split is None:
            jac = [ca.densify(J) for J in (ca.jacobian(f, X), ca.jacobian(f, P)[:, idx], ca.jacobian(y, X),
                                           ca.jacobian(y, P)[:, idx])]
        # the entry holds the ode, so that its id is not reused while the entry lives
        entry = (ode, _expand(ca.Function("lin", args, jac)), {})
        _FUNCTIONS[key] = entry
        if len(_FUNCTIONS) > _KEEP:
            _FUNCTIONS.popitem(last=False)
    _FUNCTIONS.move_to_end(key)
    return entry[1], entry[2]


def affine_scan(P: np.ndarray, G: np.ndarray, S0: np.ndarray) -> np.ndarray:
    """S_k = P_k S_(k-1) + G_k for k = 0 .. n-1 from S_(-1) = ``S0``; P (n, nx, nx), G (n, nx, ns).

    Solved in blocks of about sqrt(n) steps: within every block at once (a loop over the
    position in the block, vectorised over the blocks) the maps from the block's start, then the
    blocks' starts one after another, then every point from its block's start: about 2 sqrt(n)
    vectorised steps instead of n small ones, O(n nx^2 (nx + ns)) work as before."""
    n, nx, ns = G.shape
    if n == 0:
        return G.copy()
    m = int(np.ceil(np.sqrt(n)))
    L = -(-n // m)
    pad = L * m - n
    if pad:
        P = np.concatenate([P, np.broadcast_to(np.eye(nx), (pad, nx, nx))])
        G = np.concatenate([G, np.zeros((pad, nx, ns))])
    P, G = P.reshape(L, m, nx, nx), G.reshape(L, m, nx, ns)
    Pp, Gp = np.empty_like(P), np.empty_like(G)
    Pp[:, 0], Gp[:, 0] = P[:, 0], G[:, 0]
    for i in range(1, m):            # within each block: S_(b,i) = Pp_(b,i) S_start(b) + Gp_(b,i)
        Pp[:, i] = P[:, i] @ Pp[:, i - 1]
        Gp[:, i] = P[:, i] @ Gp[:, i - 1] + G[:, i]
    starts = np.empty((L, nx, ns))
    S = S0
    with np.errstate(over="ignore", invalid="ignore"):    # (a run that blows up: not finite, refused by the fit)
        for b in range(L):               # the blocks' starts, one after another
            starts[b] = S
            S = Pp[b, -1] @ S + Gp[b, -1]
        out = np.einsum("bmij,bjk->bmik", Pp, starts) + Gp
    return out.reshape(L * m, nx, ns)[:n]


#: from this many states on, the rule's steps are taken one after another with the factors of a
#: fixed matrix (:func:`_low_rank_steps`): the blocked scan costs ~5 nx^3 a point
LOW_RANK_MIN_STATES = 12


def _low_rank_steps(A, prev_A, G, h, S0, first: bool) -> np.ndarray | None:
    """The rule's steps S_k = (I - h A_k / 2)^-1 ((I + h A_(k-1) / 2) S_(k-1) + G_k) one after
    another, for a model whose Jacobian A varies along the run in few rows (a law in a model of
    fixed parts): I - h A_k / 2 = M - (h/2) E D_k with M fixed and D_k the rows that vary, so
    by Woodbury its inverse is M^-1 + W (I - D_k W)^-1 D_k M^-1, W = (h/2) M^-1 E: O(nx^2 ns) a
    step instead of O(nx^3). None when the step varies or too many rows vary (the caller then
    takes the blocked scan). ``first``: the chunk starts the run (S there is ``S0``)."""
    n, nx, ns = G.shape
    steps = h[1:] if first else h
    if not len(steps) or np.ptp(steps) > 1e-9 * steps[0]:
        return None
    hk = float(steps[0])
    A0 = A[-1]
    scale = 1e-12 * (1.0 + np.max(np.abs(A0)))
    rows = np.flatnonzero(np.max(np.abs(A - A0), axis=(0, 2)) > scale)
    if 3 * len(rows) > nx:
        return None
    Minv = np.linalg.inv(np.eye(nx) - 0.5 * hk * A0)
    D = (A - A0)[:, rows, :]                                  # (n, r, nx)
    W = 0.5 * hk * Minv[:, rows]                              # (nx, r)
    Cinv = np.linalg.inv(np.eye(len(rows)) - D @ W) if len(rows) else None
    R = 0.5 * h[:, None, None] * prev_A                       # (I + R_k) S: the rule's explicit half
    out = np.empty((n, nx, ns))
    S = np.asarray(S0, float)
    for k in range(n):
        if not (k == 0 and first):
            z = Minv @ (S + R[k] @ S + G[k])
            S = z + W @ (Cinv[k] @ (D[k] @ z)) if Cinv is not None else z
        out[k] = S
    return out


def _steps(A, prev_A, G, h, S, first: bool) -> np.ndarray:
    """The rule's states S_k at the points of a block (A_k, A_(k-1), the forcing's half-sums
    G_k = h/2 (F_(k-1) + F_k), steps h_k), from S before it (S(t0) itself where ``first``)."""
    nx = A.shape[1]
    Sk = _low_rank_steps(A, prev_A, G, h, S, first) if nx >= LOW_RANK_MIN_STATES else None
    if Sk is None:
        I, hh = np.eye(nx), h[:, None, None]
        lhs = I - 0.5 * hh * A
        P = np.linalg.solve(lhs, I + 0.5 * hh * prev_A)
        G = np.linalg.solve(lhs, G)
        if first:                 # S(t0) = S0
            G[0] = S
            P[0] = 0.0
        Sk = affine_scan(P, G, S)
    return Sk


class Linearisation:
    """df/dx, df/dq, dy/dx, dy/dq along a run (``states`` (N, nx) at ``time``, parameter vector
    ``p``) for the free parameters named ``params``, evaluated a chunk of the run at a time;
    with the run's ``switches`` (:class:`mcl.simulation.Switch`), S jumps at each (:class:`_Jumps`)."""

    jumps = None

    def __init__(self, model, states: np.ndarray, time: np.ndarray, inputs, p: np.ndarray, params: list[str],
                 switches=()):
        ode = model.ode
        self.time = np.asarray(time, float)
        idx = [ode.p_names.index(n) for n in params]
        self.ode, self.idx = ode, idx
        self.fun, self._maps = _functions(ode, idx)
        u = prepare_inputs(model, inputs)
        N = len(self.time)
        self.U = np.array([np.interp(self.time, u.time, u.values[:, k]) for k in range(len(u.names))]).reshape(-1, N)
        self.X, self.p = np.asarray(states, float).T, np.asarray(p, float)
        self.split = parametric.split(ode)
        if self.split is not None:
            self.q, self.qp = self.split.values(self.p), self.split.jacobian(self.p, idx)
        self.nx, self.ny, self.nq = len(ode.x_names), len(ode.y_names), len(idx)
        nx, ny, nq = self.nx, self.ny, self.nq
        # per point: the four Jacobians, and the rule's matrices and partial solutions
        per_point = nx * (nx + nq) + ny * (nx + nq) + 4 * nx * nx + 3 * nx * nq
        self.chunk = int(max(16, CHUNK_NUMBERS // max(1, per_point)))
        self.jumps = _Jumps(self, switches) if len(switches) and nx else None

    def _mapped(self, fun: ca.Function, n: int) -> "_Mapped":
        key = (fun.name(), n)
        if key not in self._maps:
            self._maps[key] = _Mapped(fun, n)
        return self._maps[key]

    def _at(self, pick) -> list[np.ndarray]:
        """The four Jacobians (flat, as the mapped function gives them) at the points ``pick``
        (a slice or indices): first the algebraic loops' solutions there, where the function
        takes them."""
        X, U, t = self.X[:, pick], self.U[:, pick], self.time[None, pick]
        n = X.shape[1]
        args = [X, U, np.repeat(self.p[:, None], n, 1), t]
        if self.split is not None:
            args += [np.repeat(self.q[:, None], n, 1), np.repeat(self.qp.ravel(order="F")[:, None], n, 1)]
        elif self.fun.n_in() == 5:
            args.append(self._mapped(self.ode.loops, n)(*args)[0])
        return self._mapped(self.fun, n)(*args)

    def jacobians(self, k0: int, k1: int):
        """(A, B, C, E) at points k0 .. k1-1, each (k1 - k0, rows, cols)."""
        n = k1 - k0
        out = self._at(slice(k0, k1))
        shape = lambda M, r, c: M.reshape(r, n, c).transpose(1, 0, 2) if r * c else np.zeros((n, r, c))
        nx, ny, nq = self.nx, self.ny, self.nq
        return shape(out[0], nx, nx), shape(out[1], nx, nq), shape(out[2], ny, nx), shape(out[3], ny, nq)

    def rate(self) -> float:
        """The fastest mode along the run (max |eig A|, per unit time), from a sample of points."""
        if not self.nx:
            return 0.0
        pick = np.unique(np.linspace(0, len(self.time) - 1, min(50, len(self.time))).astype(int))
        n = len(pick)
        A = self._at(pick)[0].reshape(self.nx, n, self.nx).transpose(1, 0, 2)
        A = A[np.isfinite(A).all(axis=(1, 2))]        # a point where the model has no derivative
        return float(np.max(np.abs(np.linalg.eigvals(A)))) if len(A) else 0.0

    def propagate(self, forcing, at: np.ndarray, ns: int, batched: bool = False, S0=None) -> np.ndarray:
        """Output sensitivities (len(at), ny, ns) at grid points ``at`` (increasing), for forcing
        ``forcing(k, B, E) -> (Fx (nx, ns), Fy (ny, ns))``: the direct effect at grid point k
        on x' and on y, given df/dq and dy/dq there; with ``batched``, ``forcing(k0, k1, B, E)``
        gives them for the points k0 .. k1-1 at once ((n, nx, ns), (n, ny, ns)). S(t0) = ``S0``
        (nx, ns), 0 when not given."""
        t, N, nx, ny = self.time, len(self.time), self.nx, self.ny
        at = np.asarray(at, int)
        Y = np.zeros((len(at), ny, ns))
        S = np.zeros((nx, ns)) if S0 is None else np.asarray(S0, float).reshape(nx, ns)
        F_prev, A_prev = None, None
        for k0 in range(0, N, self.chunk):
            k1 = min(N, k0 + self.chunk)
            A, B, C, E = self.jacobians(k0, k1)
            if batched:
                Fx, Fy = forcing(k0, k1, B, E)
            else:
                pairs = [forcing(k, B[j], E[j]) for j, k in enumerate(range(k0, k1))]
                Fx = np.array([p[0] for p in pairs], float).reshape(k1 - k0, nx, ns)
                Fy = np.array([p[1] for p in pairs], float).reshape(k1 - k0, ny, ns)
            out = (at >= k0) & (at < k1)
            j_out = at[out] - k0
            if nx:
                # S_k = P_k S_(k-1) + (I - h A_k / 2)^-1 (h / 2) (F_(k-1) + F_k): the trapezoidal rule
                prev_A = np.concatenate([A_prev[None] if A_prev is not None else A[:1], A[:-1]])
                prev_F = np.concatenate([F_prev[None] if F_prev is not None else Fx[:1], Fx[:-1]])
                h = (t[k0:k1] - t[np.maximum(np.arange(k0, k1) - 1, 0)])[:, None, None]
                G = 0.5 * h * (prev_F + Fx)
                # the block's steps; a step with a switch in it is taken in two, S jumping between
                cuts = [] if self.jumps is None else sorted({k - k0 for k in self.jumps.at if k0 <= k < k1})
                parts, j0 = [], 0
                for j in [*cuts, k1 - k0]:
                    if j > j0:
                        parts.append(_steps(A[j0:j], prev_A[j0:j], G[j0:j], h[j0:j, 0, 0], S, k0 + j0 == 0))
                        S = parts[-1][-1]
                    if j < k1 - k0:
                        S = self.jumps.across(k0 + j, S, (prev_A[j], prev_F[j]), (A[j], Fx[j]), forcing, batched)
                        parts.append(S[None])
                    j0 = j + 1
                Sk = np.concatenate(parts) if len(parts) > 1 else parts[0]
                A_prev, F_prev = A[-1], Fx[-1]
                Y[out] = np.einsum("kij,kjs->kis", C[j_out], Sk[j_out]) + Fy[j_out]
            else:
                Y[out] = Fy[j_out]
        return Y

    def parameters(self, at: np.ndarray) -> np.ndarray:
        """d y / d q at grid points ``at`` for every parameter q of the linearisation, from the
        initial state's own dependence on q (a parameter that sets a state in an initial
        equation, s0 in M.s = s0, acts through it alone)."""
        return self.propagate(lambda k0, k1, B, E: (B, E), at, self.nq, batched=True, S0=self.initial())

    def initial(self) -> np.ndarray:
        """d x(t0) / d q (nx, nq): the initial equations differentiated in the parameters."""
        if not (self.nx and self.nq):
            return np.zeros((self.nx, self.nq))
        try:
            if "dx0" not in self._maps:     # made once per model and selection, with the others
                from .compile.structure import initial_state

                self._maps["dx0"] = initial_state(self.ode, self.idx)
            S0 = np.array(self._maps["dx0"](self.U[:, 0], self.p, self.time[0])[1], float)
        except RuntimeError:        # an initial solve that does not differentiate: from 0, as before
            return np.zeros((self.nx, self.nq))
        return np.where(np.isfinite(S0), S0, 0.0)


class _Jumps:
    """The sensitivities' jumps at a run's switches (:class:`mcl.simulation.Switch`): where the
    relation g(x, p, t) that switched crosses 0, its time moves by dtau = -(g_x S + g_q) /
    (g_x f- + g_t) with the parameters, and past it the states' slopes are f+ instead of f-:
    S+ = S- + (f- - f+) dtau. The grid step a switch falls in is taken in two, by implicit
    Euler on each side (the trapezoidal rule across it averages two modes' forcing: a
    thermostat's sensitivity to its heater's power drifted 45 % off over ten switches).
    Left out, a thermostat's room seemed not to care how fast its wall loses heat."""

    def __init__(self, lin: Linearisation, switches):
        t = self.time = lin.time
        if "jump" not in lin._maps:
            lin._maps["jump"] = self.function(lin.ode)
        fun = lin._maps["jump"]
        self.at, self.rows = [], []
        for sw in switches:
            k = int(np.searchsorted(t, sw.time, side="left"))
            if not 0 < k < len(t):
                continue
            uk = np.array([np.interp(sw.time, t, row) for row in lin.U])
            g0, gx, gp, gt, f_minus = (np.array(v, float) for v in fun(sw.before, uk, lin.p, sw.time))
            f_plus = np.array(fun(sw.after, uk, lin.p, sw.time)[4], float).ravel()
            f_minus = f_minus.ravel()
            hit = crossed(g0, gx, gt, f_minus, sw.relations)
            if hit is None:
                continue
            r, v = hit
            step = f_minus - f_plus
            step[sw.after != sw.before] = 0.0           # (states a reinit() set)
            if not np.all(np.isfinite(step)):
                continue
            self.at.append(k)
            self.rows.append((float(sw.time), step, gx[r] / v, gp[r, lin.idx] / v))

    @staticmethod
    def function(ode) -> ca.Function:
        """(g, dg/dx, dg/dp, dg/dt, f) at a point: made once per model and kept with the
        linearisation's other functions, not again at each linearisation of a fit's runs."""
        x, u, p, t = (ca.MX.sym(n, ode.zero.size1_in(k)) for k, n in enumerate(("x", "u", "p", "t")))
        g = ode.zero(x, u, p, t)
        return ca.Function("jump", [x, u, p, t], [g, ca.jacobian(g, x), ca.jacobian(g, p), ca.jacobian(g, t),
                                                  ode.ode(x, u, p, t)])

    def across(self, k: int, S: np.ndarray, before, after, forcing, batched: bool) -> np.ndarray:
        """S (nx, ns) at grid point k from S at k - 1, across the switches between them:
        ``before`` and ``after`` are (A, F) at k - 1 and at k, the modes on either side."""
        I = np.eye(len(S))
        t0, (A, F) = self.time[k - 1], before
        for tk, step, a, b in sorted((row for kk, row in zip(self.at, self.rows) if kk == k), key=lambda r: r[0]):
            dt = max(tk - t0, 0.0)
            S = np.linalg.solve(I - dt * A, S + dt * F)
            if batched:
                gq = forcing(k, k + 1, b[None, None, :], np.zeros((1, 1, len(b))))[0].reshape(-1)
            else:
                gq = np.asarray(forcing(k, b[None, :], np.zeros((1, len(b))))[0], float).reshape(-1)
            S = S - np.outer(step, a @ S + gq)
            t0, (A, F) = tk, after
        dt = self.time[k] - t0
        return np.linalg.solve(I - dt * A, S + dt * F)
