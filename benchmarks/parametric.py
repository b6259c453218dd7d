"""CPU seconds of a run of a model whose parameters set heavy coefficients (MSL filters: the
Chebyshev and Butterworth poles of f_cut and the ripple), with the purely parametric parts split
out of the right-hand side (:mod:`mcl.compile.parametric`) and, as the baseline measured in the
same run, without: plain runs, runs with forward sensitivities in f_cut, and a linearisation.
A second baseline is the model compiled without merging its repeated subexpressions (as the
flat model writes them: each use of a coefficient function inlined), split nowhere; and the
compile's CPU seconds with and without the merge.

    python benchmarks/parametric.py [--msl DIR] [--repeat 3] [--json PATH]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

MODEL = """
model Chain "a Chebyshev low-pass, a gain, a Butterworth low-pass"
  import Modelica.Blocks;
  Blocks.Interfaces.RealInput u;
  Blocks.Continuous.Filter first(analogFilter=Blocks.Types.AnalogFilter.ChebyshevI,
    filterType=Blocks.Types.FilterType.LowPass, order=3, f_cut=5, A_ripple=0.5, init=Blocks.Types.Init.InitialState);
  Blocks.Math.Gain k(k=2);
  Blocks.Continuous.Filter second(analogFilter=Blocks.Types.AnalogFilter.Butterworth,
    filterType=Blocks.Types.FilterType.LowPass, order=4, f_cut=8, init=Blocks.Types.Init.InitialState);
  Blocks.Interfaces.RealOutput y;
equation
  connect(u, first.u);
  connect(first.y, k.u);
  connect(k.y, second.u);
  connect(second.y, y);
end Chain;
"""


def cpu(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        times.append(time.process_time() - t0)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--msl", default=str(ROOT.parent / "shared" / "msl"))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json")
    args = ap.parse_args()

    from mcl import compile_model, simulate
    from mcl.compile import parametric
    from mcl.data import TimeSeries
    from mcl.sensitivity import Linearisation

    from mcl.compile import dae, structure
    from mcl.compile.isolation import cpu_seconds

    def compiled(merge: bool):
        """The model and its compile's CPU seconds (cold: a cache of its own)."""
        with tempfile.TemporaryDirectory() as d:
            (Path(d) / "Chain.mo").write_text(MODEL)
            saved = dae.CSE_MIN, structure.CSE_MIN, os.environ.get("MCL_CACHE_DIR")
            os.environ["MCL_CACHE_DIR"] = str(Path(d) / "cache")
            if not merge:
                dae.CSE_MIN = structure.CSE_MIN = float("inf")
            t0 = cpu_seconds()
            try:
                return compile_model([Path(d) / "Chain.mo"], "Chain", libraries=[args.msl]), cpu_seconds() - t0
            finally:
                dae.CSE_MIN, structure.CSE_MIN, cache = saved
                if cache is None:
                    os.environ.pop("MCL_CACHE_DIR", None)
                else:
                    os.environ["MCL_CACHE_DIR"] = cache

    model, compile_s = compiled(True)
    unmerged, unmerged_compile_s = compiled(False)
    t = np.linspace(0, 2, 2001)
    data = TimeSeries(t, (np.sin(2 * np.pi * 3 * t) + 0.5 * np.sin(2 * np.pi * 13 * t))[:, None], ["u"])
    split = parametric.split(model.ode)
    whole = model.ode.ode.n_instructions()
    print(f"right-hand side: {whole} instructions; split: {split.ode.n_instructions()} "
          f"+ {split.nq} parametric values once per run")
    p = model.parameter_vector()
    res = simulate(model, data)
    jobs = {"plain run": lambda: simulate(model, data),
            "run with sensitivities in f_cut": lambda: simulate(model, data, sensitivities=["first.f_cut"]),
            "linearisation (f_cut)": lambda: Linearisation(model, res.states, res.time, data, p,
                                                           ["first.f_cut"])._at(slice(None))}
    print(f"compile: {compile_s:.2f} CPU-s, without the merge {unmerged_compile_s:.2f} CPU-s "
          f"({unmerged.ode.ode.n_instructions()} instructions)")
    rows = {"compile": {"cpu_s": compile_s, "unmerged_cpu_s": unmerged_compile_s}}
    for label, job in jobs.items():
        fast = cpu(job, args.repeat)
        original = parametric.split
        parametric.split = lambda ode: None
        try:
            import mcl.sensitivity as sens
            sens._FUNCTIONS.clear()
            slow = cpu(job, 1)
            if label == "plain run":    # the unmerged whole function (its sensitivities take minutes)
                raw = cpu(lambda: simulate(unmerged, data), 1)
        finally:
            parametric.split = original
            sens._FUNCTIONS.clear()
        rows[label] = {"split_cpu_s": fast, "whole_cpu_s": slow, "ratio": slow / max(fast, 1e-9)}
        print(f"{label:34s} split {fast:8.3f} CPU-s   whole {slow:8.3f} CPU-s   {slow / max(fast, 1e-9):7.1f}x")
    rows["plain run"].update(unmerged_whole_cpu_s=raw, unmerged_ratio=raw / max(rows["plain run"]["split_cpu_s"], 1e-9))
    print(f"{'plain run, unmerged and whole':34s} {raw:8.3f} CPU-s   {rows['plain run']['unmerged_ratio']:7.1f}x the split")
    if args.json:
        Path(args.json).write_text(json.dumps({"instructions": {"whole": whole, "split": split.ode.n_instructions(),
                                                               "unmerged": unmerged.ode.ode.n_instructions()},
                                               "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
