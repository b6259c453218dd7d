"""CPU seconds of MSL fluid models with their if-branches' singular operations guarded
(:mod:`mcl.compile.guards`) and, as the baseline measured in the same run, without: the cold
compile, a plain run and a run with sensitivities, each model in its own process.

    python benchmarks/guards.py [--msl DIR] [--repeat 3] [--json PATH]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: model -> (stop time, parameters of the sensitivity run)
MODELS = {
    "Modelica.Fluid.Examples.Tanks.TanksWithOverflow": (6000.0, ["upperTank.crossArea"]),
    "Modelica.Fluid.Examples.DrumBoiler.DrumBoiler": (5400.0, ["evaporator.V_t"]),
}

CHILD = """
import json, statistics, sys, time
import numpy as np
import mcl, mcl.compile.rumoca_frontend as rf
from mcl.data import TimeSeries
name, stop, sens, guarded, repeat = sys.argv[1], float(sys.argv[2]), json.loads(sys.argv[3]), sys.argv[4] == "on", int(sys.argv[5])
if not guarded:
    rf.guard_branches = lambda dae: dae
from mcl.compile.isolation import cpu_seconds
t = cpu_seconds()
model = mcl.compile_model([], name, libraries=[sys.argv[6]])
out = {"compile": cpu_seconds() - t}
grid = np.linspace(0.0, stop, 201)
none = TimeSeries(grid, np.zeros((len(grid), 0)), [])
def cpu(**kw):
    times, ok = [], True
    for _ in range(repeat):
        t = time.process_time()
        ok = mcl.simulate(model, none, t_out=grid, **kw).ok and ok
        times.append(time.process_time() - t)
    return statistics.median(times), ok
out["run"], out["run_ok"] = cpu()
if sens:
    out["sensitivities"], out["sensitivities_ok"] = cpu(sensitivities=sens)
print("RESULT " + json.dumps(out))
"""


def measure(name: str, stop: float, sens: list, guarded: bool, repeat: int, msl: Path) -> dict:
    env = {**os.environ, "MCL_NO_COMPILE_CACHE": "1", "MODELICAPATH": ""}
    done = subprocess.run([sys.executable, "-c", CHILD, name, str(stop), json.dumps(sens),
                           "on" if guarded else "off", str(repeat), str(msl)],
                          capture_output=True, text=True, env=env, cwd=ROOT)
    for line in done.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    return {"error": (done.stderr.strip().splitlines() or ["no output"])[-1]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--msl", type=Path, default=ROOT.parent / "shared" / "msl")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    rows = []
    for name, (stop, sens) in MODELS.items():
        on, off = (measure(name, stop, sens, g, args.repeat, args.msl) for g in (True, False))
        row = {"model": name, "guarded": on, "unguarded": off}
        for key in ("compile", "run", "sensitivities"):
            if key in on and key in off and off[key] > 0:
                row[f"{key}_ratio"] = on[key] / off[key]
        rows.append(row)
        short = name.rsplit(".", 1)[-1]
        print(f"{short:28s} " + "  ".join(
            f"{k}: {on.get(k, float('nan')):.2f} / {off.get(k, float('nan')):.2f} CPU-s "
            f"(x{row.get(k + '_ratio', float('nan')):.2f}; ok {on.get(k + '_ok', True)}/{off.get(k + '_ok', True)})"
            for k in ("compile", "run", "sensitivities") if k in on or k in off), flush=True)
    if args.json:
        args.json.write_text(json.dumps({"rows": rows}, indent=1))


if __name__ == "__main__":
    main()
