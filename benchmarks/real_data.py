"""Baselines on real measured benchmarks (examples/real), each on the benchmark's own split.

For each case and test split: the simulation RMS error of the engineer's nominal Modelica model as
written and with its parameters fitted by least squares (mcl simulations with sensitivities), of
a linear output-error model and of a polynomial NARX run free on the test input (their orders
chosen on the last 20 % of the training split, the test splits unseen), and the columns
"mcl law alone" and "mcl law + joint refit" that :func:`mcl_discovery` fills once discovery can
run on a case (the case's model from parts, trained on the training split alone; n/a for a
case without one). Every Modelica model starts each test split from the initial state fitted on
the split's first ``window`` samples (the benchmark's protocol). Each method's CPU seconds are
printed; the results go to benchmarks/results/real_data.json.

The data are the benchmarks' own files split by examples/real/prepare.py; they are looked up in
$MCL_REAL_DATA, then ../shared/real beside the checkout (a case whose files are missing is
skipped with a note). The MSL is found through MODELICAPATH or ../shared/msl.

    python benchmarks/real_data.py [--cases cascaded_tanks,silverbox] [--json PATH]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass
from itertools import combinations_with_replacement
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples" / "real"


@dataclass(frozen=True)
class Case:
    """A real benchmark: its nominal model, the nominal's free parameters (start values as
    written), its initial-state parameters, and the benchmark's protocol."""

    name: str
    source: Path
    model: str
    free: dict                       # positive physical parameters fitted on the training data
    states: dict                     # initial-state parameters, fitted on each split's first samples
    state_scale: dict                # their typical size (the least-squares step scale)
    window: int                      # first samples of a split not counted (the benchmark's state initialisation)
    tests: tuple
    unit: tuple = (1.0, "")          # (factor, label) for the table
    train_samples: int | None = None # samples of the training split used by the Modelica fits (time)
    direct: bool = False             # the input acts within a sample (input lags from 0, not 1)
    good: str = ""                   # the literature's good-model range on the test split
    initial: callable = None         # initial-state parameters from a split's first measured output
    parts: tuple | None = None       # (source, model, initial) of the model from parts discovery runs on


def _tanks_initial(y0: float) -> dict:
    h2 = y0 / 40.0                   # ks = 40 V/m; tank 1 at the level that holds tank 2 steady
    return {"h1_0": h2, "h2_0": h2}


def _tank_parts_initial(y0: float, params: dict) -> dict:
    h2 = y0 / params.get("sensor.ks", 40.0)
    return {"tank1.h_start": h2, "tank2.h_start": h2}


def _silverbox_initial(y0: float) -> dict:
    return {"s0": y0 / 1000.0, "v0": 0.0}


def _silverbox_parts_initial(y0: float, params: dict) -> dict:
    return {"s0": y0 / params.get("ks", 1000.0), "v0": 0.0}


def _emps_initial(y0: float) -> dict:
    return {"s0": y0, "v0": 0.0}


CASES = {
    "cascaded_tanks": Case(
        "cascaded_tanks", EXAMPLES / "cascaded_tanks" / "CascadedTanks.mo", "CascadedTanks.Tanks",
        free={"kp": 4.5e-6, "R1": 2e4, "R2": 2e4, "h_op": 0.1}, states={"h1_0": 0.13, "h2_0": 0.13},
        state_scale={"h1_0": 0.05, "h2_0": 0.05}, window=5, tests=("test.csv",), unit=(1.0, "V"),
        good="0.34-0.45 V, linear 0.76 V (examples/real/cascaded_tanks/README.md)",
        initial=_tanks_initial,
        parts=(EXAMPLES / "cascaded_tanks" / "CascadedTanksParts.mo", "CascadedTanksParts.Cascade",
               _tank_parts_initial)),
    "silverbox": Case(
        "silverbox", EXAMPLES / "silverbox" / "Silverbox.mo", "Silverbox.Oscillator",
        free={"kf": 150.0, "S.c": 2e5, "D.d": 40.0}, states={"s0": 0.0, "v0": 0.0},
        state_scale={"s0": 5e-5, "v0": 0.02}, window=50, tests=("test_multisine.csv", "test_arrow.csv"),
        unit=(1e3, "mV"), train_samples=16384, direct=True,
        good="0.3-1.5 mV on the arrow, linear 13.5 mV (examples/real/silverbox/README.md)",
        initial=_silverbox_initial,
        parts=(EXAMPLES / "silverbox" / "Silverbox.mo", "Silverbox.Oscillator", _silverbox_parts_initial)),
    "emps": Case(
        "emps", EXAMPLES / "emps" / "Emps.mo", "Emps.Axis",
        free={"M.m": 100.0, "F.d": 200.0}, states={"s0": 0.0, "v0": 0.0},
        state_scale={"s0": 1e-3, "v0": 1e-3}, window=20, tests=("test.csv",), unit=(1e3, "mm"),
        train_samples=None, good="see examples/real/emps/README.md", initial=_emps_initial,
        parts=(EXAMPLES / "emps" / "Emps.mo", "Emps.Axis", lambda y0, params: _emps_initial(y0))),
}


def data_root() -> Path | None:
    for root in (os.environ.get("MCL_REAL_DATA"), ROOT.parent / "shared" / "real"):
        if root and Path(root).is_dir():
            return Path(root)
    return None


def msl_path() -> list[Path]:
    if os.environ.get("MODELICAPATH"):
        return []
    msl = ROOT.parent / "shared" / "msl"
    return [msl] if msl.is_dir() else []


def load(case: Case, root: Path, file: str):
    """time, u, y of one split."""
    d = np.loadtxt(root / case.name / file, delimiter=",", skiprows=1)
    return d[:, 0], d[:, 1], d[:, 2]


def rms(e) -> float:
    e = np.asarray(e, float)
    return float(np.sqrt(np.mean(e[np.isfinite(e)] ** 2))) if np.isfinite(e).any() else float("nan")


# -- the nominal Modelica model, simulated by mcl ---------------------------------------------------

class Nominal:
    """The nominal model compiled once (or a given model: discovery's extended one); simulations
    of a split with given parameters, and a least-squares fit of chosen parameters (positive ones
    in log scale) with mcl's sensitivities."""

    def __init__(self, case: Case, model=None):
        import mcl

        self.case = case
        self.model = model or mcl.compile_model([case.source], case.model, libraries=msl_path())

    def series(self, t, u, y):
        from mcl.data import TimeSeries

        return TimeSeries(t, np.column_stack([u, y]), ["u", "y"], source=self.case.name)

    def simulate(self, data, params: dict, gradient=None):
        import mcl

        res = mcl.simulate(self.model, data.select(["u"]), params, t_out=data.time, sensitivities=gradient)
        return res

    def fit(self, data, params: dict, names: list[str], max_nfev: int = 30) -> dict:
        """Least squares of the output error over ``names`` starting from ``params``."""
        from scipy.optimize import least_squares

        y = data.column("y")
        positive = [n in self.case.free for n in names]
        p0 = np.array([params[n] for n in names], float)
        scale = np.array([abs(params[n]) if pos else self.state_scale(n, params[n]) for n, pos in zip(names, positive)])

        def unpack(th):
            return {**params, **{n: (p0[k] * np.exp(th[k]) if positive[k] else p0[k] + scale[k] * th[k])
                                 for k, n in enumerate(names)}}

        cache = {}

        def run(th):
            key = th.tobytes()
            if key not in cache:
                cache.clear()
                res = self.simulate(data, unpack(th), gradient=names)
                cache[key] = res
            return cache[key]

        def fun(th):
            res = run(th)
            if not res.ok:
                return np.full(len(y), 1e3 * (np.std(y) + 1))
            return res.outputs[:, 0] - y

        def jac(th):
            res = run(th)
            if not res.ok:
                return np.zeros((len(y), len(names)))
            p = unpack(th)
            dp = np.array([p[n] if pos else s for n, pos, s in zip(names, positive, scale)])
            return res.sensitivities[:, 0, :] * dp

        sol = least_squares(fun, np.zeros(len(names)), jac=jac, method="lm", max_nfev=max_nfev)
        return unpack(sol.x)

    def state_scale(self, name: str, value: float) -> float:
        """An initial-state parameter's step scale: the case's, else a third of its value."""
        return self.case.state_scale.get(name) or max(abs(value) / 3.0, 1e-3)

    def test_error(self, params: dict, t, u, y, initial=None) -> float:
        """RMS on a split after fitting its initial state (``initial(y0)``: the parameters
        that set it and their first guess from the first output; the case's by default) on the
        first ``window`` samples."""
        data = self.series(t, u, y)
        guess = (initial or self.case.initial)(y[0])
        start = {**params, **guess}
        head = self.series(t[: max(self.case.window, 4)], u[: max(self.case.window, 4)], y[: max(self.case.window, 4)])
        start = self.fit(head, start, list(guess), max_nfev=20)
        res = self.simulate(data, start)
        return rms((res.outputs[:, 0] - y)[self.case.window:]) if res.ok else float("nan")


# -- black-box baselines ---------------------------------------------------------------------------

def regressors(u, y, na: int, nb: int):
    """Rows [y_{k-1..k-na}, u_{k-1..k-nb}] for k >= max(na, nb)."""
    n0 = max(na, nb)
    cols = [y[n0 - i: len(y) - i] for i in range(1, na + 1)] + [u[n0 - j: len(u) - j] for j in range(1, nb + 1)]
    return np.column_stack(cols), y[n0:]


def monomial_index(width: int, degree: int) -> np.ndarray:
    """Index rows into [1, x_1 .. x_width]: one row per monomial of degree <= ``degree`` (the
    constant first), padded with 0 (the 1) so that a product along a row is the monomial."""
    rows = [c + (0,) * (degree - len(c)) for d in range(degree + 1)
            for c in combinations_with_replacement(range(1, width + 1), d)]
    return np.array(rows, dtype=int).reshape(len(rows), degree)


def monomials(X, degree: int):
    """1 and every product of up to ``degree`` columns of X."""
    ext = np.column_stack([np.ones(len(X)), X])
    return np.prod(ext[:, monomial_index(X.shape[1], degree)], axis=2)


def free_run(theta, u, y_init, na: int, nb: int, degree: int):
    """Simulate a NARX (degree 1: ARX) on input u from the measured first samples y_init;
    NaN from where it diverges."""
    idx = monomial_index(na + nb, degree)
    y = np.empty(len(u))
    y[: len(y_init)] = y_init
    bound = 1e3 * (np.max(np.abs(y_init)) + 1.0)
    ext = np.ones(na + nb + 1)
    for k in range(len(y_init), len(u)):
        ext[1: na + 1] = y[k - na: k][::-1]
        ext[na + 1:] = u[k - nb: k][::-1]
        y[k] = float(np.prod(ext[idx], axis=1) @ theta)
        if not abs(y[k]) <= bound:
            y[k:] = np.nan
            break
    return y


def narx(u, y, na: int, nb: int, degree: int, ridge: float = 1e-8):
    """One-step least squares of a polynomial NARX (standardised regressors, a little ridge)."""
    X, target = regressors(u, y, na, nb)
    Phi = monomials(X, degree)
    s = np.std(Phi, axis=0)
    s[s == 0] = 1.0
    A = Phi / s
    theta = np.linalg.solve(A.T @ A + ridge * len(A) * np.eye(A.shape[1]), A.T @ target)
    return theta / s


def output_error(u, y, na: int, nb: int):
    """A linear output-error model: the ARX fit refined on the simulation error (scipy)."""
    from scipy.optimize import least_squares
    from scipy.signal import lfilter, lfiltic

    theta0 = narx(u, y, na, nb, 1, ridge=0.0)

    def sim(th, uu, y_init):
        c, a, b = th[0], th[1: na + 1], th[na + 1:]
        den = np.concatenate([[1.0], -a])
        num = np.concatenate([[0.0], b])
        # y = c / (1 - sum a) + G(q) u, started from the measured first samples
        ss = c / den.sum()
        zi = lfiltic(num, den, (y_init[::-1] - ss), uu[: len(y_init)][::-1])
        return lfilter(num, den, uu[len(y_init):], zi=zi)[0] + ss

    n0 = max(na, nb)
    sol = least_squares(lambda th: sim(th, u, y[:n0]) - y[n0:], theta0, method="lm", max_nfev=200)
    return lambda uu, y_init: np.concatenate([y_init, sim(sol.x, uu, y_init)])


def lead(u, direct: bool):
    """The input seen by the regressors: advanced one sample when it acts within a sample, so
    that input lag 1 is u_k."""
    return np.concatenate([u[1:], u[-1:]]) if direct else u


def select_orders(u, y, fit_and_run, grid, window: int):
    """The orders of ``grid`` whose model, fitted on the first 80 % of the training split, runs
    best on its last 20 % (the test splits are not looked at)."""
    cut = int(0.8 * len(u))
    best, err = None, np.inf
    for orders in grid:
        e = rms(fit_and_run(u[:cut], y[:cut], u[cut:], y[cut:], *orders)[window:] - y[cut:][window:])
        if np.isfinite(e) and e < err:
            best, err = orders, e
    return best, err


# -- the discovery columns -------------------------------------------------------------------------

def mcl_discovery(case: Case, train, tests: dict, written: str = "parts") -> dict | None:
    """mcl's discovery on ``case`` (its model from parts; with ``written="equations"`` the nominal
    model as equations; trained on the training split only, the test splits unseen): {"law":
    {test: rms}, "joint": {test: rms}, "cpu_s", "cause"} for the learned law alone and for the
    law refitted with the nominal parameters (``free: auto``); None for a case without a model
    from parts (the columns print n/a). ``train`` and each of ``tests`` are (time, u, y) of a
    split."""
    if case.parts is None:
        return None
    import tempfile

    from mcl import Discovery
    from mcl.compile.isolation import cpu_seconds

    source, model, initial = case.parts
    if written == "equations":
        source, model, initial = case.source, case.model, lambda y0, _params: case.initial(y0)
    t, u, y = train
    c0, w0 = cpu_seconds(), time.perf_counter()    # the workers' CPU too
    with tempfile.TemporaryDirectory() as tmp:
        # the whole training split: a long record is searched on its head by mcl itself
        d = Discovery(model, sources=[source], free="auto", libraries=msl_path(), output=Path(tmp) / "run",
                      verbose=False).fit({"time": t, "u": u, "y": y})
        extended = d.extended_model()
        cal = d.report_.get("calibration") or {}
        joint = {**{k: v["after"] for k, v in (cal.get("values") or {}).items()}, **(cal.get("laws") or {})}
        out = {"law": {}, "joint": {}, "cause": d.cause_["effect"] if d.cause_ else None,
               # the written model against the one fitted in process (the table measures the written one)
               "recompiled_difference": (d.report_.get("extended") or {}).get("recompiled_difference")}
        model = Nominal(case, extended)     # each split's initial state fitted on its window, as for the nominal
        for key, params in (("law", {}), ("joint", joint)):
            for name, (tt, uu, yy) in tests.items():
                error = model.test_error(params, tt, uu, yy, initial=lambda y0: initial(y0, params))
                out[key][name] = error if np.isfinite(error) else float("inf")
    out["cpu_s"], out["wall_s"] = cpu_seconds() - c0, time.perf_counter() - w0
    return out


# -- the table ------------------------------------------------------------------------------------

def run_case(case: Case, root: Path) -> dict:
    t, u, y = load(case, root, "train.csv")
    tests = {name: load(case, root, name) for name in case.tests}
    out = {"good_models": case.good, "unit": case.unit[1], "window": case.window, "methods": {}}
    cut = slice(0, case.train_samples)
    t_fit, u_fit, y_fit = t[cut], u[cut], y[cut]
    out["train_samples"] = {"all": len(t), "modelica_fits": len(t_fit)}

    def record(method, errors, cpu, **extra):
        out["methods"][method] = {"test_rms": errors, "cpu_s": round(cpu, 3), **extra}

    from mcl.compile.isolation import cpu_seconds

    c0 = cpu_seconds()
    nominal = Nominal(case)
    compile_s = cpu_seconds() - c0
    as_written = {**case.free, **case.states}
    c0 = time.process_time()
    train = nominal.series(t_fit, u_fit, y_fit)
    start = {**as_written, **case.initial(y_fit[0])}
    res = nominal.simulate(train, start)
    errors = {name: nominal.test_error(as_written, *split) for name, split in tests.items()}
    record("nominal as written", errors, time.process_time() - c0,
           train_rms=rms(res.outputs[:, 0] - y_fit) if res.ok else None, compile_cpu_s=round(compile_s, 3))
    c0 = time.process_time()
    fitted = nominal.fit(train, start, list(case.free) + list(case.states))
    res = nominal.simulate(train, fitted)
    errors = {name: nominal.test_error({k: fitted[k] for k in case.free}, *split) for name, split in tests.items()}
    record("nominal fitted (LS)", errors, time.process_time() - c0,
           train_rms=rms(res.outputs[:, 0] - y_fit) if res.ok else None,
           parameters={k: float(fitted[k]) for k in case.free})

    c0 = time.process_time()
    v = lead(u, case.direct)

    def oe_run(ut, yt, uv, yv, na, nb):
        n0 = max(na, nb, case.window)
        return output_error(lead(ut, case.direct), yt, na, nb)(lead(uv, case.direct), yv[:n0])

    (na, nb), val = select_orders(u, y, oe_run, [(k, k) for k in (1, 2, 3, 4)], case.window)
    oe = output_error(v, y, na, nb)
    n0 = max(na, nb, case.window)
    errors = {name: rms((oe(lead(uu, case.direct), yy[:n0]) - yy)[case.window:])
              for name, (tt, uu, yy) in tests.items()}
    record(f"linear OE({na},{nb})", errors, time.process_time() - c0, validation_rms=val)

    def narx_run(ut, yt, uv, yv, na, nb, degree):
        theta = narx(lead(ut, case.direct), yt, na, nb, degree)
        return free_run(theta, lead(uv, case.direct), yv[:max(na, nb, case.window)], na, nb, degree)

    c0 = time.process_time()
    grid = [(a, b, d) for d in (2, 3) for a in (1, 2, 3, 4) for b in (a, a + 1)]
    (na, nb, degree), val = select_orders(u, y, narx_run, grid, case.window)
    theta = narx(v, y, na, nb, degree)
    n0 = max(na, nb, case.window)
    errors = {name: rms((free_run(theta, lead(uu, case.direct), yy[:n0], na, nb, degree) - yy)[case.window:])
              for name, (tt, uu, yy) in tests.items()}
    record(f"poly NARX({na},{nb}) deg {degree}", errors, time.process_time() - c0, terms=len(theta),
           validation_rms=val)

    found = mcl_discovery(case, (t, u, y), tests)
    if found and found.get("cause"):
        out["mcl_cause"] = found["cause"]
    for key, label in (("law", "mcl law alone"), ("joint", "mcl law + joint refit")):
        record(label, found[key] if found else {name: None for name in tests},
               found.get("cpu_s", 0.0) if found else 0.0, **({"wall_s": round(found["wall_s"], 1)} if found else {}))
    return out


def _cell(v, factor: float) -> str:
    return "n/a" if v is None else "diverged" if not np.isfinite(v) else f"{v * factor:.4g}"


def table(results: dict) -> str:
    lines = []
    for name, r in results.items():
        factor, unit = CASES[name].unit[0], r["unit"]
        tests = list(next(iter(r["methods"].values()))["test_rms"])
        head = f"{name} (simulation RMS on the test splits in {unit}; good models: {r['good_models']})"
        lines += [head, f"  {'method':32s}" + "".join(f"{t:>20s}" for t in tests) + f"{'CPU s':>10s}"]
        for method, m in r["methods"].items():
            cells = "".join(f"{_cell(v, factor):>20s}" for v in m["test_rms"].values())
            lines.append(f"  {method:32s}{cells}{m['cpu_s']:>10.2f}")
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "real_data.json"))
    args = ap.parse_args(argv)
    root = data_root()
    if root is None:
        print("real benchmark data not found: set MCL_REAL_DATA or place them in ../shared/real "
              "(examples/real/prepare.py makes them from the benchmarks' files); nothing run")
        return 0
    out = Path(args.json)
    results = json.loads(out.read_text()) if out.exists() else {}     # other cases' rows are kept
    for name in args.cases.split(","):
        case = CASES[name]
        if not (root / name / "train.csv").exists():
            print(f"{name}: skipped (no {root / name / 'train.csv'})")
            continue
        results[name] = run_case(case, root)
        print(table({name: results[name]}), flush=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=1, default=float) + "\n")
    print(f"results -> {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
