"""Screening every component in one pass: which law at which component could explain the misfit.

A candidate law at component c is a deviation D_c = sum_k w_k phi_k(v_c, i_c, dv_c, di_c) at its
terminals (:mod:`.inject`). Near the nominal model (w = w0, D = 0) the outputs move by
dy = sum_k (dw_k) s_ck(t), where s_ck is the model's response to a deviation at c whose value
is the signal phi_k along the *nominal* run: a linear, time-varying response, the same for every
term at one component. So one simulation of a model with a deviation parameter j_c at every
component (:func:`.inject.with_injections`) gives everything: the nominal trajectory, the
Jacobians A = df/dx, B = df/dj, C = dy/dx, E = dy/dj along it, and the signals phi_ck; the
sensitivities are then the solution of S' = A S + B_c phi_ck, y = C S + E_c phi_ck, integrated
by the trapezoidal rule on the data grid (refined) for all terms of all components at once.
The Gauss-Newton step of each candidate then predicts the RSS it can reach: RSS - g^T (S^T S)^+ g,
g = S^T r. The cost is one simulation and a linear solve per time step, whatever the number of
components.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..sensitivity import Linearisation
from ..simulation import prepare_inputs
from ..stats import gram_inverse
from .inject import ACROSS, FLOW


@dataclass
class Signals:
    """A component's law variables along a run: v, i and their time derivatives, and the
    potentials va, vb of its connectors a and b (v = va - vb)."""

    v: np.ndarray
    i: np.ndarray
    dv: np.ndarray
    di: np.ndarray
    va: np.ndarray
    vb: np.ndarray

    def env(self) -> dict:
        return {"v": self.v, "i": self.i, "dv": self.dv, "di": self.di, "va": self.va, "vb": self.vb}


def law_signals(model, states: np.ndarray, time: np.ndarray, inputs, components) -> dict[str, Signals]:
    """v, i, dv/dt, di/dt, va, vb of each component along a run (``states`` (N, nx) at ``time``),
    exact: d/dt of a variable is its gradient in the states times the right-hand side, plus its
    partial derivatives in time and in the inputs (these times the inputs' slopes)."""
    ode = model.ode
    names = []
    for c in components:
        xa, xb = c.across()
        fa, _ = c.flow()
        v_name, i_name = f"{c.name}.{ACROSS}", f"{c.name}.{FLOW}"
        if v_name not in ode.probe_names and c.term:    # (its value is the term's, of v: below)
            fa = xa
        names.append(((v_name, None, i_name) if v_name in ode.probe_names else (xa, xb, fa), (xa, xb)))
    X, U, P, T = ode.probe.mx_in()
    Ud = ca.MX.sym("ud", U.numel())
    probe = ode.probe(X, U, P, T)
    idx = {n: k for k, n in enumerate(ode.probe_names)}
    vals, pots = [], []
    for (a, b, f), (xa, xb) in names:       # a signal block: v is its input, against no b
        vals += [probe[idx[a]] - (probe[idx[b]] if b else 0), probe[idx[f]]]
        pots += [probe[idx[xa]], probe[idx[xb]] if xb else ca.MX(0)]
    q = ca.vertcat(*vals) if vals else ca.MX(0, 1)
    xdot = ode.ode(X, U, P, T)
    dq = ca.jtimes(q, X, xdot) + ca.jacobian(q, T) + (ca.jtimes(q, U, Ud) if U.numel() else 0)
    fun = ca.Function("signals", [X, U, P, T, Ud], [q, dq, ca.vertcat(*pots) if pots else ca.MX(0, 1)])
    try:
        fun = fun.expand()
    except RuntimeError:
        pass
    u = prepare_inputs(model, inputs)
    N = len(time)
    Uo = np.array([np.interp(time, u.time, u.values[:, j]) for j in range(len(u.names))]).reshape(-1, N)
    Ud_ = np.array([np.interp(time, u.time, np.gradient(u.values[:, j], u.time)) for j in range(len(u.names))]).reshape(-1, N)
    p = model.parameter_vector()
    Q, dQ, V = (np.array(v) for v in fun.map(N)(states.T, Uo, np.repeat(p[:, None], N, 1), time[None], Ud_))
    out = {}
    for k, c in enumerate(components):
        out[c.name] = Signals(Q[2 * k], Q[2 * k + 1], dQ[2 * k], dQ[2 * k + 1], V[2 * k], V[2 * k + 1])
        if c.term and f"{c.name}.{ACROSS}" not in ode.probe_names:
            out[c.name] = _term_signals(model, c, out[c.name], p)
    return out


def _term_signals(model, comp, sig: Signals, p: np.ndarray) -> Signals:
    """A term of the user's balance along the run: i its value at v (its unknown), di = i'(v) dv."""
    from ..compile.equations import term_of

    dae = model.dae
    term, _ = term_of(dae, comp)
    x = dae.exprs[comp.inputs[0]]
    values = dict(zip(model.ode.p_names, p))
    pv = [values.get(n, v) for n, v in zip(dae.p_names, np.asarray(dae.p_values, float))]
    fun = ca.Function("term", [x, dae.p], [term, ca.jacobian(term, x)])
    i, slope = (np.asarray(a, float).ravel() for a in fun.map(len(sig.v))(sig.v[None], np.repeat(np.asarray(pv)[:, None], len(sig.v), 1)))
    return dataclasses.replace(sig, i=i, di=slope * sig.dv)


@dataclass
class Response:
    """Output sensitivities of every screened term: ``S[k, o, j]`` = d y_o(t_k) / d w_j at the
    data points, columns ``columns[j]`` = (key of the law, term index within it)."""

    S: np.ndarray
    columns: list


def linear_response(model, j_names: list[str], inputs, result, at_data: np.ndarray, phis: dict) -> Response:
    """The outputs' response at the data points ``at_data`` of the run ``result`` (the nominal
    model on a fine grid) to a deviation j = phi_k(t) at a component, for every term signal
    ``phis[key]`` ((n_terms, N_fine) on that grid) whose component's deviation parameter is
    ``j_names[i]`` (one per key, in order)."""
    lin = Linearisation(model, result.states, result.time, inputs, model.parameter_vector(), j_names,
                        result.switches)
    columns, comp_of, sig = [], [], []
    for ci, (key, phi) in enumerate(phis.items()):
        for k in range(phi.shape[0]):
            columns.append((key, k))
            comp_of.append(ci)
            sig.append(phi[k])
    comp_of = np.array(comp_of, int)
    sig = np.array(sig).reshape(len(columns), len(result.time))
    S = lin.propagate(lambda k, B, E: (B[:, comp_of] * sig[:, k], E[:, comp_of] * sig[:, k]), at_data, len(columns))
    return Response(S, columns)


def predicted_rss(S: np.ndarray, r: np.ndarray) -> float:
    """RSS after one Gauss-Newton step: RSS - g^T (S^T S)^+ g with g = S^T r (measured entries)."""
    ok = np.isfinite(r)
    S, r = S[ok], r[ok]
    g = S.T @ r
    gain = float(g @ gram_inverse(S.T @ S) @ g) if S.size else 0.0
    return float(max(r @ r - gain, 0.0))
