"""Structured LM (paper 004, Algorithm 2) against SciPy's least_squares on the Lorenz problem.

For each N_d, the same residuals g(b), the same start: our LM serial (one segment) and with N_s
segments, and SciPy's TRF with the sparse Jacobian (lsmr). Times to reach a common cost (the best
of the final costs times 1 + 1e-6; a solver that does not reach it is marked), taken from the
clock at every residual evaluation of either solver, as ratios to SciPy measured in the same
run, plus the time of one linear step of each.

    python benchmarks/lm_scaling.py [--sizes 1000 10000 100000] [--json PATH]
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares
from scipy.sparse.linalg import lsmr

from lorenz import lorenz, rhs


def problem(n_d: int, seed: int = 0):
    from mcl.lm import IdentificationProblem, Measurements

    t_end = n_d * 1e-3
    t = np.round(np.arange(0, t_end + 1e-9, 0.01), 10)
    sol = solve_ivp(lorenz, (0, t_end), [-8.0, 7.0, 27.0], t_eval=t, rtol=1e-10, atol=1e-10)
    rng = np.random.default_rng(seed)
    y = sol.y + rng.normal(0, 0.1, sol.y.shape)
    meas = Measurements(t, y.T)
    return IdentificationProblem(rhs, lambda s, x: x, 3, 30, meas, dt=1e-3, Sx=np.sqrt(10.0), Sy=1.0,
                                 mu_x=1e-8, mu_a=1e-3)


class Clock:
    """prob.blocks with the time and cost of every evaluation recorded (both solvers use it)."""

    def __init__(self, prob):
        self.blocks, self.log = prob.blocks, []
        prob.blocks = self

    def __call__(self, X, a):
        b = self.blocks(X, a)
        self.log.append((time.perf_counter(), b.cost()))
        return b

    def start(self):
        self.log, self.t0 = [], time.perf_counter()

    def time_to(self, target):
        """Seconds from start until a residual evaluation first reached ``target`` (else total)."""
        hit = [t for t, c in self.log if c <= target]
        return (hit[0] if hit else self.log[-1][0]) - self.t0


def run_ours(prob, clock, segments, max_iter=100):
    from mcl.lm import levenberg_marquardt

    X0 = prob.initial_states()
    clock.start()
    res = levenberg_marquardt(prob, X0, np.zeros(30), segments=segments, max_iter=max_iter, rtol=1e-10)
    return res.cost, list(clock.log), clock.t0, res.iterations


def run_scipy(prob, clock):
    from mcl.lm import jacobian_matrix

    X0 = prob.initial_states()
    n = X0.size

    def split(b):
        return b[:n].reshape(X0.shape), b[n:]

    def fun(b):
        blk = prob.blocks(*split(b))
        return np.concatenate([blk.g.ravel(), blk.ga])

    def jac(b):
        return jacobian_matrix(prob.blocks(*split(b)))

    clock.start()
    res = least_squares(fun, np.concatenate([X0.ravel(), np.zeros(30)]), jac=jac, method="trf",
                        tr_solver="lsmr", x_scale="jac", max_nfev=200)
    return float(np.sum(res.fun**2)), list(clock.log), clock.t0, res.nfev


def step_times(prob, segments):
    from mcl.lm import jacobian_matrix, structured_step

    blk = prob.blocks(prob.initial_states(), np.zeros(30))
    t0 = time.perf_counter()
    structured_step(blk, 1e-2, 1)
    serial = time.perf_counter() - t0
    t0 = time.perf_counter()
    structured_step(blk, 1e-2, segments)
    par = time.perf_counter() - t0
    J = jacobian_matrix(blk)
    g = np.concatenate([blk.g.ravel(), blk.ga])
    t0 = time.perf_counter()
    lsmr(J, -g, damp=0.1)
    return serial, par, time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000, 100000])
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    rows = []
    cores = os.cpu_count() or 1
    for n_d in args.sizes:
        prob = problem(n_d)
        clock = Clock(prob)
        seg = max(1, int(np.sqrt(prob.N)))
        runs = {"ser": run_ours(prob, clock, 1), "par": run_ours(prob, clock, seg), "sci": run_scipy(prob, clock)}
        target = min(r[0] for r in runs.values()) * (1 + 1e-6)

        def time_to(key):
            clock.log, clock.t0 = runs[key][1], runs[key][2]
            return clock.time_to(target)

        (c_ser, _, _, it_ser), (c_par, _, _, it_par), (c_sci, _, _, nfev) = runs.values()
        t_ser, t_par, t_sci = time_to("ser"), time_to("par"), time_to("sci")
        prob.blocks = clock.blocks          # the step timings below without the clock
        s_ser, s_par, s_sci = step_times(prob, seg)
        row = {"N_d": prob.N, "structured_s": t_ser, "parallel_s": t_par, "segments": seg,
               "scipy_trf_s": t_sci, "final_cost": target,
               "reached": {"structured": c_ser <= target * 1.001, "parallel": c_par <= target * 1.001,
                           "scipy": c_sci <= target * 1.001},
               "step_s": {"structured": s_ser, "parallel": s_par, "scipy_lsmr": s_sci},
               "cores": cores}
        rows.append(row)
        print(f"N_d={prob.N:7d}: structured {t_ser:8.2f} s ({it_ser} it, cost {c_ser:.6g}), "
              f"{seg} segments {t_par:8.2f} s, SciPy TRF {t_sci:8.2f} s ({nfev} evals, cost {c_sci:.6g}); "
              f"ratio SciPy/segments = {t_sci / t_par:.1f}; linear step: {s_ser * 1e3:.0f} / "
              f"{s_par * 1e3:.0f} / {s_sci * 1e3:.0f} ms")
    if args.json:
        args.json.write_text(json.dumps({"rows": rows}, indent=1))


if __name__ == "__main__":
    main()
