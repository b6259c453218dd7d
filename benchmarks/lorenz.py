"""Paper 004, section VI-A: sparse identification of the Lorenz system.

(a) x1, x2 every 0.3 and x3 every 0.4 on [0, 4.8], noise variance 1, degree-2 polynomial model of
all three derivatives (30 parameters), W_x = 10 I, W_y = I, mu_x = 1e-8, mu_a = 1e-3, dt = 1e-3;
backward elimination stage-wise by degree. The paper's result, eq. (56), has 7 terms.
(b) only x1, x2 every 0.01 on [0, 5], variance 1e-4 (the paper's eq. (57) up to the change of
coordinates (58)).

    python benchmarks/lorenz.py [--json PATH] [--setting a|b|both] [--segments 16]
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import casadi as ca
import numpy as np
from scipy.integrate import solve_ivp

SIGMA, BETA, RHO = 10.0, 8.0 / 3.0, 28.0
MONOMIALS = ["1", "x1", "x2", "x3", "x1^2", "x1*x2", "x1*x3", "x2^2", "x2*x3", "x3^2"]
DEGREES = [0, 1, 1, 1, 2, 2, 2, 2, 2, 2]


def library(x):
    x1, x2, x3 = x[0], x[1], x[2]
    return ca.vertcat(1, x1, x2, x3, x1 * x1, x1 * x2, x1 * x3, x2 * x2, x2 * x3, x3 * x3)


def rhs(t, x, a):
    return ca.mtimes(ca.reshape(a, 10, 3).T, library(x))


def lorenz(t, x):
    return [SIGMA * (x[1] - x[0]), x[0] * (RHO - x[2]) - x[1], x[0] * x[1] - BETA * x[2]]


def data(setting: str, seed: int):
    from pipeline.lm import Measurements

    rng = np.random.default_rng(seed)
    if setting == "a":
        grids = {0: np.round(np.arange(0, 4.8 + 1e-9, 0.3), 10), 1: np.round(np.arange(0, 4.8 + 1e-9, 0.3), 10),
                 2: np.round(np.arange(0, 4.8 + 1e-9, 0.4), 10)}
        sd, t_end = 1.0, 4.8
    else:
        g = np.round(np.arange(0, 5 + 1e-9, 0.01), 10)
        grids, sd, t_end = {0: g, 1: g}, 1e-2, 5.0
    t_all = np.unique(np.concatenate(list(grids.values())))
    sol = solve_ivp(lorenz, (0, t_end), [-8.0, 7.0, 27.0], t_eval=t_all, rtol=1e-11, atol=1e-11)
    series = []
    for k, t in grids.items():
        series.append((t, sol.y[k][np.searchsorted(t_all, t)] + rng.normal(0, sd, len(t)), k))
    return Measurements.merge(series, 3), sol


def run(setting: str, segments: int, seed: int = 0) -> dict:
    from pipeline.lm import IdentificationProblem
    from pipeline.sparsify import BackwardElimination

    meas, _ = data(setting, seed)
    n_y = 3
    h = (lambda t, x: x) if setting == "a" else (lambda t, x: x)
    prob = IdentificationProblem(rhs, h, 3, 30, meas, dt=1e-3, Sx=np.sqrt(10.0), Sy=1.0,
                                 mu_x=1e-8, mu_a=1e-3)
    X0 = prob.initial_states()
    if setting == "b":   # x3 is never measured: start it at its mean level
        X0[:, 2] = 25.0
    names = [f"x{s + 1}:{m}" for s in range(3) for m in MONOMIALS]
    t0 = time.perf_counter()
    res = BackwardElimination("bic", segments=segments, lm_options={"max_iter": 150}).fit(
        prob, X0, np.zeros(30), names, DEGREES * 3)
    terms = {f"x{s + 1}": {} for s in range(3)}
    for name, value in res.terms().items():
        state, mono = name.split(":")
        terms[state][mono] = round(value, 4)
    return {"terms": terms, "seconds": time.perf_counter() - t0, "N_d": prob.N,
            "n_terms": int(res.active.sum()), "n_y": n_y}


def main(argv=None):
    ap = argparse.ArgumentParser(description="Paper 004, section VI-A (Lorenz)")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--setting", choices=["a", "b", "both"], default="both")
    ap.add_argument("--segments", type=int, default=16)
    args = ap.parse_args(argv)
    out = {}
    for s in (["a", "b"] if args.setting == "both" else [args.setting]):
        out[s] = run(s, args.segments)
        print(f"setting ({s}): {out[s]['n_terms']} terms in {out[s]['seconds']:.1f} s (N_d = {out[s]['N_d']})")
        for state, t in out[s]["terms"].items():
            print(f"  d{state}/dt = " + " + ".join(f"{v:g}*{m}" for m, v in t.items()))
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
