"""Measurements of the 'real' Cauer filter (paper 000, sec. V), made without mcl's simulator.

The real nonlinear resistor conducts i = 0.01 v^3; the model in MCL.Examples.CauerFilterNominal
believes it is a linear 20 ohm resistor. The filter is integrated here from its hand-derived
equations (node voltages, capacitor loops eliminated by hand) with SciPy; the source is
band-limited white noise; the voltage across R4 is measured with 1 % noise.
Writes train.csv (seed 0) and validate.csv (seed 1).
"""
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from make_input import band_limited_noise

L1, L2, C1, C3, C5 = 1.304, 0.8586, 1.072, 1.682, 0.7262
C2, C4 = 1 / (1.704992**2 * L1), 1 / (1.179945**2 * L2)
M = np.array([[C1 + C2, -C2, 0], [-C2, C2 + C3 + C4, -C4], [0, -C4, C4 + C5]])


def resistor_current(e3, R4=1.0):
    """i through the nonlinear resistor in series with R4: i = 0.01 (e3 - R4 i)^3."""
    bound = abs(e3) / R4 + 1.0
    return brentq(lambda i: i - 0.01 * (e3 - R4 * i) ** 3, -bound, bound, xtol=1e-14)


def measure(seed: int, t_end: float = 100.0, dt: float = 0.05, rms: float = 1.5):
    t = np.round(np.arange(0, t_end + 1e-9, dt), 10)
    u_s = band_limited_noise(t, rms=rms, seed=seed)
    u = lambda s: np.interp(s, t, u_s)

    def rhs(s, x):
        e1, e2, e3, i1, i2 = x
        de = np.linalg.solve(M, [(u(s) - e1) / 1.0 - i1, i1 - i2, i2 - resistor_current(e3)])
        return [*de, (e1 - e2) / L1, (e2 - e3) / L2]

    sol = solve_ivp(rhs, (0, t_end), np.zeros(5), t_eval=t, rtol=1e-9, atol=1e-11, max_step=dt)
    y = np.array([resistor_current(e3) for e3 in sol.y[2]])
    y = y + np.random.default_rng(100 + seed).normal(0, 0.01 * np.std(y), len(y))
    return t, u_s, y


if __name__ == "__main__":
    here = Path(__file__).parent
    for name, seed in (("train", 0), ("validate", 1)):
        t, u, y = measure(seed)
        np.savetxt(here / f"{name}.csv", np.column_stack([t, u, y]), delimiter=",",
                   header="time,u,y", comments="", fmt="%.10g")
        print(f"wrote {here / name}.csv")
