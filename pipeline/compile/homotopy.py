"""homotopy(actual, simplified): the model is the actual one; the simplified one says where an
algebraic loop's solution is sought at the start (Modelica's initialisation by homotopy).

The front end writes homotopy(a, s) as a + lambda (s - a), lambda a parameter named
:data:`NAME` of value 0. Before the structural analysis :func:`split` sets lambda to 0 (the
product folds away: the model's structure is the actual one's); the causalisation then starts
each loop that reads lambda where lambda, from 1 (simplified) to 0 (actual), leads Newton's
method (:func:`guess`). A Schmitt trigger whose amplifier is declared to start at its upper
limit starts there, not at the unstable solution between its limits, where a Newton method
from zeros lands and the oscillator never starts.
"""
from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np

from .dae import Dae
from .saved import SYMBOLS

NAME = "$homotopy"
SYMBOL = ca.SX.sym(NAME)
STEPS = 10              # lambda from 1 to 0 in this many steps
ITERATIONS = 30         # Newton steps at each (damped)
BLOCK_MAX = 100         # a larger loop keeps its start values
TOL = 1e-9


def homotopy(actual, simplified):
    return actual + SYMBOL * (simplified - actual)


def split(dae: Dae) -> tuple[Dae, tuple[ca.SX, ca.SX] | None]:
    """(``dae`` with lambda 0 everywhere, (its residual with lambda kept, lambda)); the second
    None where the model calls no homotopy."""
    if NAME not in dae.p_names:
        return dae, None
    lam = dae.p[dae.p_names.index(NAME)]
    where, exprs = [], []
    for f in dataclasses.fields(dae):
        value = getattr(dae, f.name)
        if f.name in SYMBOLS:        # (the symbols themselves stay)
            continue
        if isinstance(value, ca.SX):
            where.append((f.name, None))
            exprs.append(value)
        elif isinstance(value, dict) and any(isinstance(v, ca.SX) for v in value.values()):
            for k, v in value.items():
                where.append((f.name, k))
                exprs.append(ca.SX(v))
    off = ca.substitute(exprs, [lam], [ca.SX(0)])      # (jointly: shared subexpressions once)
    changes: dict = {}
    for (name, key), e in zip(where, off):
        if key is None:
            changes[name] = e
        else:
            changes.setdefault(name, dict(getattr(dae, name)))[key] = e
    return dataclasses.replace(dae, **changes), (dae.residual, lam)


def guess(rows: ca.SX, lam: ca.SX, unknowns: ca.SX, par: ca.SX, par0: np.ndarray,
          start: np.ndarray) -> np.ndarray | None:
    """A loop's unknowns where 0 = ``rows`` (which read ``lam``) is solved from lambda = 1 to 0,
    each step's Newton method from the last one's solution and the first from ``start``;
    ``par`` at ``par0``. None where a step does not converge (the start values then stay)."""
    if unknowns.numel() > BLOCK_MAX:
        return None
    s = ca.SX.sym("lambda")
    r = ca.substitute(rows, lam, s)
    fun = ca.Function("homotopy", [unknowns, par, s], [r, ca.jacobian(r, unknowns)])
    z = np.array(start, float)
    try:
        for level in np.linspace(1.0, 0.0, STEPS + 1):
            z = _newton(lambda v: [np.array(a, float) for a in fun(v, par0, level)], z)
            if z is None:
                return None
    except RuntimeError:
        return None
    return z


def _newton(f, z: np.ndarray) -> np.ndarray | None:
    """Newton's method with step halving from ``z``; None where it does not converge."""
    r, J = f(z)
    r = r.ravel()
    for _ in range(ITERATIONS):
        if not np.all(np.isfinite(r)) or not np.all(np.isfinite(J)):
            return None
        if np.abs(r).max(initial=0.0) <= TOL * (1 + np.abs(z).max(initial=0.0)):
            return z
        dz = np.linalg.lstsq(J, -r, rcond=None)[0]
        step = 1.0
        while step > 1e-4:
            r1, J1 = f(z + step * dz)
            r1 = r1.ravel()
            if np.all(np.isfinite(r1)) and np.linalg.norm(r1) < np.linalg.norm(r):
                break
            step /= 2
        else:
            return None
        z, r, J = z + step * dz, r1, J1
    return z if np.abs(r).max(initial=0.0) <= 1e3 * TOL * (1 + np.abs(z).max(initial=0.0)) else None
