"""Refinement of a candidate's law by full discretisation (paper 004) inside ``mcl run``.

``refinement: {method: full-discretisation}`` in a run file: instead of fitting the template by
repeated simulation, the candidate model's states at every sample time and the template's terms
are the unknowns of the least-squares problem of eq. (12) (:mod:`mcl.lm`), with
f = the compiled model's right-hand side (:class:`mcl.lm.CompiledRhs`) and h = its outputs.
Backward elimination (:mod:`mcl.sparsify`) then prunes the terms stage-wise by degree.
The result is checked by simulation, so candidates stay comparable with each other and with the
nominal model.

Weights: W_y is the measurement noise estimated from the data (so the cost is -2 log L and BIC
counts in its units); W_x, the covariance of the model error, is a small fraction of the states'
rate of change in the start simulation (the model is meant to be nearly exact).
"""
from __future__ import annotations

import numpy as np

from .data import TimeSeries


def degree(term) -> int:
    return int(sum(p for _, p in getattr(term, "powers", ())))


def refine(model, data: TimeSeries, names: list[str], w0, criterion: str, terms=None,
           model_error: float = 1e-2, max_samples: int = 2000):
    """Fit and prune the template parameters ``names`` (names[0], the scale anchor, stays at
    w0[0]); ``terms`` (the template's monomials, one per name) order the pruning by degree.
    Returns (w, active, path): the full parameter vector, which terms survive and the pruning
    path as dicts (removed, estimate, cost, score, accepted)."""
    from .services import simulate
    from .stats import noise_estimate
    from .lm import CompiledRhs, IdentificationProblem, Measurements
    from .sparsify import BackwardElimination

    outs = [o for o in model.output_names if o in data.names]
    keep = np.unique(np.linspace(0, len(data.time) - 1, min(len(data.time), max_samples)).round().astype(int))
    t, Y = data.time[keep], data.select(outs).values[keep]
    start = simulate(model, data, dict(zip(names, w0)), t_out=t)
    if not start.ok or start.states is None:
        return np.asarray(w0, float), np.ones(len(names), bool), []
    rhs = CompiledRhs(model, data, names[1:], {names[0]: float(w0[0])})
    out_idx = [model.output_names.index(o) for o in outs]
    sy = np.array([max(noise_estimate(Y[:, k]), 1e-9 * (np.ptp(Y[:, k]) + 1e-300)) for k in range(len(outs))])
    rate = np.std(np.gradient(start.states, t, axis=0), axis=0)
    sx = model_error * np.where(rate > 0, rate, 1.0)
    prob = IdentificationProblem(rhs, lambda s, x, a: rhs.output(s, x, a)[out_idx], len(model.ode.x_names),
                                 len(names) - 1, Measurements(t, Y), dt=float(np.median(np.diff(t))) * 1.0001,
                                 Sx=sx, Sy=sy, mu_x=0.0, mu_a=1e-10)
    X0 = np.array([np.interp(prob.t, t, start.states[:, k]) for k in range(start.states.shape[1])]).T
    terms = list(terms or [])
    degrees = [degree(m) for m in terms[1:]] if len(terms) == len(names) else None
    res = BackwardElimination(criterion, lm_options={"max_iter": 60}, segments=8).fit(
        prob, X0, np.asarray(w0[1:], float), names[1:], degrees)
    w = np.concatenate([[w0[0]], res.a])
    active = np.concatenate([[True], res.active])
    path = [{"removed": s.removed, "estimate": s.estimate, "cost": s.cost, "score": s.criterion,
             "accepted": s.accepted} for s in res.path]
    return w, active, path
