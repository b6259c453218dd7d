"""Time per simulation of paper 000's Cauer filter over 100 s, each engine as a ratio to rumoca;
the MSL's CauerLowPassAnalog (its own step source) the same way; first and cached compile times.

rumoca (a Rust Modelica compiler on PyPI) is the baseline, measured in the same run. It takes no
input tables, so the source voltage is a band-limited multisine written into a Modelica wrapper;
our engines get the same signal sampled every 10 ms. Wall-clock and CPU seconds (this process and
its children: the FMU engine runs in one) are medians of ``--repeat`` runs. The FMU rows: mcl's
FMU engine (Co-Simulation, the input's slope given at each sample), and FMPy's
``simulate_fmu`` with its defaults at the input's interval as Co-Simulation (what FMPy picks)
and as Model Exchange, each with its largest deviation from the in-process engine. The MSL part
runs when the Modelica Standard Library is found (``--msl DIR``, default ../shared/msl); it
ends with the same rows for two hybrid MSL examples (an on-off temperature controller: pre() and
state events; a PWM chopper: sample() clocks, when, reinit), on the FMU's DefaultExperiment.

    python benchmarks/simulate.py [--repeat 5] [--json PATH] [--msl DIR]
"""
from __future__ import annotations

import argparse
import json
import resource
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
LIB = ROOT / "modelica" / "MCL"
T_END, DT = 100.0, 0.01


def multisine(seed=0, n=12, w_max=2.0):
    """Band-limited signal: n sines up to w_max rad/s with random phases (unit RMS)."""
    rng = np.random.default_rng(seed)
    w = np.linspace(w_max / n, w_max, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    a = np.full(n, np.sqrt(2.0 / n))
    return a, w, phi


def wrapper_source(a, w, phi) -> str:
    terms = " + ".join(f"{ai:.17g}*sin({wi:.17g}*time + {pi:.17g})" for ai, wi, pi in zip(a, w, phi))
    return (f"model CauerBench\n  MCL.Examples.CauerFilter f;\nequation\n  f.u = {terms};\n"
            f"end CauerBench;\n")


def cpu_seconds() -> float:
    """CPU time of this process and of its children that have ended."""
    child = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + child.ru_utime + child.ru_stime


def timed(fn, repeat, cpu=False):
    """Median wall-clock seconds of ``repeat`` calls; (wall, cpu) with ``cpu``."""
    walls, cpus = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), cpu_seconds()
        fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(cpu_seconds() - c0)
    return (statistics.median(walls), statistics.median(cpus)) if cpu else statistics.median(walls)


def fmpy_defaults(path, t, u, fmi_type):
    """FMPy as a user runs it: defaults, the input table, output at the input's interval."""
    from fmpy import simulate_fmu

    table = np.zeros(len(t), dtype=[("time", float), ("u", float)])
    table["time"], table["u"] = t, u
    res = simulate_fmu(str(path), input=table, output_interval=float(t[1] - t[0]), stop_time=float(t[-1]),
                       fmi_type=fmi_type, output=["y"])
    return np.interp(t, res["time"], res["y"])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--msl", type=Path, default=ROOT.parent / "shared" / "msl")
    args = ap.parse_args(argv)

    import rumoca as rm

    from mcl.api import compile_model, simulate
    from mcl.data import TimeSeries
    from mcl.engine_casadi import CasadiEngine
    from mcl.compile.fmu.export import build_fmu
    from mcl.model import FmuModel

    a, w, phi = multisine()
    t = np.arange(0.0, T_END + DT / 2, DT)
    u = TimeSeries(t, (a[None, :] * np.sin(np.outer(t, w) + phi)).sum(axis=1), ["u"])
    opts = {"rtol": 1e-6, "atol": 1e-8}

    with tempfile.TemporaryDirectory() as tmp:
        wrapper = Path(tmp) / "CauerBench.mo"
        wrapper.write_text(wrapper_source(a, w, phi))
        session = rm.Session(roots=[str(LIB.parent)])
        ref = session.load(str(wrapper), model="CauerBench")
        cfg = rm.SimConfig(rtol=1e-6, atol=1e-8, dt=DT)
        rumoca_s = timed(lambda: ref.simulate(t=(0.0, T_END), config=cfg), args.repeat, cpu=True)

        model = compile_model([LIB], "MCL.Examples.CauerFilter")
        path = build_fmu(model, Path(tmp) / "cauer.fmu")
        fmu = FmuModel.read(path)
        warm_engine = CasadiEngine()
        y_own = warm_engine.simulate(model, u).outputs[:, 0]  # builds the integrator once, as a fitting loop does
        rows = {
            "rumoca": rumoca_s,
            "casadi (repeated, fitting loop)": timed(lambda: warm_engine.simulate(model, u), args.repeat, cpu=True),
            "casadi (first call, builds integrator)": timed(
                lambda: CasadiEngine().simulate(model, u), args.repeat, cpu=True),
            "fmu engine (CS, input slopes, child process)": timed(
                lambda: simulate(fmu, u, options=opts), args.repeat, cpu=True),
            "FMPy defaults, Co-Simulation": timed(
                lambda: fmpy_defaults(path, t, u.values[:, 0], "CoSimulation"), args.repeat, cpu=True),
            "FMPy defaults, Model Exchange": timed(
                lambda: fmpy_defaults(path, t, u.values[:, 0], "ModelExchange"), args.repeat, cpu=True),
        }
        scale = np.max(np.abs(y_own))
        deviation = {
            "fmu engine (CS, input slopes, child process)":
                np.max(np.abs(simulate(fmu, u, options=opts).outputs[:, 0] - y_own)) / scale,
            "FMPy defaults, Co-Simulation":
                np.max(np.abs(fmpy_defaults(path, t, u.values[:, 0], "CoSimulation") - y_own)) / scale,
            "FMPy defaults, Model Exchange":
                np.max(np.abs(fmpy_defaults(path, t, u.values[:, 0], "ModelExchange") - y_own)) / scale,
        }
    base_wall, base_cpu = rumoca_s
    own_cpu = rows["casadi (repeated, fitting loop)"][1]
    print(f"Cauer filter, {T_END:g} s, input sampled every {DT:g} s; median of {args.repeat} runs")
    print(f"{'engine':46s} {'wall s':>8s} {'cpu s':>8s} {'cpu/rumoca':>11s} {'cpu/casadi':>11s} {'max dev':>9s}")
    for name, (wall, cpu) in rows.items():
        dev = f"{deviation[name]:9.1e}" if name in deviation else f"{'':9s}"
        print(f"{name:46s} {wall:8.3f} {cpu:8.3f} {cpu / base_cpu:11.2f} {cpu / own_cpu:11.2f} {dev}")
    out = {"rows": [{"engine": k, "seconds": w, "cpu_seconds": c, "ratio": w / base_wall,
                     "cpu_ratio": c / base_cpu, "cpu_ratio_to_casadi": c / own_cpu,
                     **({"max_relative_deviation": float(deviation[k])} if k in deviation else {})}
                    for k, (w, c) in rows.items()]}
    if (args.msl / "Modelica" / "package.mo").is_file():
        out["msl"] = msl_rows(args.msl, args.repeat)
        out["hybrid"] = hybrid_rows(args.msl, args.repeat)
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))


def msl_rows(msl: Path, repeat: int) -> list[dict]:
    """CauerLowPassAnalog from the MSL: compile (first, then cached) and simulate vs rumoca."""
    import os

    import rumoca as rm

    from mcl.api import compile_model
    from mcl.data import TimeSeries
    from mcl.engine_casadi import CasadiEngine

    name = "Modelica.Electrical.Analog.Examples.CauerLowPassAnalog"
    os.environ["MODELICAPATH"] = str(msl)
    with tempfile.TemporaryDirectory() as cache:
        os.environ["MCL_CACHE_DIR"] = cache          # a cold cache: the first compile is a real one
        t0 = time.perf_counter()
        model = compile_model([], name)
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        cached = compile_model([], name)
        again = time.perf_counter() - t0
        assert cached.info.get("cached")
    session = rm.Session(roots=[str(msl)])
    ref = session.loads(f"model BenchEntry_\n  extends {name};\nend BenchEntry_;\n", model="BenchEntry_",
                        filename="/mcl-bench/BenchEntry_.mo")
    t_end, dt = 60.0, 0.01
    cfg = rm.SimConfig(rtol=1e-6, atol=1e-8, dt=dt)
    rumoca_s = timed(lambda: ref.simulate(t=(0.0, t_end), config=cfg), repeat)
    t = np.arange(0.0, t_end + dt / 2, dt)
    engine = CasadiEngine()
    no_input = TimeSeries(t, np.zeros((len(t), 0)), [])
    engine.simulate(model, no_input)
    ours = timed(lambda: engine.simulate(model, no_input), repeat)
    print(f"\nMSL {name.split('.')[-1]}, {t_end:g} s (step source, time event at t = 1)")
    print(f"  compile: first {first:.2f} s, cached {again:.3f} s ({first / again:.0f}x)")
    print(f"  {'casadi (repeated)':40s} {ours:9.3f} s, {ours / rumoca_s:.2f} x rumoca ({rumoca_s:.3f} s)")
    return [{"what": "compile first", "seconds": first}, {"what": "compile cached", "seconds": again},
            {"engine": "rumoca", "seconds": rumoca_s},
            {"engine": "casadi (repeated)", "seconds": ours, "ratio": ours / rumoca_s}]


HYBRID = ["Modelica.Thermal.HeatTransfer.Examples.ControlledTemperature",
          "Modelica.Electrical.PowerConverters.Examples.DCDC.ChopperStepDown.ChopperStepDown_R"]


def hybrid_rows(msl: Path, repeat: int) -> list[dict]:
    """Hybrid MSL examples over their DefaultExperiment: rumoca, the in-process engine, mcl's FMU
    engine and FMPy's defaults (CS; ME on the same output grid), CPU seconds and the largest
    deviation of a continuous state (outputs for mcl's FMU engine) from the in-process engine
    at tight tolerances (1e-9), relative to its range (grid points on a clock tick are left
    out: either side of the event is right there)."""
    import os

    import rumoca as rm
    from fmpy import read_model_description, simulate_fmu

    from mcl.api import compile_model, simulate
    from mcl.compile.fmu.export import build_fmu
    from mcl.data import TimeSeries
    from mcl.engine_casadi import CasadiEngine
    from mcl.model import FmuModel
    from mcl.simulation import SimulationOptions

    os.environ["MODELICAPATH"] = str(msl)
    rows = []
    for name in HYBRID:
        model = compile_model([], name)
        o = model.ode
        with tempfile.TemporaryDirectory() as tmp:
            path = build_fmu(model, Path(tmp) / "m.fmu")
            md = read_model_description(str(path))
            continuous = [v.name for v in md.modelVariables if v.derivative is None and v.name in o.x_names
                          and v.variability == "continuous"]
            cs = simulate_fmu(str(path), output=continuous)
            t = cs["time"]
            grid = TimeSeries(t, np.zeros((len(t), 0)), [])
            engine = CasadiEngine()
            tight = CasadiEngine().simulate(model, grid, options=SimulationOptions(rtol=1e-9, atol=1e-11,
                                                                                   time_limit=600))
            assert tight.ok, tight.reason
            ref = {n: tight.states[:, o.x_names.index(n)] for n in continuous}
            ref.update({n: tight.output(n) for n in o.y_names})
            keep = ~_on_ticks(t, o.events["clocks"])

            def deviation(values, names=continuous):       # a dict or FMPy's structured array
                given = values.dtype.names if hasattr(values, "dtype") else values
                return max(np.max(np.abs(values[n] - ref[n])[keep]) / max(np.ptp(ref[n]), 1e-12)
                           for n in names if n in given)

            own = engine.simulate(model, grid)
            mine = simulate(FmuModel.read(path), grid)

            def me():
                res = simulate_fmu(str(path), output=continuous, fmi_type="ModelExchange",
                                   output_interval=float(t[1] - t[0]))
                last = res[np.r_[res["time"][1:] != res["time"][:-1], True]]      # after each event
                return last[np.searchsorted(last["time"], t - 1e-9 * np.maximum(1.0, np.abs(t)))]

            fmu = FmuModel.read(path)
            timings = {
                "casadi (repeated)": (timed(lambda: engine.simulate(model, grid), repeat, cpu=True),
                                      deviation({n: own.states[:, o.x_names.index(n)] for n in continuous})),
                "fmu engine (CS, child process)": (timed(lambda: simulate(fmu, grid), repeat, cpu=True),
                                                   deviation({n: mine.output(n) for n in o.y_names}, o.y_names)
                                                   if o.y_names else None),
                "FMPy defaults, Co-Simulation": (timed(lambda: simulate_fmu(str(path), output=continuous), repeat, cpu=True),
                                                 deviation(cs)),
                "FMPy defaults, Model Exchange": (timed(me, repeat, cpu=True), deviation(me())),
            }
            try:
                session = rm.Session(roots=[str(msl)])
                ref_model = session.loads(f"model BenchEntry_\n  extends {name};\nend BenchEntry_;\n",
                                          model="BenchEntry_", filename="/mcl-bench/BenchEntry_.mo")
                cfg = rm.SimConfig(rtol=1e-6, atol=1e-8, dt=float(t[1] - t[0]))
                theirs = ref_model.simulate(t=(float(t[0]), float(t[-1])), config=cfg)
                values = {n: np.interp(t, np.asarray(theirs.time), np.asarray(theirs[n]))
                          for n in continuous if n in theirs.names}
                timings = {"rumoca": (timed(lambda: ref_model.simulate(t=(float(t[0]), float(t[-1])), config=cfg),
                                            repeat, cpu=True), deviation(values) if values else None), **timings}
            except rm.RumocaError as exc:
                print(f"  rumoca cannot simulate {name}: {str(exc).splitlines()[0][:100]}")
        own_cpu = timings["casadi (repeated)"][0][1]
        print(f"\nhybrid MSL {name.split('.')[-1]}, {t[-1] - t[0]:g} s ({len(o.events['clocks'])} clock(s), "
              f"{0 if o.zero is None else o.zero.size1_out(0)} event indicator(s)); median of {repeat} runs")
        print(f"  {'engine':38s} {'wall s':>8s} {'cpu s':>8s} {'cpu/casadi':>11s} {'max dev':>9s}")
        for label, ((wall, cpu), dev) in timings.items():
            shown = f"{dev:9.1e}" if dev is not None else f"{'':9s}"
            print(f"  {label:38s} {wall:8.3f} {cpu:8.3f} {cpu / own_cpu:11.2f} {shown}")
            rows.append({"model": name, "engine": label, "seconds": wall, "cpu_seconds": cpu,
                         "cpu_ratio_to_casadi": cpu / own_cpu,
                         **({"max_relative_deviation": float(dev)} if dev is not None else {})})
    return rows


def _on_ticks(t, clocks):
    hit = np.zeros(len(t), dtype=bool)
    for start, period in clocks:
        n = np.round((t - start) / period)
        hit |= (n >= 0) & (np.abs(start + n * period - t) <= 1e-9 * np.maximum(1.0, np.abs(t)))
    return hit


if __name__ == "__main__":
    main()
