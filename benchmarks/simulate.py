"""Time per simulation of paper 000's Cauer filter over 100 s, each engine as a ratio to rumoca;
the MSL's CauerLowPassAnalog (its own step source) the same way; first and cached compile times.

rumoca (a Rust Modelica compiler on PyPI) is the baseline, measured in the same run. It takes no
input tables, so the source voltage is a band-limited multisine written into a Modelica wrapper;
our engines get the same signal sampled every 10 ms. The MSL part runs when the Modelica Standard
Library is found (``--msl DIR``, default ../shared/msl).

    python benchmarks/simulate.py [--repeat 5] [--json PATH] [--msl DIR]
"""
from __future__ import annotations

import argparse
import json
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


def timed(fn, repeat):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


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
        rumoca_s = timed(lambda: ref.simulate(t=(0.0, T_END), config=cfg), args.repeat)

        model = compile_model([LIB], "MCL.Examples.CauerFilter")
        fmu = FmuModel.read(build_fmu(model, Path(tmp) / "cauer.fmu"))
        warm_engine = CasadiEngine()
        warm_engine.simulate(model, u)  # builds the integrator once, as a fitting loop does
        rows = {
            "rumoca": rumoca_s,
            "casadi (repeated, fitting loop)": timed(lambda: warm_engine.simulate(model, u), args.repeat),
            "casadi (first call, builds integrator)": timed(
                lambda: CasadiEngine().simulate(model, u), args.repeat),
            "fmu (FMPy, child process)": timed(lambda: simulate(fmu, u, options=opts), args.repeat),
        }
    print(f"Cauer filter, {T_END:g} s, input sampled every {DT:g} s; median of {args.repeat} runs")
    print(f"{'engine':42s} {'seconds':>9s} {'ratio to rumoca':>16s}")
    for name, s in rows.items():
        print(f"{name:42s} {s:9.3f} {s / rumoca_s:16.2f}")
    out = {"rows": [{"engine": k, "seconds": v, "ratio": v / rumoca_s} for k, v in rows.items()]}
    if (args.msl / "Modelica" / "package.mo").is_file():
        out["msl"] = msl_rows(args.msl, args.repeat)
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))


def msl_rows(msl: Path, repeat: int) -> list[dict]:
    """CauerLowPassAnalog from the MSL: compile (first, then cached) and simulate vs rumoca."""
    import os

    import rumoca as rm

    from mcl.compile import cache as compile_cache
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


if __name__ == "__main__":
    main()
