"""The user's own constitutive laws as components, in a model written with equations, not parts.

An engineer's small model is often a handful of equations (two tanks: two balances, two outflow
laws, a pump and a sensor; an oscillator: m*der(v) = kf*u - d*v - k*x) with no part that
discovery could question. Two kinds of the model's own equations (top-level, or of an instance
of the user's own class that is not a part: a ``Tank`` of Real inputs and outputs) hold its
laws:

- an equation that gives one algebraic variable as a function of one other (or of the
  difference of two) and of parameters, ``q1 = (h1 + h_op)/R1``: a component of kind
  ``equation``, named by the variable it gives, whose law is that variable in what it reads;
- a term of a balance made of parameters and one unknown that no other term of the balance
  reads, ``k*x``: a component of kind ``term``, named by its text (``k_x``), whose law is the
  term in its unknown (one flow written in the balances of both tanks it joins is one term).

Balances themselves, aliases, equations of time and the parts' own equations are not laws.
Found in the compiled DAE before alias elimination, where each row is still one equation of the
flat model; a candidate law replaces the equation or the term there (``discovery/inject.py``).
"""
from __future__ import annotations

import re

import casadi as ca
import numpy as np

from .components import Component, Connector, Structure, split_name
from .dae import rows_reading


def user_instances(dae, structure: Structure, classes_of) -> set[str]:
    """The instances of the user's own classes that are not parts (a ``Tank`` of a level, an
    inflow and an outflow declared ``input Real``/``output Real``, no connectors): their
    equations are the user's as much as the model's own are. ``classes_of(paths)`` gives each
    instance path's class and whether a library holds it ({path: (class, in a library)});
    an instance of a library class, a component or anything inside one is not the user's, nor
    is anything inside those."""
    parts = {c.name for c in structure.components.values()}
    paths = {tuple(split_name(n)[:-1]) for n in [*dae.x_names, *dae.z_names, *dae.u_names, *dae.p_names]}
    own: set[str] = set()
    level = sorted({p[:1] for p in paths if p})
    while level:
        names = [".".join(p) for p in level]
        found = classes_of([n for n in names if not any(n == c or n.startswith(c + ".") for c in parts)])
        kept = [p for p, n in zip(level, names) if n in found and not found[n][1]]
        own.update(".".join(p) for p in kept)
        level = sorted({q[:len(p) + 1] for p in kept for q in paths if len(q) > len(p) and q[:len(p)] == p})
    return own


def with_equations(structure: Structure, dae, own: set[str] = frozenset()) -> Structure:
    """``structure`` with the user's constitutive equations of ``dae`` added as components: the
    equations that give a variable (:func:`equation_laws`), the terms of the balances
    (:func:`term_laws`). ``own``: the instances whose equations are the user's, besides the
    model's own (:func:`user_instances`)."""
    rows = ca.vertsplit(dae.residual) if dae.residual.numel() else []
    if not rows:
        return structure
    reads = rows_reading(ca.jacobian_sparsity(dae.residual, ca.vertcat(dae.x, dae.dx, dae.z, dae.u)))
    plain = [*dae.x_names, *dae.x_names, *dae.z_names, *dae.u_names]      # (der(x) as x)
    # the model's own variables are its top-level ones and those of its instances of the user's
    # own classes; a part's (a PI controller's state, a tank's level inside a Tank with
    # connectors) are its class's, whose equations are not the user's here
    of_parts = [".".join(split_name(n)[:-1]) not in {"", *own} for n in plain]
    mine = [k for k in range(len(rows)) if not all(of_parts[c] for c in reads[k])]
    for comp in [*equation_laws(dae, rows, reads, mine, of_parts),
                 *term_laws(dae, rows, reads, mine, of_parts, structure)]:
        structure.components.setdefault(comp.name, comp)
    return structure


def equation_laws(dae, rows, reads, mine, of_parts) -> list[Component]:
    """The equations among rows ``mine`` of ``dae`` of the form y = g(x, p) (or g(xa - xb, p)):
    y an algebraic variable of the model's own (``of_parts``: the columns that are not), the equation affine in it with a constant
    coefficient, x one unknown or input (two whose difference g reads), no derivative, no time,
    at least one parameter (a plain alias is a connection, not a law)."""
    names = [*dae.x_names, *(f"der({n})" for n in dae.x_names), *dae.z_names, *dae.u_names]
    unknowns = ca.vertcat(dae.x, dae.dx, dae.z, dae.u)
    nx, nz = len(dae.x_names), len(dae.z_names)
    fixed = ca.vertcat(unknowns, dae.t)
    out, taken = [], set()
    for k in mine:
        row, cols = rows[k], reads[k]
        if (len(cols) not in (2, 3) or any(nx <= c < 2 * nx for c in cols) or ca.depends_on(row, dae.t)
                or not ca.depends_on(row, dae.p)):
            continue
        given = _given(row, [c for c in cols if 2 * nx <= c < 2 * nx + nz and not of_parts[c]],
                       unknowns, fixed, names)
        if given is None or names[given] in taken:
            continue
        read = [c for c in cols if c != given]
        across = _across(row, read, unknowns, names, ca.jacobian(row, unknowns[given]))
        if across is None:
            continue
        y = names[given]
        taken.add(y)
        chain = y in dae.outputs or any(names[c] in dae.u_names for c in read)
        params = [n for n, s in zip(dae.p_names, ca.vertsplit(dae.p)) if ca.depends_on(row, s)]
        conns = [Connector(n, "input Real", (), ()) for n in across] + [Connector(y, "output Real", (), ())]
        out.append(Component(y, "equation", conns, params, [*across, y], kind="equation", chain=chain))
    return out


def _given(row, candidates: list[int], unknowns, fixed, names) -> int | None:
    """The algebraic unknown ``row`` gives: affine in it with a constant coefficient, of
    magnitude one where several are (``v = R*i`` gives v), else none."""
    found = []
    for c in candidates:
        d = ca.jacobian(row, unknowns[c])
        if not ca.depends_on(d, fixed):
            found.append((c, d))
    if len(found) == 1:
        return found[0][0]
    unit = [c for c, d in found if d.is_constant() and abs(abs(float(ca.DM(d))) - 1.0) < 1e-12]
    return unit[0] if len(unit) == 1 else None


def _across(row, read: list[int], unknowns, names, coefficient) -> list[str] | None:
    """What the law reads: the one variable, or two whose difference alone the equation reads
    (q = (h1 - h2)/R: [h1, h2], the one of positive slope first); None otherwise."""
    if len(read) == 1:
        return [names[read[0]]]
    a, b = (unknowns[c] for c in read)
    ga, gb = ca.jacobian(row, a), ca.jacobian(row, b)
    rng = np.random.default_rng(0)
    syms = ca.symvar(ca.vertcat(ga, gb, coefficient))
    g = ca.Function("g", syms, [ga + gb, -ga / coefficient])
    for _ in range(3):
        total, slope = (float(v) for v in g(*rng.uniform(0.5, 2.0, len(syms))))
        if not np.isfinite(total) or abs(total) > 1e-9 * max(abs(slope), 1e-300):
            return None
    # the row is c*y - g: the law's v is the variable along which y rises, less the other
    return [names[read[0]], names[read[1]]] if slope > 0 else [names[read[1]], names[read[0]]]


def term_laws(dae, rows, reads, mine, of_parts, structure: Structure) -> list[Component]:
    """The terms of the user's own balances that are laws: in ``m*der(v) = kf*u - d*v - k*x``,
    d*v and k*x (a term of parameters and one unknown that no other term of the balance reads;
    not a derivative, an input or time), each a component named by its text (``k*x``: ``k_x``)
    whose law is that term as a function of its unknown."""
    nx = len(dae.x_names)
    kinds = {**{s.name(): ("x", n) for s, n in zip(ca.vertsplit(dae.x), dae.x_names)},
             **{s.name(): ("z", n) for s, n in zip(ca.vertsplit(dae.z), dae.z_names)},
             **{s.name(): ("dx", n) for s, n in zip(ca.vertsplit(dae.dx), dae.x_names)},
             **{s.name(): ("u", n) for s, n in zip(ca.vertsplit(dae.u), dae.u_names)},
             **{s.name(): ("p", n) for s, n in zip(ca.vertsplit(dae.p), dae.p_names)}}
    moving = ca.vertcat(dae.x, dae.dx, dae.z, dae.u, dae.t)
    out, taken, seen = [], set(structure.components), {}
    for k in mine:
        row = rows[k]
        # (a balance of the user's own variables only)
        if not any(nx <= c < 2 * nx for c in reads[k]) or any(of_parts[c] for c in reads[k]) or ca.depends_on(row, dae.t):
            continue
        leaves = additive_terms(row, moving)
        terms = [[kinds.get(s.name(), ("?", "")) for s in ca.symvar(leaf)] for leaf, _ in leaves]
        for (leaf, _), r in zip(leaves, terms):
            unknowns = {n for kind, n in r if kind in ("x", "z")}
            if (len(unknowns) != 1 or any(kind not in ("x", "z", "p") for kind, _ in r)
                    or not any(kind == "p" for kind, _ in r)):
                continue
            (x,) = unknowns
            if sum(x in {n for kind, n in other if kind in ("x", "z")} for other in terms) != 1:
                continue
            label = term_text(leaf, {s: n for s, (_, n) in kinds.items()})
            if label is None:
                continue
            if label in seen:           # the same flow in two balances (out of one tank, into the next)
                seen[label].rows.append(k)
                continue
            name = _term_name(label, [n for _, n in r])
            while name in taken:
                name += "_"
            taken.add(name)
            params = [n for kind, n in r if kind == "p"]
            conns = [Connector(x, "input Real", (), ()), Connector(label, "output Real", (), ())]
            out.append(Component(name, f"term {label}", conns, params, [x, label], kind="term", rows=[k]))
            seen[label] = out[-1]
    return out


def _term_name(label: str, names: list[str]) -> str:
    """A term's component name: its text as an identifier (``k*x``: ``k_x``), after the
    instance all its names are of (``upper.k*upper.h``: ``upper.k_h``)."""
    heads = {tuple(split_name(n)[:-1]) for n in names}
    inst = ".".join(next(iter(heads))) if len(heads) == 1 else ""
    if inst:
        label = re.sub(rf"(?<![\w.]){re.escape(inst)}\.", "", label)
    return (f"{inst}." if inst else "") + (re.sub(r"\W+", "_", label).strip("_") or "term")


def additive_terms(expr, moving) -> list[tuple]:
    """The terms of ``expr`` as a sum, each with its factor (parameters and constants): through
    +, -, unary minus and a factor (or divisor) free of ``moving`` times a sum of terms in
    several of ``moving``."""
    def pure(e):
        return not ca.depends_on(e, moving)

    def summed(e):      # a sum of several unknowns' terms (a factor of one unknown's sum stays: G*(T - Ta))
        return ((e.is_op(ca.OP_ADD) or e.is_op(ca.OP_SUB) or e.is_op(ca.OP_NEG))
                and sum(ca.depends_on(s, moving) for s in ca.symvar(e)) > 1)

    todo, out = [(expr, ca.SX(1))], []
    while todo:
        e, m = todo.pop()
        if e.is_op(ca.OP_ADD):
            todo += [(e.dep(1), m), (e.dep(0), m)]
        elif e.is_op(ca.OP_SUB):
            todo += [(e.dep(1), -m), (e.dep(0), m)]
        elif e.is_op(ca.OP_NEG):
            todo.append((e.dep(0), -m))
        elif e.is_op(ca.OP_MUL) and summed(e.dep(1)) and pure(e.dep(0)):
            todo.append((e.dep(1), m * e.dep(0)))
        elif e.is_op(ca.OP_MUL) and summed(e.dep(0)) and pure(e.dep(1)):
            todo.append((e.dep(0), m * e.dep(1)))
        elif e.is_op(ca.OP_DIV) and summed(e.dep(0)) and pure(e.dep(1)):
            todo.append((e.dep(0), m / e.dep(1)))
        else:
            out.append((e, m))
    return out


_BINARY = {ca.OP_ADD: (" + ", 1), ca.OP_SUB: (" - ", 1), ca.OP_MUL: ("*", 2), ca.OP_DIV: ("/", 2),
           ca.OP_POW: ("^", 4)}
_CALLS = {ca.OP_SQRT: "sqrt", ca.OP_EXP: "exp", ca.OP_LOG: "log", ca.OP_SIN: "sin", ca.OP_COS: "cos",
          ca.OP_TANH: "tanh", ca.OP_FABS: "abs", ca.OP_SIGN: "sign"}


def term_text(e, names: dict) -> str | None:
    """A term as Modelica text in the model's names (None for what it cannot write)."""
    def text(e) -> tuple[str, int] | None:
        if e.is_symbolic():
            return names[e.name()], 9
        if e.is_constant():
            v = float(ca.DM(e))
            s = f"{v:.12g}"
            return (s, 9) if v >= 0 else (f"({s})", 9)
        if e.is_op(ca.OP_NEG):
            a = text(e.dep(0))
            return None if a is None else (f"-{a[0] if a[1] > 1 else '(' + a[0] + ')'}", 3)
        if e.is_op(ca.OP_SQ):
            a = text(e.dep(0))
            return None if a is None else (f"{a[0] if a[1] > 4 else '(' + a[0] + ')'}^2", 4)
        for op, fn in _CALLS.items():
            if e.is_op(op):
                a = text(e.dep(0))
                return None if a is None else (f"{fn}({a[0]})", 9)
        for op, (sym, p) in _BINARY.items():
            if e.is_op(op):
                a, b = text(e.dep(0)), text(e.dep(1))
                if a is None or b is None:
                    return None
                left = a[0] if a[1] >= p and not (op == ca.OP_POW and a[1] == p) else f"({a[0]})"
                right = b[0] if b[1] > p or (b[1] == p and op in (ca.OP_ADD, ca.OP_MUL)) else f"({b[0]})"
                return f"{left}{sym}{right}", p
        return None

    out = text(e)
    return out[0] if out else None


def term_of(dae, comp, row: int | None = None):
    """(the term ``comp`` in its balance ``row`` of ``dae``, default its first; its factor
    there): the term of that row that reads the term's unknown (:func:`additive_terms`)."""
    expr = ca.vertsplit(dae.residual)[comp.rows[0] if row is None else row]
    x = dae.exprs[comp.inputs[0]]
    for leaf, m in additive_terms(expr, ca.vertcat(dae.x, dae.dx, dae.z, dae.u, dae.t)):
        if ca.depends_on(leaf, x):
            return leaf, m
    raise ValueError(f"the term {comp.cls} is not in its balance")
