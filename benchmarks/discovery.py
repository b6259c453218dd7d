"""Seconds and simulations per discovery (``mcl run``, ``unknown: auto``, no templates), each as a
ratio to the same run with ``fitting: {early_stop: false}`` (every promising candidate fitted to
the end), measured in the same run; and whether the answer is the right one.

Cases: systems generated here with one hidden effect each (data from SciPy: a resistor cubic
in its voltage, a damper cubic in its speed, Coulomb-like friction, a leaky capacitor), the
bundled Cauer example, and a user model of MSL parts when the Modelica Standard Library is found
(``--msl DIR``, default ../shared/msl).

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

import numpy as np
from scipy.integrate import solve_ivp

ROOT = Path(__file__).resolve().parents[1]
LIB = ROOT / "modelica" / "MCL"

SYSTEMS = """
package Bench
  model RC
    input Real u;
    output Real y;
    MCL.Electrical.VoltageSource V;
    MCL.Electrical.Ground G;
    MCL.Electrical.Resistor R1(R = 1);
    MCL.Electrical.Capacitor C(C = 0.5);
    MCL.Electrical.Resistor Rx(R = 2);
  equation
    V.u = u;
    connect(V.p, R1.p); connect(R1.n, C.p); connect(C.p, Rx.p);
    connect(C.n, G.p); connect(Rx.n, G.p); connect(V.n, G.p);
    y = C.v;
  end RC;
  model Slider
    input Real u;
    output Real y;
    MCL.Translational.Fixed wall;
    MCL.Translational.Force push;
    MCL.Translational.Mass M(m = 1.2);
    MCL.Translational.Spring S(c = 3);
    MCL.Translational.Damper D(d = 0.5);
  equation
    push.u = u;
    connect(wall.flange, push.flange_a); connect(push.flange_b, M.flange_a);
    connect(wall.flange, S.flange_a); connect(S.flange_b, M.flange_a);
    connect(wall.flange, D.flange_a); connect(D.flange_b, M.flange_a);
    y = M.s;
  end Slider;
  model Ladder
    input Real u;
    output Real y;
    MCL.Electrical.VoltageSource V;
    MCL.Electrical.Ground G;
    MCL.Electrical.Resistor R1(R = 1);
    MCL.Electrical.Capacitor C1(C = 0.5);
    MCL.Electrical.Resistor R2(R = 2);
    MCL.Electrical.Capacitor C2(C = 1);
  equation
    V.u = u;
    connect(V.p, R1.p); connect(R1.n, C1.p); connect(C1.p, R2.p); connect(R2.n, C2.p);
    connect(C1.n, G.p); connect(C2.n, G.p); connect(V.n, G.p);
    y = C2.v;
  end Ladder;
end Bench;
"""

USER_MSL = """
model UserRC
  Modelica.Blocks.Interfaces.RealInput u;
  Modelica.Blocks.Interfaces.RealOutput y;
  Modelica.Electrical.Analog.Sources.SignalVoltage V;
  Modelica.Electrical.Analog.Basic.Ground G;
  Modelica.Electrical.Analog.Basic.Resistor R1(R = 1);
  Modelica.Electrical.Analog.Basic.Capacitor C(C = 0.5);
  Modelica.Electrical.Analog.Basic.Resistor R2(R = 2);
  Modelica.Electrical.Analog.Sensors.VoltageSensor S;
equation
  connect(u, V.v);
  connect(V.p, R1.p); connect(R1.n, C.p); connect(C.p, R2.p); connect(R2.n, G.p);
  connect(C.n, G.p); connect(V.n, G.p);
  connect(S.p, C.p); connect(S.n, G.p); connect(S.v, y);
end UserRC;
"""


def excitation(seed, amplitude, lo=0.3, hi=2.0, n=4):
    rng = np.random.default_rng(seed)
    w, ph = rng.uniform(lo, hi, n), rng.uniform(0, 6, n)
    return rng, lambda s: sum(amplitude * np.sin(wk * s + pk) for wk, pk in zip(w, ph))


def write(path, t, u, y, rng):
    y = y + rng.normal(0, 0.01 * np.std(y), len(y))
    np.savetxt(path, np.column_stack([t, u, y]), delimiter=",", header="time,u,y", comments="")


def rc(path, seed):
    rng, u = excitation(seed, 1.0, hi=2.5)
    t = np.linspace(0, 20, 401)
    sol = solve_ivp(lambda s, e: [((u(s) - e[0]) - 0.5 * e[0] - 0.3 * e[0] ** 3) / 0.5], (0, 20), [0.0],
                    t_eval=t, rtol=1e-10, atol=1e-12)
    write(path, t, u(t), sol.y[0], rng)


def slider(friction):
    def make(path, seed):
        rng, u = excitation(seed, 1.5)
        t = np.linspace(0, 30, 1201)
        sol = solve_ivp(lambda s, x: [x[1], (u(s) - 3 * x[0] - friction(x[1])) / 1.2], (0, 30), [0, 0],
                        t_eval=t, rtol=1e-10, atol=1e-12)
        write(path, t, u(t), sol.y[0], rng)
    return make


def leaky(path, seed):
    rng, u = excitation(seed, 1.2, lo=0.2, hi=1.5)
    t = np.linspace(0, 30, 1201)

    def rhs(s, x):
        i2 = (x[0] - x[1]) / 2
        return [((u(s) - x[0]) - i2) / 0.5, i2 - 0.4 * x[1]]

    sol = solve_ivp(rhs, (0, 30), [0, 0], t_eval=t, rtol=1e-10, atol=1e-12)
    write(path, t, u(t), sol.y[1], rng)


def generated(name, model, make, truth):
    def setup(work: Path) -> Path:
        (work / "Bench.mo").write_text(SYSTEMS)
        make(work / "train.csv", 1)
        make(work / "validate.csv", 2)
        (work / "run.yaml").write_text(f"model: {{sources: [Bench.mo, {LIB}], name: Bench.{model}}}\n"
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
        (work / "UserRC.mo").write_text(USER_MSL)
        rc(work / "train.csv", 1)
        rc(work / "validate.csv", 2)
        (work / "run.yaml").write_text(f"model: {{sources: [UserRC.mo], name: UserRC, libraries: [{msl}]}}\n"
                                       "data: {train: train.csv, validate: validate.csv}\noutput: out\n")
        return work / "run.yaml"
    return setup


def run_case(setup, early_stop: bool) -> dict:
    from mcl.cli import main

    with tempfile.TemporaryDirectory() as d:
        run = setup(Path(d))
        if not early_stop:
            run.write_text(run.read_text() + "fitting: {early_stop: false}\n")
        t0 = time.perf_counter()
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
    cases = [generated("rc-cubic", "RC", rc, "Rx"),
             generated("damper-cubic-speed", "Slider", slider(lambda v: 0.5 * v + 0.6 * v**3), "D"),
             generated("friction-tanh", "Slider", slider(lambda v: 0.2 * v + 0.4 * np.tanh(v / 0.3)), "D"),
             generated("leaky-capacitor", "Ladder", leaky, "C2"),
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
