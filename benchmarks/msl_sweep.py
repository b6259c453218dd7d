"""A sweep over MSL 4.0.0 examples across the libraries: does each compile, simulate to its stop
time in mcl's in-process engine, (with --fmu) give an FMU that FMPy validates, and agree with
rumoca's own simulator where that runs (every common state within 0.2% of its range; rumoca's
run is given a third of the time limit, in a child of its own, and is no reference beyond it)?

Each model runs in a fresh process with a time limit, so one hang or crash costs one row.
Prints a table and the count; ``--json`` keeps the rows.

    python benchmarks/msl_sweep.py [--msl DIR] [--only SUBSTRING] [--models FILE] [--fmu] [--json PATH]
"""
from __future__ import annotations

import argparse
import json
import re
import sys
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from compile import run  # noqa: E402  (a script in a fresh process, its last JSON line)

#: 40 examples across Blocks, Analog, Machines, PowerConverters, Translational, Rotational,
#: MultiBody, HeatTransfer, FluidHeatFlow, Fluid and FluxTubes (hybrid ones included)
MODELS = """
Blocks.Examples.PID_Controller
Blocks.Examples.Filter
Blocks.Examples.FilterWithDifferentiation
Blocks.Examples.LogicalNetwork1
Blocks.Examples.SlewRateLimiter
Electrical.Analog.Examples.CauerLowPassAnalog
Electrical.Analog.Examples.CauerLowPassSC
Electrical.Analog.Examples.ChuaCircuit
Electrical.Analog.Examples.AmplifierWithOpAmpDetailed
Electrical.Analog.Examples.HeatingRectifier
Electrical.Analog.Examples.OvervoltageProtection
Electrical.Analog.Examples.Rectifier
Electrical.Analog.Examples.SeriesResonance
Electrical.Analog.Examples.DifferenceAmplifier
Electrical.Analog.Examples.NandGate
Electrical.Machines.Examples.DCMachines.DCPM_Start
Electrical.Machines.Examples.DCMachines.DCSE_Start
Electrical.PowerConverters.Examples.DCDC.ChopperStepDown.ChopperStepDown_R
Electrical.PowerConverters.Examples.ACDC.RectifierCenterTap2Pulse.ThyristorCenterTap2Pulse_R
Mechanics.Translational.Examples.Damper
Mechanics.Translational.Examples.Oscillator
Mechanics.Translational.Examples.Brake
Mechanics.Translational.Examples.PreLoad
Mechanics.Rotational.Examples.First
Mechanics.Rotational.Examples.Friction
Mechanics.Rotational.Examples.CoupledClutches
Mechanics.Rotational.Examples.Backlash
Mechanics.MultiBody.Examples.Elementary.Pendulum
Mechanics.MultiBody.Examples.Elementary.DoublePendulum
Mechanics.MultiBody.Examples.Elementary.FreeBody
Thermal.HeatTransfer.Examples.TwoMasses
Thermal.HeatTransfer.Examples.ControlledTemperature
Thermal.HeatTransfer.Examples.Motor
Thermal.FluidHeatFlow.Examples.SimpleCooling
Thermal.FluidHeatFlow.Examples.TwoMass
Thermal.FluidHeatFlow.Examples.PumpAndValve
Thermal.FluidHeatFlow.Examples.OneMass
Fluid.Examples.HeatingSystem
Magnetic.FluxTubes.Examples.BasicExamples.SaturatedInductor
Magnetic.FluxTubes.Examples.BasicExamples.QuadraticCoreAirgap
""".split()

ONE = textwrap.dedent("""
    import json, os, sys, time
    import numpy as np
    msl, name, t_end, fmu, ref_limit = sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4] == "1", float(sys.argv[5])
    os.environ["MODELICAPATH"] = msl
    row = {}
    def done(**kw):
        row.update(kw); print(json.dumps(row)); sys.exit(0)
    def reference(msl, name, t_end, states, limit):
        # rumoca's own simulation of the example (its time and states), in a forked child
        # given ``limit`` seconds: a reference that runs longer (rumoca on a robot's six axes)
        # is no reference, and leaves mcl's own run its time; a string says why there is none
        import multiprocessing, tempfile
        with tempfile.TemporaryDirectory() as tmp:
            out = os.path.join(tmp, "ref.npz")
            def child():
                try:
                    import rumoca
                    m = rumoca.Session([msl]).loads("model E_\\n  extends " + name + ";\\nend E_;\\n",
                                                    model="E_", filename="/sweep/E_.mo")
                    r = m.simulate((0.0, t_end), dt=t_end / 2000)
                    np.savez(out, time=np.asarray(r.time, float),
                             **{f"x{k}": np.asarray(r[n], float) for k, n in enumerate(states) if n in r.names})
                except Exception as exc:
                    with open(out + ".err", "w") as f:
                        f.write(f"{type(exc).__name__}: {exc}"[:120])
            proc = multiprocessing.get_context("fork").Process(target=child)
            proc.start()
            proc.join(limit)
            if proc.is_alive():
                proc.kill()
                proc.join()
                return f"rumoca's simulation ran longer than {limit:.0f} s"
            if os.path.exists(out + ".err"):
                return open(out + ".err").read()
            if not os.path.exists(out):
                return f"rumoca's simulation crashed (exit {proc.exitcode})"
            with np.load(out) as got:      # (read whole before the folder goes)
                return got["time"], {n: got[f"x{k}"] for k, n in enumerate(states) if f"x{k}" in got.files}
    import mcl
    from mcl.compile.isolation import cpu_seconds
    from mcl.data import TimeSeries
    t0 = cpu_seconds()
    try:
        model = mcl.compile_model([], name)
    except Exception as exc:
        done(stage="compile", error=f"{type(exc).__name__}: {exc}"[:300])
    row["compile_s"] = cpu_seconds() - t0
    row["states"] = len(model.ode.x_names)
    if fmu:
        import tempfile
        from mcl.compile.fmu.export import build_fmu, validate_fmu
        with tempfile.TemporaryDirectory() as tmp:
            try:
                build_fmu(model, os.path.join(tmp, "m.fmu"), validate=False)
                problems = validate_fmu(os.path.join(tmp, "m.fmu"))
            except Exception as exc:
                problems = [f"{type(exc).__name__}: {exc}"]
        if problems:
            done(stage="fmu", error="; ".join(map(str, problems))[:300])
    ref = reference(msl, name, t_end, model.ode.x_names, ref_limit)
    if isinstance(ref, str):
        row["rumoca"], ref = ref, None
    # on rumoca's grid where it ran (it holds the event instants), else an even one
    grid = np.unique(np.round(ref[0], 12)) if ref else np.linspace(0.0, t_end, 2001)
    t1 = time.process_time()
    res = mcl.simulate(model, TimeSeries(grid, np.zeros((len(grid), 0)), []), t_out=grid)
    row["simulate_s"] = time.process_time() - t1
    if not res.ok:
        done(stage="simulate", error=str(res.reason)[:300])
    if res.terminated:      # the model ended the run (terminate()): compared up to there
        row["terminated"] = res.terminated[:120]
        grid = grid[:len(res.time)]
    if ref is None:
        done(stage="ok", compared=0)
    worst, compared, spans = 0.0, 0, {}
    # a state both keep at rounding-error level (a zero-sequence current of 1e-13 A) has no
    # range of its own: one of 1e-9 of the model's largest counts as its range
    floor = 1e-9 * max([np.ptp(ref[1][n]) for n in model.ode.x_names if n in ref[1]] + [1e-3])
    for k, n in enumerate(model.ode.x_names):
        if n not in ref[1]:
            continue
        theirs = np.interp(grid, ref[0], ref[1][n])
        ours = res.states[:, k]
        span = max(np.ptp(ref[1][n]), floor)
        # an event instant may fall one sample either side: the nearest of the neighbours counts;
        # a discrete variable's switching instant, within 0.2% of the stop time (an on-off
        # controller's threshold met 0.3 ms apart: rtol 1e-6 of a 300 K temperature is 3e-4 K)
        shift = max(1, int(np.searchsorted(grid, 2e-3 * t_end))) if k >= len(model.ode.x_names) - model.ode.discrete else 1
        err = np.abs(ours - theirs)
        for s in range(1, shift + 1):
            err[s:] = np.minimum(err[s:], np.abs(ours[s:] - theirs[:-s]))
            err[:-s] = np.minimum(err[:-s], np.abs(ours[:-s] - theirs[s:]))
        compared += 1
        spans[k] = span
        if err.max() / span > worst:
            worst, row["worst_state"] = err.max() / span, n
    if worst <= 2e-3:
        done(stage="ok", compared=compared, worst=worst)
    # who is off: ours against ours at rtol 1e-10 (a run that does not move when tightened is
    # converged; then the reference is what differs: rumoca's simulator counted 5 of a PWM's
    # 100 periods in a chopper and is 7e-3 off a converged orbit of point masses)
    tight = mcl.simulate(model, TimeSeries(grid, np.zeros((len(grid), 0)), []), t_out=grid,
                         options={"rtol": 1e-10, "atol": 1e-12})
    if tight.ok and len(tight.time) == len(grid):
        row["self"] = float(max(np.abs(res.states[:, k] - tight.states[:, k]).max() / s for k, s in spans.items()))
    done(stage="differs", compared=compared, worst=worst)
""")


def stop_time(msl: Path, name: str) -> float:
    """The example's ``experiment(StopTime=...)``, from its source (1 s where none is given)."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        base = msl.joinpath(*parts[:k])
        for f in (base.with_suffix(".mo"), base / "package.mo"):
            if f.is_file():
                text = f.read_text(encoding="utf-8", errors="replace")
                start = text.find(f"model {parts[-1]}") if f.stem != parts[-1] else 0
                found = re.search(r"StopTime\s*=\s*([0-9.eE+-]+)", text[max(start, 0):])
                return float(found.group(1)) if found else 1.0
    return 1.0


def run_one(msl: Path, name: str, fmu: bool, limit: float) -> dict:
    t_end = stop_time(msl, name)
    t = time.perf_counter()
    # rumoca's reference gets a third of the time, mcl the rest
    row = run(ONE, msl, name, t_end, "1" if fmu else "0", limit / 3, timeout=limit, width=300)
    if "timeout" in row:
        row = {"stage": "timeout", "error": f"more than {limit:.0f} s"}
    elif "stage" not in row:
        row = {"stage": "crash", **row}
    return {"model": name, "stop": t_end, "wall_s": time.perf_counter() - t, **row}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--msl", default=str(ROOT.parent / "shared" / "msl"))
    ap.add_argument("--only", default="", help="run the models whose name contains this")
    ap.add_argument("--models", default=None, help="a file of other models to run, one per line "
                    "(names below Modelica., as in the list above)")
    ap.add_argument("--fmu", action="store_true", help="also build and validate each FMU")
    ap.add_argument("--limit", type=float, default=600.0, help="seconds per model")
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    msl = Path(args.msl)
    rows = []
    models = Path(args.models).read_text().split() if args.models else MODELS
    for short in models:
        if args.only and args.only not in short:
            continue
        row = run_one(msl, "Modelica." + short, args.fmu, args.limit)
        rows.append(row)
        converged = f" (ours against ours at rtol 1e-10: {row['self']:.1e})" if "self" in row else ""
        detail = (f"{row.get('compared', 0)} states, worst {row['worst']:.1e} of range{converged}" if "worst" in row
                  else row.get("error") or row.get("rumoca", "rumoca did not run"))
        print(f"{short:70s} {row['stage']:9s} {row['wall_s']:6.1f} s  {detail}", flush=True)
    good = sum(r["stage"] == "ok" for r in rows)
    print(f"\n{good} of {len(rows)} compile{', validate' if args.fmu else ''}, simulate to their stop time "
          f"and agree with rumoca where it runs")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
