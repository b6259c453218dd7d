"""One simulation interface, two engines (in-process CasADi, FMU via FMPy).

A failed simulation is a result, not an exception: :class:`SimulationResult` says ``ok`` and,
when not, ``reason`` — solver error, non-finite values, end time not reached, algebraic loop not
converged, invariant drift, or time limit exceeded (../shared/DESIGN.md, section 6: reliable
detection needs every one of these checks).
"""
from __future__ import annotations

import dataclasses

import contextlib
import logging
import math
import os
import sys
import time as _time
from dataclasses import dataclass, field

import numpy as np

from .data import TimeSeries
from .errors import ConfigError


#: seconds a simulation the user asks for (``mcl simulate``, :func:`mcl.simulate`) may take by
#: default: a 10 s machine model with a load dump takes 220 CPU-s; a fit's runs keep 60 s
RUN_TIME_LIMIT = 600.0


@dataclass
class SimulationOptions:
    """Solver settings shared by the engines."""

    rtol: float = 1e-6
    atol: float = 1e-10             # states of small size (a bearing's housing speed, ~1e-5) need it
    time_limit: float = 60.0        # wall-clock seconds for one simulation, checked during the integration
    max_steps: int = 20000          # solver steps between two output points
    max_work: int | None = None     # solver steps in all (None: no bound); beyond it the run fails
    state_bound: float | None = None  # max |x| of any state (None: no bound); beyond it the run fails
    residual_tol: float = 1e-6      # algebraic loops: max |g| accepted (relative to scale)
    drift_tol: float = 1e-3         # invariants of index reduction: max |I| accepted
    fmu_substeps: int = 4           # FMU engine: communication steps per output interval
    partial: bool = False           # a failed run also gives its outputs up to where it failed

    def __post_init__(self):
        _check_options(vars(self), lambda name: name)

    @classmethod
    def from_dict(cls, d: dict | None, option=lambda name: name) -> "SimulationOptions":
        """Options from a mapping; ``option`` turns a field name into the name the user wrote
        (``--time-limit`` on the command line) for the error messages."""
        d = dict(d or {})
        unknown = set(d) - set(cls.__dataclass_fields__)
        if unknown:
            raise ConfigError(f"unknown simulation option(s): {', '.join(sorted(unknown))} "
                              f"(known: {', '.join(cls.__dataclass_fields__)})")
        _check_options({**{f: getattr(cls, f) for f in cls.__dataclass_fields__}, **d}, option)
        return cls(**d)


#: option -> (lowest, highest), both excluded; whole numbers where the default is an int
_LIMITS = {"rtol": (0.0, 1.0), "atol": (0.0, math.inf), "time_limit": (0.0, math.inf),
           "max_steps": (0, math.inf), "max_work": (0, math.inf), "state_bound": (0.0, math.inf),
           "residual_tol": (0.0, math.inf), "drift_tol": (0.0, math.inf),
           "fmu_substeps": (0, 10_000)}


def _check_options(values: dict, option) -> None:
    """Every option a finite number in its range, else a ConfigError naming ``option(name)``."""
    for name, (lo, hi) in _LIMITS.items():
        value = values.get(name)
        if value is None and name in ("max_work", "state_bound"):        # no bound
            continue
        integer = isinstance(lo, int)
        ok = (isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
              and math.isfinite(value) and lo < value < hi and (not integer or float(value).is_integer()))
        if not ok:
            kind = "a whole number" if integer else "a finite number"
            rng = f"greater than {lo:g}" + ("" if hi == math.inf else f" and less than {hi:g}")
            shown = f"{value:g}" if isinstance(value, (int, float)) and not isinstance(value, bool) else repr(value)
            raise ConfigError(f"{option(name)} = {shown}: must be {kind} {rng}")


@dataclass
class Switch:
    """An event located on the states where the right-hand side jumped: its time, the relations
    that changed sign there (indices into the model's relations) and the states (with the
    discrete values) just before and just after it."""

    time: float
    relations: np.ndarray
    before: np.ndarray
    after: np.ndarray


def crossed(g, gx, gt, f_minus, rels):
    """(r, speed) of the relation among ``rels`` that crossed at an event: the one nearest its
    crossing in time along the slopes f- (g / (g_x f- + g_t), from its values ``g``, its
    derivatives ``gx`` in the states and ``gt`` in time); None where it grazes (its speed
    is 0: the event's time is not a smooth function of the parameters)."""
    rels = np.asarray(rels, int)
    speed = gx[rels] @ f_minus + gt[rels, 0]
    k = int(np.argmin(np.abs(np.ravel(g)[rels]) / np.maximum(np.abs(speed), 1e-300)))
    r = int(rels[k])
    if not np.isfinite(speed[k]) or abs(speed[k]) <= 1e-12 * (np.abs(gx[r]) @ np.abs(f_minus) + abs(gt[r, 0])):
        return None
    return r, float(speed[k])


@dataclass
class SimulationResult:
    """Outputs on the output grid; ``sensitivities[k, i, j]`` = d y_i(t_k) / d p_j."""

    time: np.ndarray
    outputs: np.ndarray
    output_names: list[str]
    ok: bool = True
    reason: str | None = None
    seconds: float = 0.0
    engine: str = ""
    sensitivities: np.ndarray | None = None
    sensitivity_names: list[str] = field(default_factory=list)
    states: np.ndarray | None = None
    steps: int = 0                  # solver steps taken (the work done; summed over all calls)
    method: str = ""                # the solver's method ("bdf", "adams"), where the engine chose one
    #: where the model called terminate() ("t = ...: its message"): the run ends at that point
    terminated: str | None = None
    #: a failed run's outputs at the points it reached (NaN after), for the user to look at
    #: (its ``outputs`` stay NaN: a fit must not read them)
    partial: np.ndarray | None = None
    #: the events the run located on the states where the right-hand side jumped (a
    #: thermostat's heater, a relay): the switching times move with the parameters, and a
    #: sensitivity jumps there (the engine's own do; a linearisation along the run reads these)
    switches: list = field(default_factory=list)

    @property
    def switched(self) -> bool:
        return bool(self.switches)

    def output(self, name: str) -> np.ndarray:
        return self.outputs[:, self.output_names.index(name)]

    def as_series(self) -> TimeSeries:
        return TimeSeries(self.time, self.outputs, list(self.output_names), f"<{self.engine}>")

    def to_frame(self):
        """The outputs as a pandas DataFrame indexed by ``time``."""
        return self.as_series().to_frame()

    def __repr__(self) -> str:
        state = "ok" if self.ok else f"failed: {self.reason}"
        return (f"SimulationResult({len(self.time)} points, t = {self.time[0]:g}..{self.time[-1]:g}, "
                f"outputs {', '.join(self.output_names)}; {state})") if len(self.time) else "SimulationResult(empty)"

    def _repr_html_(self) -> str:
        """A table in notebooks: each output's range and last value, and whether the run succeeded."""
        import html

        head = (f"<b>{'simulation' if self.ok else 'failed simulation: ' + html.escape(str(self.reason))}</b> "
                f"({self.engine}, {len(self.time)} points, {self.seconds:.3g} s)")
        rows = "".join(f"<tr><td>{html.escape(n)}</td><td>{np.nanmin(self.outputs[:, k]):.4g}</td>"
                       f"<td>{np.nanmax(self.outputs[:, k]):.4g}</td><td>{self.outputs[-1, k]:.4g}</td></tr>"
                       for k, n in enumerate(self.output_names)) if self.ok and len(self.time) else ""
        return (f"<div>{head}<table><tr><th>output</th><th>min</th><th>max</th><th>last</th></tr>{rows}</table></div>")

    def through(self, time) -> SimulationResult:
        """This result, or a failed one where the model ended the run (terminate()) before the
        last of ``time``: a fit compares every point."""
        if not self.ok or len(self.time) >= len(time):
            return self
        return SimulationResult.failed(f"the model terminated the run at {self.terminated}, before the "
                                       f"data's end (t = {time[-1]:g})", time, self.output_names,
                                       self.engine, self.seconds)

    def reached(self) -> SimulationResult | None:
        """A failed run's points up to the last with any finite output (None where it has none,
        or no outputs): what it computed before it failed."""
        outputs = self.outputs if self.partial is None else self.partial
        finite = np.isfinite(outputs).any(axis=1) if outputs.size else np.zeros(0, bool)
        if not finite.any():
            return None
        n = int(np.flatnonzero(finite)[-1]) + 1
        return dataclasses.replace(self, time=self.time[:n], outputs=outputs[:n], sensitivities=None, partial=None,
                                   states=None if self.states is None else self.states[:n])

    @classmethod
    def failed(cls, reason, time, output_names, engine, seconds=0.0):
        t = np.asarray(time, dtype=float)
        return cls(t, np.full((len(t), len(output_names)), np.nan), list(output_names),
                   ok=False, reason=reason, seconds=seconds, engine=engine)


class Engine:
    """Base of simulation engines. Subclasses set ``name`` and implement :meth:`simulate`."""

    name = ""

    def accepts(self, model) -> bool:  # pragma: no cover - interface
        raise NotImplementedError

    def simulate(self, model, inputs: TimeSeries, params: dict | None = None,
                 t_out: np.ndarray | None = None, options: SimulationOptions | None = None,
                 sensitivities: list[str] | None = None) -> SimulationResult:
        raise NotImplementedError  # pragma: no cover - interface


def prepare_inputs(model, inputs: TimeSeries) -> TimeSeries:
    """The model's inputs, in its order, from a series that may hold more columns."""
    if not model.input_names:
        return TimeSeries(inputs.time, np.zeros((len(inputs.time), 0)), [], inputs.source)
    return inputs.select(model.input_names).validate().filled()


class Stopwatch:
    """Seconds since it was made, on the wall clock or (``cpu``) in this process's CPU time."""

    def __init__(self, limit: float, cpu: bool = False):
        self.clock = _time.process_time if cpu else _time.perf_counter
        self.start, self.limit = self.clock(), limit

    @property
    def elapsed(self) -> float:
        return self.clock() - self.start

    @property
    def expired(self) -> bool:
        return self.elapsed > self.limit


@contextlib.contextmanager
def quiet_native_output():
    """Silence what native solvers print on stdout/stderr (CVODES, rootfinder failures).

    Their messages are folded into ``SimulationResult.reason`` instead; C++ writes to the file
    descriptors directly, so redirecting ``sys.stdout`` is not enough. mcl's own messages of
    the block (a warning assert, a terminate()) are held and written after it.
    """
    sys.stdout.flush()
    sys.stderr.flush()
    held = [_Held(h) for h in _console_handlers()]
    saved = [os.dup(1), os.dup(2)]
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, null):
            os.close(fd)
        for h in held:
            h.release()


class _Held(logging.Filter):
    """The records a console handler is given while the console is silenced, written after."""

    def __init__(self, handler: logging.Handler):
        super().__init__()
        self.handler, self.records = handler, []
        handler.addFilter(self)

    def filter(self, record) -> bool:
        self.records.append(record)
        return False

    def release(self):
        self.handler.removeFilter(self)
        for record in self.records:
            self.handler.handle(record)


def _console_handlers() -> list[logging.Handler]:
    """The handlers mcl's messages reach that write to stdout or stderr."""
    found, logger = [], logging.getLogger("mcl")
    while logger is not None:
        for h in logger.handlers:
            try:
                if isinstance(h, logging.StreamHandler) and h.stream.fileno() in (1, 2):
                    found.append(h)
            except (AttributeError, ValueError, OSError):      # (a stream without a descriptor)
                continue
        logger = logger.parent if logger.propagate else None
    return found
