"""The implicit DAE 0 = F(x', x, z, u, p, t) of a flattened model, in scalar CasADi SX.

Built from a pymoca model: every vector variable is split into named scalars, parameters whose
binding is an expression of other parameters are resolved to the *free* parameters (the ones a
user or a fitting loop sets), constants are substituted, and every name the user may ask for
(aliases included) maps to an expression in the DAE's unknowns.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..errors import ModelicaError


@dataclass
class Dae:
    """Implicit DAE in scalar SX symbols.

    ``residual`` has as many rows as ``x`` plus ``z``; ``init_residual`` holds the model's initial
    equations. ``x_start`` / ``z_start`` are expressions in ``p`` (a start value may be bound to
    a parameter); ``x_fixed`` marks states whose start value is an initial condition.
    ``exprs`` maps every variable name (aliases, dependent parameters, outputs) to its expression.
    """

    x: ca.SX
    dx: ca.SX
    z: ca.SX
    u: ca.SX
    p: ca.SX
    t: ca.SX
    residual: ca.SX
    init_residual: ca.SX
    x_names: list[str]
    z_names: list[str]
    u_names: list[str]
    p_names: list[str]
    p_values: np.ndarray
    x_start: ca.SX
    x_fixed: np.ndarray
    z_start: ca.SX
    u_start: np.ndarray
    outputs: list[str]
    exprs: dict[str, ca.SX] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    descriptions: dict[str, str] = field(default_factory=dict)
    time_events: list[float] = field(default_factory=list)   # instants where the equations jump
    #: zero-crossing functions: lhs - rhs of each relation on the unknowns in the equations
    #: (outside noEvent); where one changes sign the equations switch: a state event
    relations: ca.SX = field(default_factory=lambda: ca.SX(0, 1))
    # -- the hybrid part (empty for a continuous model) ----------------------------------
    #: discrete variables held between events (discrete Real, Integer, Boolean; then one
    #: memory per condition whose rising edge fires a when-clause), their names and starts
    d: ca.SX = field(default_factory=lambda: ca.SX(0, 1))
    d_names: list[str] = field(default_factory=list)
    d_start: ca.SX = field(default_factory=lambda: ca.SX(0, 1))
    #: symbols of pre(d), pre(x) and of the flags [initial(), terminal(), tick of each clock]
    d_pre: ca.SX = field(default_factory=lambda: ca.SX(0, 1))
    x_pre: ca.SX = field(default_factory=lambda: ca.SX(0, 1))
    flags: ca.SX = field(default_factory=lambda: ca.SX(0, 1))
    #: at an event: the new d (in x, z, u, p, t, d, d_pre, x_pre, flags) and the states after
    #: reinit(); the continuous equations read d as held values (pre(d) = d between events)
    d_update: ca.SX = field(default_factory=lambda: ca.SX(0, 1))
    x_reinit: ca.SX = field(default_factory=lambda: ca.SX(0, 1))
    clocks: list = field(default_factory=list)          # (start, period) of each sample() clock
    asserts: ca.SX = field(default_factory=lambda: ca.SX(0, 1))   # 1 where an assert is violated
    assert_info: list = field(default_factory=list)     # (level "error"|"warning", message) of each

    @property
    def hybrid(self) -> bool:
        return self.d.numel() > 0 or self.asserts.numel() > 0


def check_balance(residual: ca.SX, nx: int, nz: int, name: str) -> None:
    """As many equations as unknowns, or a one-line error counting both."""
    if residual.numel() != nx + nz:
        raise ModelicaError(f"model {name} is unbalanced: {residual.numel()} equations for {nx + nz} "
                            f"unknowns ({nx} states, {nz} algebraic variables)")


def resolve_parameters(values: ca.SX, p_all: ca.SX, free: list[int], name: str) -> tuple[ca.SX, ca.SX]:
    """The free parameters' symbols ``p`` and every parameter of ``p_all`` as an expression of
    them: a dependent parameter's binding (``values``, in ``p_all``) substituted to a fixed point."""
    p = ca.SX.sym("p", len(free))
    resolved = ca.SX(p_all)
    for k, j in enumerate(free):
        resolved[j] = p[k]
    dependent = [j for j in range(p_all.numel()) if j not in set(free)]
    for _ in range(len(dependent) + 1):
        if not dependent or not ca.depends_on(resolved, p_all):
            return p, resolved
        nxt = ca.SX(resolved)
        for j in dependent:
            nxt[j] = ca.substitute(values[j], p_all, resolved)
        resolved = nxt
    if ca.depends_on(resolved, p_all):
        raise ModelicaError(f"model {name}: parameter bindings are circular")
    return p, resolved


def _scalar_names(var) -> list[str]:
    name, n = var.symbol.name(), var.symbol.numel()
    return [name] if n == 1 else [f"{name}[{i + 1}]" for i in range(n)]


def _attr(value, default=0.0):
    """A numeric attribute, or the MX expression it is bound to."""
    if isinstance(value, ca.MX):
        return value
    try:
        out = float(value)
    except (TypeError, ValueError):
        return default
    return default if np.isnan(out) else out


def from_pymoca(model, name: str = "model") -> Dae:
    """Translate a pymoca CasADi ``Model`` into a scalar SX :class:`Dae` (with balance check)."""
    groups = dict(
        x=model.states, dx=model.der_states, z=model.alg_states, u=model.inputs,
    )
    params = list(model.parameters)
    consts = list(model.constants)
    t_mx = model.time

    def syms(vs):
        return [v.symbol for v in vs]

    mx_all = [*syms(groups["x"]), *syms(groups["dx"]), *syms(groups["z"]), *syms(groups["u"]),
              *syms(params), *syms(consts), t_mx]
    names = {k: [n for v in vs for n in _scalar_names(v)] for k, vs in groups.items()}
    sx = {k: ca.SX.sym(k, len(names[k])) for k in groups}
    p_all_names = [n for v in params for n in _scalar_names(v)]
    p_all = ca.SX.sym("p_all", len(p_all_names))
    c_vals = ca.vertcat(*[ca.DM(_attr(c.value)).reshape((-1, 1)) if not isinstance(c.value, ca.MX)
                          else ca.DM.nan(c.symbol.numel(), 1) for c in consts]) if consts else ca.DM(0, 1)
    t = ca.SX.sym("t")

    def to_sx(mx_exprs):
        """MX expressions over the model's symbols -> SX over ours (constants substituted)."""
        if not mx_exprs:
            return ca.SX(0, 1)
        f = ca.Function("f", [ca.vertcat(*[ca.vec(s) for s in mx_all[:-1]]), t_mx],
                        [ca.vertcat(*[ca.vec(ca.MX(e)) for e in mx_exprs])]).expand()
        args = ca.vertcat(sx["x"], sx["dx"], sx["z"], sx["u"], p_all, ca.SX(c_vals))
        return f(args, t)

    residual = to_sx(list(model.equations))
    check_balance(residual, len(names["x"]), len(names["z"]), name)
    init_residual = to_sx(list(model.initial_equations))

    # Parameters: free ones keep a symbol, dependent ones are resolved to expressions of free ones.
    values = [_attr(v.value, default=np.nan) for v in params]
    value_exprs = to_sx([v if isinstance(v, ca.MX) else ca.MX(ca.DM.nan(params[i].symbol.numel(), 1)
                                                              if np.isnan(v) else v)
                         for i, v in enumerate(values)])
    free = [i for i, v in enumerate(values) if not isinstance(v, ca.MX)]
    p_names = [p_all_names[i] for i in free]
    p_values = np.array([0.0 if np.isnan(values[i]) else values[i] for i in free])
    p, resolved = resolve_parameters(value_exprs, p_all, free, name)

    def bind(e):
        return ca.substitute(e, p_all, resolved)

    def starts(vs):
        return bind(to_sx([v.start if isinstance(v.start, ca.MX) else
                           ca.MX(ca.DM.ones(v.symbol.numel(), 1) * _attr(v.start)) for v in vs]))

    x_fixed = np.array([bool(_attr(v.fixed)) if not isinstance(v.fixed, ca.MX) else False
                        for v in groups["x"] for _ in range(v.symbol.numel())], dtype=bool)
    u_start = np.array([_attr(v.start) if not isinstance(v.start, ca.MX) else 0.0
                        for v in groups["u"] for _ in range(v.symbol.numel())])

    exprs: dict[str, ca.SX] = {}
    for k in ("x", "z", "u"):
        for i, n in enumerate(names[k]):
            exprs[n] = sx[k][i]
    for i, n in enumerate(p_all_names):
        exprs[n] = resolved[i]
    for c in consts:
        if not isinstance(c.value, ca.MX):
            exprs[c.symbol.name()] = ca.SX(_attr(c.value))
    for alias, (canonical, sign) in _aliases(model):
        if canonical in exprs and alias not in exprs:
            exprs[alias] = sign * exprs[canonical]
    outputs = list(model.outputs)
    missing = [o for o in outputs if o not in exprs]
    if missing:
        raise ModelicaError(f"model {name}: cannot resolve output(s) {', '.join(missing)}")
    units, descriptions = {}, {}
    return Dae(
        x=sx["x"], dx=sx["dx"], z=sx["z"], u=sx["u"], p=p, t=t,
        residual=bind(residual), init_residual=bind(init_residual),
        x_names=names["x"], z_names=names["z"], u_names=names["u"], p_names=p_names,
        p_values=p_values, x_start=starts(groups["x"]), x_fixed=x_fixed,
        z_start=starts(groups["z"]), u_start=u_start, outputs=outputs, exprs=exprs,
        units=units, descriptions=descriptions,
    )


def _aliases(model):
    """(alias, (canonical, sign)) for every alias pymoca eliminated, negated ones included."""
    rel = model.alias_relation
    for canonical in rel.canonical_variables:
        for member in rel.aliases(canonical) | rel.aliases("-" + canonical):
            name = member.lstrip("-")
            if name != canonical:
                target, sign = rel.canonical_signed(name)
                yield name, (target, float(sign))


def eliminate_aliases(dae: Dae, passes: int = 20) -> Dae:
    """Remove the trivial equations a flat model is full of (``a = b``, ``a = -b``, ``a = c*b + d``
    with constant c, ``a = parameter``): the algebraic variable they define is replaced by its
    expression everywhere. Index reduction and causalisation then see the real structure (a
    connector's potential is a state's alias, not a second state), and simulation gets cheaper.
    States are never removed; every eliminated name stays readable through ``exprs``."""
    residual, z, z_names, z_start = dae.residual, dae.z, list(dae.z_names), dae.z_start
    init_residual, exprs, relations = dae.init_residual, dict(dae.exprs), dae.relations
    d_update, x_reinit, asserts = dae.d_update, dae.x_reinit, dae.asserts
    for _ in range(passes):
        w = ca.vertcat(dae.x, z)
        nx = dae.x.numel()
        if residual.numel() == 0 or z.numel() == 0:
            break
        jac = ca.jacobian(residual, w)
        sp = jac.sparsity()
        cols_of = {}
        for r, c in zip(sp.get_triplet()[0], sp.get_triplet()[1]):
            cols_of.setdefault(r, []).append(c)
        eliminated, keep_rows, taken = {}, [], set()
        for r in range(residual.numel()):
            cols = cols_of.get(r, [])
            row = residual[r]
            if (not 1 <= len(cols) <= 2 or ca.depends_on(row, dae.dx)
                    or ca.depends_on(row, dae.t) or ca.depends_on(row, dae.u) or taken & set(cols)):
                keep_rows.append(r)
                continue
            coef = [jac[r, c] for c in cols]
            if any(ca.depends_on(k, w) for k in coef):
                keep_rows.append(r)        # not linear in the unknowns
                continue
            alg = [c for c in cols if c >= nx]
            if not alg:
                keep_rows.append(r)        # between states: index reduction's business
                continue
            e = alg[-1]                    # the algebraic variable to eliminate
            k_e = coef[cols.index(e)]
            if k_e.is_zero():
                keep_rows.append(r)
                continue
            rest = ca.substitute(row, w[e], ca.SX(0))   # row = k_e * w_e + rest (linear in w_e)
            eliminated[e - nx] = -rest / k_e
            taken |= set(cols)
        if not eliminated:
            break
        drop = sorted(eliminated)
        keep = [j for j in range(z.numel()) if j not in eliminated]
        old = ca.vertcat(*[z[j] for j in drop])
        new = ca.vertcat(*[eliminated[j] for j in drop])   # names no variable of this pass ("taken")
        residual = ca.substitute(residual[keep_rows], old, new) if keep_rows else ca.SX(0, 1)
        init_residual = ca.substitute(init_residual, old, new)
        relations = ca.substitute(relations, old, new)
        d_update, x_reinit, asserts = (ca.substitute(e, old, new) for e in (d_update, x_reinit, asserts))
        exprs = {n: ca.substitute(v, old, new) if ca.depends_on(v, old) else v for n, v in exprs.items()}
        z_start = z_start[keep] if keep else ca.SX(0, 1)
        z = ca.vertcat(*[z[j] for j in keep]) if keep else ca.SX(0, 1)
        z_names = [z_names[j] for j in keep]
    import dataclasses

    return dataclasses.replace(dae, z=z, residual=residual, init_residual=init_residual, z_names=z_names,
                               z_start=z_start, exprs=exprs, relations=relations, d_update=d_update,
                               x_reinit=x_reinit, asserts=asserts)
