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
    from mcl.lm import Measurements

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


TRUE_A = {"x1": {"x1", "x2"}, "x2": {"x1", "x2", "x1*x3"}, "x3": {"x3", "x1*x2"}}          # eq. (55)
FORM_B = {"x1": {"x1", "x2"}, "x2": {"x2", "x1*x3"}, "x3": {"1", "x3", "x1*x2"}}          # eq. (57)


def structure(terms) -> dict:
    return {s: set(t) for s, t in terms.items()}


def check_a(terms) -> dict:
    return {"structure_of_eq56": structure(terms) == TRUE_A}


def check_b(terms, x3_hat, x3_true) -> dict:
    """Eq. (57) read through the change of coordinates (58), x3~ = gamma (rho - x3): then
    dx2 = (1/gamma) x1 x3~ - x2 and dx3~ = beta gamma rho - beta x3~ - gamma x1 x2 (eq. 59)."""
    out = {"structure_of_eq57": structure(terms) == FORM_B}
    if not out["structure_of_eq57"]:
        return out
    gamma = -terms["x3"]["x1*x2"]
    beta = -terms["x3"]["x3"]
    rho = terms["x3"]["1"] / (beta * gamma)
    mapped = gamma * (RHO - x3_true)                     # the true x3 in the identified coordinates
    out.update(gamma=gamma, beta=beta, rho=rho, sigma=terms["x1"]["x2"],
               gamma_times_x1x3_coefficient=gamma * terms["x2"]["x1*x3"],
               x3_relative_rms=float(np.sqrt(np.mean((x3_hat - mapped) ** 2)) / np.std(mapped)))
    return out


def run(setting: str, segments: int, seed: int = 0, criterion: str | None = None, exchange: bool = True) -> dict:
    from mcl.lm import IdentificationProblem
    from mcl.sparsify import BackwardElimination, log_step

    meas, sol = data(setting, seed)
    # the paper's weights in both settings. In (a) W_y = I is the noise covariance, so the cost is
    # -2 log L and BIC counts in its units. In (b) (variance 1e-4) the cost is mostly
    # mu_a ||a||^2, not a likelihood: the paper's simplest rule, a cost limit 10 % above the dense
    # model's, decides. x3 of (b) is simply never measured (NaN).
    criterion = criterion or ("bic" if setting == "a" else "threshold")
    prob = IdentificationProblem(rhs, lambda t, x: x, 3, 30, meas, dt=1e-3, Sx=np.sqrt(10.0), Sy=1.0,
                                 mu_x=1e-8, mu_a=1e-3)
    X0 = prob.initial_states()
    if setting == "b":
        # x3 is never measured: start it at zero. Every affine image of x3 gives an equivalent
        # model; mu_a ||a||^2 picks the one with the smallest coefficients (gamma ~ 0.07 in the
        # paper's eq. 57). Started at x3's mean level instead, LM ends in a worse local minimum.
        X0[:, 2] = 0.0
    names = [f"x{s + 1}:{m}" for s in range(3) for m in MONOMIALS]
    t0 = time.perf_counter()
    res = BackwardElimination(criterion, threshold=0.1, segments=segments, exchange=exchange, on_step=log_step,
                              lm_options={"max_iter": 300, "rtol": 1e-10}).fit(
        prob, X0, np.zeros(30), names, DEGREES * 3)
    terms = {f"x{s + 1}": {} for s in range(3)}
    for name, value in res.terms().items():
        state, mono = name.split(":")
        terms[state][mono] = round(value, 4)
    x3_hat = res.X[prob.j_meas, 2]
    check = check_a(terms) if setting == "a" else check_b(terms, x3_hat, sol.y[2])
    return {"terms": terms, "seconds": time.perf_counter() - t0, "N_d": prob.N, "check": check,
            "n_terms": int(res.active.sum()), "criterion": criterion, "exchange": exchange,
            "law": res.equation(),
            "path": [{"removed": s.removed, "cost": s.cost, "score": s.criterion, "accepted": s.accepted}
                     for s in res.path]}


def main(argv=None):
    ap = argparse.ArgumentParser(description="Paper 004, section VI-A (Lorenz)")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--setting", choices=["a", "b", "both"], default="both")
    ap.add_argument("--segments", type=int, default=16)
    ap.add_argument("--criterion", choices=["aic", "bic", "threshold"],
                    help="default: bic in (a), threshold (10 %%) in (b)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--seeds", type=int, default=1, help="repeat with this many noise draws and summarise")
    ap.add_argument("--no-exchange", action="store_true", help="the paper's greedy elimination only")
    args = ap.parse_args(argv)
    out = {}
    for s in (["a", "b"] if args.setting == "both" else [args.setting]):
        runs = []
        for seed in range(args.seed, args.seed + args.seeds):
            r = run(s, args.segments, seed, args.criterion, not args.no_exchange)
            print(f"setting ({s}), noise draw {seed}: {r['n_terms']} terms in {r['seconds']:.1f} s (N_d = {r['N_d']})")
            print("  " + r["law"].replace("\n", "\n  "))
            print(f"  check: {r['check']}")
            runs.append(dict(r, seed=seed))
        out[s] = runs[0]
        if len(runs) > 1:
            key = "structure_of_eq56" if s == "a" else "structure_of_eq57"
            out[f"{s}_seeds"] = {"runs": [{k: r[k] for k in ("seed", "terms", "n_terms", "check")} for r in runs],
                                 "found": sum(bool(r["check"][key]) for r in runs), "of": len(runs)}
            print(f"setting ({s}): the paper's structure in {out[f'{s}_seeds']['found']} of {len(runs)} noise draws")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    import logging

    logging.basicConfig(level=logging.INFO, format="%(message)s")
    main()
