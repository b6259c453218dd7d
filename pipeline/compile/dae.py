"""The implicit DAE 0 = F(x', x, z, u, p, t) of a flattened model, in scalar CasADi SX.

Built from a pymoca model: every vector variable is split into named scalars, parameters whose
binding is an expression of other parameters are resolved to the *free* parameters (the ones a
user or a fitting loop sets), constants are substituted, and every name the user may ask for
(aliases included) maps to an expression in the DAE's unknowns.
"""
from __future__ import annotations

import dataclasses
import math
from collections import deque
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..errors import ModelicaError
from .guards import guarded

#: a relation's value from lhs - rhs, by its operator (numbers or symbols)
RELATION_TRUTH = {"greater": lambda g: g > 0, "greater_equal": lambda g: g >= 0,
                  "less": lambda g: g < 0, "less_equal": lambda g: g <= 0}


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
    relation_ops: tuple = ()    # each relation's operator (greater, less_equal, ...; None: unknown)
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
    #: pre() of algebraic variables the update reads: the values of ``exprs["$pre[k]"]`` just
    #: before the event (computed with the discrete variables' pre() values)
    z_pre: ca.SX = field(default_factory=lambda: ca.SX(0, 1))
    #: at an event: the new d (in x, z, u, p, t, d, d_pre, x_pre, flags) and the states after
    #: reinit(); the continuous equations read d as held values (pre(d) = d between events)
    d_update: ca.SX = field(default_factory=lambda: ca.SX(0, 1))
    x_reinit: ca.SX = field(default_factory=lambda: ca.SX(0, 1))
    clocks: list = field(default_factory=list)          # (start, period) of each sample() clock
    asserts: ca.SX = field(default_factory=lambda: ca.SX(0, 1))   # 1 where an assert is violated
    assert_info: list = field(default_factory=list)     # (level "error"|"warning", message) of each
    #: the start values (in p) of the continuous variables declared ``stateSelect = prefer`` or
    #: ``always``: where the initial equations leave states free, these are pinned first (a
    #: drum's pressure and level, not the mass and energy the balances differentiate)
    preferred: dict[str, ca.SX] = field(default_factory=dict)
    #: each continuous variable's ``stateSelect`` other than default (Never, Avoid, Prefer, Always)
    state_select: dict[str, str] = field(default_factory=dict)

    @property
    def hybrid(self) -> bool:
        """Whether the model has a discrete part: discrete variables, asserts, or equations that
        read pre(), initial(), terminal() or a sample() clock's tick (a SampleTrigger alone)."""
        if self.d.numel() > 0 or self.asserts.numel() > 0 or self.clocks:
            return True
        hybrid = ca.vertcat(self.d_pre, self.x_pre, self.z_pre, self.flags)
        if not hybrid.numel():
            return False
        reads = ca.vertcat(self.residual, self.init_residual, *self.exprs.values())
        return any(ca.depends_on(reads, s) for s in ca.vertsplit(hybrid))


def check_balance(residual: ca.SX, nx: int, nz: int, name: str) -> None:
    """As many equations as unknowns, or a one-line error counting both."""
    if residual.numel() != nx + nz:
        raise ModelicaError(f"model {name} is unbalanced: {residual.numel()} equations for {nx + nz} "
                            f"unknowns ({nx} states, {nz} algebraic variables)")


def resolve_parameters(values: ca.SX, p_all: ca.SX, free: list[int], name: str,
                       names: list[str] | None = None, p_values=None) -> tuple[ca.SX, ca.SX]:
    """The free parameters' symbols ``p`` and every parameter of ``p_all`` as an expression of
    them: a dependent parameter's binding (``values``, in ``p_all``) substituted to a fixed point.
    Bindings that read each other only through a branch a free parameter rules out (the MSL's
    m_flow_small = if use_eps_Re then eps*m_flow_nominal else ..., and m_flow_nominal the other
    way) are taken at the free parameters' values (``p_values``): fixed numbers of the model."""
    p = ca.SX.sym("p", len(free))
    own = dict(zip(free, ca.vertsplit(p)))
    resolved = ca.vertcat(*[own.get(j, e) for j, e in enumerate(ca.vertsplit(p_all))]) if p_all.numel() else p_all
    for _ in range(p_all.numel() - len(free) + 1):   # each pass resolves one more level
        if not ca.depends_on(resolved, p_all):
            return p, resolved
        new = ca.vertsplit(ca.substitute(values, p_all, resolved))
        resolved = ca.vertcat(*[own.get(j, e) for j, e in enumerate(new)])
    if ca.depends_on(resolved, p_all) and p_values is not None and len(free):
        at = ca.substitute(resolved, p, ca.DM(np.asarray(p_values, float)))
        for _ in range(p_all.numel() - len(free) + 1):
            if not ca.depends_on(at, p_all):
                break
            at = ca.substitute(at, p_all, at)
        resolved = ca.vertcat(*[e if not ca.depends_on(e, p_all) or ca.depends_on(a, p_all) else a
                                for e, a in zip(ca.vertsplit(resolved), ca.vertsplit(at))])
    if ca.depends_on(resolved, p_all):
        label = names if names is not None and len(names) == p_all.numel() else list(map(str, ca.vertsplit(p_all)))
        cycle = [label[j] for j, e in enumerate(ca.vertsplit(resolved)) if ca.depends_on(e, p_all)]
        raise ModelicaError(f"model {name}: parameter bindings are circular: {', '.join(cycle[:6])}"
                            f"{' ...' if len(cycle) > 6 else ''} each read another of them")
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
    p, resolved = resolve_parameters(value_exprs, p_all, free, name, p_all_names, p_values)

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


def eliminate_aliases(dae: Dae) -> Dae:
    """Remove the trivial equations a flat model is full of (``a = b``, ``a = -b``, ``a = c*b + d``
    with c and d free of unknowns, ``a = parameter``): the algebraic variable they define is
    replaced by its expression everywhere. Index reduction and causalisation then see the real
    structure (a connector's potential is a state's alias, not a second state), and simulation
    gets cheaper. States are never removed; every eliminated name stays readable through
    ``exprs``.

    Linear in the model's size: each eliminated variable is an affine function of one other
    unknown (or none), so chains of aliases are followed as in a union-find (:class:`_Aliases`)
    and every expression is substituted once, at the end."""
    w = ca.vertcat(dae.x, dae.z)
    nx, nr = dae.x.numel(), dae.residual.numel()
    if nr == 0 or dae.z.numel() == 0:
        return dae
    al = _Aliases(dae, w)
    al.run()
    if not al.defs:
        return dae
    drop = sorted(al.defs)
    old = ca.vertcat(*[al.w[e] for e in drop])
    new = ca.vertcat(*[al.expr(e) for e in drop])
    keep_rows = [r for r in range(nr) if r not in al.used]
    keep = [j for j in range(dae.z.numel()) if j + nx not in al.defs]
    names = list(dae.exprs)
    parts = [dae.residual[keep_rows] if keep_rows else ca.SX(0, 1), dae.init_residual, dae.relations,
             dae.d_update, dae.x_reinit, dae.asserts, *[dae.exprs[n] for n in names]]
    out = ca.substitute(parts, [old], [new])
    residual, init_residual, relations, d_update, x_reinit, asserts = out[:6]
    exprs = dict(zip(names, out[6:]))
    zs = ca.vertsplit(dae.z)
    z = ca.vertcat(*[zs[j] for j in keep]) if keep else ca.SX(0, 1)
    z_start = _alias_starts(al, dae.z_start, nx)
    return dataclasses.replace(dae, z=z, residual=residual, init_residual=init_residual,
                               z_names=[dae.z_names[j] for j in keep],
                               z_start=z_start[keep] if keep else ca.SX(0, 1), exprs=exprs,
                               relations=relations, d_update=d_update, x_reinit=x_reinit, asserts=asserts)


def _alias_starts(al: "_Aliases", z_start: ca.SX, nx: int) -> ca.SX:
    """The algebraic unknowns' start values (the guesses of the loops' Newton methods) with an
    unknown that stays and starts at 0 given the start value of one it stands for, as other
    tools choose one start for a set of aliases: a source's medium pressure, started at 0, is
    the room's it is joined to, started at p_start, and a loop torn at it began at 0 Pa."""
    z_start = ca.SX(z_start)
    starts = ca.vertsplit(z_start)
    for e in sorted(al.defs):
        alpha, root, beta = al.find(e)
        if e < nx or root is None or root < nx or _is_zero(_num(alpha)):
            continue
        mine, theirs = starts[e - nx], starts[root - nx]
        if theirs.is_zero() and not mine.is_zero():
            starts[root - nx] = (mine - beta) / alpha
    return ca.vertcat(*starts) if starts else z_start


def fold_initial_parameters(dae: Dae) -> Dae:
    """A state that never changes (its equation is der(x) = 0: a parameter with fixed = false,
    computed in the initial equations, as the MSL's filters compute their coefficients) whose
    initial equation gives it explicitly from parameters (and states folded before it) is a
    dependent parameter: its expression replaces it everywhere, and it leaves the states.
    Initialisation then has no Newton iteration over it, which from its start value 0 may meet
    a singular point (sqrt(c0 - c1^2/4) at c0 = c1 = 0), and index reduction no constant state
    to differentiate."""
    nx, ni = dae.x.numel(), dae.init_residual.numel()
    if nx == 0 or ni == 0:
        return dae
    xs, dxs = ca.vertsplit(dae.x), ca.vertsplit(dae.dx)
    position = {v.name(): j for j, v in enumerate(dxs)}
    still = {}                                     # state -> its residual row der(x) = 0
    for r, e in enumerate(ca.vertsplit(dae.residual)):
        if e.is_symbolic() and e.name() in position:
            still[position[e.name()]] = r
    if not still:
        return dae
    init = ca.vertsplit(dae.init_residual)
    others = ca.vertcat(dae.dx, dae.z, dae.u, dae.t, dae.d, dae.d_pre, dae.x_pre, dae.z_pre, dae.flags)
    bad = set(ca.jacobian_sparsity(dae.init_residual, others).get_triplet()[0]) if others.numel() else set()
    rows, cols = ca.jacobian_sparsity(dae.init_residual, dae.x).get_triplet()
    reads: dict[int, set] = {}
    for r, c in zip(rows, cols):
        reads.setdefault(r, set()).add(c)
    pending = [r for r in range(ni) if r not in bad and reads.get(r) and reads[r] <= still.keys()]
    solved, used = {}, set()
    while True:
        progress = False
        for r in pending:
            if r in used or len(reads[r] - solved.keys()) != 1:
                continue
            j = next(iter(reads[r] - solved.keys()))
            e = init[r]
            if solved:
                e = ca.substitute(e, ca.vertcat(*[xs[k] for k in solved]), ca.vertcat(*solved.values()))
            coef = ca.jacobian(e, xs[j])
            if not coef.is_constant() or float(coef) == 0:
                continue                       # nonlinear in it: left to the initial solve
            solved[j] = ca.substitute(-e / float(coef), xs[j], ca.SX(0))
            used.add(r)
            progress = True
        if not progress:
            break
    if not solved:
        return dae
    keep = [j for j in range(nx) if j not in solved]
    pick = lambda v: v[keep] if keep else ca.SX(0, 1)  # noqa: E731
    drop_rows = {still[j] for j in solved}
    old = [*[xs[j] for j in solved], *[dxs[j] for j in solved]]
    new = [*solved.values(), *[ca.SX(0)] * len(solved)]
    if dae.x_pre.numel() == nx:
        old += [dae.x_pre[j] for j in solved]
        new += list(solved.values())
    names = list(dae.exprs)
    res = ca.vertsplit(dae.residual)
    parts = [ca.vertcat(*[res[r] for r in range(len(res)) if r not in drop_rows]),
             ca.vertcat(*[init[r] for r in range(ni) if r not in used]),
             dae.relations, dae.d_update, pick(dae.x_reinit) if dae.x_reinit.numel() == nx else dae.x_reinit,
             dae.asserts, pick(dae.x_start), dae.z_start, dae.d_start, *[dae.exprs[n] for n in names]]
    out = ca.substitute(parts, [ca.vertcat(*old)], [ca.vertcat(*new)])
    return dataclasses.replace(
        dae, x=pick(dae.x), dx=pick(dae.dx), x_pre=pick(dae.x_pre) if dae.x_pre.numel() == nx else dae.x_pre,
        residual=out[0], init_residual=out[1], relations=out[2], d_update=out[3], x_reinit=out[4],
        asserts=out[5], x_start=out[6], z_start=out[7], d_start=out[8], exprs=dict(zip(names, out[9:])),
        x_names=[dae.x_names[j] for j in keep], x_fixed=dae.x_fixed[keep])


#: a model of more expression nodes has its repeated subexpressions merged (a flat model inlines a
#: function at each call: the MSL Chebyshev filter's coefficients made a 7-state filter chain's
#: right-hand side 621 149 instructions, 44 237 merged)
CSE_MIN = 20000


def merge_common(dae: Dae) -> Dae:
    """``dae`` with each repeated subexpression computed once, across all its expressions."""
    return _rewritten(dae, lambda parts: ca.cse(parts) if sum(ca.n_nodes(e) for e in parts) >= CSE_MIN else parts)


def guard_branches(dae: Dae) -> Dae:
    """``dae`` with the singular operations of its if-branches finite where not taken (see
    :mod:`guards`: their derivatives are then not NaN there)."""
    return _rewritten(dae, guarded)


def _rewritten(dae: Dae, rewrite) -> Dae:
    """``dae`` with all its expressions passed through ``rewrite`` together (list -> list)."""
    names = list(dae.exprs)
    fields = ("residual", "init_residual", "relations", "d_update", "x_reinit", "asserts", "x_start",
              "z_start", "d_start")
    parts = [getattr(dae, f) for f in fields] + [dae.exprs[n] for n in names]
    out = rewrite(parts)
    if out is parts:
        return dae
    return dataclasses.replace(dae, **dict(zip(fields, out)), exprs=dict(zip(names, out[len(fields):])))


class _Aliases:
    """Alias equations found among the rows linear in the unknowns (without der(), inputs or
    time). Each eliminated unknown ``e`` is ``alpha * w[root] + beta`` of one unknown that stays
    (or ``beta`` alone, free of unknowns); ``find`` follows the chain and shortens it. A row whose
    remaining unknowns (after the eliminations so far, cancelled coefficients dropped) are one or
    two, one of them algebraic, eliminates the algebraic one of higher index; a row is looked at
    again when one of its unknowns goes. A row with a coefficient in unknowns (``R * i`` where
    ``R`` is computed from a parameter) joins the candidates once those unknowns are all
    eliminated to expressions without unknowns."""

    #: a row naming more distinct unknowns than this is not looked at (it would need this many
    #: coefficients to cancel): keeps a long sum from being re-read at every elimination
    MAX_DISTINCT = 4

    def __init__(self, dae: Dae, w: ca.SX):
        self.dae, self.nx = dae, dae.x.numel()
        self.w = ca.vertsplit(w)
        self.index = {s.element_hash(): k for k, s in enumerate(self.w)}
        self.defs: dict[int, tuple] = {}     # eliminated unknown -> (alpha, root or None, beta)
        self.used: set[int] = set()          # rows that became definitions
        self.rows: dict[int, tuple] = {}     # candidate row -> ([(column, coefficient)], rest)
        self.of_root: dict[int, set] = {}    # unknown -> candidate rows that (through aliases) read it
        self.waiting: dict[int, set] = {}    # unknown -> rows with a coefficient in it
        self.queue, self.queued = deque(), set()
        self.modes = None                    # the discrete variables, pre() and the flags

    def run(self):
        dae = self.dae
        w = ca.vertcat(*self.w)
        jac = ca.jacobian(dae.residual, w)
        rows, cols = jac.sparsity().get_triplet()
        if not rows:
            return
        coefs = [_num(k) for k in ca.vertsplit(jac.nz[:])]
        outside = set(ca.jacobian_sparsity(dae.residual, ca.vertcat(dae.dx, dae.u, dae.t)).get_triplet()[0])
        nz, var = ca.jacobian_sparsity(jac.nz[:], w).get_triplet()
        for k, v in zip(nz, var):
            if rows[k] not in outside:
                self.waiting.setdefault(v, set()).add(rows[k])
        # a row reading an unknown only in a condition (a derivative that is a structural 0:
        # if x < 1 then a else b) is no alias: the rest would hold that unknown
        nonlinear = {rows[k] for k in nz} | {rows[k] for k, c in enumerate(coefs) if _is_zero(c)}
        nonlinear |= read_through_steps(dae.residual, w)
        terms: dict[int, list] = {}
        for k, (r, c) in enumerate(zip(rows, cols)):
            terms.setdefault(r, []).append((c, coefs[k]))
        cand = [r for r in sorted(terms) if r not in outside and r not in nonlinear]
        if cand:
            rests = ca.vertsplit(ca.substitute(dae.residual[cand], w, ca.SX.zeros(w.numel())))
            for j, r in enumerate(cand):
                self._candidate(r, terms[r], _num(rests[j]))
        while self.queue:
            r = self.queue.popleft()
            self.queued.discard(r)
            if r in self.used:
                continue
            found = self._solve(*self.rows[r])
            if found is not None:
                self._eliminate(r, *found)

    def _candidate(self, r: int, terms, rest):
        self.rows[r] = (terms, rest)
        for c, _k in terms:
            self.of_root.setdefault(c, set()).add(r)
        self._push(r)

    def _push(self, r: int):
        if r not in self.queued and r not in self.used:
            self.queue.append(r)
            self.queued.add(r)

    def _eliminate(self, r: int, e: int, d: tuple):
        self.defs[e] = d
        self.used.add(r)
        root = d[1]
        moved = self.of_root.pop(e, set())
        for q in moved:
            self._push(q)
        if root is not None:            # rows of e now read root (the smaller set merged in)
            mine = self.of_root.setdefault(root, set())
            if len(mine) < len(moved):
                mine, moved = moved, mine
                self.of_root[root] = mine
            mine |= moved
        for q in self.waiting.pop(e, set()):
            if root is not None:
                self.waiting.setdefault(root, set()).add(q)
            elif q not in self.rows:
                self._linearised(q)

    def _linearised(self, r: int):
        """Row ``r`` with the unknowns eliminated so far replaced: a candidate when it is now
        linear (called when an unknown of its coefficients is eliminated to a value)."""
        row = self.dae.residual[r]
        syms = [s for s in ca.symvar(row) if s.element_hash() in self.index]
        cols = [self.index[s.element_hash()] for s in syms]
        vals = [self.expr(c) for c in cols]
        row = ca.substitute([row], [ca.vertcat(*syms)], [ca.vertcat(*vals)])[0] if syms else row
        syms = [s for s in ca.symvar(row) if s.element_hash() in self.index]
        if not syms:
            return
        v = ca.vertcat(*syms)
        jac = ca.jacobian(row, v)
        if ca.depends_on(jac, v) or any(_is_zero(_num(jac[0, k])) for k in range(v.numel())):
            return                   # nonlinear, or an unknown read only in a condition
        rest = ca.substitute(row, v, ca.SX.zeros(v.numel()))
        self._candidate(r, [(self.index[s.element_hash()], _num(jac[0, k])) for k, s in enumerate(syms)], _num(rest))

    def find(self, v: int):
        """(alpha, root, beta): w[v] = alpha * w[root] + beta, root an unknown that stays (or None)."""
        chain = []
        while v in self.defs and self.defs[v][1] is not None and self.defs[v][1] in self.defs:
            chain.append(v)
            v = self.defs[v][1]
        out = self.defs.get(v, (1.0, v, 0.0))
        for u in reversed(chain):          # shortened: each now points at the root
            alpha, _, beta = self.defs[u]
            out = self.defs[u] = (_mul(alpha, out[0]), out[1], _add(_mul(alpha, out[2]), beta))
        return out

    def _solve(self, terms, rest):
        """(e, (alpha, root, beta)) when the row defines an algebraic unknown e; else None."""
        roots = set()
        for c, _k in terms:
            roots.add(self.find(c)[1])
            if len(roots) > self.MAX_DISTINCT:
                return None
        coef = {q: 0.0 for q in roots}
        const = rest
        for c, k in terms:
            alpha, root, beta = self.find(c)
            coef[root] = _add(coef[root], _mul(k, alpha))
            const = _add(const, _mul(k, beta))
        live = sorted(q for q in roots if q is not None and not _is_zero(coef[q]))
        # the unknown solved for needs a coefficient that cannot vanish with the model's mode
        # or a condition (a clutch's ``if locked then sa else ...``, a flow's semiLinear:
        # dividing by it is 0/0 in the other branch)
        alg = [q for q in live if q >= self.nx and not self._switched(coef[q])]
        # nor one that is 0 at the parameters' values (an inertia's J*a = tau with J = 0, as the
        # MSL's Vehicle example sets: a = tau/J is inf, the other unknown, tau = J*a, is fine)
        alg = [q for q in alg if not self._vanishes(coef[q])]
        if not 1 <= len(live) <= 2 or not alg:
            return None
        e = alg[-1]
        k_e = coef[e]
        other = [q for q in live if q != e]
        if other:
            return e, (_div(-coef[other[0]], k_e), other[0], _div(-const, k_e))
        return e, (0.0, None, _div(-const, k_e))

    def _switched(self, k) -> bool:
        """A coefficient that may be 0 where the model's mode or a condition says so (a
        conditional, a discrete variable): no pivot."""
        if not isinstance(k, ca.SX) or k.is_constant():
            return False
        if self.modes is None:
            d = self.dae
            self.modes = ca.vertcat(d.d, d.d_pre, d.x_pre, d.z_pre, d.flags)
        if self.modes.numel() > 0 and ca.depends_on(k, self.modes):
            return True
        f = ca.Function("k", ca.symvar(k), [k])
        return any(f.instruction_id(i) == ca.OP_IF_ELSE_ZERO for i in range(f.n_instructions()))

    def _vanishes(self, k) -> bool:
        """A coefficient in parameters that is 0 (or not finite) at their values."""
        if not isinstance(k, ca.SX) or k.is_constant() or self.dae.p_values is None:
            return False
        at = ca.substitute(k, self.dae.p, ca.DM(np.asarray(self.dae.p_values, float)))
        if not at.is_constant():
            return False
        v = float(at)
        return v == 0.0 or not math.isfinite(v)

    def expr(self, e: int) -> ca.SX:
        """w[e] in the unknowns that stay."""
        alpha, root, beta = self.find(e)
        return ca.SX(beta) if root is None else ca.SX(_add(_mul(alpha, self.w[root]), beta))


#: operations whose derivative is 0 (or undefined) where their value steps: a row reading an
#: unknown through one of them has a constant Jacobian and still is not linear in it
_STEPS = {getattr(ca, f"OP_{n}") for n in ("FLOOR", "CEIL", "SIGN", "FMOD", "REMAINDER", "COPYSIGN",
                                           "LT", "LE", "EQ", "NE", "NOT", "AND", "OR")}


def rows_reading(sp: ca.Sparsity) -> list[list[int]]:
    """The columns each row of a sparsity pattern reads."""
    rows: list[list[int]] = [[] for _ in range(sp.size1())]
    for r, c in zip(*sp.get_triplet()):
        rows[r].append(c)
    return rows


def read_through_steps(rows: ca.SX, v: ca.SX) -> set[int]:
    """The rows of ``rows`` that read ``v`` through a step (floor(x), x > 1, mod's quotient):
    ``x - floor(x)`` has the Jacobian of ``x`` and must not be solved as if it were ``x``."""
    return {r for r, mask in enumerate(steps_read(rows, v, per_entry=False)) if mask}


def steps_read(rows: ca.SX, v: ca.SX, per_entry: bool = True) -> list[int]:
    """Per row of ``rows``, a bit mask of the entries of ``v`` it reads through a step (1 for
    any, without ``per_entry``): one pass over the rows' instructions answers for every (row,
    entry) pair (a block's rows and unknowns, a tearing's pivots), where a pass per pair walked
    a steam model's shared media expressions again each time."""
    n = rows.numel()
    if n == 0 or v.numel() == 0:
        return [0] * n
    f = ca.Function("steps", [v], [ca.vec(rows)], {"allow_free": True})
    row_of = f.sparsity_out(0).row()
    dep, step = [0] * (f.sz_w() + 1), [0] * (f.sz_w() + 1)    # per work slot: masks of v read; read through a step
    found = [0] * n
    op_of, ins_of, outs_of = f.instruction_id, f.instruction_input, f.instruction_output
    for k in range(f.n_instructions()):
        op, ins, outs = op_of(k), ins_of(k), outs_of(k)
        if op == ca.OP_INPUT:
            dep[outs[0]], step[outs[0]] = 1 << ins[1] if per_entry else 1, 0
        elif op == ca.OP_OUTPUT:
            found[row_of[outs[1]]] |= step[ins[0]]
        elif op == ca.OP_IF_ELSE_ZERO:       # the condition is a step; the value is not
            c, x = ins
            dep[outs[0]], step[outs[0]] = dep[c] | dep[x], dep[c] | step[c] | step[x]
        else:                                # (the output slot may be an input's: read them first)
            d = s_ = 0
            for i in ins:
                d |= dep[i]
                s_ |= step[i]
            dep[outs[0]], step[outs[0]] = d, (d if op in _STEPS else 0) | s_
    return found


# Coefficients are mostly plain numbers (1, -1, 0): kept as floats, CasADi only when symbolic
def _num(k):
    return float(k) if isinstance(k, ca.SX) and k.is_constant() else k


def _is_zero(a) -> bool:
    return a == 0.0 if isinstance(a, float) else a.is_zero()


def _mul(a, b):
    if isinstance(a, float) and isinstance(b, float):
        return a * b
    if isinstance(a, float) and a in (0.0, 1.0):
        return b if a == 1.0 else 0.0
    if isinstance(b, float) and b in (0.0, 1.0):
        return a if b == 1.0 else 0.0
    return a * b


def _add(a, b):
    if isinstance(a, float) and isinstance(b, float):
        return a + b
    if isinstance(a, float) and a == 0.0:
        return b
    if isinstance(b, float) and b == 0.0:
        return a
    return a + b


def _div(a, b):
    if isinstance(a, float) and isinstance(b, float):
        return a / b
    if isinstance(b, float) and b == 1.0:
        return a
    if isinstance(a, float) and a == 0.0:
        return 0.0
    return a / b
