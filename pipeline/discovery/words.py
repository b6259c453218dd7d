"""Laws in the component's own words: the domain's names for the across and flow variables.

Templates are written in v (across, connector a minus b) and i (flow into connector a). A
report names them as the domain does, with the Modelica Standard Library's orientation: an
electrical or thermal element's v = p.v - n.v / dT = port_a.T - port_b.T with the flow into the
first connector; a mechanical element's s_rel = flange_b.s - flange_a.s with f = flange_b.f (the
opposite orientation, so the law's odd and even terms are rewritten accordingly). The connectors'
own potentials va, vb are named as the model names them (Outlet1.a.h, Rad.port_a.T,
D.flange_a.s): they keep their sign whatever the orientation.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import MclError

#: potential variable -> (across, its derivative, flow, orientation b - a)
DOMAINS = {
    "v": ("v", "der(v)", "i", False),
    "T": ("dT", "der(dT)", "Q_flow", False),
    "s": ("s_rel", "v_rel", "f", True),
    "phi": ("phi_rel", "w_rel", "tau", True),
    "p": ("dp", "der(dp)", "m_flow", False),
}


@dataclass(frozen=True)
class Words:
    """A component's law variables by name, with their definitions."""

    across: str
    rate: str
    flow: str
    flipped: bool           # across and flow are b - a and the flow into b
    definitions: str
    potentials: tuple[str, str] = ("va", "vb")   # the potentials of connectors a and b

    @property
    def names(self) -> dict:
        return {"v": self.across, "dv": self.rate, "i": self.flow, "va": self.potentials[0],
                "vb": self.potentials[1]}


def words(comp) -> Words:
    if comp.sensor:          # its reading in what it measures
        y = comp.inputs[0]
        x = f"{comp.name}.measured"
        return Words(x, f"der({x})", y, False, f"{x} is what {comp.name} measures ({y} as the model wrote it), "
                     f"{y} what it reads out", (x, "0"))
    if comp.term:            # a term of the user's balance, in its unknown
        x, label = comp.inputs
        return Words(x, f"der({x})", label, False, f"{label} is a term of a balance of the model, in {x}", (x, "0"))
    if comp.equation:        # the user's own equation: its variable in what it reads
        xa, xb = comp.across()
        y = comp.flow()[0]
        x = f"({xa} - {xb})" if xb else xa
        return Words(x, f"der({x})", y, False, f"{y} is given by an equation of the model in {x}", (xa, xb or "0"))
    a, b = comp.connectors
    if comp.signal:          # a block: its output in its input
        u, y = (f"{comp.name}.{c.name}" for c in (a, b))
        return Words(u, f"der({u})", y, False, f"{u} is the block's input, {y} its output", (u, "0"))
    x, f = a.potential[0], a.flow[0]
    across, rate, flow, flipped = DOMAINS.get(x, (f"d{x}", f"der(d{x})", f, False))
    first, second = (b, a) if flipped else (a, b)
    q = lambda name: f"{comp.name}.{name}"
    rate_def = f"der({q(across)})" if not rate.startswith("der(") else None
    defs = (f"{q(across)} = {q(first.name)}.{x} - {q(second.name)}.{x}, {q(flow)} = {q(first.name)}.{f}"
            + (f", {q(rate)} = {rate_def}" if rate_def else ""))
    rate_name = f"der({q(across)})" if rate.startswith("der(") else q(rate)
    return Words(q(across), rate_name, q(flow), flipped, defs, (q(f"{a.name}.{x}"), q(f"{b.name}.{x}")))


def parity(term, constants: dict | None = None) -> int:
    """+1 for an even term, -1 for an odd one, 0 for neither (checked numerically on v, i, dv, di
    changing sign together, with a hysteresis' z, the part of v it follows: the orientation
    flip; the potentials va, vb keep theirs, a constant is even; ``constants``: the values of
    scale names)."""
    rng = np.random.default_rng(1)
    env = {k: rng.uniform(0.1, 2.0, 16) for k in ("v", "i", "dv", "di", "z")}
    pots = {k: rng.uniform(0.1, 2.0, 16) for k in ("va", "vb")}
    neg = {**(constants or {}), **pots, **{k: -x for k, x in env.items()}}
    env = {**(constants or {}), **pots, **env}
    with np.errstate(all="ignore"):
        a, b = np.asarray(term.value(env), float), np.asarray(term.value(neg), float)
    if np.allclose(a, b, rtol=1e-9, atol=1e-12):
        return 1
    if np.allclose(a, -b, rtol=1e-9, atol=1e-12):
        return -1
    return 0


def in_words(template, w, comp, digits: int = 4) -> str:
    """The fitted law of ``template`` with the component's own variable names."""
    wd = words(comp)
    if not wd.flipped or not hasattr(template, "terms"):
        if wd.flipped:   # no terms to rewrite: name the variables by their definitions
            return _renamed(_equation(template, w, f"(-{wd.across})", f"(-{wd.flow})", digits, wd), wd)
        return _renamed(_equation(template, w, wd.across, wd.flow, digits, wd), wd)
    # v = -across', i = -flow' (va, vb keep their names and signs): an even term keeps its
    # value, an odd one changes sign, one that is neither (exp(v/s) - 1) is written in -across;
    # the whole law in the negated variables only where its first term is neither
    signs = np.array([parity(t, getattr(template, "scales", None)) for t in template.terms])
    if signs[0] == 0:
        return _renamed(_equation(template, w, f"(-{wd.across})", f"(-{wd.flow})", digits, wd), wd)
    w = np.asarray(w, float).copy()
    w[:len(signs)] *= np.where(signs == 0, 1, signs) * signs[0]
    return _renamed(_equation(template, w, wd.across, wd.flow, digits, wd,
                              negated={k for k in range(len(signs)) if signs[k] == 0}), wd)


def said(template, w, comp) -> str:
    """:func:`in_words`, or the template's own words where the law cannot be put in the
    component's (a third party's template)."""
    try:
        return in_words(template, w, comp)
    except MclError:
        return template.equation(w)


def _equation(template, w, across: str, flow: str, digits: int, wd: Words, negated=()) -> str:
    """``template``'s equation in these names; the potentials, and the terms ``negated``, named
    only for a law that has them (a third party's template need not know of them)."""
    more = {"negated": negated} if negated else {}
    if {"va", "vb"} & set(template.uses):
        more["potentials"] = wd.potentials
    return template.equation(w, across=across, flow=flow, digits=digits, **more)


def _renamed(text: str, wd: Words) -> str:
    """der(s_rel) reads v_rel, der(phi_rel) w_rel; der(-s_rel) reads (-v_rel)."""
    if not wd.rate.startswith("der("):
        for negated in (f"der((-{wd.across}))", f"der(-{wd.across})"):
            text = text.replace(negated, f"(-{wd.rate})")
        text = text.replace(f"der({wd.across})", wd.rate)
    return text
