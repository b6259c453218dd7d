"""RC ladders of N sections with hidden faults: the Modelica an engineer writes, and measurements
made without mcl.

The model (``write_model``) is written as an engineer writes one from MSL parts: imports, a
RealInput driving a signal voltage, voltage sensors on RealOutputs, an initial equation per
capacitor. The measurements (``write_data``) come from the ladder's ODE written out by hand and
solved by SciPy, with some resistors carrying a cubic term i = v/R + a v^3 and some capacitors a
leak i = C v' + g v, and 1% noise. The ladder's resistances and capacitances scale with 1/N so
that its time constant, and so what the data show, stays the same for every N.

    python examples/ladder/ladder.py 16 out_dir [--fault R2:0.8] [--leak C5:0.3]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp


def values(n: int) -> tuple[float, float]:
    """(R, C) of one section of an ``n``-section ladder (total R 4 ohm, total C 1.6 F)."""
    return 4.0 / n, 1.6 / n


def write_model(n: int, path, name: str | None = None, v0: float = 0.0) -> str:
    """``LadderN``: u -> V -> R1 -> node 1 (C1) -> R2 -> ... -> node n (Cn); y1 measures node
    n/2, y2 node n; every capacitor starts at ``v0`` (an initial equation). Returns the model's
    name."""
    name = name or f"Ladder{n}"
    R, C = values(n)
    lines = [f'model {name} "RC ladder of {n} sections from MSL parts"',
             "  import Modelica.Electrical.Analog;",
             "  import Modelica.Blocks.Interfaces.{RealInput, RealOutput};",
             '  RealInput u "source voltage";',
             f'  RealOutput y1 "voltage of node {max(n // 2, 1)}";',
             f'  RealOutput y2 "voltage of node {n}";',
             "  Analog.Sources.SignalVoltage V;",
             "  Analog.Basic.Ground G;",
             "  Analog.Sensors.VoltageSensor S1;",
             "  Analog.Sensors.VoltageSensor S2;"]
    for k in range(1, n + 1):
        lines += [f"  Analog.Basic.Resistor R{k}(R = {R:.6g});", f"  Analog.Basic.Capacitor C{k}(C = {C:.6g});"]
    lines.append("initial equation")
    lines += [f"  C{k}.v = {v0:g};" for k in range(1, n + 1)]
    lines += ["equation", "  connect(u, V.v);", "  connect(V.n, G.p);", "  connect(V.p, R1.p);"]
    for k in range(1, n + 1):
        lines += [f"  connect(R{k}.n, C{k}.p);", f"  connect(C{k}.n, G.p);"]
        if k < n:
            lines.append(f"  connect(R{k}.n, R{k + 1}.p);")
    lines += [f"  connect(S1.p, C{max(n // 2, 1)}.p);", "  connect(S1.n, G.p);", "  connect(S1.v, y1);",
              f"  connect(S2.p, C{n}.p);", "  connect(S2.n, G.p);", "  connect(S2.v, y2);", f"end {name};"]
    Path(path).write_text("\n".join(lines) + "\n")
    return name


def simulate(n: int, t: np.ndarray, u, cubic: dict[int, float] | None = None, leak: dict[int, float] | None = None,
             v0: float = 0.0):
    """Node voltages (n, len(t)) of the ladder: C v_k' = i_k - i_{k+1}, i_k = (v_{k-1} - v_k)/R
    (+ a (v_{k-1} - v_k)^3 for resistor k in ``cubic``), v_0 = u, and a leak g v_k out of node
    k for capacitor k in ``leak``."""
    R, C = values(n)
    a = np.zeros(n)
    g = np.zeros(n)
    for k, v in (cubic or {}).items():
        a[k - 1] = v
    for k, v in (leak or {}).items():
        g[k - 1] = v

    def rhs(s, v):
        d = np.concatenate([[u(s)], v[:-1]]) - v       # v_{k-1} - v_k
        i = d / R + a * d**3
        out = np.append(i[1:], 0.0)
        return (i - out - g * v) / C

    return solve_ivp(rhs, (t[0], t[-1]), np.full(n, v0), t_eval=t, method="LSODA", rtol=1e-9, atol=1e-11).y


def write_data(n: int, path, seed: int, cubic=None, leak=None, horizon: float = 30.0, samples: int = 601,
               v0: float = 0.0) -> None:
    """train or validation data: a sum of sines (random frequencies 0.3-2 rad/s) into the
    ladder started at ``v0``, both outputs with 1% noise."""
    rng = np.random.default_rng(seed)
    w, ph = rng.uniform(0.3, 2.0, 4), rng.uniform(0, 6, 4)
    u = lambda s: sum(1.5 * np.sin(wk * s + pk) for wk, pk in zip(w, ph))
    t = np.linspace(0, horizon, samples)
    v = simulate(n, t, u, cubic, leak, v0)
    y1, y2 = v[max(n // 2, 1) - 1], v[n - 1]
    noisy = lambda y: y + rng.normal(0, 0.01 * np.std(y), len(y))
    rows = np.column_stack([t, u(t), noisy(y1), noisy(y2)])
    Path(path).write_text("time,u,y1,y2\n" + "\n".join(",".join(repr(float(x)) for x in r) for r in rows) + "\n")


def _faults(items) -> dict[int, float]:
    out = {}
    for item in items or []:
        name, value = item.split(":")
        out[int(name[1:])] = float(value)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sections", type=int)
    ap.add_argument("out", type=Path)
    ap.add_argument("--fault", action="append", help="a cubic resistor, e.g. R2:0.8 (i = v/R + 0.8 v^3)")
    ap.add_argument("--leak", action="append", help="a leaking capacitor, e.g. C5:0.3 (i = C v' + 0.3 v)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    name = write_model(args.sections, args.out / f"Ladder{args.sections}.mo")
    for file, seed in (("train.csv", 1), ("validate.csv", 2)):
        write_data(args.sections, args.out / file, seed, _faults(args.fault), _faults(args.leak))
    print(f"wrote {args.out}/{name}.mo, train.csv and validate.csv")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
