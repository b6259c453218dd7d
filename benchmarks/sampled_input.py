"""CPU seconds of runs on a finely sampled record: the in-process engine's choice of method
(Adams' methods where the model is not stiff at the output spacing) against BDF alone, the
baseline, measured in the same run on the same model and data.

The model is a Wiener-Hammerstein chain as in the WH2009 benchmark (two third-order filters
with poles near 4.4 kHz around a static nonlinearity), driven by a random input sampled at
51.2 kHz, as that benchmark is; runs with and without forward sensitivities (a fit's runs).

    python benchmarks/sampled_input.py [--samples 8192] [--repeat 3]
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

MODEL = """
model Chain "filter, diode-like clamp, filter (the WH2009 circuit's structure), states scaled"
  input Real u;
  parameter Real a1[3] = {3.46380513e4, 1.17312392e9, 1.51225449e13};
  parameter Real a2[3] = {2.11931062e4, 2.24129699e8, 1.24031308e12};
  parameter Real k = 1;
  parameter Real wc = 2.76e4 "the filters' corner (rad/s): the states' scale";
  Real v(start = 0, fixed = true), v1(start = 0, fixed = true), v2(start = 0, fixed = true);
  output Real y(start = 0, fixed = true);
  Real y1(start = 0, fixed = true), y2(start = 0, fixed = true);
  Real w = k*v - 0.8*max(v - 0.56, 0)*tanh(10*v) "the clamp";
equation
  der(v) = wc*v1;
  der(v1) = wc*v2;
  der(v2) = (a1[3]*(u - v) - a1[2]*wc*v1 - a1[1]*wc^2*v2)/wc^2;
  der(y) = wc*y1;
  der(y1) = wc*y2;
  der(y2) = (a2[3]*(w - y) - a2[2]*wc*y1 - a2[1]*wc^2*y2)/wc^2;
end Chain;
"""


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=int, default=8192)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)

    import mcl.engine_casadi as engine
    from mcl import compile_model, simulate
    from mcl.data import TimeSeries
    from mcl.fit import FitProblem

    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "Chain.mo").write_text(MODEL)
        model = compile_model([Path(tmp) / "Chain.mo"], "Chain", libraries=[])
    rng = np.random.default_rng(0)
    t = np.arange(args.samples) / 51200.0
    u = rng.standard_normal(len(t)) * 0.3
    y = simulate(model, TimeSeries(t, u[:, None], ["u"])).output("y")     # (the fit's residual: any data)
    data = TimeSeries(t, np.column_stack([u, y]), ["u", "y"])
    free = ["a1[1]", "a2[1]", "k"]
    problem = FitProblem(model, data, free, fixed={n: v for n, v in model.parameters.items() if n not in free},
                         options={"rtol": 1e-5, "atol": 1e-7})
    runs = {"run": lambda: simulate(model, data, options={"rtol": 1e-5, "atol": 1e-7}),
            "run with sensitivities (3)": lambda: problem.simulate([model.parameters[n] for n in free], gradient=True)}
    chosen = engine.ADAMS_REACH
    print(f"{args.samples} samples at 51.2 kHz, CPU seconds (median of {args.repeat}):")
    print(f"{'':30s} {'BDF (baseline)':>15s} {'chosen':>10s} {'ratio':>7s} {'steps BDF / chosen':>20s}")
    for label, run in runs.items():
        out = {}
        for reach in (0.0, chosen):            # (0: no model qualifies, BDF alone)
            engine.ADAMS_REACH = reach
            seconds, res = [], None
            for _ in range(args.repeat):
                c0 = time.process_time()
                res = run()
                seconds.append(time.process_time() - c0)
            out[reach] = (statistics.median(seconds), res)
        engine.ADAMS_REACH = chosen
        (b, rb), (a, ra) = out[0.0], out[chosen]
        assert rb.ok and ra.ok, (rb.reason, ra.reason)
        diff = float(np.max(np.abs(rb.outputs - ra.outputs)) / max(np.ptp(rb.outputs), 1e-300))
        print(f"{label:30s} {b:15.2f} {a:10.2f} {b / a:7.2f} {rb.steps:>10d} / {ra.steps:<8d}"
              f" ({ra.method}; outputs within {diff:.1e} of their range)")


if __name__ == "__main__":
    main()
