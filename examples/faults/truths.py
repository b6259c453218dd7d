"""Measurements of the systems in Faults.mo with a hidden effect, made without mcl.

Each truth is the system's ODE derived by hand and solved by SciPy (tight tolerances), with
measurement noise of 1% of the signal's spread; a NaN in a saved column is a blank cell (a value
not measured). The tests and ``benchmarks/discovery.py`` use these; so can anyone trying mcl:

    python examples/faults/truths.py slider-friction out_dir    # writes train.csv, validate.csv
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

HERE = Path(__file__).resolve().parent
FAULTS = HERE / "Faults.mo"


def excitation(rng, amplitude, n=4, lo=0.3, hi=2.0):
    """A sum of n sines of random frequency in [lo, hi] rad/s and random phase."""
    w, ph = rng.uniform(lo, hi, n), rng.uniform(0, 6, n)
    return lambda s: sum(amplitude * np.sin(wk * s + pk) for wk, pk in zip(w, ph))


def noisy(rng, y, level=0.01):
    return y + rng.normal(0, level * np.std(y), len(y))


def save(path, columns: dict):
    """A CSV file; NaN is written as a blank cell (not measured)."""
    names = list(columns)
    rows = np.column_stack([columns[n] for n in names])
    lines = [",".join(names)] + [",".join("" if np.isnan(v) else repr(float(v)) for v in row) for row in rows]
    Path(path).write_text("\n".join(lines) + "\n")


def solve(rhs, t, x0):
    return solve_ivp(rhs, (t[0], t[-1]), x0, t_eval=t, rtol=1e-10, atol=1e-12).y


def slider(path, seed, friction, measure="y"):
    """Faults.Slider: m x'' = u - 3 x - friction(x'), m = 1.2; ``measure`` the position (y) or
    the speed (M.v). Returns the true speed."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 30, 1201)
    u = excitation(rng, 1.5)
    x = solve(lambda s, x: [x[1], (u(s) - 3 * x[0] - friction(x[1])) / 1.2], t, [0, 0])
    save(path, {"time": t, "u": u(t), measure: noisy(rng, x[0] if measure == "y" else x[1])})
    return x[1]


def ladder(path, seed, c2_rate=None, r2_current=None, every=1, irregular=False, outputs=("y1", "y2")):
    """Faults.Ladder: C1 v1' = (u - v1)/R1 - i2 with i2 = r2_current(v1 - v2) (default (v1 - v2)/2);
    v2' = c2_rate(v2, i2) (default i2 / C2). y1 is kept at every ``every``-th sample only."""
    rng = np.random.default_rng(seed)
    t = np.sort(np.r_[0, rng.uniform(0, 30, 1199), 30]) if irregular else np.linspace(0, 30, 1201)
    u = excitation(rng, 1.2, lo=0.2, hi=1.5)
    r2 = r2_current or (lambda d: d / 2)
    c2 = c2_rate or (lambda v2, i2: i2)

    def rhs(s, x):
        i2 = r2(x[0] - x[1])
        return [((u(s) - x[0]) - i2) / 0.5, c2(x[1], i2)]

    x = solve(rhs, t, [0, 0])
    y1, y2 = noisy(rng, x[0]), noisy(rng, x[1])
    y1[np.arange(len(t)) % every != 0] = np.nan          # logged at 1/every of the rate
    save(path, {"time": t, "u": u(t), **{k: v for k, v in (("y1", y1), ("y2", y2)) if k in outputs}})


def shunt(path, seed, law):
    """Faults.Shunt: C v' = (u - v)/R1 - law(v), C = 0.2, R1 = 1."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 20, 1001)
    u = excitation(rng, 1.0, lo=0.3, hi=2.5)
    v = solve(lambda s, v: [((u(s) - v[0]) - law(v[0])) / 0.2], t, [0])[0]
    save(path, {"time": t, "u": u(t), "y": noisy(rng, v)})


def rc(path, seed, cubic=0.3):
    """An RC circuit (R1 = 1, C = 0.5) whose load conducts i = 0.5 v + cubic v^3."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 20, 401)
    u = excitation(rng, 1.0, lo=0.3, hi=2.5)
    v = solve(lambda s, e: [((u(s) - e[0]) - 0.5 * e[0] - cubic * e[0] ** 3) / 0.5], t, [0.0])[0]
    save(path, {"time": t, "u": u(t), "y": noisy(rng, v)})


CASES = {
    "slider-cubic": lambda p, s: slider(p, s, lambda v: 0.5 * v + 0.6 * v**3),
    "slider-friction": lambda p, s: slider(p, s, lambda v: 0.2 * v + 0.4 * np.tanh(v / 0.3)),
    "ladder-leaky": lambda p, s: ladder(p, s, c2_rate=lambda v2, i2: i2 - 0.4 * v2),
    "shunt-sinh": lambda p, s: shunt(p, s, lambda v: 0.1 * np.sinh(v / 0.35)),
}

USAGE = f"""usage: python examples/faults/truths.py CASE OUT_DIR

Writes OUT_DIR/train.csv and OUT_DIR/validate.csv: the system of Faults.mo with a hidden fault,
solved by SciPy, with 1% measurement noise (two seeds).

cases: {', '.join(CASES)}
example: python examples/faults/truths.py slider-friction data/"""


def main(argv) -> int:
    if any(a in ("-h", "--help") for a in argv):
        print(USAGE)
        return 0
    if len(argv) != 2:
        print(USAGE, file=sys.stderr)
        return 2
    case, out = argv[0], Path(argv[1])
    if case not in CASES:
        import difflib

        close = difflib.get_close_matches(case, CASES, n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        print(f"truths.py: error: no case '{case}'{hint}; cases: {', '.join(CASES)}", file=sys.stderr)
        return 2
    files = [out / "train.csv", out / "validate.csv"]
    taken = [f for f in files if f.exists() or f.is_symlink()]
    if taken or (out.exists() and not out.is_dir()):
        print(f"truths.py: error: {taken[0] if taken else out} exists: choose another folder "
              "(nothing was changed)", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    CASES[case](files[0], 1)
    CASES[case](files[1], 2)
    print(f"wrote {files[0]} and {files[1]} ({case})")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
