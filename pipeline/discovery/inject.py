"""Candidate laws inside the compiled model: the user's DAE with one component's law changed.

The model is compiled once, exactly as written (:attr:`mcl.model.CompiledModel.dae` is its DAE
before alias elimination, where each equation is still the one the flat model has). A candidate
changes one component's law there, and only there, by a deviation ``D`` at its terminals:

- ``parallel`` (a law giving the flow, i = f(v, dv): resistors, springs, dampers, capacitors):
  in every equation outside the component (the flow sums of its nets, a user's equation that
  reads its current) the flow into connector a is ``f_a + D`` and into b ``f_b - D``: the
  component's own equations still hold for its own variables, and what the rest of the model
  sees flowing through it is the nominal law's flow plus D.
- ``series`` (a law giving the across value, v = g(i, di): inductors): inside the component
  the potential of connector a is ``x_a - D``: the component's own law holds for what is left
  of the across value.

The law's equation fixes D. For a law that gives its variable explicitly (i = f_w(v, dv)), D =
f_w(...) - f_nom(...), with f_nom the nominal law: its own linear form in the law's variables
where that is exact (fitted along the nominal run; for a law that reads the connectors' own
potentials va, vb, an affine form with its constant), else the flow the component's own
equations give (a tank's outlet q = (h_a + h_op)/R under a law in h_a - h_b). What the rest of
the model sees is exactly f_w, the candidate law, as its learned class states it; at the start
w0 (the law fitted to the nominal one) the candidate's first simulation is the nominal model
where the nominal law is in the family, and close to it otherwise. An implicit law G(v, i, ...) = 0
replaces the terminal behaviour outright. The law's derivatives (dv, di) are new states tied to
the across value or the flow; index reduction differentiates those ties as it does any
constraint. Everything else the user wrote (initial equations, start values, parameters, other
components) is untouched.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..compile.components import Component
from ..compile.dae import Dae, eliminate_aliases
from ..errors import ModelicaError, UnsupportedConstruct

#: suffixes of the names a candidate adds to its component (readable through ``probe``)
ACROSS, FLOW, DEVIATION = "mcl_v", "mcl_i", "mcl_d"


@dataclass(frozen=True)
class NominalForm:
    """The nominal law's linear form in the candidate law's variables: f_nom = sum c_k x_k
    (x_k among v, dv, va, vb and the constant 1 for a parallel law; i, di for a series one) and
    how well it fits the nominal law along the nominal run (relative RMS error; ~0 for a linear
    or affine nominal law)."""

    coefficients: dict
    error: float

    @property
    def exact(self) -> bool:
        return self.error < 1e-6


def nominal_form(env: dict, variables: list[str], target: str) -> NominalForm:
    """f_nom = the least-squares fit of the nominal law's ``target`` (i or v) along the nominal
    run on ``variables`` (a subset of v, dv, va, vb, 1 or i, di; ``1`` the constant)."""
    y = np.asarray(env[target], float)
    if not variables:
        return NominalForm({}, float(np.sqrt(np.mean(y**2)) / (np.sqrt(np.mean(y**2)) + 1e-300)) if np.any(y) else 0.0)
    X = np.column_stack([np.ones_like(y) if v == "1" else np.asarray(env[v], float) for v in variables])
    c, *_ = np.linalg.lstsq(X, y, rcond=None)
    scale = float(np.sqrt(np.mean(y**2))) or 1.0
    return NominalForm(dict(zip(variables, map(float, c))), float(np.sqrt(np.mean((y - X @ c) ** 2)) / scale))


def nominal_of(env: dict, uses, series: bool = False) -> NominalForm:
    """The nominal law's form for a candidate law that uses ``uses``: in the difference variables
    the law reads (v, dv; i, di for a series law), or, where that does not fit the nominal law
    and the law reads a connector's own potential (or has a constant term, ``"1"`` in
    ``uses``), affine in those potentials (the nominal law of a tank's outlet follows the level
    upstream, h_a, not h_a - h_b), or in both; the closest, the plainer on a tie."""
    if series:
        return nominal_form(env, [v for v in ("i", "di") if v in uses], "v")
    plain = [v for v in ("v", "dv") if v in uses]
    best = nominal_form(env, plain, "i")
    absolute = [v for v in ("va", "vb") if v in uses and v in env]
    if best.exact or not (absolute or "1" in uses):
        return best
    for variables in (["1", *absolute], [*plain, "1", *absolute]):
        form = nominal_form(env, _independent(env, variables), "i")
        if form.error < best.error - 1e-9:
            best = form
    return best


def _independent(env: dict, variables: list[str]) -> list[str]:
    """``variables`` without those the others already span along the run (v = va - vb; a
    potential held constant is the constant term), in order: a nominal form's coefficients stay
    unique and of the nominal law's size."""
    out, cols = [], []
    for v in variables:
        col = np.ones(len(np.asarray(env["i"]))) if v == "1" else np.asarray(env[v], float)
        trial = np.column_stack([*cols, col])
        sv = np.linalg.svd(trial / np.maximum(np.abs(trial).max(axis=0), 1e-300), compute_uv=False)
        if sv[-1] > 1e-6 * sv[0]:
            out.append(v)
            cols.append(col)
    return out


def mode_of(template) -> str:
    """``series`` for a law giving the across value (v = g(i, di)), else ``parallel``."""
    return "series" if template.explicit == "v" else "parallel"


def own_nominal(comp: Component, template) -> bool:
    """Whether a law of ``template`` at ``comp`` takes the nominal law's place as the model writes
    it (a user's equation or a term of a balance, whose law is known as an expression): the rest
    of the model sees exactly the candidate law, and the Modelica written for it is the law."""
    return template.explicit == "i" and (comp.equation or comp.term)


def qualified(component: str, names: list[str], taken) -> list[str]:
    """Parameter names of a candidate law: ``R1.w2``, or ``R1.mcl_w2`` where the component has
    a parameter of that name already."""
    out = []
    for n in names:
        q = f"{component}.{n}"
        out.append(q if q not in taken else f"{component}.mcl_{n}")
    return out


def with_law(dae: Dae, comp: Component, template, w0, nominal: NominalForm | None = None,
             rates: dict | None = None, active=None) -> tuple[Dae, list[str]]:
    """``dae`` with ``comp``'s terminal law changed to ``template`` (parameters at ``w0``);
    returns the new DAE (before alias elimination, like the compiled one) and the law's
    parameter names, qualified with the component's name. ``rates``: the component's across
    value and flow as functions of the states (:func:`rate_variables`), for laws in their rates.
    ``active``: which parameters are in the law (a pruned law); a rate only pruned terms use is
    not needed (their coefficient is nought)."""
    nominal = nominal or NominalForm({}, 1.0)
    dae, D, env = _deviation(dae, comp, mode_of(template))
    explicit = template.explicit is not None
    uses = template.uses if active is None else template.uses_where(active)
    needs = set(uses) | (set(nominal.coefficients) - {"1"} if explicit else set())
    env = _derivatives(dae, comp, env, needs, rates)
    env.update({v: ca.SX(0) for v in template.uses - set(env)})
    names = qualified(comp.name, template.parameter_names(), set(dae.p_names))
    w = ca.SX.sym("w", len(names))
    ws = ca.vertsplit(w)
    if hasattr(template, "state_rate"):
        dae, env = _hidden_state(dae, comp, template, ws, env)
    if explicit:
        law = D - (template.sx_explicit(ws, env) - _nominal_law(comp, template, nominal, env))
    else:
        law = template.sx_residual(ws, env)
    return _add(dae, rows=[law], p=(w, names, np.asarray(w0, float))), names


def _hidden_state(dae: Dae, comp: Component, template, ws, env: dict) -> tuple[Dae, dict]:
    """``dae`` with the law's own state (a hysteresis' z: :mod:`mcl.hysteresis`), started at 0
    (the part relaxed), and its equation; ``env`` with it."""
    name = f"{comp.name}.mcl_{template.STATE}"
    z, dz = ca.SX.sym(name), ca.SX.sym(f"der({name})")
    env = {**env, template.STATE: z}
    nx, hybrid = dae.x.numel(), {}
    if dae.x_pre.numel() == nx and nx:        # (a hybrid model's pre() and reinit() of the states)
        hybrid["x_pre"] = ca.vertcat(dae.x_pre, ca.SX.sym(f"pre({name})"))
    if dae.x_reinit.numel() == nx and nx:
        hybrid["x_reinit"] = ca.vertcat(dae.x_reinit, z)
    dae = dataclasses.replace(
        dae, x=ca.vertcat(dae.x, z), dx=ca.vertcat(dae.dx, dz), x_names=[*dae.x_names, name],
        x_start=ca.vertcat(dae.x_start, ca.SX(0)), x_fixed=np.append(np.asarray(dae.x_fixed, bool), True),
        residual=ca.vertcat(dae.residual, dz - template.state_rate(ws, env)), exprs={**dae.exprs, name: z},
        **hybrid)
    return dae, env


def _nominal_law(comp: Component, template, nominal: NominalForm, env: dict):
    """f_nom in D = f_w - f_nom: the nominal law as the model writes it where it is known (a
    user's equation, a term), else its linear form where that is exact (then the same law, in
    the law's own variables), else the component's own flow as its equations give it (a law
    the linear form misses: an outlet affine in its upstream level, q = (h_a + h_op)/R, for a
    law in h_a - h_b). Either way the rest of the model sees exactly the candidate law f_w, as
    the learned class written for it states it."""
    if own_nominal(comp, template):
        return env["nominal"]
    if nominal.exact or "own" not in env:
        return sum((c * (1.0 if v == "1" else env[v]) for v, c in nominal.coefficients.items()), ca.SX(0))
    return env["own"]


def _deviation(dae: Dae, comp: Component, mode: str) -> tuple[Dae, ca.SX, dict]:
    """The new unknown D put at ``comp``'s terminals, and the law's variables as expressions:
    v (the across value the rest of the model sees), i (the flow into connector a), va and vb
    (the potentials of connectors a and b)."""
    if comp.term:
        return _term_deviation(dae, comp)
    names = [n for n in (*comp.across(), *comp.flow()) if n is not None]
    for n in names:
        s = dae.exprs.get(n)
        if s is None or not (s.is_symbolic() and s.numel() == 1):
            raise ModelicaError(f"{n} is not a variable of the compiled model: {comp.name} cannot take a law")
    # a signal block: its input is the law's v (against nought), its output the law's i
    xa, xb, fa, fb = (dae.exprs[n] if n is not None else ca.SX(0) for n in (*comp.across(), *comp.flow()))
    D = ca.SX.sym(f"{comp.name}.{DEVIATION}")
    external = _external_rows(dae, comp)
    rows = ca.vertsplit(dae.residual) if dae.residual.numel() else []
    exprs = dict(dae.exprs)
    if mode == "parallel" and (comp.signal or comp.sensor):   # what the rest reads of its output
        old, new, pick = fa, fa + D, external
        exprs[comp.flow()[0]] = fa + D
    elif mode == "parallel":
        old, new = ca.vertcat(fa, fb), ca.vertcat(fa + D, fb - D)
        pick = external
        exprs[comp.flow()[0]], exprs[comp.flow()[1]] = fa + D, fb - D
    elif comp.signal or comp.sensor:
        raise UnsupportedConstruct(f"{comp.name} is a signal block or a sensor: its law gives its output")
    else:
        old, new = xa, xa - D
        pick = [k for k in range(len(rows)) if k not in set(external)]
    if mode == "parallel" and not (comp.signal or comp.sensor):
        old, new = _carried(dae, comp, D, old, new, exprs)
    for k in pick:
        if ca.depends_on(rows[k], old):
            rows[k] = ca.substitute(rows[k], old, new)
    i = fa + D if mode == "parallel" else fa
    env = {"v": xa - xb, "i": i, "va": xa, "vb": xb}
    if mode == "parallel":        # the flow its own equations still give (the nominal law's)
        env["own"] = fa
    if comp.equation:       # its nominal law: the equation solved for its variable (affine in it)
        row = next(rows[k] for k in range(len(rows)) if k not in set(external) and ca.depends_on(rows[k], fa))
        env["nominal"] = ca.substitute(-row / ca.jacobian(row, fa), fa, ca.SX(0))
    exprs[f"{comp.name}.{ACROSS}"], exprs[f"{comp.name}.{FLOW}"], exprs[f"{comp.name}.{DEVIATION}"] = xa - xb, i, D
    dae = dataclasses.replace(dae, residual=ca.vertcat(*rows) if rows else ca.SX(0, 1), exprs=exprs,
                              z=ca.vertcat(dae.z, D), z_names=[*dae.z_names, f"{comp.name}.{DEVIATION}"],
                              z_start=ca.vertcat(dae.z_start, ca.SX(0)))
    return dae, D, env


def _carried(dae: Dae, comp: Component, D, old, new, exprs: dict):
    """``old`` and ``new`` (what the rest of the model sees of the flows) with the pairs the
    connectors carry after their first: each flow with the deviation's share, taken from the
    side it comes from (a FluidHeatFlow pipe's enthalpy flow with its mass flow,
    ``semiLinear(D, h_a, h_b)``), as the learned class writes it (:func:`mcl.templates._carried`)."""
    a, b = comp.connectors
    for x, f in zip(a.potential[1:], a.flow[1:]):
        names = [f"{comp.name}.{c.name}.{v}" for c, v in ((a, x), (b, x), (a, f), (b, f))]
        if not all(n in dae.exprs and dae.exprs[n].is_symbolic() for n in names):
            continue
        xa, xb, fa, fb = (dae.exprs[n] for n in names)
        share = ca.if_else(D > 0, D * xa, D * xb)       # (continuous: both nought at D = 0)
        old, new = ca.vertcat(old, fa, fb), ca.vertcat(new, fa + share, fb - share)
        exprs[names[2]], exprs[names[3]] = fa + share, fb - share
    return old, new


def _term_deviation(dae: Dae, comp: Component) -> tuple[Dae, ca.SX, dict]:
    """The deviation D added to a term of the user's balance (k*x in m*der(v) = u - k*x: the
    balance reads k*x + D), and the law's variables: v the term's unknown, i the term with D."""
    from ..compile.equations import term_of

    if comp.inputs[0] not in dae.exprs:
        raise ModelicaError(f"{comp.inputs[0]} is not a variable of the compiled model: {comp.cls} cannot take a law")
    term, _ = term_of(dae, comp)
    D = ca.SX.sym(f"{comp.name}.{DEVIATION}")
    rows = ca.vertsplit(dae.residual)
    for k in comp.rows:
        rows[k] = rows[k] + term_of(dae, comp, k)[1] * D
    x = dae.exprs[comp.inputs[0]]
    env = {"v": x, "i": term + D, "va": x, "vb": ca.SX(0), "nominal": term}
    exprs = {**dae.exprs, f"{comp.name}.{ACROSS}": x, f"{comp.name}.{FLOW}": term + D, f"{comp.name}.{DEVIATION}": D}
    dae = dataclasses.replace(dae, residual=ca.vertcat(*rows), exprs=exprs, z=ca.vertcat(dae.z, D),
                              z_names=[*dae.z_names, f"{comp.name}.{DEVIATION}"], z_start=ca.vertcat(dae.z_start, ca.SX(0)))
    return dae, D, env


def _external_rows(dae: Dae, comp: Component) -> list[int]:
    """Rows of the residual that read a variable outside ``comp`` (its nets' flow sums, the
    connections, the other components' and the user's own equations)."""
    unknowns = ca.vertcat(dae.x, dae.dx, dae.z)
    names = [*dae.x_names, *dae.x_names, *dae.z_names]
    if comp.equation:     # its own row reads its variables only, no derivative (a balance may read x')
        names = [*dae.x_names, *(f"der({n})" for n in dae.x_names), *dae.z_names]
    sp = ca.jacobian_sparsity(dae.residual, unknowns) if dae.residual.numel() else None
    if sp is None:
        return []
    rows, cols = sp.get_triplet()
    foreign = np.zeros(dae.residual.numel(), bool)
    outside = np.array([n not in comp.inputs for n in names] if comp.equation else [not comp.owns(n) for n in names])
    foreign[np.asarray(rows)[outside[np.asarray(cols, int)]]] = True
    return [int(k) for k in np.flatnonzero(foreign)]


def _derivatives(dae: Dae, comp: Component, env: dict, needs, rates: dict | None) -> dict:
    """dv and di for a law that uses them: the gradient of the across value (or flow), as a
    function of the states alone, times x' (:func:`rate_variables`); a law in the rate of a
    variable the states do not set would add a state of its own (and start singular at w0,
    where its coefficient is nought): refused as not applicable there."""
    for var, d in (("v", "dv"), ("i", "di")):
        if d not in needs:
            continue
        e = (rates or {}).get(var)
        if e is None:
            what = "across value" if var == "v" else "flow"
            raise UnsupportedConstruct(f"the {what} of {comp.name} is not set by the model's states: a law in "
                                       f"its rate would add a state there")
        env[d] = ca.jtimes(e, dae.x, dae.dx) + ca.jacobian(e, dae.t)
    return env


def rate_variables(dae: Dae, comps: list[Component], modes: dict[str, str]) -> dict[str, dict]:
    """For each component, its across value v and flow i as functions of the states alone
    (``{"v": expr or None, "i": expr or None}``), read from the model with a deviation at every
    component (:func:`with_injections`) after alias elimination: a variable that depends on an
    algebraic unknown, an input or any deviation is not set by the states (a law in its rate
    would change the model's structure)."""
    sdae, j_names = with_injections(dae, comps, modes)
    e = eliminate_aliases(sdae)
    j = ca.vertcat(*[e.p[e.p_names.index(n)] for n in j_names]) if j_names else ca.SX(0, 1)
    others = ca.vertcat(e.z, e.u, j)

    def pure(expr):
        return expr if not ca.depends_on(expr, others) else None

    out = {}
    for c in comps:
        xa, xb = c.across()
        out[c.name] = {"v": pure(e.exprs[xa] - (e.exprs[xb] if xb is not None else 0)),
                       "i": pure(e.exprs[c.flow()[0]]) if modes.get(c.name) == "series" else None}
    return out


def _add(dae: Dae, rows, p) -> Dae:
    """``dae`` with equations ``rows`` and new free parameters ``p`` = (symbols, names, values)."""
    sym, names, values = p
    return dataclasses.replace(dae, residual=ca.vertcat(dae.residual, *rows), p=ca.vertcat(dae.p, sym),
                               p_names=[*dae.p_names, *names], p_values=np.concatenate([dae.p_values, values]),
                               exprs={**dae.exprs, **{n: sym[k] for k, n in enumerate(names)}})


def with_injections(dae: Dae, comps: list[Component], modes: dict[str, str]) -> tuple[Dae, list[str]]:
    """``dae`` with a deviation at each of ``comps`` equal to a parameter of its own (named
    ``<component>.mcl_j``, nominal value 0): the screening model, in which the response to a
    deviation at any component can be read off one simulation."""
    names = []
    for comp in comps:
        dae, D, _env = _deviation(dae, comp, modes.get(comp.name, "parallel"))
        j = ca.SX.sym(f"{comp.name}.mcl_j")
        name = f"{comp.name}.mcl_j"
        dae = _add(dae, rows=[D - j], p=(j, [name], np.zeros(1)))
        names.append(name)
    return dae, names


def compiled(dae: Dae, name: str, outputs=(), info: dict | None = None, structure=None):
    """A :class:`mcl.model.CompiledModel` of ``dae`` with ``outputs`` appended to its outputs."""
    from ..model import CompiledModel

    return CompiledModel.from_dae(dae, name, outputs, info, structure)
