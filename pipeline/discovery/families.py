"""Law families: which constitutive laws discovery tries for a component, chosen by its role.

The role is read off the nominal component's own law along the nominal simulation (v across,
i flow into connector a, dv and di their time derivatives):

- ``static``: i follows v (resistor, spring, thermal conductor), or v plus a constant;
- ``rate``: i follows dv (capacitor, damper, heat capacity between two ports);
- ``integral``: v follows di (inductor, inerter-like elements);
- ``absolute``: i follows one connector's own potential, affinely (a tank's outlet linearised
  about its operating level: q = (h_a + h_op)/R, whatever the level h_b downstream).

Families per role (each a template spec; all start from the nominal law, so the first
simulation of a candidate reproduces the nominal model):

- ``static``: i = f(v) (cubic; with a constant when the nominal law has one); a storage law
  i = f(v) dv + g(v) (a spring with damping);
- ``rate``: i = c0 + h(dv) (a damper cubic in the speed; Coulomb-like friction tanh(dv/s); a
  constant: the offset force of a friction model, the bias current of a capacitor); the
  storage law (a capacitor whose
  capacitance depends on its voltage, a leaky capacitor: i = C dv + G v);
- ``integral``: v = f(i) di + g(i);
- ``absolute``: i = c0 + c1 x + c2 x^2 + c3 x^3 in the potential x (va or vb) the nominal law
  follows (the model says the flow follows that potential, not the difference: one family).

Two more laws of a static component are tried only where the laws in v cannot reach the noise
(from the shape stage): the law the other way round, v = f(i) (:func:`inverse_families`: a
pipe's turbulent pressure drop, a saturating core), and laws in both potentials (radiation,
Q = G (T_a^4 - T_b^4), where the model has a linear conductor: :func:`potential_families`).
Terms in a potential are written in units of its span ((va/400)^4, not va^4 ~ 1e10 beside
v ~ 10): the screening's and the fit's least squares stay well conditioned.

Non-polynomial shapes (tanh, sinh, |x| x, x/sqrt(1 + x^2), exp) are found afterwards for the
most promising component only: a neural law fitted to the data is distilled into a sparse
readable law over that basis (:func:`distil`), which is fitted and pruned like the others.
"""
from __future__ import annotations

import re

import numpy as np

STATIC = {"name": "polynomial", "lhs": ["i"], "rhs": ["v", "v^2", "v^3"], "family": "static"}
#: the static law the other way round, the across value in the flow: where it grows faster
#: than the flow (a pipe's turbulent pressure drop k q|q|, a saturating core's magnetic
#: potential R (Phi + Phi^3/Phi_s^2)), i = f(v) is a root that no cubic in v follows
INVERSE = {"name": "polynomial", "lhs": ["v"], "rhs": ["i", "i*abs(i)", "i^3"], "family": "inverse"}
RATE = {"name": "polynomial", "lhs": ["i"], "rhs": ["dv", "dv^2", "dv^3"], "family": "rate"}
STORAGE = {"name": "polynomial", "lhs": ["i"], "rhs": ["dv", "v*dv", "v^2*dv", "v", "v^2", "v^3"],
           "family": "storage"}
INTEGRAL = {"name": "polynomial", "lhs": ["v"], "rhs": ["di", "i*di", "i^2*di", "i", "i^3"],
            "family": "storage"}
FAMILIES = {"static": [STATIC, STORAGE], "rate": [RATE, STORAGE], "integral": [INTEGRAL],
            "unknown": [STATIC, RATE, STORAGE], "absolute": []}
#: the variable a role's law is a function of (for the law curve and the shape family)
LAW_VARIABLE = {"static": "v", "rate": "dv", "integral": "i", "unknown": "v", "absolute": "va"}
#: R^2 a role's line must reach along the nominal run
ROLE_FIT = 0.99


def spec_name(spec) -> str:
    """The template name of a template spec (a name, or a dict with ``name``; a pair's two specs
    joined by +)."""
    if isinstance(spec, (list, tuple)):
        return "+".join(spec_name(s) for s in spec)
    return spec if isinstance(spec, str) else spec.get("name", "?")


def family_of(spec) -> str:
    """The law family a spec was chosen as (discovery's own specs say so), else its template name."""
    return (spec.get("family") if isinstance(spec, dict) else None) or spec_name(spec)


def _r2(y, x) -> float:
    """R^2 of a line through the origin."""
    y, x = np.asarray(y, float), np.asarray(x, float)
    if not np.any(x) or not np.any(y):
        return 0.0
    a = (x @ y) / (x @ x)
    return float(1.0 - np.sum((y - a * x) ** 2) / np.sum(y**2))


def _affine(y, x) -> tuple[float, float]:
    """(R^2 of a line with its constant, the constant's share of y's RMS)."""
    y, x = np.asarray(y, float), np.asarray(x, float)
    if not np.any(y) or np.ptp(x) <= 1e-12 * (np.max(np.abs(x)) + 1e-300):
        return 0.0, 0.0
    slope, c = np.polyfit(x, y, 1)
    rms = float(np.sqrt(np.mean(y**2)))
    return float(1.0 - np.sum((y - slope * x - c) ** 2) / np.sum(y**2)), abs(float(c)) / rms


def role_of(env: dict) -> str:
    """``static``, ``rate`` or ``integral``: which single variable explains the nominal law
    (R^2 > 0.99 of a line through the origin); else ``static`` for a law affine in v, and
    ``absolute`` for one affine in a connector's own potential (va or vb; one that v explains as
    well is static); ``unknown`` otherwise."""
    fits = {"static": _r2(env["i"], env["v"]), "rate": _r2(env["i"], env["dv"]), "integral": _r2(env["v"], env["di"])}
    best = max(fits, key=fits.get)
    if fits[best] > ROLE_FIT:
        return best
    if "va" not in env:
        return "unknown"
    affine = {"static": _affine(env["i"], env["v"])[0],
              "absolute": max(_affine(env["i"], env[x])[0] for x in ("va", "vb"))}
    best = "static" if affine["static"] >= affine["absolute"] - 1e-9 else "absolute"
    return best if affine[best] > ROLE_FIT else "unknown"


def _constant(env: dict) -> bool:
    """Whether the nominal flow has a constant beside its part in v (an affine law: more than a
    thousandth of its RMS, and a better fit with it)."""
    r2, share = _affine(env["i"], env["v"])
    return share > 1e-3 and r2 > _r2(env["i"], env["v"]) + 1e-6


def potential_of(env: dict) -> str:
    """The connector's potential (va or vb) the nominal flow follows best (affinely)."""
    return max(("va", "vb"), key=lambda x: _affine(env["i"], env[x])[0])


def unit_of(x) -> float:
    """The unit a potential's terms are written in: its largest value, to two digits (1 where
    that is between 0.3 and 3: a level in metres stays va^2)."""
    s = float(f"{float(np.max(np.abs(x))) if np.size(x) and np.any(x) else 1.0:.2g}")
    return 1.0 if 0.3 <= s <= 3.0 else s


#: the scales of the rate family's Coulomb-like terms, as shares of the rate's span: a sharp
#: one (dry friction's step at 0, which the wider ones round off over a fifth of the span) and
#: two wider (a friction that builds up, a saturation)
RATE_TANH = (0.01, 0.05, 0.25)


def families(role: str, env: dict | None = None, signal: bool = False, sensor: bool = False) -> list[dict]:
    """The template specs tried for a component of this role. A law in the rate also gets
    Coulomb-like friction terms tanh(dv/s), the dissipative element's classic non-polynomial
    part, at fixed scales (:data:`RATE_TANH` of the rate's nominal span: the law stays linear
    in its parameters, and pruning keeps what the data need; the shape stage fits the scale
    itself), and a constant (the offset force of a positioning axis's friction,
    M q'' = tau - Fv q' - Fc sign(q') - offset: without it a law bends its other terms to mimic
    one, and an open-loop position drifts). A signal block's law is static, its output in its
    input, with saturation terms tanh(v/s) at two fixed scales (a twentieth and a quarter of the input's span):
    the effect a block diagram most often lacks (an amplifier's or a valve's limits, which a
    cubic cannot follow beyond its knee). A sensor's law is its reading in what it measures,
    with those terms, a zero offset and |v|: a counter blind to the direction (a pulse
    counter's speed), a rectifying transducer."""
    if sensor:
        out = families("static", env, signal=True)
        out[0]["rhs"] = ["1", "v", "abs(v)", *out[0]["rhs"][1:]]
        return out
    out = [dict(f) for f in ([STATIC] if signal else FAMILIES[role])]
    span = float(np.max(np.abs(env["dv"]))) if env is not None and np.any(env["dv"]) else 1.0
    if signal:
        reach = float(np.max(np.abs(env["v"]))) if env is not None and np.any(env["v"]) else 1.0
        out[0]["rhs"] = [*out[0]["rhs"], f"tanh(v/{0.05 * reach:.3g})", f"tanh(v/{0.25 * reach:.3g})"]
    for f in out:
        if f.get("family") == "rate":
            f["rhs"] = ["1", *f["rhs"], *(f"tanh(dv/{k * span:.3g})" for k in RATE_TANH)]
        if f.get("family") == "static" and env is not None and _constant(env):
            f["rhs"] = ["1", *f["rhs"]]       # the nominal law has a constant: so may the law
    if signal and env is not None and np.min(env["v"]) > 0:
        # a block's input (an equation's variable) that stays above 0, a level: the outflow it
        # drives may go with its square root (Torricelli, an orifice to the open)
        out.append({"name": "polynomial", "lhs": ["i"], "rhs": ["1", "sqrt(abs(v))*sign(v)"], "family": "static"})
    if role == "absolute":
        from ..templates import scaled

        x = potential_of(env) if env is not None else "va"
        s = unit_of(env[x]) if env is not None else 1.0
        out.insert(0, {"name": "polynomial", "lhs": ["i"], "rhs": ["1", *(scaled(x, k, s) for k in (1, 2, 3))],
                       "family": "absolute"})
        # a free outflow (Torricelli, an orifice to the open): the flow goes with the square
        # root of the level, a law of one parameter that a cubic only approximates
        out.insert(1, {"name": "polynomial", "lhs": ["i"], "rhs": ["1", f"sqrt(abs({x}))*sign({x})"],
                       "family": "absolute"})
    return out


def inverse_families(env: dict) -> list[dict]:
    """The static law the other way round, v = f(i) in odd terms (with a constant where the
    nominal law has one), for a static component whose law in v cannot reach the noise."""
    out = dict(INVERSE)
    if _constant(env):
        out["rhs"] = ["1", *out["rhs"]]
    return [out]


#: the shapes (h1, h2) a hysteresis is fitted from: z as v while loading and bending back on
#: unloading, and z saturating both ways (a Bouc-Wen fit from one start falls into a local
#: minimum as often as not: the benchmark's loop was found from the first, not from (1, 0.5))
HYSTERESIS_STARTS = ((1.0, -1.0), (1.0, 1.0))


def hysteresis_families(env: dict) -> list[dict]:
    """Bouc-Wen hysteresis (:mod:`mcl.hysteresis`) for a static component whose force depends on
    the direction of motion: i = c1 v + c2 dv + c3 z (with a constant where the nominal law has
    one), z's scale half the span v visits along the run, from each of :data:`HYSTERESIS_STARTS`."""
    v = np.asarray(env["v"], float)
    span = float(f"{0.5 * float(np.ptp(v)) or float(np.max(np.abs(v))) or 1.0:.3g}")
    rhs = ["v", "dv", "z"]
    if _constant(env):
        rhs = ["1", *rhs]
    return [{"name": "hysteresis", "rhs": rhs, "span": span, "shape": list(h), "family": "hysteresis"}
            for h in HYSTERESIS_STARTS]


def potential_families(env: dict) -> list[dict]:
    """Laws in both connectors' own potentials, for a static component whose law in v cannot
    reach the noise: radiation, i = c1 v + c2 va^4 + c3 vb^4 (a linear conductor's law, and
    G (T_a^4 - T_b^4) when c1 = 0), the potentials in units of their span; drawn against v with
    vb held at its mean. None where a potential does not vary along the run (a conductor to a
    fixed temperature: its law is in v), or where the potentials are not on an absolute scale
    (they cross 0: an electrical potential against an arbitrary ground; a temperature in K, a
    level, an absolute pressure stay above it)."""
    from ..templates import scaled

    va, vb = np.asarray(env["va"], float), np.asarray(env["vb"], float)
    span = max(float(np.ptp(va)), float(np.ptp(vb)), 1e-300)
    if min(np.ptp(va), np.ptp(vb)) < 0.05 * span or min(np.min(va), np.min(vb)) <= 0:
        return []
    s = unit_of(np.concatenate([va, vb]))
    return [{"name": "polynomial", "lhs": ["i"], "rhs": ["v", scaled("va", 4, s), scaled("vb", 4, s)],
             "at": {"vb": float(f"{np.mean(vb):.4g}")}, "family": "potentials"}]


#: the shapes of the laws engineers meet, each with a scale s (fitted): Coulomb friction and
#: saturation (tanh, x/sqrt(1+(x/s)^2)), sinh and exp(x/s) - 1 (diodes, Shockley; exponential
#: growth), a soft dead zone x - s tanh(x/s), the Stribeck bump tanh(x/s) exp(-(x/s)^2), and the
#: signed square root of orifices and Torricelli outflows, sqrt(|x|) tanh(x/s) (s small: the
#: rounding at 0)
_SHAPES = ("tanh({x}/{s})", "sinh({x}/{s})", "{x}/sqrt(1 + ({x}/{s})^2)", "exp({x}/{s}) - 1",
           "{x} - {s}*tanh({x}/{s})", "tanh({x}/{s})*exp(-({x}/{s})^2)", "sqrt(abs({x}))*tanh({x}/{s})")


#: Torricelli's outflow from an opening s above the level's datum (a level measured from the
#: tank's bottom, or by a sensor whose zero is not the opening's height)
_TORRICELLI = "sqrt(abs({x} - {s}))*sign({x} - {s})"

#: a knee: the slope changes by 1 about x = s (above it, or below -s), rounded over a width w
#: (a softplus, w log(1 + exp((x - s)/w)), written as the ramp plus its rounding so that no
#: exp overflows far past the knee): a diode that starts to conduct, a clamp, a limit on one
#: side, a dead zone or a stop on one side; with the line through 0 it is a one-sided
#: saturation of any sharpness
_KNEES = ("({x} - {s} + abs({x} - {s}))/2 + {w}*log(1 + exp(-abs({x} - {s})/{w}))",
          "(abs({x} + {s}) - {x} - {s})/2 + {w}*log(1 + exp(-abs({x} + {s})/{w}))")


#: what an engineer calls each shape (the effect's words)
_SHAPE_WORDS = {"tanh({x}/{s})": "Coulomb-like friction or saturation", "sinh({x}/{s})": "an exponential rise on both sides",
                "{x}/sqrt(1 + ({x}/{s})^2)": "saturation", "exp({x}/{s}) - 1": "an exponential rise (a diode, an overflow)",
                "z": "hysteresis (z: the part of the across value that remembers its path, Bouc-Wen)",
                "{x} - {s}*tanh({x}/{s})": "a dead zone", "tanh({x}/{s})*exp(-({x}/{s})^2)": "the Stribeck effect",
                "sqrt(abs({x}))*tanh({x}/{s})": "a square root (an orifice)",
                _TORRICELLI: "a square root of the level above an opening (Torricelli)",
                "abs({x})": "a reading blind to the sign (a counter that cannot tell the direction)",
                **{k: "a knee on one side (a diode's, a clamp's or a stop's)" for k in _KNEES}}


def shape_words(term: str, signal: bool = False, speed: bool = True) -> str:
    """``term`` (a basis term, its scale named s1, s2, ...) with what an engineer calls it:
    "a dead zone: v - s1*tanh(v/s1)"; a term of no named shape as it is. In a signal block
    (``signal``) a tanh is a saturation, not friction; a law not in a speed (``speed`` false: a
    tank's level) has no Stribeck effect, only its shape."""
    for pattern, said in _SHAPE_WORDS.items():
        if re.fullmatch(_pattern(pattern), term.replace(" ", "")):
            if not speed and "Stribeck" in said:
                said = "a bump that fades on both sides (a Stribeck-shaped term)"
            return f"{'saturation' if signal and 'saturation' in said else said}: {term}"
    return term


#: a shape's scale in a term: named (s1, s2, ...) or a number (a family's fixed scales)
_SCALE = r"(?:s\d+|(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)"
#: the placeholders of a shape: the variable, and the scales it is fitted in
_SLOTS = {"{x}": r"[a-z]+", "{s}": _SCALE, "{w}": _SCALE}


def _pattern(shape: str) -> str:
    """A regular expression for ``shape`` with any variable and any scales, named or numbers."""
    parts = re.split(r"(\{[xsw]\})", shape.replace(" ", ""))
    out, seen = [], set()
    for p in parts:
        if p in _SLOTS:
            g = p[1]
            out.append(f"(?P={g})" if g in seen else f"(?P<{g}>{_SLOTS[p]})")
            seen.add(g)
        else:
            out.append(re.escape(p))
    return "".join(out)


def _slots(pattern: str) -> list[str]:
    """The scales a shape is fitted in, in order (s, then w where it has one)."""
    return [g for g in ("s", "w") if "{" + g + "}" in pattern]


#: the scales a shape starts from, as shares of the visited span: the sharp ones for a step
#: (dry friction's at 0, which from a wider start the least squares of the distillation
#: rounds off with other shapes before its scale is fitted)
SHAPE_SCALES = (0.01, 0.03, 0.1, 0.3, 1.0)


def basis(x: np.ndarray, name: str, sensor: bool = False) -> list[tuple[str, tuple | None]]:
    """Candidate terms in the variable ``name`` for a law visited over ``x``, as (pattern, scales):
    polynomials, |x| x, and the shapes of friction, saturation and exponential laws at scales
    spread over the visited span (the scale of a chosen shape is then fitted); knees on either
    side at a few places and widths; in a connector's own potential (va, vb) also a constant (an
    outflow that starts above the bottom); in a variable that stays above 0 (a level) also
    Torricelli's square root of its height above an opening, the opening's height s fitted (the
    level's datum is rarely the opening's). A sensor's reading (``sensor``) also gets a constant
    (its zero) and |x| (a counter blind to the direction)."""
    span = float(np.max(np.abs(x))) or 1.0
    terms = [(t, None) for t in ("{x}", "{x}^2", "{x}^3", "{x}*abs({x})", "sqrt(abs({x}))*sign({x})")]
    if sensor:
        terms[:0] = [("1", None), ("abs({x})", None)]
    shapes = [(shape, (k * span,)) for k in SHAPE_SCALES for shape in _SHAPES]
    shapes += [(knee, (k * span, w * span)) for knee in _KNEES for k in (0.1, 0.3, 0.6) for w in (0.03, 0.15)]
    if name in ("va", "vb") and not sensor:
        terms.insert(0, ("1", None))
    if np.min(x) > 0:      # a level (or a drop) that stays above 0: an opening may sit above its datum
        shapes += [(_TORRICELLI, (k * float(np.min(x)),)) for k in (0.25, 0.5, 0.75, 0.9)]
    return terms + shapes


def _text(term, name: str, scales=None, digits: int = 4) -> str:
    pattern, grid = term
    if grid is None:
        return pattern.format(x=name)
    values = scales if scales is not None else grid
    return pattern.format(x=name, **{g: f"{v:.{digits}g}" for g, v in zip(_slots(pattern), values)})


def _values(term, x, name, scales=None) -> np.ndarray:
    from ..templates import Monomial

    with np.errstate(all="ignore"):
        return np.broadcast_to(Monomial.parse(_text(term, name, scales, digits=17)).value({name: x}), np.shape(x))


def _fit_scales(chosen, x, f, name):
    """Fitted scales of the shapes among ``chosen`` (variable projection: least squares in the
    coefficients inside); returns (rms error, scales by position (a tuple each), coefficients)."""
    from scipy.optimize import least_squares

    shaped = [k for k, t in enumerate(chosen) if t[1] is not None]
    cuts = np.cumsum([0] + [len(chosen[k][1]) for k in shaped])

    def split(log_s):
        s = np.exp(log_s)
        return {k: tuple(s[a:b]) for k, a, b in zip(shaped, cuts[:-1], cuts[1:])}

    def design(log_s):
        s = split(log_s)
        return np.column_stack([_values(t, x, name, s.get(k)) for k, t in enumerate(chosen)])

    def solve(log_s):
        A = design(log_s)
        if not np.all(np.isfinite(A)):
            return np.full(len(f), 1e6 * (np.ptp(f) + 1.0)), None
        c, *_ = np.linalg.lstsq(A, f, rcond=None)
        return f - A @ c, c

    log_s = np.log([v for k in shaped for v in chosen[k][1]])
    if shaped:
        log_s = least_squares(lambda ls: solve(ls)[0], log_s, x_scale=1.0, diff_step=1e-6).x
    r, c = solve(log_s)
    return float(np.sqrt(np.mean(r**2))), split(log_s), c


def distillations(x: np.ndarray, f: np.ndarray, name: str, max_terms: int = 3,
                  refine_best: int = 6, sensor: bool = False, keep: tuple = (),
                  plain: bool = False) -> list[tuple[list[str], np.ndarray, float]]:
    """Sparse laws f(x) ~ sum_k c_k phi_k(x) over :func:`basis`, the best of one, two, ...
    ``max_terms`` terms: every subset is fitted by least squares at the grid's scales, the
    ``refine_best`` best of each size get their shapes' scales fitted. Returns (terms, c, rms
    error) per size; a simulation fit of each then decides (the curve is only a network's
    reading of the data). Each law is a dict: terms (scales named s1, s2, ...), scales, c, err.
    ``keep``: basis terms ("1", "{x}") every law has beside its own, the law it stands for
    keeping them (a friction's offset force, small on the curve, drives an open-loop position
    away; a damper's viscous term, without which a sharp step and a line came as a step, a dead
    zone and a correction). ``plain``: the best law of each size made of the polynomial terms
    alone too, where it is not the best (the curve of a law that fitted noise with shapes
    favours shapes: a damper's v + v^3, which the data prefer by 16 BIC, lost on the curve
    of a law that kept three tanh instead of the line)."""
    import heapq
    from itertools import combinations

    x, f = np.asarray(x, float), np.asarray(f, float)
    ok = np.isfinite(f)
    x, f = x[ok], f[ok]
    terms = basis(x, name, sensor)
    terms += [(t, None) for t in keep if (t, None) not in terms]
    fixed = tuple(terms.index((t, None)) for t in keep)
    Phi = np.column_stack([_values(t, x, name) for t in terms])
    usable = [k for k in range(len(terms)) if k not in fixed
              and np.all(np.isfinite(Phi[:, k])) and (np.ptp(Phi[:, k]) > 0 or terms[k][0] == "1")]
    Phi = Phi / np.where(np.abs(Phi).max(axis=0) > 0, np.abs(Phi).max(axis=0), 1.0)   # conditioning
    scale = float(np.ptp(f)) or 1.0
    span = float(np.max(np.abs(x))) or 1.0
    out = []
    for size in range(1, max_terms + 1):
        errs = []
        for combo in combinations(usable, size):
            A = Phi[:, fixed + combo]
            c, *_ = np.linalg.lstsq(A, f, rcond=None)
            errs.append((float(np.sqrt(np.mean((f - A @ c) ** 2))), fixed + combo))
        best = (np.inf, None)
        for _, combo in heapq.nsmallest(refine_best, errs):
            chosen = [terms[k] for k in combo]
            err, scales, c = _fit_scales(chosen, x, f, name)
            # at equal fit the plainer law: a shape is a small cost, one whose scale ran far
            # beyond the visited span (a tanh become linear) a large one
            score = err / scale + 1e-4 * len(scales) + sum(s > 20 * span for v in scales.values() for s in v)
            if score < best[0]:
                best = (score, _law(chosen, name, scales, c, err))
        if best[1] is not None:
            out.append(best[1])
        polynomial = [e for e in errs if all(terms[k][1] is None for k in e[1])] if plain else []
        if polynomial and best[1] is not None:
            chosen = [terms[k] for k in min(polynomial)[1]]
            err, scales, c = _fit_scales(chosen, x, f, name)
            law = _law(chosen, name, scales, c, err)
            if law["terms"] != best[1]["terms"]:
                out.append(law)
    return out


#: the friction laws of the textbooks beside a law's own offset and viscous terms: Coulomb's,
#: Fc tanh(v/s) (a sign rounded off, s fitted), and with the Stribeck dip; each shape's start
#: scale as a share of the visited span
FRICTION = ((("tanh({x}/{s})", 0.01),), (("tanh({x}/{s})", 0.01), ("tanh({x}/{s})*exp(-({x}/{s})^2)", 0.1)))


def friction_laws(x: np.ndarray, f: np.ndarray, name: str, keep: tuple = ()) -> list[dict]:
    """The :data:`FRICTION` laws fitted to the curve f(x) of a speed's law, beside the basis
    terms ``keep`` (its constant and line): the readable law a friction's wordy one stands for,
    whose Coulomb step the distillation's curve error may rate below a rounder shape (a
    positioning axis's seven-term friction distilled to sqrt(|v|) tanh(v/s) beside the line,
    ten times the error of the Coulomb law the benchmark's reference model has)."""
    x, f = np.asarray(x, float), np.asarray(f, float)
    ok = np.isfinite(f)
    x, f = x[ok], f[ok]
    span = float(np.max(np.abs(x))) if len(x) else 0.0
    if not span > 0:
        return []
    out = []
    for shapes in FRICTION:
        chosen = [(t, None) for t in keep] + [(shape, (k * span,)) for shape, k in shapes]
        err, scales, c = _fit_scales(chosen, x, f, name)
        if np.all(np.isfinite(c)):
            out.append(_law(chosen, name, scales, c, err))
    return out


def _law(chosen, name: str, scales: dict, c, err: float) -> dict:
    """A distilled law: its terms with named scales (s1, s2, ...: fitted further by simulation),
    their values, the coefficients and the curve error."""
    terms, named = [], {}
    for k, (pattern, grid) in enumerate(chosen):
        if grid is None:
            terms.append(pattern.format(x=name))
            continue
        keys = {}
        for g, v in zip(_slots(pattern), scales.get(k, grid)):
            keys[g] = f"s{len(named) + 1}"
            named[keys[g]] = float(v)
        terms.append(pattern.format(x=name, **keys))
    return {"terms": terms, "scales": named, "c": np.asarray(c, float), "err": err}
