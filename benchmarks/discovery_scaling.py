"""How discovery's cost grows with the model: RC ladders of N sections (MSL parts, written as an
engineer writes them) with one faulty resistor, data made by SciPy without mcl
(examples/ladder/ladder.py). Prints, per N: CPU seconds of the whole ``mcl run`` (this process
and its workers; the model compiled from scratch, not from the compile cache), wall seconds,
whether the right component and law were found; then the growth exponent of CPU seconds in N (least squares on log-log) and the ratio
of each size's CPU seconds to the smallest size's, measured in the same run.

    python benchmarks/discovery_scaling.py [--sizes 4,8,16,32,64] [--msl DIR] [--json PATH]
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "examples" / "ladder"))
from ladder import values, write_data, write_model  # noqa: E402  (made without mcl)

def cubic(n: int) -> float:
    """The faulty resistor's cubic coefficient, i = v/R + a v^3: the voltage across one section
    falls as 1/n, so a grows as n^3 for the fault to matter as much at every size (a = 0.8 at 4)."""
    return 0.8 * (n / 4) ** 3


def cpu() -> float:
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def run(n: int, msl: Path, work: Path) -> dict:
    from mcl.cli import main

    fault = 2
    name = write_model(n, work / f"Ladder{n}.mo")
    write_data(n, work / "train.csv", 1, cubic={fault: cubic(n)})
    write_data(n, work / "validate.csv", 2, cubic={fault: cubic(n)})
    (work / "run.yaml").write_text(f"model: {{sources: [Ladder{n}.mo], name: {name}, libraries: [{msl}]}}\n"
                                   "data: {train: train.csv, validate: validate.csv}\noutput: out\n")
    os.environ["MCL_CACHE_DIR"] = str(work / "cache")     # a cold compile counts
    c0, t0 = cpu(), time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(["--quiet", "run", str(work / "run.yaml")])
    seconds, cpu_s = time.perf_counter() - t0, cpu() - c0
    report = json.loads((work / "out" / "report.json").read_text()) if code == 0 else {}
    cause = report.get("cause") or {}
    law = cause.get("law") or {}
    R, _ = values(n)
    err = None
    if law.get("curve"):
        xs, fs = np.array(law["curve"]).T
        truth = xs / R + cubic(n) * xs**3
        err = float(np.max(np.abs(fs - truth)) / np.max(np.abs(truth)))
    return {"N": n, "components": report.get("components"), "cpu_seconds": cpu_s, "wall_seconds": seconds,
            "exit": code, "component": cause.get("component"), "right": cause.get("component") == f"R{fault}",
            "law_error": err, "equation": law.get("equation"),
            "validation": [(report.get("gain") or {}).get(k) for k in ("validation_rms_before", "validation_rms_after")]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="4,8,16,32,64")
    ap.add_argument("--msl", type=Path, default=ROOT.parent / "shared" / "msl")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    if not (args.msl / "Modelica" / "package.mo").is_file():
        print(f"no MSL at {args.msl}: nothing to measure", file=sys.stderr)
        return 0
    rows = []
    print(f"{'N':>4s} {'comps':>5s} {'CPU s':>8s} {'wall s':>8s} {'ratio':>6s}  answer")
    for n in map(int, args.sizes.split(",")):
        with tempfile.TemporaryDirectory() as d:
            row = run(n, args.msl, Path(d))
        rows.append(row)
        ratio = row["cpu_seconds"] / rows[0]["cpu_seconds"]
        answer = ("right" if row["right"] else f"WRONG ({row['component']})") + \
                 (f", law within {100 * row['law_error']:.1f}%" if row["law_error"] is not None else "")
        print(f"{n:4d} {row['components'] or 0:5d} {row['cpu_seconds']:8.1f} {row['wall_seconds']:8.1f} {ratio:6.2f}  {answer}",
              flush=True)
    if len(rows) > 1:
        ns, cs = np.log([r["N"] for r in rows]), np.log([r["cpu_seconds"] for r in rows])
        slope = float(np.polyfit(ns, cs, 1)[0])
        print(f"growth exponent of CPU seconds in N: {slope:.2f}")
        rows.append({"growth_exponent": slope})
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
