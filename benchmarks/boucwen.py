"""The Bouc-Wen hysteresis benchmark (Noel & Schoukens, 2016; nonlinearbenchmark.org), its system
simulated here: does mcl find the hysteresis an engineer's linear model lacks, and how well?

The benchmark's own system and protocol: a 2 kg mass, viscous damping 10 N s/m, a linear
stiffness 5e4 N/m and a Bouc-Wen force z (dz/dt = alpha y' - beta (gamma |y'| z + delta y' |z|),
alpha 5e4 N/m, beta 1e3 1/m, gamma 0.8, delta -1.1), random-phase multisines of 5-150 Hz at
50 N RMS sampled at 750 Hz, output noise of standard deviation 8e-3 mm. The benchmark ships its
system as code (training data are made by its users) and two validation records; here both are
made with SciPy from the published equations (the benchmark's files are not in this
repository), the input linear between samples as mcl reads it. The engineer's model is a mass
on a linear spring (at the initial stiffness, 1e5 N/m) and damper, from the MSL.

Printed: CPU seconds of the run (this process and its workers), the validation RMS of the
nominal model, of the law alone and with the joint refit, against the noise; the found law.

    python benchmarks/boucwen.py [--periods 2] [--out DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from discovery_scaling import cpu  # noqa: E402  (this process's and its workers' CPU seconds)
from mcl.data import TimeSeries, write_csv  # noqa: E402
M, C, K, ALPHA, BETA, GAMMA, DELTA = 2.0, 10.0, 5e4, 5e4, 1e3, 0.8, -1.1
FS, N, NOISE = 750.0, 8192, 8e-6

MODEL = """within ;
package BoucWen "the engineer's model of the Bouc-Wen benchmark: a mass on a spring and a damper"
  model Oscillator
    import Modelica.Mechanics.Translational.Components;
    Modelica.Blocks.Interfaces.RealInput u(unit = "N") "force on the mass";
    Modelica.Blocks.Interfaces.RealOutput y(unit = "m") "displacement";
    Components.Fixed wall;
    Modelica.Mechanics.Translational.Sources.Force push;
    Components.Mass M(m = 2) "moving mass";
    Components.Spring S(c = 1e5) "restoring element: its stiffness at small strokes";
    Components.Damper D(d = 10) "viscous damping";
    Modelica.Mechanics.Translational.Sensors.PositionSensor position;
  initial equation
    M.s = 0;
    M.v = 0;
  equation
    connect(u, push.f);
    connect(push.flange, M.flange_a);
    connect(wall.flange, S.flange_a);
    connect(S.flange_b, M.flange_a);
    connect(wall.flange, D.flange_a);
    connect(D.flange_b, M.flange_a);
    connect(M.flange_b, position.flange);
    connect(position.s, y);
  end Oscillator;
end BoucWen;
"""


def multisine(rng, n: int) -> np.ndarray:
    """A random-phase multisine over the lines of 5-150 Hz of an n-sample period, 50 N RMS."""
    f = np.arange(n) * FS / n
    t = np.arange(n) / FS
    u = sum(np.cos(2 * np.pi * f[k] * t + rng.uniform(0, 2 * np.pi)) for k in np.flatnonzero((f >= 5) & (f <= 150)))
    return 50.0 * u / np.std(u)


def simulate(u: np.ndarray) -> np.ndarray:
    """The benchmark's displacement under the force ``u`` (linear between samples), from rest."""
    t = np.arange(len(u)) / FS

    def rhs(tt, s):
        y, v, z = s
        return [v, (np.interp(tt, t, u) - C * v - K * y - z) / M,
                ALPHA * v - BETA * (GAMMA * abs(v) * z + DELTA * v * abs(z))]
    return solve_ivp(rhs, (0, t[-1]), [0, 0, 0], t_eval=t, method="DOP853", rtol=1e-9, atol=1e-12, max_step=1 / FS).y[0]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=2, help="multisine periods of 8192 samples to train on")
    ap.add_argument("--out", default=None, help="where the run goes (default: a temporary folder)")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(2016)
    work = Path(args.out or tempfile.mkdtemp(prefix="mcl-boucwen-"))
    work.mkdir(parents=True, exist_ok=True)
    t0 = cpu()
    for name, n in (("train", args.periods * N), ("validate", N)):
        u = multisine(rng, n)
        y = simulate(u) + rng.normal(0, NOISE, n)
        write_csv(work / f"{name}.csv", TimeSeries(np.arange(n) / FS, np.column_stack([u, y]), ["u", "y"]))
    made = cpu() - t0
    (work / "BoucWen.mo").write_text(MODEL)
    msl = os.environ.get("MODELICAPATH") or str(ROOT.parent / "shared" / "msl")
    (work / "run.yaml").write_text(
        f"model: {{sources: [BoucWen.mo], name: BoucWen.Oscillator, libraries: [{msl}]}}\n"
        "data: {train: train.csv, validate: validate.csv}\nunknown: auto\nfree: auto\noutput: out\n")
    from mcl.cli import main as mcl

    t1, wall = cpu(), time.perf_counter()
    code = mcl(["--quiet", "run", "--force", str(work / "run.yaml")])
    spent, wall = cpu() - t1, time.perf_counter() - wall
    if code != 0:
        print(f"mcl run failed (exit {code}); see {work}")
        return 1
    report = json.loads((work / "out" / "report.json").read_text())
    gain, cause = report["gain"], report.get("cause") or {}
    calibrated = (report.get("calibration") or {}).get("validation_rms")
    print(f"data made in {made:.1f} CPU-s; mcl run: {spent:.1f} CPU-s ({wall:.0f} s wall), in {work}")
    print(f"cause: {cause.get('component')} ({(cause.get('template') or {}).get('name')}): "
          f"{(cause.get('law') or {}).get('equation')}")
    print(f"validation RMS [m]: nominal {gain['validation_rms_before']:.3g}, law alone {gain['validation_rms_after']:.3g}"
          + (f", with the joint refit {calibrated:.3g}" if calibrated else "") + f"; noise {NOISE:.3g}")
    print(f"truth: k {K:g}, alpha {ALPHA:g} N/m, beta*gamma {BETA * GAMMA:g} 1/m, beta*delta {BETA * DELTA:g} 1/m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
