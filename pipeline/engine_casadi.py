"""In-process engine: CVODES on the compiled ODE, inputs baked in as a linear interpolant.

The fitting loops' workhorse (../shared/DESIGN.md, section 4: 10-50x faster than the FMU route).
Forward sensitivities integrate S' = (df/dx) S + df/dp alongside the state, so dy/dp is exact up
to the solver tolerance.

The horizon is integrated in calls of CVODES over a few output points each; between calls the
engine checks the wall-clock limit and the work budget (solver steps) and sizes the next call so
that even a call that crawls cannot overrun them by much: its points and its steps per point are
bounded by what is left, at the step rate measured so far.

Each run is integrated by Adams' methods where the model is not stiff at the spacing of its output
points (its fastest mode at the start against that spacing, :data:`ADAMS_REACH`), by BDF
elsewhere, and by BDF again where the solver gives an Adams run up.

Hybrid models (:class:`~mcl.compile.structure.Ode` with ``discrete`` > 0) carry their discrete
variables at the end of the state vector with a zero derivative; at an event (a relation changing
sign, located between two points; a time event; a clock tick) the ``update`` function is iterated
until the discrete values stop changing (Modelica's event iteration), then the solver restarts.
"""
from __future__ import annotations

import functools
import logging
import math
from collections import OrderedDict

import casadi as ca
import numpy as np

from .calls import Call
from .data import TimeSeries
from .errors import DataError
from .compile import parametric
from .compile.dae import RELATION_TRUTH
from .compile.structure import differentiable, initial_state
from .model import CompiledModel
from .simulation import (Engine, SimulationOptions, SimulationResult, Stopwatch, Switch, crossed, prepare_inputs,
                         quiet_native_output)

log = logging.getLogger(__name__)

N_CHUNKS = 10
_CACHE_SIZE = 16
_INTEGRATORS = 64         # integrators kept per plan (built on demand: a few ms each)
#: sensitivities are integrated scaled by this times |p| (1 for p = 0), so they sit far below
#: the absolute tolerance: CVODES's error control then follows the states alone (2.5x fewer
#: steps on a 64-section ladder, sensitivities still within 1e-5 of a tight solve); a
#: Gauss-Newton step needs them roughly, and the linear sensitivity ODE is exact under scaling
SENS_SCALE = 1e-6
DETECTION_POINTS = 400    # at least this many points over the horizon where relations are checked
MAX_EVENT_ITERATIONS = 100
#: a state's derivative that changes across a located event by more than this (relative) is a
#: switched right-hand side (SimulationResult.switched): rounding is far below, a heater's
#: power switched on or off far above
SWITCHED = 1e-6
#: a time event's iteration reads time this far past the instant (relative, at least 1): a
#: relation on time takes its value after the event there (``time > 1`` is true after the
#: event at 1, but false at 1 itself, and a when-clause on it waited for the run's end); well
#: above the rounding an instant is snapped within (see _snapped)
AFTER_TIME_EVENT = 1024 * np.finfo(float).eps
MAX_EVENTS = 100000
EVENT_SPAN = 4.0          # a call spans this many times the spacing of the events so far
#: a call ends at most this many times as far as the time in which a relation on the states
#: reaches zero on its trend (see _Hybrid.reach). Not short of it: a call run past a crossing
#: into a branch held beyond it fails within its frugal steps (see _Hybrid.called), and calls
#: ended at half the way restarted the solver 5x as often (a furnished room's fits: 250 CPU-s
#: at 0.5, 50 at 2)
REACH = 2.0
ZOOM_TOL = 1e-7           # a crossing on the states located to this fraction of the interval it was seen in
ZOOM_POINTS = 32         # points of one call that narrows a crossing on the states (32x narrower a call)
#: output points whose outputs and checks a model with algebraic loops evaluates in one call
#: (the time limit is checked between such calls)
CHECK_CHUNK = 256
PROBE_STEPS = 2000        # solver steps of one hop of a probe after a failure (a failing hop stops soon)
FOLLOW_POINTS = 32        # points of a call where the loops' solutions are checked to follow on
FOLLOW_FIRST = 8          # points of a run's first call where there are loops (see _Plan.advance)
FOLLOW_GROWTH = 1.5       # ... and how many times more after a call that followed to its end
FOLLOW_TOL = 1e-3         # a loop's solution off the one followed point to point by more (relative): another root
#: a call that CVODES ends with this (its error test failed repeatedly, or at the least step)
#: is tried once more with its tolerances times TIGHTER
_TEST_FAILURES, TIGHTER = "CV_ERR_FAILURE", 0.1
#: a call of the solver may use this share of the wall time still left
CALL_SHARE = 0.4
#: output points of a run's first call (whose steps and seconds size the calls after it)
FIRST_CALL = 8
#: a run whose fastest mode at its start, times the output spacing, is at most this is not
#: stiff at the resolution the data ask for: it is integrated by Adams' methods (no stiffness
#: to pay BDF's low orders for; the Wiener-Hammerstein circuit at 51.2 kHz: 76 000 steps on
#: 8 192 samples where BDF took 133 000, 1.6x less CPU with sensitivities), and by BDF again
#: where that run fails (a law that stiffens the model on the way)
ADAMS_REACH = 1.0
#: the stiffness is judged (eigenvalues of the state Jacobian) on models up to this many states
ADAMS_STATES = 64



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
               t_out.tobytes(), sel, opts.rtol, opts.atol, opts.max_steps, opts.state_bound is None)
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


class _Stop(Exception):
    """A simulation ends early: its reason is the failed result's."""


class _Unsettled(_Stop):
    """The event iteration found no fixed point of the discrete values."""


class _NonFinite(_Stop):
    """The event iteration met non-finite values (a singular mode's linear block)."""


class _OverBudget(_Stop):
    """The run used up its work budget (solver steps): another method may need fewer."""


class _Diverged(_Stop):
    """The states grew past the bound or became non-finite: a hybrid run first looks for a
    crossing the call ran past with its relations held (:meth:`_Hybrid.probe`: an end stop's
    force, its contact held past the parting, pushed a mass off to 3 km/s)."""


class _SolverFailed(_Stop):
    """The solver gave up (an error, or too much work where time was not short): a hybrid run
    first looks for a crossing it ran into (:meth:`_Hybrid.probe`)."""


class _Frugal(_SolverFailed):
    """A frugal call (see :meth:`_Plan.advance`) needed more steps than it was given."""


class _Unlimited:
    """A budget that never stops a run (the outputs of one that already failed)."""

    def check(self, t: float):
        pass


class _Budget:
    """Wall time and solver steps: what is spent, and how big the next call may be."""

    def __init__(self, opts: SimulationOptions, clock: Stopwatch):
        self.opts, self.clock = opts, clock
        self.steps = 0
        self.points = 0           # output points integrated so far
        self.last = 0.0           # steps per point of the last call
        self.rate = None          # seconds per step, measured
        self.guessed = False      # rate is a guess made before any call

    def record(self, steps: int, seconds: float, points: int = 0):
        self.steps += int(steps)
        self.points += int(points)
        if points:
            self.last = steps / points
        if steps > 0:
            r = seconds / steps
            self.rate = r if self.rate is None or self.guessed else max(r, 0.5 * self.rate)
            self.guessed = False

    def check(self, t: float):
        if self.clock.expired:
            raise self.stop("time", t)
        if self.opts.max_work is not None and self.steps >= self.opts.max_work:
            raise self.stop("work", t)

    def call_size(self, n_points: int, share: float = CALL_SHARE, rest: bool = False) -> tuple[int, int, str | None]:
        """(points, steps per point, the bound that limited them) for the next call of at most
        ``n_points`` points. ``rest``: the call is the rest of a run (not a retry, not a hop).

        With a work budget (a fit's runs) the rest of a run goes in one call whose points may
        each take 8x the steps the points have taken so far, within the work left; a point that
        needs more is retried alone. Without one, the rest goes in one call where the run, going
        as it has so far, fits easily in the time left. Each call boundary is a solver restart,
        so the calls must not follow the machine's load: the budget's steps size a fit's calls,
        and the rate is measured in CPU seconds, which a loaded machine changes far less than
        the wall clock (sized by the wall-clock rate, a loaded machine gave the
        Wiener-Hammerstein fits 29 calls where a quiet one gave 3, and another law). The first
        call, retries and hops, where a run that crawls shows itself, stay within ``share`` of
        the time left at that rate; the wall time is checked between calls."""
        cap = self.opts.max_steps
        if not self.points:          # the first call: a fixed few points, its cost then measured
            n_points = min(n_points, FIRST_CALL)
        budget = self.opts.max_work
        by_time = (math.inf if self.rate is None
                   else share * max(self.opts.time_limit - self.clock.elapsed, 0.0) / self.rate)
        if self.points and rest:
            if budget is not None:
                work = max(budget - self.steps, 1)
                need = self.need()
                if n_points * need <= work:
                    return n_points, need, "work"
                return self._split(n_points, work, "work")
            if 4.0 * self.steps / self.points * n_points <= by_time:
                return n_points, cap, None
        if budget is not None and budget - self.steps <= by_time:
            return self._split(n_points, max(budget - self.steps, 1), "work")
        return self._split(n_points, by_time, "time")

    def need(self) -> int:
        """Steps per point of a call whose points may each take 8x the steps the points have
        taken so far, or 4x those of the last call's (where the run has turned stiff: a spring
        stiffening a millionfold halfway, each point at the run's mean failed first), at least
        64, at most the cap; a power of 2: few integrators are built."""
        return _pow2(min(max(64, int(8 * self.steps / self.points), int(4 * self.last)), self.opts.max_steps))

    def _split(self, n_points: int, allowed: float, bound: str) -> tuple[int, int, str | None]:
        """A call of at most ``n_points`` points whose steps in all stay within ``allowed``."""
        cap = self.opts.max_steps
        if n_points * cap <= allowed:
            return n_points, cap, None
        per_point = max(int(allowed // n_points), 1)
        if per_point >= 256:          # fewer steps per point: most calls need few
            return n_points, _pow2(min(per_point, cap)), bound
        if self.points:
            need = self.need()
            if allowed >= 2 * need:   # (each call is a restart: small steps, fresh Jacobians)
                return min(n_points, int(allowed // need)), need, bound
        n = max(1, int(allowed // min(cap, 4096)))
        n = min(n_points, 1 << (n.bit_length() - 1))
        return n, _pow2(max(min(int(allowed // n), cap), 16)), bound

    def stop(self, bound: str | None, t: float) -> _Stop:
        """The run's end at ``t`` by the ``bound`` that limited it (the work budget, else time)."""
        if bound == "work":
            return _OverBudget(f"work budget of {self.opts.max_work} solver steps exceeded at t = {t:g}")
        return _Stop(f"time limit of {self.opts.time_limit:g} s exceeded at t = {t:g}")


def _snapped(te: float, t_out: np.ndarray) -> float:
    """An event instant within rounding of an output time is that time: a tick computed as
    0.001 + 85 * 0.001 is 0.08600000000000001, and the output at 0.086 would otherwise show
    the value before the event, where the instant's own value is the one after it."""
    k = int(np.clip(np.searchsorted(t_out, te), 1, len(t_out) - 1))
    near = t_out[k - 1] if abs(te - t_out[k - 1]) < abs(te - t_out[k]) else t_out[k]
    return float(near) if abs(te - near) <= 64 * np.finfo(float).eps * max(abs(te), 1.0) else float(te)


def _sens_scale(p):
    """The scale of each sensitivity column (see SENS_SCALE), numeric or symbolic."""
    if isinstance(p, np.ndarray):
        return SENS_SCALE * np.where(p != 0.0, np.abs(p), 1.0)
    return SENS_SCALE * ca.if_else(p != 0, ca.fabs(p), 1)


def _pow2(n: int) -> int:
    return 1 << max(int(n), 1).bit_length() - 1


class _Plan:
    """Integrators and output maps for one (model, input, grid, sensitivity) combination."""

    def __init__(self, model: CompiledModel, u: TimeSeries, t_out, sel, opts):
        # a model with loops runs with their guesses after the parameters: each call of the
        # solver starts their Newton methods from the last solution (:meth:`refresh`)
        ode = self.ode = model.ode.warm or model.ode
        self.model, self.t_out, self.sel, self.u = model, t_out, sel, u
        self.ng = 0 if ode.guess0 is None else len(ode.guess0)
        self.branched = bool((ode.events or {}).get("branches"))    # loops held on a branch
        nx, npar, ns = len(ode.x_names), len(ode.p_names) + self.ng, len(sel)
        X, P, T = ca.MX.sym("x", nx), ca.MX.sym("p", npar), ca.MX.sym("t")
        if u.names:
            interp = ca.interpolant("U", "linear", [u.time], u.values.ravel(order="C"))
            Ut = interp(T)
            self.u_out = np.array([np.interp(t_out, u.time, u.values[:, j])
                                   for j in range(len(u.names))])
        else:
            Ut = ca.MX(0, 1)
            self.u_out = np.zeros((0, len(t_out)))
        # what the parameters alone determine (a filter's coefficients) is computed once per
        # run, outside the solver's calls: q, and dq/dp for the sensitivities (QP)
        self.split = None if self.ng else parametric.split(ode)
        if self.split is not None:
            Q, QP = ca.MX.sym("q", self.split.nq), ca.MX.sym("qp", self.split.nq, ns)
            f = self.split.ode(X, Ut, P, Q, T)
        else:
            f = differentiable(ode, p_cols=sel)(X, Ut, P, T)
        # the state Jacobian at a run's start, for the choice of method (:meth:`method_for`):
        # only where Adams' methods may be chosen (no loops, zero crossings or discrete variables)
        adams = 0 < nx <= ADAMS_STATES and not self.ng and ode.zero is None and not getattr(ode, "discrete", 0)
        self.stiffness = (ca.Function("jx", [X, P, *((Q,) if self.split is not None else ()), T],
                                      [ca.jacobian(f, X)]) if adams else None)
        self.spacing = float(np.median(np.diff(t_out))) if len(t_out) > 1 else 0.0
        xa, fa = X, f
        if ns:
            S = ca.MX.sym("S", nx, ns)
            f_p = self.split.d_dp(f, P, Q, QP, sel) if self.split is not None else ca.jacobian(f, P)[:, sel]
            dS = ca.mtimes(ca.jacobian(f, X), S) + ca.mtimes(f_p, ca.diag(_sens_scale(P[sel])))
            xa, fa = ca.vertcat(X, ca.vec(S)), ca.vertcat(f, ca.vec(dS))
        fa = ca.densify(fa)       # CVODES takes dense right-hand sides (a state held constant is a structural 0)
        # a run that leaves the caller's bound on |x| (a candidate law that blows up) is frozen
        # there, which the solver crosses in a few steps, and then stopped: left to run, one
        # such run took 30000 steps where a fit's others took 4000 (only where a bound is
        # asked for: the guard makes the solver's Jacobian dense)
        B = ca.MX.sym("bound")
        if opts.state_bound is not None:
            fa = fa * (ca.mmax(ca.fabs(X)) <= B)
        P = ca.vertcat(P, B, *((Q, ca.vec(QP)) if self.split is not None else ()))
        self.na = xa.numel()
        empty = ca.MX.sym("z", 0, 1), ca.MX.sym("u", 0, 1)
        # one oracle for every integrator: its derivatives are built once, so an integrator
        # over any grid costs milliseconds. Where output times lie closer than a microsecond
        # it runs in time scaled to the horizon: CasADi's integrator does not move to an output
        # time within 1e-9 (absolute) of the last, which on a nanosecond circuit is a whole
        # output interval (elsewhere unscaled: the solver's path, and so a fit's, as before)
        fine = len(t_out) > 1 and float(np.min(np.diff(t_out))) < 1e-6
        self.t_origin, self.t_scale = (float(t_out[0]), float(t_out[-1] - t_out[0]) or 1.0) if fine else (0.0, 1.0)
        tau = ca.MX.sym("tau")
        self.oracle = ca.Function("dae", [tau, xa, empty[0], P, empty[1]],
                                  [ca.substitute(fa, T, self.t_origin + self.t_scale * tau) * self.t_scale,
                                   ca.MX(0, 1), ca.MX(0, 1), ca.MX(0, 1)], ca.dyn_in(), ca.dyn_out())
        self.iopts = {"reltol": opts.rtol, "abstol": opts.atol,
                      "disable_internal_warnings": True, "show_eval_warnings": False}
        self.method = "bdf"       # this run's (:meth:`method_for`)
        self._integrators: OrderedDict = OrderedDict()
        t0, h = ca.MX.sym("t0"), ca.MX.sym("h")
        PH = ca.vertcat(P, t0, h)
        self.hop_oracle = ca.Function("hop", [tau, xa, empty[0], PH, empty[1]],
                                      [ca.substitute(fa, T, t0 + tau * h) * h, ca.MX(0, 1), ca.MX(0, 1), ca.MX(0, 1)],
                                      ca.dyn_in(), ca.dyn_out())
        self.hybrid = (_Hybrid(ode, t_out) if (ode.zero is not None or getattr(ode, "discrete", 0)
                                               or getattr(ode, "asserts", None) is not None) else None)
        # the integration grid: output times, time events and clock ticks (a restart at each),
        # and where relations are watched, enough points to see their sign changes
        events = sorted({_snapped(te, t_out) for te in ode.time_events if t_out[0] < te < t_out[-1]})
        ticks = {}
        for te, clocks in (self.hybrid.ticks(t_out[0], t_out[-1]) if self.hybrid else {}).items():
            ticks.setdefault(_snapped(te, t_out), []).extend(clocks)
        t_int = np.union1d(np.union1d(t_out, events), sorted(ticks))
        if ode.zero is not None and len(t_int) - 1 < DETECTION_POINTS:
            k = int(math.ceil(DETECTION_POINTS / (len(t_int) - 1)))
            t_int = np.union1d(t_int, (t_int[:-1, None] + np.diff(t_int)[:, None] * np.arange(1, k) / k).ravel())
        self.t_int = t_int
        self.out_idx = np.searchsorted(t_int, t_out)
        self.tick_at = {int(np.searchsorted(t_int, te)): clocks for te, clocks in ticks.items()}
        self.time_event_at = {int(np.searchsorted(t_int, te)) for te in events}
        restarts = sorted({int(np.searchsorted(t_int, te)) for te in events} | set(self.tick_at))
        pieces = np.split(np.arange(1, len(t_int)), restarts)
        # with state events, a call integrates past the first crossing and is redone from there:
        # short calls waste little. Without, each call is a restart of the solver (small steps
        # and fresh Jacobians again: 3x the steps of one call on a MultiBody pendulum), and the
        # budget alone sizes the calls
        n_chunks = N_CHUNKS if model.ode.zero is not None else 1
        # chunks of a share of the whole grid, not of each piece: with a clock ticking every
        # few grid points, a piece split N_CHUNKS ways is a restart at every point
        size = max(1, math.ceil((len(t_int) - 1) / n_chunks))
        chunks = []
        for piece in pieces:
            if not len(piece):
                continue
            # a small first call measures the step rate before the big ones are sized
            head = piece[: max(1, len(piece) // (4 * N_CHUNKS))] if not chunks else piece[:0]
            if len(head):
                chunks.append(head)
            rest = piece[len(head):]
            if len(rest):
                chunks += list(np.array_split(rest, math.ceil(len(rest) / size)))
        self.chunks = [] if nx == 0 else chunks   # purely algebraic: nothing to integrate
        N = len(t_out)
        Xs, Us, Ps, Ts = (ca.MX.sym(n, k) for n, k in
                          (("x", nx), ("u", len(ode.u_names)), ("p", npar), ("t", 1)))
        # outputs and checks with one solve of the loops per point (with q, where split)
        checks = self.split.checks if self.split is not None else ode.checks
        # (a model with loops: a chunk of points at a time, the time limit checked between:
        # where Newton's method fails, each point's fallback can take a second)
        self.check_chunk = CHECK_CHUNK if ode.nonlinear_blocks and N > CHECK_CHUNK else N
        self.checks = checks.map(self.check_chunk)
        self.checks_rest = checks.map(N % self.check_chunk) if N % self.check_chunk else None
        if self.branched:   # at the output points, the loops' branches their call had
            z = ode.solved(Xs, Us, Ps, Ts)
            g = Ps[npar - self.ng:]
            found = ca.logic_and(ca.mmin(z == z), ca.mmax(ca.fabs(z)) < np.inf)
            self.at_guesses = ca.Function("at_guesses", [Xs, Us, Ps, Ts], [ca.if_else(found, z, g)]).map(N)
        self.follow_maps: dict = {}
        if ns:
            Ss = ca.MX.sym("S", nx, ns)
            if self.split is not None:     # q and dq/dp (flattened) as the last arguments
                Qs, QPs = ca.MX.sym("q", self.split.nq), ca.MX.sym("qp", self.split.nq, ns)
                y = self.split.out(Xs, Us, Ps, Qs, Ts)
                dy = ca.mtimes(ca.jacobian(y, Xs), Ss) + self.split.d_dp(y, Ps, Qs, QPs, sel)
                self.sens = ca.Function("dy", [Xs, Ss, Us, Ps, Ts, Qs, ca.vec(QPs)], [dy]).map(N)
            else:
                y = differentiable(ode, "out", p_cols=sel)(Xs, Us, Ps, Ts)
                dy = ca.mtimes(ca.jacobian(y, Xs), Ss) + ca.jacobian(y, Ps)[:, sel]
                self.sens = ca.Function("dy", [Xs, Ss, Us, Ps, Ts], [dy]).map(N)
            self.dx0 = initial_state(ode, sel)
        self.nx, self.ns = nx, ns
        self.scale = lambda p: _sens_scale(np.asarray(p, float)[self.sel])
        self.u_at = (lambda t: np.array([np.interp(t, u.time, u.values[:, j]) for j in range(len(u.names))]))
        self.zero_maps: dict = {}

    # -- integrators -----------------------------------------------------------------------
    def integrator(self, t0: float, grid: np.ndarray, steps: int, tight: float = 1.0):
        key = (float(t0), grid.tobytes(), steps, self.method, tight)
        if key not in self._integrators:
            self._integrators[key] = ca.integrator("I", "cvodes", self.oracle, self.tau(t0), self.tau(grid).tolist(),
                                                   self.options(steps, tight))
            if len(self._integrators) > _INTEGRATORS:
                self._integrators.popitem(last=False)
        self._integrators.move_to_end(key)
        return self._integrators[key]

    def hop_integrator(self, steps: int, points: int, to_end: bool, tight: float = 1.0):
        """An integrator in time scaled to its call (parameters: its start and length), its
        output times :func:`hop_grid`'s: one serves every call of that many points, where one
        created for each call's times costs 0.6 ms (a rectifier's 1 300 calls a second)."""
        key = ("hop", steps, points, to_end, self.method, tight)
        if key not in self._integrators:
            self._integrators[key] = ca.integrator("hop", "cvodes", self.hop_oracle, 0.0, hop_grid(points, to_end).tolist(),
                                                   self.options(steps, tight))
        self._integrators.move_to_end(key)
        return self._integrators[key]

    def options(self, steps: int, tight: float = 1.0) -> dict:
        """The solver's options for calls of ``steps`` steps, its tolerances times ``tight``."""
        return {**self.iopts, "reltol": self.iopts["reltol"] * tight, "abstol": self.iopts["abstol"] * tight,
                "max_num_steps": steps, "linear_multistep_method": self.method}

    def method_for(self, x, p, t) -> str:
        """"adams" where the model is not stiff at the output spacing at ``x`` (its fastest
        mode times the spacing at most :data:`ADAMS_REACH`), else "bdf"; models with events,
        loops or many states keep BDF (asserts alone are read after the run)."""
        if self.stiffness is None:
            return "bdf"
        try:
            J = np.array(self.stiffness(x[: self.nx], p, *((self.q,) if self.split is not None else ()), t))
        except RuntimeError:
            return "bdf"
        if not np.all(np.isfinite(J)):
            return "bdf"
        return "adams" if np.max(np.abs(np.linalg.eigvals(J))) * self.spacing <= ADAMS_REACH else "bdf"

    def call_for(self, t0: float, sub, steps: int, tight: float = 1.0):
        """(integrator, the parameters it takes after the model's) over the grid points ``sub``
        from ``t0``: a hop's where they are equally spaced from ``t0`` in a model with events
        or loops (each event a call from its own instant, a loop's calls as long as its
        guesses lead: a new integrator each, otherwise)."""
        times = self.t_int[sub]
        if (self.hybrid is not None or self.ng) and _even(t0, times):
            return self.hop_integrator(steps, len(sub), False, tight), [t0, times[-1] - t0]
        return self.integrator(t0, times, steps, tight), []

    def refresh(self, x, t, p) -> None:
        """The loops' guesses, the tail of ``p`` (changed in place: the event handling holds
        it too), set to their solution at ``x``, ``t`` where it is found."""
        if self.ng:
            try:
                z = np.array(self.ode.solved(x[: self.nx], self.u_at(t), p, t)).ravel()
            except RuntimeError:             # not found from the guesses held: they stay
                return
            if np.all(np.isfinite(z)):       # (the comparisons of a failed solve are not its branch)
                p[-self.ng:] = z

    def tau(self, t):
        return (np.asarray(t, float) - self.t_origin) / self.t_scale

    def hop(self, x, p, ta, tb, budget: _Budget, steps: int | None = None, points: int = 1,
            to_end: bool = False):
        """The state at ``tb`` from ``x`` at ``ta``: one fresh integration (a restart). With
        ``points`` > 1: the states at that many times up to ``tb`` (columns), from the same
        solver steps (interpolated between them): equally spaced, or with ``to_end`` closing in
        on ``tb`` (:func:`hop_grid`)."""
        if tb <= ta:
            return np.asarray(x, float) if points == 1 else np.repeat(np.asarray(x, float)[:, None], points, 1)
        steps = steps or budget.call_size(1, 1.0)[1]
        integ = self.hop_integrator(steps, points, to_end)
        self.refresh(x, ta, p)
        clock = Stopwatch(0, cpu=True)
        try:
            xf = integ(x0=x, p=np.concatenate([p, self.tail, [ta, tb - ta]]))["xf"]
        except RuntimeError as exc:
            budget.record(_spent(integ, steps, exc), clock.elapsed)
            raise
        budget.record(_nsteps(integ), clock.elapsed)
        xf = np.array(xf)
        self.within_bound(xf[: self.nx], ta + (tb - ta) * hop_grid(points, to_end))
        return xf.ravel() if points == 1 else xf

    def hop_halved(self, x, p, ta, tb, budget: _Budget, least: float, **kw):
        """(end, states) of :meth:`hop` from ``ta`` towards ``tb``, the end halved towards ``ta``
        while the solver gives up, until it is within ``least`` of ``ta`` (then RuntimeError)."""
        while True:
            budget.check(ta)
            try:
                return tb, self.hop(x, p, ta, tb, budget, **kw)
            except (RuntimeError, _Diverged):     # (held relations past a crossing: shorter)
                if tb - ta <= least:
                    raise
                tb = 0.5 * (ta + tb)

    def advance(self, x, t0, idx, p, budget: _Budget, traj, one_call: bool = False,
                frugal: bool = False) -> int:
        """Integrate from ``x`` at ``t0`` over the grid points ``idx``, filling ``traj``; each
        call sized by the budget. A call that runs out of its reduced steps ends the run.
        ``one_call``: return after the first call that succeeds (the loops' guesses are
        renewed at each call, and the relations read along it must be read with its own).
        ``frugal``: each point at most the steps the points need so far (:meth:`_Budget.need`),
        a call that needs more a failure (a model with events: its caller looks for a crossing
        before it gives a call all its steps). Returns the number of points filled."""
        pos, failed, tight = 0, None, 1.0       # (tight: the tolerances' factor of a call retried)
        upto, then = None, None                # (a call's points the last, failed, call got past)
        while pos < len(idx) and not (one_call and pos):
            budget.check(t0)
            # after a call that ran out of its reduced steps: again with more steps, sized with
            # all that is left, for its first point alone (the one that may need them all)
            n, steps, bound = (budget.call_size(len(idx) - pos, rest=True) if failed is None
                               else budget.call_size(1, 1.0))
            if failed is not None and steps <= failed:
                raise budget.stop(bound, t0)
            need = budget.need() if frugal and failed is None and budget.points else steps
            short = need < steps
            steps = min(steps, need)
            if self.followed_points is not None:
                # a call is thrown away from where its loops' guesses led it to another solution,
                # and past there the solver meets jumps (a four-bar linkage whose calls each ran
                # to the end of the run and kept one point: 400 steps a point): as many points
                # as the last call followed, more after one that followed to its end (a power
                # of 2: an integrator is built for each size, 1 s each on an engine's loops)
                n = min(n, _pow2(self.followed_points))
            sub = idx[pos:pos + (n if upto is None else min(n, upto))]
            if self.hybrid is not None and len(sub) > 1 and not _even(t0, self.t_int[sub]) and _even(
                    self.t_int[sub[0]], self.t_int[sub[1:]]):
                sub = sub[:1]        # (from an event's instant: to the next point, then evenly on)
            integ, extra = self.call_for(t0, sub, steps, tight)
            self.refresh(x, t0, p)
            clock = Stopwatch(0, cpu=True)
            try:
                xf = np.array(integ(x0=x, p=np.concatenate([p, self.tail, extra]))["xf"])
            except RuntimeError as exc:
                budget.record(_spent(integ, steps, exc), clock.elapsed)   # its steps, the rate measured
                if short and "TOO_MUCH_WORK" in str(exc):
                    raise _Frugal(f"more than {steps} solver steps a point before t = {self.t_int[sub[-1]]:g}") from None
                if bound is not None and "TOO_MUCH_WORK" in str(exc):
                    # out of steps past its first point: the points it got past again, as they
                    # were, then the one it failed on alone with more steps (its first point
                    # alone again each time: a stiff law's run redid up to 30 points for each
                    # point it kept, 210 s of a fit)
                    grid = hop_grid(len(sub)) if extra else self.tau(self.t_int[sub])
                    upto = _passed(integ, grid) or None
                    failed, then = (steps, None) if upto is None else (None, steps)
                    continue
                if tight == 1.0 and _TEST_FAILURES in str(exc):
                    # the error test failing over and over where the step cannot shrink: once
                    # more with tighter tolerances (an induction machine started through a
                    # transformer failed so on one output grid and ran on others; at rtol/10 it
                    # runs on each)
                    tight = TIGHTER
                    continue
                raise _SolverFailed(f"solver error before t = {self.t_int[sub[-1]]:g}: {_last_line(exc)}") from None
            failed, tight, upto, then = then, 1.0, None, None
            budget.record(_nsteps(integ), clock.elapsed, len(sub))
            traj[:, sub] = xf
            if not np.all(np.isfinite(xf)):
                bad = sub[np.argmax(~np.all(np.isfinite(xf), axis=0))]
                raise _Diverged(f"non-finite state at t = {self.t_int[bad]:g}")
            self.within_bound(xf[: self.nx], self.t_int[sub])
            kept = self.followed(xf, sub, p)
            if kept < len(sub):
                self.followed_points = kept
            elif self.followed_points is not None and len(sub) >= _pow2(self.followed_points):
                self.followed_points = math.ceil(self.followed_points * FOLLOW_GROWTH)
            if self.ng:
                self.guesses[:, sub[:kept]] = p[-self.ng:, None]
            x, t0, pos = xf[:, kept - 1], self.t_int[sub[kept - 1]], pos + kept
        return pos

    def followed(self, xf, sub, p) -> int:
        """The points of a call (the columns of ``xf``, at the grid points ``sub``) up to the
        last sampled one where the loops' solution from the call's guesses (the tail of
        ``p``) is still the one followed from the sample before, at least one: the call is
        taken up to there and redone from there with its guesses renewed. A guess left
        behind by a long call can find another solution (a junction with three balances)."""
        n = len(sub)
        if not self.ng or n < 2:
            return n
        at = np.unique(np.linspace(0, n - 1, min(n, FOLLOW_POINTS)).round().astype(int))
        m = len(at)
        t = self.t_int[sub][at]
        X, U = xf[: self.nx, at], self.u_at(t).reshape(-1, m)
        P = np.repeat(p[:, None], m, axis=1)
        stale = np.array(self._solved_map(m)(X, U, P, t[None, :]))
        P[-self.ng:, 1:] = stale[:, :-1]
        follow = np.array(self._solved_map(m - 1)(X[:, 1:], U[:, 1:], P[:, 1:], t[None, 1:]))
        off = ~(np.abs(stale[:, 1:] - follow) <= FOLLOW_TOL * (1 + np.abs(follow)))
        bad = np.flatnonzero(off.any(axis=0))
        return max(int(at[bad[0]]) + 1, 1) if bad.size else n

    def _solved_map(self, m: int):
        if m not in self.follow_maps:
            self.follow_maps[m] = Call(self.ode.solved.map(m))
        return self.follow_maps[m]

    def within_bound(self, x: np.ndarray, times) -> None:
        """Stop the run where a state (columns of ``x`` at ``times``) passed the bound."""
        over = np.max(np.abs(x), axis=0) > self.bound
        if np.any(over):
            raise _Diverged(f"the solution diverged: a state passed |x| = {self.bound:g} "
                        f"by t = {times[int(np.argmax(over))]:g}")

    def step_cost(self, x, u, p, t) -> float:
        """A first guess of the seconds per solver step (before any call has measured it): a
        step evaluates the right-hand side a few times and now and then its Jacobian."""
        f = self.ode.ode
        best = math.inf
        for _ in range(3):
            clock = Stopwatch(0, cpu=True)
            f(x[: self.nx], u, p, t)
            best = min(best, clock.elapsed)
        return max(40 * best, 2e-6)

    def checked(self, at: tuple, budget) -> tuple:
        """(outputs, loop residuals, drift) at every output point, a chunk at a time."""
        n, c = len(self.t_out), self.check_chunk
        parts = []
        for start in range(0, n, c):
            fun = self.checks if start + c <= n else self.checks_rest
            parts.append([np.array(v) for v in fun(*(a[:, start:start + c] for a in at))])
            if start + c < n:
                budget.check(float(self.t_out[start + c]))
        return tuple(np.hstack(vs) for vs in zip(*parts))

    # -- a run -------------------------------------------------------------------------------
    def run(self, p: np.ndarray, opts: SimulationOptions) -> SimulationResult:
        """A run with ``p``: by Adams' methods where the model is not stiff at its start
        (:meth:`method_for`), and by BDF where that fails, within the same time limit."""
        clock = Stopwatch(opts.time_limit)
        result = self._run(p, opts, clock, adams=True)
        if not result.ok and self.method == "adams" and self.gave_up and not clock.expired:
            result = self._run(p, opts, clock, adams=False)
        result.method = self.method
        return result

    def evaluated(self, traj: np.ndarray, p: np.ndarray, npu: int, budget) -> tuple:
        """(states, parameters and guesses, (outputs, loop residuals, drift)) at the output points
        of the integration points' states ``traj``."""
        t_out, N = self.t_out, len(self.t_out)
        traj = traj[:, self.out_idx]
        X = traj[: self.nx]
        P = np.repeat(p[:, None], N, axis=1)
        if self.ng:       # the guesses each point's call had (a point set by an event: its last call's)
            P[npu:] = _filled_forward(self.guesses)[:, self.out_idx]
            if self.branched:    # (held comparisons: the branch at the point, not at its call's start)
                P[npu:] = np.array(self.at_guesses(X, self.u_out, P, t_out[None, :]))
        at = (X, self.u_out, P, t_out[None, :])
        if self.split is not None:
            at = (*at[:3], np.repeat(self.q[:, None], N, 1), at[3])
        return X, P, self.checked(at, budget)

    def reached(self, traj: np.ndarray, p: np.ndarray, npu: int) -> np.ndarray:
        """The outputs at the output points a failed run reached (NaN after them); all NaN where
        they cannot be evaluated."""
        reached = np.isfinite(traj[: self.nx, self.out_idx]).all(axis=0)
        none = np.full((len(self.t_out), len(self.ode.y_names)), np.nan)
        if not reached.any():
            return none
        try:      # (the points not reached: the last state reached, as after a terminate())
            y = self.evaluated(_filled_forward(traj), p, npu, _Unlimited())[2][0].T
        except (RuntimeError, _Stop):
            return none
        y[~reached] = np.nan
        return y

    def _run(self, p: np.ndarray, opts: SimulationOptions, clock: Stopwatch, adams: bool) -> SimulationResult:
        ode, t_out, N = self.ode, self.t_out, len(self.t_out)
        npu = len(p)
        p = np.concatenate([np.asarray(p, float), ode.guess0]) if self.ng else p
        self.method, self.gave_up = "bdf", False
        self.followed_points = FOLLOW_FIRST if self.ng else None      # (see :meth:`advance`)
        budget = _Budget(opts, clock)
        self.opts_max_steps = opts.max_steps
        self.bound = math.inf if opts.state_bound is None else float(opts.state_bound)
        # the integrators' parameters after p: the bound, and the parametric parts q(p), dq/dp
        # (computed once for the run: the outputs and their sensitivities read them too)
        self.tail = np.array([self.bound])
        if self.split is not None:
            self.q = self.split.values(p)
            self.qp = (self.split.jacobian(p, self.sel) if self.ns else np.zeros((self.split.nq, 0))).ravel(order="F")
            self.tail = np.concatenate([self.tail, self.q, self.qp])
        names = ode.y_names

        def fail(reason, traj=None):
            res = SimulationResult.failed(reason, t_out, names, "casadi", clock.elapsed)
            res.steps = budget.steps
            if traj is not None and opts.partial:      # the points before the failure, for the user
                res.partial = self.reached(traj, p, npu)
            return res

        u0 = self.u_out[:, 0]
        try:
            if self.ns:
                x0, s0 = (np.array(v) for v in self.dx0(u0, p, t_out[0]))
                xa = np.concatenate([x0.ravel(), (s0 * self.scale(p)).ravel(order="F")])
            else:
                xa = np.array(ode.init(u0, p, t_out[0])).ravel()
        except RuntimeError as exc:
            return fail(f"initialisation failed: {_last_line(exc)}")
        if not np.all(np.isfinite(xa)):
            return fail("initialisation failed: no start satisfying the initial equations was found "
                        "from the start values (give the states start values nearer the solution)")
        self.refresh(xa, t_out[0], p)
        if adams:
            self.method = self.method_for(xa, p, t_out[0])
        # the guesses each grid point was integrated with (those of its call)
        self.guesses = np.full((self.ng, len(self.t_int)), np.nan)
        self.guesses[:, 0] = p[npu:]
        t_int = self.t_int
        traj = np.full((len(xa), len(t_int)), np.nan)
        hybrid = self.hybrid
        try:
            try:      # (the step's cost with the initial event's modes: a tank's ports open or closed)
                if hybrid is not None:
                    hybrid.reset()
                    xa = hybrid.initial(self, xa, p, t_int[0])
                budget.rate, budget.guessed = self.step_cost(xa, u0, p, t_out[0]), True
            except RuntimeError as exc:       # (a linear block that sparse QR finds singular)
                return fail(f"model evaluation failed at the start: {_last_line(exc)}")
            traj[:, 0] = xa
            ended = None            # (the last point, why) where the model called terminate()
            for idx in self.chunks:
                if hybrid is None:
                    self.advance(traj[:, idx[0] - 1], t_int[idx[0] - 1], idx, p, budget, traj)
                else:
                    hybrid.advance(self, idx, p, budget, traj)
                    ended = hybrid.terminated(self, traj, idx, p)
                    if ended is not None:
                        break
        except _Stop as stop:
            # (the solver gave up, where another method may not; a solution that diverged or
            # left the model's domain does so whichever integrates it)
            self.gave_up = isinstance(stop, (_SolverFailed, _OverBudget))
            return fail(str(stop), traj)
        except RuntimeError as exc:
            self.gave_up = True
            return fail(f"solver error: {_last_line(exc)}", traj)
        if ended is not None:       # (the points after it: its state, for the mapped functions)
            traj[:, ended[0] + 1:] = traj[:, ended[0]:ended[0] + 1]
        try:
            X, P, (y, res, drift) = self.evaluated(traj, p, npu, budget)
        except RuntimeError as exc:
            return fail(f"evaluating the outputs failed: {_last_line(exc)}")
        except _Stop as stop:
            return fail(f"evaluating the outputs: {stop}")
        # the run ends where the model called terminate(), as in other tools: its points so far
        n = N if ended is None else int(np.searchsorted(self.out_idx, ended[0], side="right"))
        result = SimulationResult(t_out[:n].copy(), y.T[:n], list(names), seconds=clock.elapsed,
                                  engine="casadi", states=X.T[:n])
        result.steps = budget.steps
        result.switches = list(hybrid.switches) if hybrid is not None else []
        scale = 1.0 + (np.max(np.abs(X)) if X.size else 0.0)
        # a failed assert first: the model's own words for what went wrong (sqrt of a negative
        # argument asserted >= 0 is also a non-finite output)
        reason = hybrid.asserts(X[:, :n], self.u_out[:, :n], P[:, :n], t_out[:n]) if hybrid is not None else None
        reason = reason or _check(y[:, :n], res.ravel()[:n], drift.ravel()[:n], t_out[:n], scale, opts)
        if reason:
            result.ok, result.reason = False, reason
        elif ended is not None:
            result.terminated = ended[1]
            log.info("the model terminated the run at %s", ended[1])
        if self.ns:
            # column k of traj holds vec(S) at integration point k; the mapped function wants
            # [S(t_1), ..., S(t_N)] at the output points (until stop 83 the first N integration
            # points: with events or a relation watched, the grid holds more points than the
            # output, and a thermostat's sensitivities were read at the wrong times)
            S = np.hstack([traj[self.nx:, k].reshape(self.nx, self.ns, order="F") / self.scale(p)
                           for k in self.out_idx])
            extra = ([np.repeat(self.q[:, None], N, 1), np.repeat(self.qp[:, None], N, 1)]
                     if self.split is not None else [])
            dy = np.array(self.sens(X, S, self.u_out, P, t_out[None, :], *extra))
            result.sensitivities = dy.reshape(len(names), N, self.ns).transpose(1, 0, 2)[:n]
            result.sensitivity_names = [ode.p_names[i] for i in self.sel]
        return result


def _filled_forward(G: np.ndarray) -> np.ndarray:
    """Each NaN column of ``G`` replaced by the last column before it that has none."""
    idx = np.where(np.isnan(G).any(axis=0), 0, np.arange(G.shape[1]))
    return G[:, np.maximum.accumulate(idx)]


def _nsteps(integ) -> int:
    try:
        return int(integ.stats().get("nsteps", 0))
    except RuntimeError:
        return 0


def _passed(integ, grid: np.ndarray) -> int:
    """The output points (``grid``: their times in the integrator's own time) a failed call of
    ``integ`` got past."""
    try:
        reached = float(integ.stats().get("tcur", np.nan))
    except RuntimeError:
        return 0
    return int(np.searchsorted(grid, reached, side="right")) if np.isfinite(reached) else 0


def _spent(integ, steps: int, exc: Exception) -> int:
    """The solver steps a call that failed with ``exc`` took, given ``steps`` a point. Out of
    steps, CVODES's count is of the points it reached, not the allowance spent on the last (24
    where 20 000 took 13 s, and the rate measured from them 500x too slow)."""
    done = _nsteps(integ)
    return max(done, steps) if "TOO_MUCH_WORK" in str(exc) else done or steps


class _Hybrid:
    """Events of one plan: relations watched between grid points, time events and clock ticks,
    and the event iteration of a hybrid model's discrete variables.

    A relation that changes sign between two points is located on the solution by narrowing its
    interval (:meth:`zoom`: each call one integration, read at many points), one on time alone
    by a safeguarded secant (:meth:`bisect`: no integration), the state taken just past it, and the discrete variables iterated to a fixed point; a relation that switches and
    switches back between two points is not seen. Sensitivities jump where a located crossing
    moves with the parameters (:meth:`jumped`).
    """

    def __init__(self, ode, t_out):
        self.ode = ode
        self.zero = ode.zero
        self.nd = getattr(ode, "discrete", 0) or 0
        self.update = Call(ode.update) if getattr(ode, "update", None) is not None else None
        self.zero_call = Call(self.zero) if self.zero is not None else None
        info = getattr(ode, "events", None) or {}
        self.clocks = [tuple(c) for c in info.get("clocks", [])]
        self.flag_names = info.get("flags", ["initial", "terminal"])
        self.assert_info = info.get("asserts", [])
        self.assert_fun = getattr(ode, "asserts", None)
        self.ops = info.get("relation_ops")
        self.reset()
        self.maps: dict = {}
        self._free = None
        self._g_jac = None

    def reset(self):
        self.count = 0
        self.switches = []        # the located events where the right-hand side jumped (SimulationResult)
        self.span = None          # how far past its start a call goes: EVENT_SPAN x the events' spacing
        self.last_event = None
        self.recent = None        # (times, relations) read last since the last event (see reach)
        self.grow = None          # points of the next call: 2 after an event (a trend to read), else any

    def ticks(self, t0, t1) -> dict:
        """Clock tick instants in [t0, t1] -> the clocks ticking there."""
        out: dict = {}
        for k, (start, period) in enumerate(self.clocks):
            if period <= 0:
                continue
            first = max(0, math.ceil((t0 - start) / period - 1e-9))
            n = int(math.floor((t1 - start) / period + 1e-9)) - first + 1
            for i in range(first, first + max(n, 0)):
                t = start + i * period
                if t0 - 1e-12 <= t <= t1 + 1e-12:
                    out.setdefault(min(max(t, t0), t1), []).append(k)
        return out

    def flags(self, initial=False, terminal=False, clocks=()):
        f = np.zeros(2 + len(self.clocks))
        f[0], f[1] = float(initial), float(terminal)
        for k in clocks:
            f[2 + k] = 1.0
        return f

    # -- event iteration ---------------------------------------------------------------------
    def iterate(self, plan, x, p, t, flags):
        """Modelica's event iteration: update until the discrete values (and states reinit'ed)
        no longer change, pre() taking the last values each time they settle. Where they never
        settle with pre() held, again with pre() taking each new value once they cycle."""
        if self.update is None:
            return x
        try:
            return self._iterate(plan, x, p, t, flags, False)
        except _Unsettled as exc:
            try:
                return self._iterate(plan, x, p, t, flags, True)
            except _Stop:
                raise exc from None

    def _iterate(self, plan, x, p, t, flags, promote: bool):
        nx, nc = plan.nx, plan.nx - self.nd
        xa = np.asarray(x, float).copy()
        cur = xa[:nx].copy()
        pre = cur.copy()
        u = plan.u_at(t)
        reinit = None         # the states a reinit() sets, applied once the iteration settles
        seen = set()          # the values met since pre() last changed: meeting one again is a cycle
        cycles = 0            # cycles met since then
        for _ in range(MAX_EVENT_ITERATIONS):
            new = self.update(cur, u, p, t, pre, flags).ravel()
            if not np.all(np.isfinite(new)):
                bad = [self.ode.x_names[i] for i in np.flatnonzero(~np.isfinite(new[:nx]))]
                raise _NonFinite(f"event iteration gave non-finite values at t = {t:g}"
                                 + (f" ({', '.join(bad[:3])}{' ...' if len(bad) > 3 else ''})" if bad else ""))
            if not np.array_equal(new[:nc], cur[:nc]):
                reinit = new[:nc].copy()
            new[:nc] = cur[:nc]
            seen.add((cur[nc:] + 0.0).tobytes())      # + 0.0: -0.0 is 0.0
            if (new[nc:] + 0.0).tobytes() in seen:
                cycles += 1
                new = one_change(cur, new, nc)
            if np.array_equal(new, cur):
                if np.array_equal(cur, pre):
                    if reinit is None:
                        xa[:nx] = cur
                        return xa
                    cur[:nc], reinit = reinit, None     # then settle again with the new states
                pre = cur.copy()
                seen, cycles = set(), 0
                continue
            cur = new
            if promote and cycles > 1:
                # with pre() held, the values have no fixed point (a one-way clutch: locked, the
                # torque it holds starts it forward; rolling, its torque no longer does, and it
                # locks again): pre() takes each new value, as in Modelica's event iteration
                # (the clutch starts forward, pre(startForward) then keeps it rolling)
                pre = cur.copy()
        raise _Unsettled(f"event iteration did not converge at t = {t:g} (discrete variables keep changing)")

    def initial(self, plan, x, p, t0):
        """The initial event iteration (initial() true), then the clocks ticking at t0."""
        if self.update is None:
            return x
        try:
            x = self.iterate(plan, x, p, t0, self.flags(initial=True))
        except (RuntimeError, _NonFinite):
            # the relations held all false may leave the model no solution (a tank's ports
            # closed, its junction singular); their values before the first event are a guess
            # the iteration corrects: all true then
            from .compile.rumoca_frontend import HELD_PREFIX

            held = [i for i, n in enumerate(self.ode.x_names) if n.startswith(HELD_PREFIX)]
            if not held or np.all(x[held] == 1):
                raise
            x = x.copy()
            x[held] = 1.0
            x = self.iterate(plan, x, p, t0, self.flags(initial=True))
        x = self.after_init(plan, x, p, t0)
        clocks = plan.tick_at.get(0, [])
        if clocks:
            x = self.iterate(plan, x, p, t0, self.flags(clocks=clocks))
            x = self.iterate(plan, x, p, t0, self.flags())
        return x

    def after_init(self, plan, x, p, t0):
        """The continuous initial state again with the discrete values the iteration found."""
        init_d = getattr(self.ode, "init_discrete", None)
        if init_d is None or not self.nd:
            return x
        nx = plan.nx
        u = plan.u_at(t0)
        seen, first = set(), None
        for _ in range(MAX_EVENT_ITERATIONS):
            x0 = np.array(init_d(u, p, t0, x[nx - self.nd:nx])).ravel()
            if not np.all(np.isfinite(x0)):
                raise _Stop(self._no_start(plan, x, p, t0))
            new = x.copy()
            new[:nx - self.nd] = x0
            first = new.copy() if first is None else first
            new = self.iterate(plan, new, p, t0, self.flags(initial=True))
            d = (new[nx - self.nd:nx] + 0.0).tobytes()
            if np.array_equal(new[nx - self.nd:nx], x[nx - self.nd:nx]):
                return new
            if d in seen:
                # the values alternate: a relation on a quantity the initial system leaves at 0
                # within its tolerance (a friction's w = +-6e-9: forward, then backward, ...);
                # the run starts from the first iteration's values (found from the start
                # values, where that quantity is exactly 0) with the states solved for them
                log.info("the discrete initial values alternate at t = %g; the run starts from the first", t0)
                return first
            seen.add(d)
            x = new
        raise _Stop("initialisation did not settle: discrete and continuous initial values keep changing")

    def _no_start(self, plan, x, p, t0) -> str:
        """Why the run cannot start: the discrete values the initial event iteration set in ``x``
        (those it changed from their start values named) leave the initial equations no solution
        from the start values (a robot's bearings locked at rest)."""
        nx, names = plan.nx, self.ode.x_names
        start = np.array(plan.ode.init(plan.u_at(t0), p, t0)).ravel()
        moved = [f"{names[i]} = {x[i]:g}" for i in range(nx - self.nd, nx)
                 if x[i] != start[i] and not names[i].startswith("$")]
        return ("initialisation failed: the initial equations have no solution from the start values with "
                f"the discrete values the initial event iteration set at t = {t0:g}"
                + (f" ({', '.join(moved[:4])}{' ...' if len(moved) > 4 else ''})" if moved else ""))

    # -- integration with events ---------------------------------------------------------------
    def g(self, plan, x, p, t):
        return self.zero_call(x[: plan.nx], plan.u_at(t), p, t).ravel()

    def values(self, plan, X, t, p) -> np.ndarray:
        """The relations (rows) at the state columns ``X`` and times ``t``, in one mapped call."""
        n = len(t)
        if n not in self.maps:
            self.maps[n] = Call(self.zero.map(n))
        U = np.column_stack([plan.u_at(tc) for tc in t]) if plan.u.names else np.zeros((0, n))
        return self.maps[n](X, U, np.repeat(np.asarray(p)[:, None], n, 1), np.asarray(t)[None])

    def changes(self, G) -> np.ndarray:
        """(relations, intervals): where a relation changes between the columns of ``G``, the
        first column a restart point (:meth:`start_signs`). A relation changes when its sign
        does; reaching exactly 0 counts (T < 18 at 18)."""
        S = np.sign(G)
        S[:, 0] = self.start_signs(G[:, 0], G[:, 1])
        return S[:, 1:] != S[:, :-1]

    def advance(self, plan, idx, p, budget, traj):
        """Integrate over the chunk ``idx`` with events: after each call the relations are
        compared point to point; at the first sign change the crossing is located, the event
        handled and the rest of the chunk integrated again from there. A crossing of relations
        on time alone is foreseen (:meth:`foreseen`): the call ends before it."""
        t_int = plan.t_int
        t0, x0 = t_int[idx[0] - 1], traj[:, idx[0] - 1]
        pos = 0
        while pos < len(idx):
            rest = idx[pos:]
            ahead, crossing = self.foreseen(plan, x0, t0, rest, p), None
            if ahead == 0 and (not self.state_free().all() or self.count >= MAX_EVENTS):
                ahead = 1        # other relations may change first: this interval as any other
            if ahead:                              # up to the interval of a foreseen crossing
                rest = rest[:ahead]
            if ahead != 0:
                # events come every so often: a call far past the next one is thrown away (an
                # arc's every 5 ms, calls to the end of a 1 s chunk: 160 steps an event); and
                # a call stops short of a crossing its relations' trend shows (see reach)
                end = min(t0 + self.span if self.span is not None else np.inf, self.reach(t0))
                n = min(int(np.searchsorted(t_int[rest], end, side="right")), self.grow or len(rest))
                rest = rest[:max(1, n)]
                try:
                    filled, crossing = self.called(plan, x0, t0, rest, p, budget, traj)
                    rest = rest if crossing is not None else rest[:filled]
                except (_SolverFailed, _Diverged):
                    crossing = self.probe(plan, x0, t0, rest, p, budget, traj) if self.zero is not None else None
                    if crossing is None or self.count >= MAX_EVENTS:
                        raise
            else:                                  # a foreseen crossing in the first interval
                rest = rest[:1]
                crossing = self.crossing_ahead(plan, x0, t0, t_int[rest[0]], p)
            if crossing is None and self.zero is not None:
                crossing = self.first_flip(plan, x0, t0, rest, p, traj)
            if crossing is None:
                if self.span is not None:
                    self.span *= 2                 # (no event in it: the next goes further)
                self.grow = None                   # (the relations' trend now reaches past it)
                self.at_point(plan, rest[-1], p, traj)
                pos += len(rest)
                t0, x0 = t_int[rest[-1]], traj[:, rest[-1]]
                continue
            j, ta, xa, rels, g_a, tb = crossing
            self.count += 1
            self.recent, self.grow = None, 2       # (the right-hand side may change: no trend yet)
            t_star, x_star = self.locate(plan, xa, ta, tb, p, rels, g_a, budget)
            self.spaced(t_star)
            before = x_star
            t_star, x_star = self.settle(plan, x_star, p, t_star, t_int[rest[j]], budget)
            x_star = self.jumped(plan, before, x_star, p, t_star, rels)
            if t_star >= t_int[rest[j]]:          # located at the grid point itself
                traj[:, rest[j]] = x_star
                self.at_point(plan, rest[j], p, traj)
                pos += j + 1
                t0, x0 = tb, traj[:, rest[j]]
            else:
                pos += j
                t0, x0 = t_star, x_star

    def called(self, plan, x0, t0, rest, p, budget, traj) -> tuple[int, tuple | None]:
        """(points filled, a crossing) of :meth:`_Plan.advance` over ``rest``, frugal first
        where a failure can be looked into: a call run past a crossing into a branch held
        beyond it fails there, with all its steps (20 000 a point: a check valve's took 12 s);
        frugal, it fails within the steps the points have needed so far, and :meth:`probe`
        finds the crossing. Where it finds none, the call again with all its steps."""
        if self.zero is not None:
            try:
                return plan.advance(x0, t0, rest, p, budget, traj, one_call=plan.branched, frugal=True), None
            except _Frugal:
                crossing = self.probe(plan, x0, t0, rest, p, budget, traj)
                if crossing is not None:
                    return 0, crossing
        return plan.advance(x0, t0, rest, p, budget, traj, one_call=plan.branched), None

    def settle(self, plan, x, p, t, t_next, budget):
        """(time, state) of the event at ``t`` once its iteration settles. Where its discrete
        values keep changing, the states are carried a little further, up to 1e-4 of the way to
        ``t_next``, before each new try: two relations that cross at the same instant, each
        located past its own hysteresis band, may leave one flipping until the other has
        crossed (a tank's port at its level: closed, the pressure pushes it open; open, the
        flow leaves; until the level is past the port, as it is 1e-7 s later)."""
        try:
            return t, self.iterate(plan, x, p, t, self.flags())
        except _Unsettled as exc:
            for k in range(4):
                dt = (t_next - t) * 10.0 ** (k - 7)
                if dt <= 4 * np.finfo(float).eps * max(1.0, abs(t)):
                    continue
                x_k = plan.hop(x, p, t, t + dt, budget)
                try:
                    return t + dt, self.iterate(plan, x_k, p, t + dt, self.flags())
                except _Unsettled:
                    pass
            raise exc from None

    def jumped(self, plan, before, after, p, t, rels):
        """``after`` (the state past the event at ``t``) with its sensitivities moved as the event
        moves: where the relation r crosses, g_r(x(tau), p, tau) = 0, so its time moves by
        dtau/dp = -(g_x S + g_p) / (g_x f- + g_t), and past it the states' slopes are f+ instead
        of f-: S+ = S- + (f- - f+) dtau/dp. Carried through unchanged, a thermostat's switching
        times did not move in a fit's derivatives, and the fit of its room's wall stalled far
        from the data. States a reinit() set keep theirs (their jump needs the reinit's own
        derivative)."""
        nx, ns = plan.nx, plan.ns
        rels = np.flatnonzero(rels) if np.asarray(rels).dtype == bool else np.asarray(rels, int)
        if self.zero is None or not len(rels):
            return after
        u = plan.u_at(t)
        f_minus = np.array(self.ode.ode(before[:nx], u, p, t)).ravel()
        f_plus = np.array(self.ode.ode(after[:nx], u, p, t)).ravel()
        step = np.abs(f_minus - f_plus)[: nx - self.nd]
        if np.any(step > SWITCHED * (np.abs(f_minus) + np.abs(f_plus))[: nx - self.nd] + 1e-300) \
                and len(self.switches) < MAX_EVENTS:
            self.switches.append(Switch(t, rels, np.array(before[:nx], float), np.array(after[:nx], float)))
        jac = self.g_jacobian() if ns else None
        if jac is None:
            return after
        gx, gp, gt = (np.array(v) for v in jac(before[:nx], u, p, t))
        S = before[nx:nx * (ns + 1)].reshape(nx, ns, order="F")
        hit = crossed(self.g(plan, before, p, t), gx, gt, f_minus, rels)
        if hit is None:
            return after
        r, speed = hit
        dtau = -(gx[r] @ S + gp[r, plan.sel] * plan.scale(p)) / speed
        jump = np.outer(f_minus - f_plus, dtau)
        kept = after[:nx] != before[:nx]
        kept[nx - self.nd:] = False
        jump[kept] = 0.0          # (set by a reinit)
        if not np.all(np.isfinite(jump)):
            return after
        out = np.array(after, float)
        out[nx:nx * (ns + 1)] = (after[nx:nx * (ns + 1)].reshape(nx, ns, order="F") + jump).ravel(order="F")
        return out

    def g_jacobian(self):
        """The relations' derivatives in the states, the parameters and time (a Call), or None
        where they cannot be taken."""
        if self._g_jac is None:
            f = self.zero
            args = [ca.MX.sym(n, f.size1_in(k)) for k, n in enumerate(("x", "u", "p", "t"))]
            g = f(*args)
            try:
                self._g_jac = Call(ca.Function("g_jac", args, [ca.jacobian(g, args[0]), ca.jacobian(g, args[2]),
                                                               ca.jacobian(g, args[3])]))
            except RuntimeError:
                self._g_jac = False
        return self._g_jac or None

    def spaced(self, t: float) -> None:
        """An event at ``t``: the span of the next calls from the events' spacing so far."""
        if self.last_event is not None and t > self.last_event:
            gap = t - self.last_event
            self.span = EVENT_SPAN * gap if self.span is None else 0.5 * (self.span + EVENT_SPAN * gap)
        self.last_event = t

    def reach(self, t0: float) -> float:
        """How far a call from ``t0`` may go: REACH times the time in which the first relation
        on the states reaches zero on the parabola through its last three values (the line
        through two), read where the calls since the last event ended, or inf. Past a crossing
        the model may have no solution, and the relations are checked only after a call: a
        pump whose check valve shuts as its speed falls, integrated on as if open, failed every
        loop solve and one call ran for minutes. After an event the first call is two points
        long, so that there is a trend to read. (A parabola, not the tangent: a relation
        decaying towards 0, never crossing, has no root on it but one every time constant on
        its tangent.)"""
        if self.recent is None or self.recent[0][-1] != t0 or len(self.recent[0]) < 2:
            return np.inf
        t, G = self.recent
        on = ~self.state_free() & (G[:, -1] != 0)
        G = G[on]
        d1 = (G[:, -1] - G[:, -2]) / (t[-1] - t[-2])
        if len(t) == 2:
            a, b = np.zeros_like(d1), d1
        else:
            a = (d1 - (G[:, -2] - G[:, -3]) / (t[-2] - t[-3])) / (t[-1] - t[-3])
            b = d1 + a * (t[-1] - t[-2])
        return t0 + REACH * first_root(a, b, G[:, -1])

    def read(self, t, G) -> None:
        """The relations ``G`` (columns) read at the times ``t`` after a call crossed none: the
        last three since the last event are kept for :meth:`reach`."""
        if self.recent is not None and self.recent[0][-1] == t[0]:
            t, G = np.r_[self.recent[0], t[1:]], np.column_stack([self.recent[1], G[:, 1:]])
        self.recent = (np.asarray(t, float)[-3:], np.asarray(G, float)[:, -3:])

    def crossing_ahead(self, plan, x0, t0, t1, p):
        """The crossing in (t0, t1] of relations on time alone, as :meth:`advance` takes it."""
        g_a, g_b = self.g(plan, x0, p, t0), self.g(plan, x0, p, t1)
        rels = np.flatnonzero(self.state_free() & (np.sign(g_b) != self.start_signs(g_a, g_b)))
        return 0, t0, x0, rels, g_a, t1

    def first_flip(self, plan, x0, t0, rest, p, traj):
        """The first interval of the integrated points ``rest`` (after ``x0`` at ``t0``) where a
        relation changed, as :meth:`advance` takes it, or None."""
        t_int = plan.t_int
        G = self.values(plan, traj[: plan.nx, rest], t_int[rest], p)
        G = np.column_stack([self.g(plan, x0, p, t0), G])   # at the restart point, not the grid point
        flip = self.changes(G)
        hits = np.flatnonzero(flip.any(axis=0))
        if not hits.size:
            self.read(np.r_[t0, t_int[rest]], G)
        if not hits.size or self.count >= MAX_EVENTS:
            return None
        j = hits[0]
        ta, xa = (t0, x0) if j == 0 else (t_int[rest[j - 1]], traj[:, rest[j - 1]])
        return j, ta, xa, np.flatnonzero(flip[:, j]), G[:, j], t_int[rest[j]]

    def start_signs(self, g0, g1):
        """The signs of the relations at a restart point (``g0``) as compared with ``g1`` at the
        next point. A relation exactly 0 there (lhs = rhs: a clock's tick that set pulseStart
        = time) changes only if its value does: time >= pulseStart stays true, T < 22 at 22
        stays false as T rises, T > 18 at 18 becomes true. Where its operator is unknown,
        leaving 0 counts as a change."""
        s0, s1 = np.sign(g0), np.sign(g1)
        ops = self.ops
        if not ops or len(ops) != len(s0):
            return s0
        out = s0.copy()
        for k in np.flatnonzero(s0 == 0):
            truth = RELATION_TRUTH.get(ops[k])
            if truth is not None and truth(0.0) == truth(float(g1[k])):
                out[k] = s1[k]
        return out

    def foreseen(self, plan, x0, t0, rest, p) -> int | None:
        """The grid points of ``rest`` to integrate before the next crossing of a relation that
        reads no continuous state (a pulse's edge: time against a discrete variable, fixed
        until the next event), found without integrating: the points before its interval (0:
        it is in the first interval, whose end is then not integrated to), or None where there
        is none. Integrated past it, the call would be thrown away at the event and the
        crossing found again by integrating (a switched-capacitor filter: 4x the steps)."""
        free = self.state_free() if self.zero is not None else None
        if free is None or not free.any():
            return None
        t = np.r_[t0, plan.t_int[rest]]
        X = np.repeat(np.asarray(x0, float)[: plan.nx, None], len(t), axis=1)
        flips = np.flatnonzero(self.changes(self.values(plan, X, t, p))[free].any(axis=0))
        return int(flips[0]) if flips.size else None

    def probe(self, plan, x0, t0, rest, p, budget, traj):
        """After the solver gave up on the grid points ``rest``: the same points one at a time,
        an interval that fails halved, until a relation changes sign (a crossing the failed
        call ran past: a current chattering through zero because the arc that would quench
        it at 0.6 mA was never seen). The crossing as :meth:`advance` takes it (its interval
        may end between grid points), or None where there is none before the failure."""
        t_int = plan.t_int
        xa, ta = np.asarray(x0, float), t0
        g_a = self.g(plan, xa, p, ta)
        for j, k in enumerate(rest):
            tb = t_int[k]
            while True:
                try:
                    tb, xb = plan.hop_halved(xa, p, ta, tb, budget, 1e-12 * max(1.0, abs(ta)), steps=PROBE_STEPS)
                except (RuntimeError, _Diverged):
                    return None
                g_b = self.g(plan, xb, p, tb)
                flips = np.flatnonzero(np.sign(g_b) != np.sign(g_a))
                if flips.size:
                    return j, ta, xa, flips, g_a, tb
                xa, ta, g_a = xb, tb, g_b
                if tb == t_int[k]:
                    traj[:, k] = xb
                    break
                tb = t_int[k]
        return None

    def at_point(self, plan, k, p, traj):
        """A time event or clock ticks at grid point ``k``: the event iteration there (with the
        ticks, then once more without: a sampled condition is true only at its instant); at
        the last point, the one of terminal()."""
        if self.update is None:
            return
        k, t = int(k), plan.t_int[k]
        clocks = plan.tick_at.get(k)
        if clocks:
            traj[:, k] = self.iterate(plan, traj[:, k], p, t, self.flags(clocks=clocks))
        if clocks or k in plan.time_event_at:
            after = t + AFTER_TIME_EVENT * max(1.0, abs(t)) if k in plan.time_event_at else t
            traj[:, k] = self.iterate(plan, traj[:, k], p, after, self.flags())
        if k == len(plan.t_int) - 1:
            traj[:, k] = self.iterate(plan, traj[:, k], p, t, self.flags(terminal=True))

    def state_free(self) -> np.ndarray:
        """Per relation: whether it reads no continuous state (structurally)."""
        if self._free is None:
            reads = np.asarray(ca.DM(self.zero.sparsity_jac(0, 0), 1))
            # the last ``nd`` entries of x are discrete: constant until the event, so read at xa
            continuous = reads[:, : reads.shape[1] - self.nd] if self.nd else reads
            self._free = continuous.sum(axis=1) == 0
        return self._free

    def locate(self, plan, xa, ta, tb, p, flips, g_a, budget):
        """The earliest crossing of the relations ``flips`` in (ta, tb] and the state just past it
        (where only relations on time alone cross: the state just before it)."""
        free = self.state_free()
        on_time = [r for r in flips if free[r]]
        on_states = [r for r in flips if not free[r]]
        best_t, before = (self.bisect(plan, xa, ta, tb, p, on_time, g_a, budget) if on_time else (tb, tb))
        if not on_states:
            # the states reached just before the crossing: the relations read none, and the
            # model's right-hand side may switch with them (to just past it: 240 steps more)
            return best_t, plan.hop(xa, p, ta, before, budget)
        t_s, x_s = self.zoom(plan, xa, ta, tb, p, on_states, g_a, budget)
        if t_s <= best_t:
            return t_s, x_s
        return best_t, plan.hop(xa, p, ta, best_t, budget)   # just past the crossing on time

    def bisect(self, plan, xa, ta, tb, p, rels, g_a, budget):
        """(just past, just before) the first crossing of the relations ``rels`` on time alone,
        to the last digit (each trial one evaluation, no integration). The trial is the
        earliest secant root of the relations that change across the bracket and stay as steep
        as over the whole interval (a relation linear in time: its crossing at the second
        trial), else the bracket's middle (also after two trials that moved the same end, as a
        secant does on a curved relation): safe where a relation jumps (a sampled pulse's
        sawtooth, an integer() count), whose secant root would sit at the bracket's end."""
        lo, hi = ta, tb
        g_lo, g_hi = g_a[rels], self.g(plan, xa, p, tb)[rels]
        s_lo = np.sign(g_lo)
        tol = 4 * np.finfo(float).eps * max(abs(hi), tb - ta)
        steep = 4 * np.abs(g_hi - g_lo) / (hi - lo)
        moved = []              # the ends the trials moved: a secant that moves one end twice is slow
        for _ in range(200):
            if hi - lo <= tol:
                break
            budget.check(lo)       # (a relation reading a loop whose solve fails costs a second a trial)
            t = 0.5 * (lo + hi)
            # (a relation exactly 0 at lo, a count equal to its bound until a tick: its secant
            # root is lo itself, and it jumps)
            smooth = (np.sign(g_hi) != s_lo) & (g_lo != 0) & (np.abs(g_hi - g_lo) <= steep * (hi - lo))
            if not smooth.any() and not moved:
                # a jump is first tried at the bracket's end: a tick on a grid point (a PWM's
                # period) is found in one trial instead of 45 halvings
                t = hi - 0.5 * tol
            elif smooth.any() and moved[-2:] not in (["lo", "lo"], ["hi", "hi"]):
                with np.errstate(divide="ignore", invalid="ignore"):
                    roots = lo + (hi - lo) * g_lo[smooth] / (g_lo[smooth] - g_hi[smooth])
                roots = roots[np.isfinite(roots)]
                if roots.size:
                    t = min(max(roots.min(), lo + 0.5 * tol), hi - 0.5 * tol)
            g_t = self.g(plan, xa, p, t)[rels]
            if np.array_equal(np.sign(g_t), s_lo):
                lo, g_lo = t, g_t
                moved.append("lo")
            else:
                hi, g_hi = t, g_t
                moved.append("hi")
        return hi, lo

    def zoom(self, plan, xa, ta, tb, p, rels, g_a, budget):
        """(time, state) just past the first crossing of any of the relations ``rels`` on the
        states, narrowed by integrations from the bracket's early end, each read at many points
        from the same solver steps: the relations read along one call are smooth, where
        restarts of different lengths would each carry their own error (a thyristor's current:
        17 restarts an event). The first call spreads ``ZOOM_POINTS`` evenly; the next close in
        on the crossing estimated from the bracket's relation values (a secant, a little past
        it), which narrows a smooth crossing ~1000x a call instead of 32x (a rectifier's 600
        crossings a second: 6.5 restarts each before). A call that narrowed less than 16x, or
        whose estimate fell short, is followed by an even one (a relation that jumps)."""
        rels = np.asarray(rels)
        lo, x_lo, hi, x_hi = ta, np.asarray(xa, float), tb, None
        s_lo, g_lo, g_hi, even, first = None, None, None, True, None
        # to 1e-7 of the interval it was seen in, below the solver's own error there (rtol
        # 1e-6): the last digits cost a rectifier a restart per crossing and changed nothing
        tol = max(1e-12 * max(1.0, abs(tb)), ZOOM_TOL * (tb - ta))
        while True:
            end = hi if even else _past_estimate(lo, hi, g_lo, g_hi, max(tol, 1e-3 * (hi - lo) ** 2 / first))
            # (the solver may give up where a call from another start went past: a machine's
            # stator through a diode bridge, its zero sequence at 1e-5 A)
            end, X = plan.hop_halved(x_lo, p, lo, end, budget, tol, points=ZOOM_POINTS, to_end=not even)
            ts = lo + (end - lo) * hop_grid(ZOOM_POINTS, not even)
            G = self.values(plan, X[: plan.nx], ts, p)
            if s_lo is None:
                s_lo = self.start_signs(g_a, G[:, -1])[rels]
                g_lo = g_a[rels]
            G = G[rels]
            changed = np.flatnonzero((np.sign(G) != s_lo[:, None]).any(axis=0))
            width = hi - lo
            if not changed.size:
                if end >= hi:          # not seen again (the crossing was at the solver's error level)
                    return (hi, x_hi) if x_hi is not None else (hi, X[:, -1])
                # the estimate was early: evenly next (a secant from a curved relation's far
                # end keeps falling short: 3600 restarts for one of a machine's crossings)
                lo, x_lo, g_lo, even = end, X[:, -1], G[:, -1], True
                continue
            j = changed[0]
            if j > 0:
                lo, x_lo, g_lo = ts[j - 1], X[:, j - 1], G[:, j - 1]
            hi, x_hi, g_hi = ts[j], X[:, j], G[:, j]
            first = first or hi - lo
            if hi - lo <= tol:
                return hi, x_hi
            even = not even and (hi - lo) > width / (ZOOM_POINTS // 2)

    # -- asserts ---------------------------------------------------------------------------------
    def asserts(self, X, U, P, t) -> str | None:
        """The first assert of level error violated at an output point fails the run; those of
        level warning are logged once each."""
        if self.assert_fun is None or not self.assert_info:
            return None
        V = self.assert_values(X, U, P, t)
        for i, (level, message) in enumerate(self.assert_info):
            bad = np.flatnonzero(V[i] > 0.5)
            if not bad.size or level == "terminate":
                continue
            if level == "warning":
                log.warning("warning at t = %g: %s", t[bad[0]], message)
                continue
            return f"assertion failed at t = {t[bad[0]]:g}: {message}"
        return None

    def terminated(self, plan, traj, idx, p) -> tuple[int, str] | None:
        """(the first point of ``idx`` where a terminate() is called, "t = ...: its message"),
        or None."""
        ends = [i for i, (level, _) in enumerate(self.assert_info) if level == "terminate"]
        if not ends or self.assert_fun is None:
            return None
        t = plan.t_int[idx]
        U = np.column_stack([plan.u_at(tc) for tc in t]) if plan.u.names else np.zeros((0, len(t)))
        V = self.assert_values(traj[: plan.nx, idx], U, p, t)[ends]
        hits = np.flatnonzero((V > 0.5).any(axis=0))
        if not hits.size:
            return None
        k = hits[0]
        return int(idx[k]), f"t = {t[k]:g}: {self.assert_info[ends[int(np.argmax(V[:, k] > 0.5))]][1]}"

    def assert_values(self, X, U, P, t) -> np.ndarray:
        """(asserts, points): 1 where an assert is violated; ``P`` one column or one per point."""
        n, fun = X.shape[1], self.assert_fun
        P = np.asarray(P, float)
        P = P[:, None] if P.ndim == 1 else P
        if _varies(fun):
            return np.array(_mapped(fun, n)(X, U, P if P.shape[1] == n else np.repeat(P[:, :1], n, 1), t[None, :]))
        # on parameters only (the MSL's range checks): one point tells, no loop solved n times
        return np.repeat(np.array(fun(X[:, :1], U[:, :1], P[:, :1], t[:1])), n, axis=1)


def _even(t0: float, times: np.ndarray) -> bool:
    """Whether ``times`` are equally spaced from ``t0`` on (as :func:`hop_grid` spaces them)."""
    h = times[-1] - t0
    return h > 0 and np.allclose(times - t0, h * hop_grid(len(times)), rtol=0.0, atol=1e-10 * h)


def hop_grid(points: int, to_end: bool = False) -> np.ndarray:
    """The output times of a hop on [0, 1]: equally spaced, or ``to_end``: half of them equally
    spaced, the other half closing in on 1 from the last of those (1 - 4^-k/h, down to 1e-11
    of the interval at 32 points), and 1 itself."""
    if not to_end:
        return np.arange(1, points + 1) / points
    h = points // 2
    return np.r_[np.arange(1, h) / h, 1.0 - 4.0 ** -np.arange(1, points - h + 1) / h, 1.0]


def first_root(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    """The least positive root among the quadratics a tau^2 + b tau + c (elementwise), or inf."""
    with np.errstate(divide="ignore", invalid="ignore"):
        d = b * b - 4 * a * c
        q = -0.5 * (b + np.where(b < 0, -1.0, 1.0) * np.sqrt(np.where(d >= 0, d, np.nan)))
        roots = np.concatenate([np.where(a != 0, q / a, -c / b), c / q])
    roots = roots[np.isfinite(roots) & (roots > 0)]
    return float(roots.min()) if roots.size else np.inf


def _past_estimate(lo, hi, g_lo, g_hi, margin) -> float:
    """A time ``margin`` past the earliest secant root in (lo, hi] of the relations that change
    sign there (a secant on a curved relation misses by about its bracket squared over the
    relation's time scale: 1e-3 of the first bracket, then that squared), at most ``hi``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        f = g_lo / (g_lo - g_hi)
    f = f[(np.sign(g_lo) != np.sign(g_hi)) & np.isfinite(f)]
    t = lo + (hi - lo) * (f.min() if f.size else 0.5)
    return min(hi, t + margin)


def one_change(cur: np.ndarray, new: np.ndarray, nc: int) -> np.ndarray:
    """``cur`` with only the first discrete value that ``new`` changes. Updating all at once,
    an iteration can swing between two sets of values, each computed from the other (a
    clutch's locked from startBackward and startBackward from the torque locked gives); one
    change at a time, in the model's order, the rest are computed from it (as a tool that sorts
    the discrete equations does) and the iteration settles."""
    out = cur.copy()
    changed = np.flatnonzero(new[nc:] != cur[nc:])
    if changed.size:
        out[nc + changed[0]] = new[nc + changed[0]]
    return out


@functools.lru_cache(maxsize=64)
def _varies(fun) -> bool:
    """Whether an assert function depends on the states, inputs or time (structurally)."""
    return any(fun.sparsity_jac(i, 0).nnz() for i in (0, 1, 3))


@functools.lru_cache(maxsize=64)
def _mapped(fun, n: int):
    """``fun`` mapped over ``n`` points, built once per function and length (the cache holds
    ``fun``, so its identity, which CasADi hashes, is not reused while the entry lives)."""
    return fun.map(n)


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
