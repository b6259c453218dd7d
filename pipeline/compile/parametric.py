"""The purely parametric parts of a model's right-hand side, computed once per parameter vector.

The flat model writes what its parameters determine into the equations that use it: an MSL
filter's coefficients (``Blocks.Continuous.Filter``: the Chebyshev poles of ``f_cut`` and the
ripple, computed by functions with loops) become part of the right-hand side. The Wiener-
Hammerstein circuit's six linear states then cost 621 149 instructions a call (1 ms), where
their own part is 48. CasADi's ``extract_parametric`` takes those parts out: q = q(p) is
evaluated once per run (and its derivative dq/dp, once, where sensitivities are asked for), and
the solver's calls evaluate g(x, u, p, q, t) alone.
"""
from __future__ import annotations

import functools
from collections import OrderedDict
from dataclasses import dataclass

import casadi as ca
import numpy as np

#: split only where the states' part is at most this share of the whole (else the extra
#: arguments are not worth it)
WORTH = 0.5
#: functions of fewer instructions in all have nothing worth taking out
SMALL = 1000
_SPLITS: OrderedDict = OrderedDict()
_KEEP = 16


@dataclass(frozen=True)
class Split:
    """``ode.ode`` and ``ode.out`` as functions of (x, u, p, q, t), with q = ``q(p)``."""

    q: ca.Function          # p -> q
    ode: ca.Function        # (x, u, p, q, t) -> x'
    out: ca.Function        # (x, u, p, q, t) -> y
    checks: ca.Function     # (x, u, p, q, t) -> (y, algebraic residual, drift): ``ode.checks``

    @property
    def nq(self) -> int:
        return self.q.nnz_out(0)

    @staticmethod
    def d_dp(expr, P, Q, QP, cols):
        """d expr / d p in the columns ``cols``: directly and through q (``QP`` = dq/dp there)."""
        return ca.jacobian(expr, P)[:, cols] + ca.mtimes(ca.jacobian(expr, Q), QP)

    def values(self, p) -> np.ndarray:
        return np.asarray(self.q(np.asarray(p, float)), float).ravel()

    def jacobian(self, p, cols) -> np.ndarray:
        """dq/dp in the columns ``cols`` (nq x len(cols))."""
        return np.asarray(self._jac(np.asarray(p, float)), float)[:, list(cols)]

    @functools.cached_property
    def _jac(self) -> ca.Function:
        P = self.q.sx_in(0)
        return ca.Function("dq", [P], [ca.densify(ca.jacobian(self.q(P), P))])


def split(ode) -> Split | None:
    """The split of ``ode`` (once per model), or None where it has no parametric part worth
    taking out, holds algebraic loops (their Newton form reads p as a whole) or is not SX."""
    key = (id(ode.ode), id(ode.out))
    if key in _SPLITS:
        _SPLITS.move_to_end(key)
        return _SPLITS[key][1]
    made = _made(ode)
    _SPLITS[key] = (ode, made)          # the entry holds the ode: its id is not reused meanwhile
    if len(_SPLITS) > _KEEP:
        _SPLITS.popitem(last=False)
    return made


def _made(ode) -> Split | None:
    funs = (ode.ode, ode.out, ode.checks)
    if getattr(ode, "loops", None) is not None or not all(f.is_a("SXFunction") for f in funs):
        return None
    X, U, P, T = ode.ode.sx_in()
    exprs = [ode.ode(X, U, P, T), ode.out(X, U, P, T), *ode.checks(X, U, P, T)]
    before = ca.Function("whole", [X, U, P, T], exprs).n_instructions()
    if before < SMALL:
        return None
    split_exprs, symbols, parts = ca.extract_parametric(exprs, P)
    parts = _resolved(parts, symbols)
    if not symbols or parts is None:
        return None
    Q = ca.vertcat(*[ca.vec(s) for s in symbols])
    args, names = [X, U, P, Q, T], ["x", "u", "p", "q", "t"]
    made = Split(ca.Function("q", [P], [ca.vertcat(*[ca.vec(e) for e in parts])]),
                 ca.Function("ode_q", args, split_exprs[:1], names, ["xdot"]),
                 ca.Function("out_q", args, split_exprs[1:2], names, ["y"]),
                 ca.Function("checks_q", args, split_exprs[2:], names, ode.checks.name_out()))
    # (the solver's calls: ode and out, against ode and out as they were; the whole, checks
    # included, let a 13 % saving pass, and SMEE_Rectifier's diode events ran 2.5x slower)
    if made.ode.n_instructions() + made.out.n_instructions() > WORTH * (
            ode.ode.n_instructions() + ode.out.n_instructions()):
        return None
    return made


def _resolved(parts: list, symbols: list, rounds: int = 50) -> list | None:
    """``parts`` in the parameters alone: CasADi's extract_parametric can give a part that reads
    another part's symbol (water's density from IF97 at a parametric pressure: 'q' then had
    free variables, an internal error); None where they do not resolve."""
    if not symbols:
        return parts
    syms = ca.vertcat(*[ca.vec(s) for s in symbols])
    for _ in range(rounds):
        if not ca.depends_on(ca.vertcat(*[ca.vec(e) for e in parts]), syms):
            return parts
        parts = ca.substitute(parts, symbols, parts)
    return None


def split_functions(funcs: dict, p_at: dict, n_p: int) -> tuple[dict, ca.Function | None]:
    """Functions that read the parameters (``p_at[name]``: the argument that holds them), with
    their purely parametric parts taken out together: ``(funcs', derived)``, where each
    function of ``funcs'`` reads the parameters followed by q = derived(p) in that argument (an
    FMU computes q when a parameter is set, not in every call). A function that does not expand
    to SX keeps reading the parameters alone (the first ``n_p`` entries of the same argument).
    ``derived`` is None where nothing worth taking out was found."""
    from .structure import too_large_to_expand

    sx = {}
    for name, f in funcs.items():
        if too_large_to_expand(f):
            continue        # kept MX by the compile (a fluid's media calls): expanded, 8 MB of C each
        try:
            g = f.expand() if f is not None and not f.is_a("SXFunction") else f
        except RuntimeError:       # holds a rootfinder: reads p as it is
            continue
        if g is not None and g.is_a("SXFunction") and g.nnz_in(p_at[name]) == n_p:
            sx[name] = g
    before = sum(g.n_instructions() for g in sx.values())
    if before < SMALL:
        return funcs, None
    P = ca.SX.sym("p", n_p)
    calls = {}
    for name, g in sx.items():
        args = g.sx_in()
        args[p_at[name]] = P
        calls[name] = (args, g.call(args))
    flat = [e for _, outs in calls.values() for e in outs]
    exprs, symbols, parts = ca.extract_parametric(flat, P)
    parts = _resolved(parts, symbols)
    if not symbols or parts is None:
        return funcs, None
    Q = ca.vertcat(*[ca.vec(s) for s in symbols])
    PQ = ca.SX.sym("p", n_p + Q.numel())
    exprs = ca.substitute(exprs, [ca.vertcat(P, Q)], [PQ])
    made, k = dict(funcs), 0
    for name, (args, outs) in calls.items():
        args[p_at[name]] = PQ
        g = sx[name]
        made[name] = ca.Function(g.name(), args, exprs[k:k + len(outs)], g.name_in(), g.name_out())
        k += len(outs)
    if sum(made[n].n_instructions() for n in calls) > WORTH * before:
        return funcs, None
    q = ca.cse(ca.vertcat(*[ca.vec(e) for e in parts]))
    return made, ca.Function("derived", [P], [q], ["p"], ["q"])
