"""FMU engine: any FMI 2.0/3.0 FMU simulated with FMPy, in a child process.

The child process is what makes "a simulation can never hang or crash the caller" true for
foreign binaries: a time limit kills it, and a segfault becomes a failed result.

FMI 2.0 Co-Simulation FMUs that interpolate their inputs (mcl's own, among others) are stepped
here from one input sample or output time to the next, each step given the input's value and the
slope of its next segment (``fmi2SetRealInputDerivatives``): the FMU then sees the measured input
exactly as the in-process engine does, linear between samples, events handled inside it.
FMI 2.0 Model Exchange FMUs without events are integrated with SciPy's LSODA, the input
interpolated linearly at every right-hand-side evaluation: FMPy's own loop sets inputs once per
communication interval and CVode steps past the interval end on the old input (a first-order
lag, ../shared/DESIGN.md, section 5). Every other FMU (events, other Co-Simulation FMUs, FMI
3.0) goes through ``fmpy.simulate_fmu``, with the input sampled at interval midpoints (the hold
then acts like the midpoint rule) and ``fmu_substeps`` intervals per output interval.
"""
from __future__ import annotations

import multiprocessing as mp
import sys
import time

import numpy as np

from .data import TimeSeries
from .errors import DataError
from .model import FmuModel
from .simulation import Engine, SimulationOptions, SimulationResult, prepare_inputs


class FmuEngine(Engine):
    """Simulate an :class:`FmuModel` with FMPy (CVode for Model Exchange)."""

    name = "fmu"

    def accepts(self, model) -> bool:
        return isinstance(model, FmuModel)

    def simulate(self, model: FmuModel, inputs: TimeSeries, params=None, t_out=None,
                 options: SimulationOptions | None = None, sensitivities=None) -> SimulationResult:
        opts = options or SimulationOptions()
        if sensitivities:
            raise DataError("the FMU engine gives no sensitivities; use the casadi engine")
        u = prepare_inputs(model, inputs)
        t_out = u.time if t_out is None else np.asarray(t_out, dtype=float)
        start_values = model.parameter_vector(params)
        job = dict(path=str(model.path), u_time=u.time, u_values=u.values, u_names=u.names,
                   t_out=t_out, outputs=model.output_names, start_values=start_values,
                   rtol=opts.rtol, substeps=opts.fmu_substeps)
        t0 = time.perf_counter()
        status, payload = _run_isolated(job, opts.time_limit)
        seconds = time.perf_counter() - t0
        if status != "ok":
            return SimulationResult.failed(payload, t_out, model.output_names, "fmu", seconds)
        y, ended = payload
        result = SimulationResult(t_out[:len(y)].copy(), y, list(model.output_names), seconds=seconds,
                                  engine="fmu", terminated=ended)
        if not np.all(np.isfinite(y)):
            k = int(np.argmax(~np.all(np.isfinite(y), axis=1)))
            result.ok, result.reason = False, f"non-finite output at t = {t_out[k]:g}"
        return result


def _run_isolated(job: dict, time_limit: float):
    """The FMU run in a child process; the FMU unpacked in a directory the parent removes (a
    child killed at the time limit, or crashed, leaves nothing behind)."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="mcl-fmu-run-") as tmp:
        return _run_child({**job, "workdir": tmp}, time_limit)


def _run_child(job: dict, time_limit: float):
    ctx = mp.get_context("fork" if sys.platform.startswith("linux") else "spawn")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(job, send), daemon=True)
    proc.start()
    send.close()
    try:
        if recv.poll(time_limit):
            try:
                return recv.recv()
            except EOFError:
                pass
            proc.join(5)
            return "failed", f"FMU process crashed (exit code {proc.exitcode})"
        return "failed", f"time limit of {time_limit:g} s exceeded"
    finally:
        if proc.is_alive():
            proc.kill()
        proc.join(5)
        recv.close()


def _child(job: dict, conn) -> None:
    import os

    from .executor import die_with_parent

    die_with_parent()
    null = os.open(os.devnull, os.O_WRONLY)  # FMPy and the FMU print; their words go in `reason`
    os.dup2(null, 1)
    os.dup2(null, 2)
    messages: list[str] = []
    try:
        conn.send(("ok", _simulate(job, messages)))
    except Exception as exc:  # noqa: BLE001 - every failure becomes a result
        msg = str(exc).strip().splitlines()
        why = msg[-1] if msg else type(exc).__name__
        if messages:
            why = f"{messages[-1]} ({why})"
        conn.send(("failed", f"FMU simulation failed: {why}"))
    finally:
        conn.close()


def _simulate(job: dict, messages: list[str]) -> tuple[np.ndarray, str | None]:
    """(the outputs at the output times, "t = ...: message" where the model called terminate():
    the outputs then end at the last output time before it)."""
    from fmpy import read_model_description

    from .compile.fmu.archive import safe_extract

    ended: list[str] = []

    def logger(_env, _name, status, _category, message):
        text = message.decode("utf-8", "replace")
        if status >= 2:  # discard, error, fatal
            messages.append(text)
        elif text.startswith(_TERMINATED):
            ended.append(text[len(_TERMINATED):])

    unzipdir = safe_extract(job["path"], job["workdir"])     # (the parent's: removed by it)
    md = read_model_description(unzipdir, validate=False)
    job = {**job, "path": unzipdir}
    cs = md.coSimulation
    if (md.fmiVersion == "2.0" and cs is not None and cs.canInterpolateInputs
            and cs.canHandleVariableCommunicationStepSize):
        y = _simulate_cs2(job, md, logger)
    elif md.fmiVersion == "2.0" and md.modelExchange is not None and not md.numberOfEventIndicators:
        y = _simulate_me2(job, md, logger)
    else:
        y = _simulate_fmpy(job, logger)
    return y, (ended[0] if ended and len(y) < len(job["t_out"]) else None)


#: how the FMU's log message of a terminate() call begins (fmi2_model.c's check_asserts)
_TERMINATED = "terminated at "


def _simulate_cs2(job: dict, md, logger) -> np.ndarray:
    """Step an FMI 2.0 Co-Simulation FMU through every input sample and output time, with the
    input's value and the slope of its next segment at each communication point."""
    from ctypes import c_double, c_int, c_uint

    from fmpy import instantiate_fmu
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import fmi2Discard, fmi2Terminated

    vr = {v.name: v.valueReference for v in md.modelVariables}
    t_out, u_t, u_v = job["t_out"], job["u_time"], job["u_values"]
    nu, ny = len(job["u_names"]), len(job["outputs"])
    t0, t_end = float(t_out[0]), float(t_out[-1])
    inner = u_t[(u_t > t0) & (u_t < t_end)] if nu else np.zeros(0)
    grid = np.union1d(t_out, inner)
    u_grid = np.column_stack([np.interp(grid, u_t, u_v[:, j]) for j in range(nu)]) if nu else None
    slopes = np.diff(u_grid, axis=0) / np.diff(grid)[:, None] if nu else None
    out_at = np.searchsorted(grid, t_out)
    u_vr, y_vr = (c_uint * nu)(*[vr[n] for n in job["u_names"]]), (c_uint * ny)(*[vr[n] for n in job["outputs"]])
    u_val, du_val, y_val = (c_double * nu)(), (c_double * nu)(), (c_double * ny)()
    order = (c_int * nu)(*([1] * nu))
    y = np.empty((len(t_out), ny))
    fmu = instantiate_fmu(job["path"], md, "CoSimulation", logger=logger)
    try:
        fmu.setupExperiment(tolerance=job["rtol"], startTime=t0, stopTime=t_end)
        params = {k: v for k, v in job["start_values"].items() if k in vr}
        if params:
            fmu.setReal([vr[k] for k in params], list(params.values()))
        fmu.enterInitializationMode()
        if nu:
            u_val[:] = u_grid[0]
            fmu.fmi2SetReal(fmu.component, u_vr, nu, u_val)
        fmu.exitInitializationMode()
        k_out = 0
        for k in range(len(grid)):
            if k_out < len(t_out) and out_at[k_out] == k and ny:
                fmu.fmi2GetReal(fmu.component, y_vr, ny, y_val)
            while k_out < len(t_out) and out_at[k_out] == k:   # an output time may repeat
                y[k_out] = y_val
                k_out += 1
            if k + 1 == len(grid):
                break
            if nu:
                u_val[:], du_val[:] = u_grid[k], slopes[k]
                fmu.fmi2SetReal(fmu.component, u_vr, nu, u_val)
                fmu.fmi2SetRealInputDerivatives(fmu.component, u_vr, nu, order, du_val)
            try:
                fmu.fmi2DoStep(fmu.component, float(grid[k]), float(grid[k + 1] - grid[k]), 1)
            except FMICallException as exc:     # the model called terminate(): its points so far
                if exc.status != fmi2Discard or not fmu.getBooleanStatus(fmi2Terminated):
                    raise
                y = y[:k_out]
                break
        fmu.terminate()
    finally:
        fmu.freeInstance()
    return y


def _simulate_me2(job: dict, md, logger) -> np.ndarray:
    """Integrate an event-free FMI 2.0 ME FMU with LSODA, inputs interpolated exactly."""
    from ctypes import POINTER, c_double

    from fmpy import instantiate_fmu
    from scipy.integrate import solve_ivp

    vr = {v.name: v.valueReference for v in md.modelVariables}
    t_out, u_t, u_v = job["t_out"], job["u_time"], job["u_values"]
    u_vr = [vr[n] for n in job["u_names"]]
    y_vr = [vr[n] for n in job["outputs"]]
    nx = md.numberOfContinuousStates
    fmu = instantiate_fmu(job["path"], md, "ModelExchange", logger=logger)

    def u_at(t):
        return [float(np.interp(t, u_t, u_v[:, j])) for j in range(len(u_vr))]

    def ptr(a):
        return a.ctypes.data_as(POINTER(c_double))

    x, dx = np.zeros(nx), np.zeros(nx)
    try:
        fmu.setupExperiment(startTime=float(t_out[0]))
        fmu.enterInitializationMode()
        params = {k: v for k, v in job["start_values"].items() if k in vr}
        if params:
            fmu.setReal([vr[k] for k in params], list(params.values()))
        if u_vr:
            fmu.setReal(u_vr, u_at(t_out[0]))
        fmu.exitInitializationMode()
        info = fmu.newDiscreteStates()
        fmu.enterContinuousTimeMode()
        fmu.getContinuousStates(ptr(x), nx)

        def set_point(t, state):
            x[:] = state
            fmu.setTime(float(t))
            if u_vr:
                fmu.setReal(u_vr, u_at(t))
            fmu.setContinuousStates(ptr(x), nx)

        def rhs(t, state):
            set_point(t, state)
            fmu.getDerivatives(ptr(dx), nx)
            return dx.copy()

        states = np.zeros((len(t_out), nx))
        states[0] = x
        t_cur, state, k = float(t_out[0]), x.copy(), 1
        while nx and k < len(t_out):
            # integrate up to the next time event the FMU announces, then restart after it
            t_next = float(info[5]) if info[4] and t_cur < info[5] < t_out[-1] else float(t_out[-1])
            last = k + int(np.searchsorted(t_out[k:], t_next, side="right"))
            sol = solve_ivp(rhs, (t_cur, t_next), state, method="LSODA", t_eval=t_out[k:last],
                            rtol=job["rtol"], atol=job["rtol"] * 1e-2, dense_output=True)
            if sol.status != 0:
                raise RuntimeError(f"end time not reached: {sol.message}")
            states[k:last] = sol.y.T
            state, t_cur, k = sol.sol(t_next), t_next, last
            if t_next < t_out[-1]:
                set_point(t_next, state)
                fmu.enterEventMode()
                info = fmu.newDiscreteStates()
                fmu.enterContinuousTimeMode()
                fmu.getContinuousStates(ptr(x), nx)
                state = x.copy()
        y = np.empty((len(t_out), len(y_vr)))
        for k, t in enumerate(t_out):
            set_point(t, states[k])
            y[k] = fmu.getReal(y_vr) if y_vr else []
        fmu.terminate()
    finally:
        fmu.freeInstance()
    return y


def _simulate_fmpy(job: dict, logger) -> np.ndarray:
    """Any other FMU through FMPy's own loop, inputs sampled at communication midpoints."""
    from fmpy import simulate_fmu

    t_out = job["t_out"]
    h = float(np.min(np.diff(t_out))) / job["substeps"]
    signals = None
    if job["u_names"]:
        grid = np.arange(t_out[0], t_out[-1] + h, h)
        mid = np.minimum(grid + h / 2, job["u_time"][-1])
        signals = np.zeros(len(grid), dtype=[("time", float)] + [(n, float) for n in job["u_names"]])
        signals["time"] = grid
        for j, n in enumerate(job["u_names"]):
            signals[n] = np.interp(mid, job["u_time"], job["u_values"][:, j])
    res = simulate_fmu(job["path"], start_time=float(t_out[0]), stop_time=float(t_out[-1]),
                       relative_tolerance=job["rtol"], output_interval=h, input=signals,
                       output=job["outputs"], start_values=job["start_values"],
                       validate=False, logger=logger)
    if abs(res["time"][-1] - t_out[-1]) > 1e-6 * h + 1e-12:
        raise RuntimeError(f"end time not reached (stopped at t = {res['time'][-1]:g})")
    if not job["outputs"]:
        return np.zeros((len(t_out), 0))
    return np.column_stack([np.interp(t_out, res["time"], res[n]) for n in job["outputs"]])
