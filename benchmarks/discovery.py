"""Seconds and simulations per discovery (``mcl run``, ``unknown: auto``, no templates), each as a
ratio to the same run with ``fitting: {early_stop: false}`` (every promising candidate fitted to
the end), measured in the same run; and whether the answer is the right one.

Cases: the systems of examples/faults with one hidden effect each (data from SciPy truths: a
damper cubic in its speed, Coulomb-like friction, a leaky capacitor, a sinh-shaped shunt), the
bundled Cauer example, and a user model of MSL parts with a cubic load when the Modelica
Standard Library is found (``--msl DIR``, default ../shared/msl).

    python benchmarks/discovery.py [--json PATH] [--msl DIR] [--cases a,b,...]
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIB = ROOT / "modelica" / "MCL"
FAULTS = ROOT / "examples" / "faults" / "Faults.mo"
sys.path.insert(0, str(FAULTS.parent))
from truths import CASES, rc  # noqa: E402  (examples/faults: SciPy truths, made without mcl)



def generated(name, model, case, truth):
    def setup(work: Path) -> Path:
        CASES[case](work / "train.csv", 1)
        CASES[case](work / "validate.csv", 2)
        (work / "run.yaml").write_text(f"model: {{sources: [{FAULTS}, {LIB}], name: Faults.{model}}}\n"
                                       "data: {train: train.csv, validate: validate.csv}\noutput: out\n")
        return work / "run.yaml"
    return name, setup, truth


def cauer(work: Path) -> Path:
    shutil.copytree(ROOT / "examples" / "cauer", work / "examples" / "cauer")
    run = work / "examples" / "cauer" / "run.yaml"
    run.write_text(run.read_text().replace("../../out/cauer", "out"))
    return run


def msl_case(msl: Path):
    def setup(work: Path) -> Path:
        shutil.copyfile(FAULTS.parent / "UserRC.mo", work / "UserRC.mo")
        rc(work / "train.csv", 1)
        rc(work / "validate.csv", 2)
        (work / "run.yaml").write_text(f"model: {{sources: [UserRC.mo], name: UserRC, libraries: [{msl}]}}\n"
                                       "data: {train: train.csv, validate: validate.csv}\noutput: out\n")
        return work / "run.yaml"
    return setup


def warm_up(setup) -> None:
    """Parse the libraries and compile the nominal model once, untimed: both timed runs then
    start from the same state (the library parsed in this process, the nominal model cached)."""
    from mcl.api import compile_model
    from mcl.runfile import load_runfile

    with tempfile.TemporaryDirectory() as d:
        spec = load_runfile(setup(Path(d)))
        compile_model(spec.sources, spec.model_name, libraries=spec.libraries)


def run_case(setup, early_stop: bool) -> dict:
    import contextlib
    import io

    from mcl.cli import main

    with tempfile.TemporaryDirectory() as d:
        run = setup(Path(d))
        if not early_stop:
            run.write_text(run.read_text() + "fitting: {early_stop: false}\n")
        t0 = time.perf_counter()
        with contextlib.redirect_stdout(io.StringIO()):      # the result is read from report.json
            code = main(["--quiet", "run", str(run)])
        seconds = time.perf_counter() - t0
        report = json.loads((run.parent / "out" / "report.json").read_text()) if code == 0 else {}
    sims = len(report.get("screening", [])) + sum(c.get("simulations") or 0 for c in report.get("candidates", []))
    cause = report.get("cause") or {}
    return {"seconds": seconds, "simulations": sims, "component": cause.get("component"),
            "equation": (cause.get("law") or {}).get("equation"), "exit": code}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path)
    ap.add_argument("--msl", type=Path, default=ROOT.parent / "shared" / "msl")
    ap.add_argument("--cases", help="comma-separated case names (default: all)")
    args = ap.parse_args(argv)
    cases = [generated("damper-cubic-speed", "Slider", "slider-cubic", "D"),
             generated("friction-tanh", "Slider", "slider-friction", "D"),
             generated("leaky-capacitor", "Ladder", "ladder-leaky", "C2"),
             generated("sinh-shunt", "Shunt", "shunt-sinh", "Gs"),
             ("cauer-example", cauer, "Rnl")]
    if (args.msl / "Modelica" / "package.mo").is_file() or (args.msl / "Modelica 4.0.0" / "package.mo").is_file():
        cases.append(("msl-user-rc", msl_case(args.msl), "R2"))
    else:
        print(f"(no MSL at {args.msl}: the MSL case is skipped)", file=sys.stderr)
    if args.cases:
        cases = [c for c in cases if c[0] in args.cases.split(",")]
    rows = []
    print(f"{'case':22s} {'seconds':>8s} {'sims':>6s} {'baseline s':>10s} {'base sims':>9s} {'time ratio':>10s}  answer")
    for name, setup, truth in cases:
        warm_up(setup)
        ours, base = run_case(setup, True), run_case(setup, False)
        ratio = ours["seconds"] / base["seconds"]
        right = "right" if ours["component"] == truth else f"WRONG ({ours['component']}, expected {truth})"
        print(f"{name:22s} {ours['seconds']:8.1f} {ours['simulations']:6d} {base['seconds']:10.1f} "
              f"{base['simulations']:9d} {ratio:10.2f}  {right}: {ours['equation']}")
        rows.append({"case": name, "truth": truth, "ours": ours, "baseline_no_early_stop": base, "time_ratio": ratio})
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
