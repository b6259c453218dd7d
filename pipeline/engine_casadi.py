"""In-process engine: CVODES on the compiled ODE, inputs baked in as a linear interpolant.

The fitting loops' workhorse (../shared/DESIGN.md, section 4: 10-50x faster than the FMU route).
Forward sensitivities integrate S' = (df/dx) S + df/dp alongside the state, so dy/dp is exact up
to the solver tolerance. The horizon is integrated in chunks so a wall-clock limit can stop a run
that crawls (some infeasible parameters make CVODES take tiny steps for ever).
"""
from __future__ import annotations

from collections import OrderedDict

import casadi as ca
import numpy as np

from .data import TimeSeries
from .errors import DataError
from .model import CompiledModel
from .simulation import (Engine, SimulationOptions, SimulationResult, Stopwatch, prepare_inputs,
                       quiet_native_output)

N_CHUNKS = 10
_CACHE_SIZE = 16


class CasadiEngine(Engine):
    """Simulate a :class:`CompiledModel` in this process."""

    name = "casadi"

    def __init__(self):
        self._plans: OrderedDict = OrderedDict()

    def accepts(self, model) -> bool:
        return isinstance(model, CompiledModel)

    def simulate(self, model: CompiledModel, inputs: TimeSeries, params=None, t_out=None,
                 options: SimulationOptions | None = None, sensitivities=None) -> SimulationResult:
        opts = options or SimulationOptions()
        u = prepare_inputs(model, inputs)
        t_out = u.time if t_out is None else np.asarray(t_out, dtype=float)
        _check_grid(t_out, u)
        p = model.parameter_vector(params)
        unknown = [n for n in (sensitivities or []) if n not in model.ode.p_names]
        if unknown:
            raise DataError(f"no free parameter(s) {', '.join(unknown)} to differentiate by")
        sel = [model.ode.p_names.index(n) for n in (sensitivities or [])]
        plan = self._plan(model, u, t_out, tuple(sel), opts)
        with quiet_native_output():
            return plan.run(p, opts)

    def _plan(self, model, u, t_out, sel, opts):
        # a cached plan holds its model, so the id cannot be reused while the entry exists
        key = (id(model), id(model.ode.ode), u.time.tobytes(), u.values.tobytes(),
               t_out.tobytes(), sel, opts.rtol, opts.atol, opts.max_steps)
        if key not in self._plans:
            self._plans[key] = _Plan(model, u, t_out, list(sel), opts)
            if len(self._plans) > _CACHE_SIZE:
                self._plans.popitem(last=False)
        self._plans.move_to_end(key)
        return self._plans[key]


def _check_grid(t_out, u: TimeSeries):
    if len(t_out) < 2 or np.any(np.diff(t_out) <= 0):
        raise DataError("output times must be strictly increasing (at least two)")
    if len(u.names) and (t_out[0] < u.time[0] - 1e-12 or t_out[-1] > u.time[-1] + 1e-12):
        raise DataError(f"output times [{t_out[0]:g}, {t_out[-1]:g}] leave the input's range "
                        f"[{u.time[0]:g}, {u.time[-1]:g}]", where=u.source)


class _Plan:
    """Integrators and output maps for one (model, input, grid, sensitivity) combination."""

    def __init__(self, model: CompiledModel, u: TimeSeries, t_out, sel, opts):
        ode = model.ode
        self.model, self.t_out, self.sel, self.u = model, t_out, sel, u
        nx, npar, ns = len(ode.x_names), len(ode.p_names), len(sel)
        X, P, T = ca.MX.sym("x", nx), ca.MX.sym("p", npar), ca.MX.sym("t")
        if u.names:
            interp = ca.interpolant("U", "linear", [u.time], u.values.ravel(order="C"))
            Ut = interp(T)
            self.u_out = np.array([np.interp(t_out, u.time, u.values[:, j])
                                   for j in range(len(u.names))])
        else:
            Ut = ca.MX(0, 1)
            self.u_out = np.zeros((0, len(t_out)))
        f = ode.ode(X, Ut, P, T)
        xa, fa = X, f
        if ns:
            S = ca.MX.sym("S", nx, ns)
            dS = ca.mtimes(ca.jacobian(f, X), S) + ca.jacobian(f, P)[:, sel]
            xa, fa = ca.vertcat(X, ca.vec(S)), ca.vertcat(f, ca.vec(dS))
        dae = {"x": xa, "p": P, "t": T, "ode": fa}
        iopts = {"reltol": opts.rtol, "abstol": opts.atol, "max_num_steps": opts.max_steps,
                 "disable_internal_warnings": True, "show_eval_warnings": False}
        self.events = _StateEvents(ode, xa, fa, P, T, Ut, nx, iopts) if ode.zero is not None else None
        # the integration grid: the output times and the model's time events, a restart at each
        events = [te for te in ode.time_events if t_out[0] < te < t_out[-1]]
        self.t_int = np.union1d(t_out, events)
        self.out_idx = np.searchsorted(self.t_int, t_out)
        starts = [int(np.searchsorted(self.t_int, te)) for te in events]
        pieces = np.split(np.arange(1, len(self.t_int)), [s for s in starts])
        chunks = [c for piece in pieces if len(piece)
                  for c in np.array_split(piece, min(N_CHUNKS, len(piece)))]
        if nx == 0:  # purely algebraic model: nothing to integrate, outputs evaluated below
            chunks = []
        self.chunks = []
        for k, idx in enumerate(chunks):
            t0 = self.t_int[idx[0] - 1]
            integ = ca.integrator(f"I{k}", "cvodes", dae, t0, self.t_int[idx].tolist(), iopts)
            self.chunks.append((idx, integ))
        N = len(t_out)
        Xs, Us, Ps, Ts = (ca.MX.sym(n, k) for n, k in
                          (("x", nx), ("u", len(ode.u_names)), ("p", npar), ("t", 1)))
        self.checks = ode.checks.map(N)   # outputs and checks with one solve of the loops per point
        if ns:
            Ss = ca.MX.sym("S", nx, ns)
            y = ode.out(Xs, Us, Ps, Ts)
            dy = ca.mtimes(ca.jacobian(y, Xs), Ss) + ca.jacobian(y, Ps)[:, sel]
            self.sens = ca.Function("dy", [Xs, Ss, Us, Ps, Ts], [dy]).map(N)
            x0 = ode.init(Us, Ps, Ts)
            self.dx0 = ca.Function("dx0", [Us, Ps, Ts], [x0, ca.jacobian(x0, Ps)[:, sel]])
        self.nx, self.ns = nx, ns
        self.u_at = (lambda t: np.array([np.interp(t, u.time, u.values[:, j]) for j in range(len(u.names))]))

    def run(self, p: np.ndarray, opts: SimulationOptions) -> SimulationResult:
        ode, t_out, N = self.model.ode, self.t_out, len(self.t_out)
        clock = Stopwatch(opts.time_limit)
        names = ode.y_names

        def fail(reason):
            return SimulationResult.failed(reason, t_out, names, "casadi", clock.elapsed)

        u0 = self.u_out[:, 0]
        try:
            if self.ns:
                x0, s0 = (np.array(v) for v in self.dx0(u0, p, t_out[0]))
                xa = np.concatenate([x0.ravel(), s0.ravel(order="F")])
            else:
                xa = np.array(ode.init(u0, p, t_out[0])).ravel()
        except RuntimeError as exc:
            return fail(f"initialisation failed: {_last_line(exc)}")
        if not np.all(np.isfinite(xa)):
            return fail("initialisation gave non-finite values")
        t_int = self.t_int
        if self.events is not None:
            self.events.count = 0
        traj = np.full((len(xa), len(t_int)), np.nan)
        traj[:, 0] = xa
        for idx, integ in self.chunks:
            if clock.expired:
                return fail(f"time limit of {opts.time_limit:g} s exceeded at t = {t_int[idx[0] - 1]:g}")
            try:
                xf = np.array(integ(x0=traj[:, idx[0] - 1], p=p)["xf"])
            except RuntimeError as exc:
                return fail(f"solver error before t = {t_int[idx[-1]]:g}: {_last_line(exc)}")
            traj[:, idx] = xf
            if not np.all(np.isfinite(xf)):
                bad = idx[np.argmax(~np.all(np.isfinite(xf), axis=0))]
                return fail(f"non-finite state at t = {t_int[bad]:g}")
            if self.events is not None and self.events.crossed(traj, idx, t_int, p, self.u_at):
                try:
                    self.events.correct(traj, idx, t_int, p, self.u_at)
                except RuntimeError as exc:
                    return fail(f"solver error after a state event before t = {t_int[idx[-1]]:g}: {_last_line(exc)}")
        traj = traj[:, self.out_idx]
        X = traj[: self.nx]
        P = np.repeat(p[:, None], N, axis=1)
        try:
            y, res, drift = (np.array(v) for v in self.checks(X, self.u_out, P, t_out[None, :]))
        except RuntimeError as exc:
            return fail(f"evaluating the outputs failed: {_last_line(exc)}")
        result = SimulationResult(t_out.copy(), y.T, list(names), seconds=clock.elapsed,
                                  engine="casadi", states=X.T)
        scale = 1.0 + (np.max(np.abs(X)) if X.size else 0.0)
        reason = _check(y, res.ravel(), drift.ravel(), t_out, scale, opts)
        if reason:
            result.ok, result.reason = False, reason
        if self.ns:
            # column k of traj holds vec(S(t_k)); the mapped function wants [S(t_1), ..., S(t_N)]
            S = np.hstack([traj[self.nx:, k].reshape(self.nx, self.ns, order="F") for k in range(N)])
            dy = np.array(self.sens(X, S, self.u_out, P, t_out[None, :]))
            result.sensitivities = dy.reshape(len(names), N, self.ns).transpose(1, 0, 2)
            result.sensitivity_names = [ode.p_names[i] for i in self.sel]
        return result


class _StateEvents:
    """State events: where a relation on the states changes sign between two output points, the
    crossing is located (Illinois regula falsi on the relation along the solution) and the
    solver restarted there and at every later point of the chunk (CVODES's own root-finding is
    not reachable through CasADi's integrator). A relation that switches and switches back
    between two output points is not seen: the solver's error control is all that handles it.

    One integrator over normalised time tau in [0, 1] with (p, t0, h) as parameters, so any
    interval is one call. Sensitivities are carried through unchanged across an event: their jump
    (f+ - f-) dt*/dp is left out (a Gauss-Newton step only needs them roughly).
    """

    def __init__(self, ode, xa, fa, P, T, Ut, nx, iopts):
        self.zero, self.nx = ode.zero, nx
        self._dae = (xa, fa, P, T, iopts)
        self.hop_int = None        # built at the first event (most runs have none)
        self.maps: dict = {}
        self.count = 0

    def hop(self, x, p, ta, tb):
        """The state at tb from x at ta: one fresh integration (a restart)."""
        if tb <= ta:
            return np.asarray(x, float)
        if self.hop_int is None:
            xa, fa, P, T, iopts = self._dae
            tau, t0, h = ca.MX.sym("tau"), ca.MX.sym("t0"), ca.MX.sym("h")
            f = ca.substitute(fa, T, t0 + tau * h) * h
            self.hop_int = ca.integrator("hop", "cvodes", {"x": xa, "p": ca.vertcat(P, t0, h), "t": tau, "ode": f},
                                         0.0, [1.0], iopts)
        return np.array(self.hop_int(x0=x, p=np.concatenate([p, [ta, tb - ta]]))["xf"]).ravel()

    def g(self, x, p, t, u_at):
        return np.array(self.zero(x[: self.nx], u_at(t), p, t)).ravel()

    def crossed(self, traj, idx, t_int, p, u_at) -> bool:
        """Whether any relation changes sign between the points of this chunk (one mapped call)."""
        cols = np.r_[idx[0] - 1, idx]
        if len(cols) not in self.maps:            # chunks have a few sizes: map each once
            self.maps[len(cols)] = self.zero.map(len(cols))
        U = np.column_stack([u_at(t_int[c]) for c in cols])
        G = np.array(self.maps[len(cols)](traj[: self.nx, cols], U, np.repeat(np.asarray(p)[:, None], len(cols), 1),
                                          t_int[cols][None]))
        return bool(np.any(np.sign(G[:, 1:]) * np.sign(G[:, :-1]) < 0))

    def correct(self, traj, idx, t_int, p, u_at, max_events: int = 2000):
        """Check each interval of this chunk for a sign change of a relation; from the first one
        on, every point is integrated again from the located crossing(s) (restarts). Beyond
        ``max_events`` in one simulation (a chattering switch) the solver steps through."""
        g_prev = self.g(traj[:, idx[0] - 1], p, t_int[idx[0] - 1], u_at)
        restarted = False
        for j in idx:
            ta, tb, x_a = t_int[j - 1], t_int[j], traj[:, j - 1]
            x_b = self.hop(x_a, p, ta, tb) if restarted else traj[:, j]
            g_b = self.g(x_b, p, tb, u_at)
            g_a = g_prev
            while self.count < max_events:
                flips = np.flatnonzero(np.sign(g_a) * np.sign(g_b) < 0)
                if not flips.size:
                    break
                self.count += 1
                ta, x_a = self.locate(x_a, ta, tb, p, u_at, flips, g_a)
                g_a = self.g(x_a, p, ta, u_at)
                x_b = self.hop(x_a, p, ta, tb)          # the solver restarted past the crossing
                g_b = self.g(x_b, p, tb, u_at)
                restarted = True
            traj[:, j] = x_b
            g_prev = g_b

    def locate(self, xa, ta, tb, p, u_at, flips, g_a):
        """The earliest crossing of the relations ``flips`` in (ta, tb) and the state just past it."""
        best_t = tb
        for r in flips:
            lo, hi, g_lo = ta, tb, g_a[r]
            g_hi = self.g(self.hop(xa, p, ta, hi), p, hi, u_at)[r]
            side = 0
            for _ in range(60):
                if hi - lo <= 1e-12 * max(1.0, abs(hi)):
                    break
                t = (lo * g_hi - hi * g_lo) / (g_hi - g_lo) if g_hi != g_lo else 0.5 * (lo + hi)
                t = min(max(t, lo + 1e-3 * (hi - lo)), hi - 1e-3 * (hi - lo))
                g_t = self.g(self.hop(xa, p, ta, t), p, t, u_at)[r]
                if np.sign(g_t) == np.sign(g_lo):
                    lo, g_lo = t, g_t
                    g_hi = g_hi / 2 if side == -1 else g_hi      # Illinois
                    side = -1
                else:
                    hi, g_hi = t, g_t
                    g_lo = g_lo / 2 if side == 1 else g_lo
                    side = 1
            if hi < best_t:
                best_t = hi
        return best_t, self.hop(xa, p, ta, best_t)   # hi: just past the crossing


def _check(y, res, drift, t, scale, opts) -> str | None:
    if not np.all(np.isfinite(y)):
        return f"non-finite output at t = {t[np.argmax(~np.all(np.isfinite(y), axis=0))]:g}"
    bad = np.nonzero(~(res <= opts.residual_tol * scale))[0]
    if bad.size:
        k = bad[0]
        return f"algebraic loop not converged at t = {t[k]:g} (residual {res[k]:.3g})"
    bad = np.nonzero(~(drift <= opts.drift_tol * scale))[0]
    if bad.size:
        k = bad[0]
        return f"constraint drift {drift[k]:.3g} at t = {t[k]:g} (index-reduced invariants violated)"
    return None


def _last_line(exc: Exception) -> str:
    """A one-line reason from a CasADi exception (its text is a stack of C++ locations)."""
    text = str(exc)
    if "rootfinder process failed" in text:
        return "algebraic loop did not converge (Newton's method failed)"
    lines = [line.strip() for line in text.strip().splitlines() if line.strip()]
    msg = lines[-1] if lines else type(exc).__name__
    msg = msg.split(": ", 1)[-1] if msg.startswith(".../") else msg
    if msg == "Evaluation failed":
        return "model evaluation failed (singular algebraic loop or non-finite value)"
    return msg
