"""Output sensitivities from the model linearised along a run.

The sensitivity S = dx/dq of the states to a parameter (or to a signal injected into the model)
obeys the linear, time-varying equation S' = A(t) S + F(t), with A = df/dx along the run and F
the parameter's (or signal's) direct effect; the outputs move by C(t) S + G(t), C = dy/dx. Given
the run on a grid finer than the data's, the trapezoidal rule integrates S for every parameter at
once: per step one matrix product, whatever the number of parameters, and the run itself is one
plain simulation. Forward sensitivities carried by the integrator cost several simulations
each; these cost a fraction of one, and are accurate to the rule's second order (ample for a
Gauss-Newton step, whose Jacobian need not be exact; the residual comes from the solver).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .simulation import prepare_inputs

#: points per data interval on the grid the rule integrates on (at least)
SUBSTEPS = 1
#: the rule's step is shortened until the fastest mode moves by at most this in one step
#: (h |lambda|: for oscillations the turn in radians, for decays the fraction lost)
MAX_STEP = 0.3
#: numbers held per chunk of the run (the Jacobians are evaluated a chunk at a time)
CHUNK_NUMBERS = 4_000_000


def fine_grid(t: np.ndarray, substeps: int = SUBSTEPS) -> tuple[np.ndarray, np.ndarray]:
    """The data grid ``t`` with ``substeps`` points in each interval, and where the data points are."""
    substeps = max(1, int(substeps))
    pieces = [np.linspace(a, b, substeps + 1)[:-1] for a, b in zip(t[:-1], t[1:])]
    fine = np.concatenate([*pieces, t[-1:]])
    return fine, np.arange(0, len(fine), substeps)


def _expand(f: ca.Function) -> ca.Function:
    try:
        return f.expand()
    except RuntimeError:      # holds a rootfinder or a run-time linear solver
        return f


class Linearisation:
    """df/dx, df/dq, dy/dx, dy/dq along a run (``states`` (N, nx) at ``time``, parameter vector
    ``p``) for the free parameters named ``params``, evaluated a chunk of the run at a time."""

    def __init__(self, model, states: np.ndarray, time: np.ndarray, inputs, p: np.ndarray, params: list[str]):
        ode = model.ode
        self.time = np.asarray(time, float)
        idx = [ode.p_names.index(n) for n in params]
        X, U, P, T = ode.ode.mx_in()
        f, y = ode.ode(X, U, P, T), ode.out(X, U, P, T)
        self.fun = _expand(ca.Function("lin", [X, U, P, T], [ca.jacobian(f, X), ca.jacobian(f, P)[:, idx],
                                                           ca.jacobian(y, X), ca.jacobian(y, P)[:, idx]]))
        u = prepare_inputs(model, inputs)
        N = len(self.time)
        self.U = np.array([np.interp(self.time, u.time, u.values[:, k]) for k in range(len(u.names))]).reshape(-1, N)
        self.X, self.p = np.asarray(states, float).T, np.asarray(p, float)
        self.nx, self.ny, self.nq = len(ode.x_names), len(ode.y_names), len(idx)
        self.chunk = int(max(16, CHUNK_NUMBERS // max(1, self.nx * (self.nx + self.nq) + self.ny * (self.nx + self.nq))))
        self._maps: dict = {}

    def jacobians(self, k0: int, k1: int):
        """(A, B, C, E) at points k0 .. k1-1, each (k1 - k0, rows, cols)."""
        n = k1 - k0
        if n not in self._maps:
            self._maps[n] = self.fun.map(n)
        out = [np.array(v) for v in self._maps[n](self.X[:, k0:k1], self.U[:, k0:k1],
                                                  np.repeat(self.p[:, None], n, 1), self.time[None, k0:k1])]
        shape = lambda M, r, c: M.reshape(r, n, c).transpose(1, 0, 2) if r * c else np.zeros((n, r, c))
        nx, ny, nq = self.nx, self.ny, self.nq
        return shape(out[0], nx, nx), shape(out[1], nx, nq), shape(out[2], ny, nx), shape(out[3], ny, nq)

    def rate(self) -> float:
        """The fastest mode along the run (max |eig A|, per unit time), from a sample of points."""
        if not self.nx:
            return 0.0
        pick = np.unique(np.linspace(0, len(self.time) - 1, min(50, len(self.time))).astype(int))
        n = len(pick)
        A = np.array(self.fun.map(n)(self.X[:, pick], self.U[:, pick], np.repeat(self.p[:, None], n, 1),
                                     self.time[None, pick])[0]).reshape(self.nx, n, self.nx).transpose(1, 0, 2)
        return float(np.max(np.abs(np.linalg.eigvals(A))))

    def propagate(self, forcing, at: np.ndarray, ns: int) -> np.ndarray:
        """Output sensitivities (len(at), ny, ns) at grid points ``at`` (increasing), for forcing
        ``forcing(k, B, E) -> (Fx (nx, ns), Fy (ny, ns))``: the direct effect at grid point k
        on x' and on y, given df/dq and dy/dq there. S(t0) = 0."""
        t, N, nx = self.time, len(self.time), self.nx
        Y = np.zeros((len(at), self.ny, ns))
        S = np.zeros((nx, ns))
        I = np.eye(nx)
        F_prev, A_prev, k_out = None, None, 0
        for k0 in range(0, N, self.chunk):
            k1 = min(N, k0 + self.chunk)
            A, B, C, E = self.jacobians(k0, k1)
            if nx:
                # S_k = P_k S_{k-1} + Q_k (F_{k-1} + F_k): the trapezoidal rule, solved a chunk at a time
                prev = np.concatenate([A_prev[None] if A_prev is not None else A[:1], A[:-1]])
                h = (t[k0:k1] - t[np.maximum(np.arange(k0, k1) - 1, 0)])[:, None, None]
                lhs = I - 0.5 * h * A
                P = np.linalg.solve(lhs, I + 0.5 * h * prev)
                Q = np.linalg.solve(lhs, np.broadcast_to(0.5 * h * I, lhs.shape))
                A_prev = A[-1]
            for j in range(k1 - k0):
                k = k0 + j
                Fx, Fy = forcing(k, B[j], E[j])
                if k > 0 and nx:
                    S = P[j] @ S + Q[j] @ (F_prev + Fx)
                F_prev = Fx
                if k_out < len(at) and at[k_out] == k:
                    Y[k_out] = (C[j] @ S if nx else 0.0) + Fy
                    k_out += 1
        return Y

    def parameters(self, at: np.ndarray) -> np.ndarray:
        """d y / d q at grid points ``at`` for every parameter q of the linearisation."""
        return self.propagate(lambda k, B, E: (B, E), at, self.nq)
