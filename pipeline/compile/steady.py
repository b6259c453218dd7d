"""Steady initial states by pseudo-transient continuation.

A steady initial system (``der(x) = 0``: Modelica.Fluid's ``SteadyStateInitial``) solved by
Newton's method from the start values may have no step to take. Water at rest in every pipe
(all pressures at one start value) leaves the energy balances' Jacobian singular, since no
flow carries heat. The model's own dynamics do move it: implicit Euler steps, each h longer
than the last, walk from the start values towards the steady state. Each step's system is
regular for a small h (its 1/h term) and becomes the steady one as h grows (the step lengths
follow the residual's fall: switched evolution relaxation, Mulder and van Leer 1985).
"""
from __future__ import annotations

import logging
import time

import numpy as np

from . import homotopy

log = logging.getLogger(__name__)

H0 = 1e-3             # the first step's length, in the model's time unit
H_MIN = 1e-12         # a step that does not converge is shortened, at most down to this
H_MAX = 1e12          # ... and the walk ends when the steps are this long
GROWTH = (2.0, 100.0)  # each step at least 2x, at most 100x the last
MAX_STEPS = 200
ITERATIONS = 30       # Newton steps at each, with step halving
CPU_LIMIT = 30.0      # seconds: a walk that cannot finish in this is no help to a compile


def walk(step, steady, x0: np.ndarray, tol: float) -> np.ndarray | None:
    """The end of the walk from ``x0``: ``step(x, x_prev, 1/h)`` gives (residual, Jacobian in
    x) of the square system of one implicit Euler step; ``steady(x)`` the largest residual of
    the steady system. None where no step converges or the walk leaves the steady residual no
    smaller than at ``x0``."""
    clock = time.process_time()
    x, h = np.array(x0, float), H0
    first = last = steady(x)
    for _ in range(MAX_STEPS):
        if last <= tol or h >= H_MAX or time.process_time() - clock > CPU_LIMIT:
            break
        new = _step(step, x, h)
        if new is None:
            h /= 10.0
            if h < H_MIN:
                break
            continue
        now = steady(new)
        if not np.isfinite(now):
            h /= 10.0
            continue
        h *= float(np.clip(last / max(now, 1e-300), *GROWTH))
        x, last = new, now
    log.info("pseudo-transient walk: steady residual %.3g -> %.3g (h = %.3g)", first, last, h)
    return x if last < first else None


def _step(step, x_prev: np.ndarray, h: float) -> np.ndarray | None:
    try:
        return _newton(lambda v: [np.array(a, float) for a in step(v, x_prev, 1.0 / h)], x_prev)
    except (RuntimeError, np.linalg.LinAlgError):
        return None


def term_sizes(J: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Each row's size at ``z``: the sum of its terms' magnitudes, linearised (|J| |z|)."""
    return np.abs(J) @ (np.abs(z) + 1e-10)


def _newton(f, z: np.ndarray) -> np.ndarray | None:
    """Newton's method with step halving, each step solved with the Jacobian's rows and
    columns scaled to 1 (a valve's area of 3e-6 m2 beside pressures of 1e5 Pa and their rows
    of 1e12: unscaled, the step in the pressures' common level is lost to rounding)."""
    r, J = f(z)
    r = r.ravel()
    for _ in range(ITERATIONS):
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J))):
            return None
        # met row by row against the size of its terms (a tank's slow heat balance beside a
        # pressure's fast mass balance: one tolerance for all left the tank 0.03 K off steady)
        if np.all(np.abs(r) <= homotopy.TOL * (term_sizes(J, z) + 1e-300)):
            return z
        cols = 1.0 / np.maximum(np.abs(J).max(axis=0, initial=0.0), 1e-300)
        rows = 1.0 / np.maximum(np.abs(J * cols).max(axis=1, initial=0.0), 1e-300)
        dz = cols * np.linalg.lstsq(rows[:, None] * J * cols, -rows * r, rcond=None)[0]
        norm = np.linalg.norm(rows * r)
        for length in 0.5 ** np.arange(14):
            r1, J1 = f(z + length * dz)
            r1 = r1.ravel()
            if np.all(np.isfinite(r1)) and np.linalg.norm(rows * r1) < norm:
                break
        else:
            return None
        z, r, J = z + length * dz, r1, J1
    return None
