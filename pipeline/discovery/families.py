"""Law families: which constitutive laws discovery tries for a component, chosen by its role.

The role is read off the nominal component's own law along the nominal simulation (v across,
i flow into connector a, dv and di their time derivatives):

- ``static``: i follows v (resistor, spring, thermal conductor);
- ``rate``: i follows dv (capacitor, damper, heat capacity between two ports);
- ``integral``: v follows di (inductor, inerter-like elements).

Families per role (each a template spec; all start from the nominal law, so the first
simulation of a candidate reproduces the nominal model):

- ``static``: i = f(v) (cubic); a storage law i = f(v) dv + g(v) (a spring with damping);
- ``rate``: i = h(dv) (a damper cubic in the speed; Coulomb-like friction tanh(dv/s)); the
  storage law (a capacitor whose
  capacitance depends on its voltage, a leaky capacitor: i = C dv + G v);
- ``integral``: v = f(i) di + g(i).

Non-polynomial shapes (tanh, sinh, |x| x, x/sqrt(1 + x^2), exp) are found afterwards for the
most promising component only: a neural law fitted to the data is distilled into a sparse
readable law over that basis (:func:`distil`), which is fitted and pruned like the others.
"""
from __future__ import annotations

import numpy as np

STATIC = {"name": "polynomial", "lhs": ["i"], "rhs": ["v", "v^2", "v^3"], "family": "static"}
RATE = {"name": "polynomial", "lhs": ["i"], "rhs": ["dv", "dv^2", "dv^3"], "family": "rate"}
STORAGE = {"name": "polynomial", "lhs": ["i"], "rhs": ["dv", "v*dv", "v^2*dv", "v", "v^2", "v^3"],
           "family": "storage"}
INTEGRAL = {"name": "polynomial", "lhs": ["v"], "rhs": ["di", "i*di", "i^2*di", "i", "i^3"],
            "family": "storage"}
FAMILIES = {"static": [STATIC, STORAGE], "rate": [RATE, STORAGE], "integral": [INTEGRAL],
            "unknown": [STATIC, RATE, STORAGE]}
#: the variable a role's law is a function of (for the law curve and the shape family)
LAW_VARIABLE = {"static": "v", "rate": "dv", "integral": "i", "unknown": "v"}


def spec_name(spec) -> str:
    """The template name of a template spec (a name, or a dict with ``name``)."""
    return spec if isinstance(spec, str) else spec.get("name", "?")


def family_of(spec) -> str:
    """The law family a spec was chosen as (discovery's own specs say so), else its template name."""
    return (spec.get("family") if isinstance(spec, dict) else None) or spec_name(spec)


def role_of(env: dict) -> str:
    """``static``, ``rate`` or ``integral``: which single variable explains the nominal law
    (R^2 > 0.99 of a line through the origin); ``unknown`` otherwise."""
    def r2(y, x):
        y, x = np.asarray(y, float), np.asarray(x, float)
        if not np.any(x) or not np.any(y):
            return 0.0
        a = (x @ y) / (x @ x)
        return 1.0 - np.sum((y - a * x) ** 2) / np.sum(y**2)

    fits = {"static": r2(env["i"], env["v"]), "rate": r2(env["i"], env["dv"]), "integral": r2(env["v"], env["di"])}
    best = max(fits, key=fits.get)
    return best if fits[best] > 0.99 else "unknown"


def families(role: str, env: dict | None = None) -> list[dict]:
    """The template specs tried for a component of this role. A law in the rate also gets
    Coulomb-like friction terms tanh(dv/s), the dissipative element's classic non-polynomial
    part, at two fixed scales (a twentieth and a quarter of the rate's nominal span: the law
    stays linear in its parameters, and pruning keeps what the data need; the shape stage
    fits the scale itself)."""
    out = [dict(f) for f in FAMILIES[role]]
    span = float(np.max(np.abs(env["dv"]))) if env is not None and np.any(env["dv"]) else 1.0
    for f in out:
        if f.get("family") == "rate":
            f["rhs"] = [*f["rhs"], f"tanh(dv/{0.05 * span:.3g})", f"tanh(dv/{0.25 * span:.3g})"]
    return out


#: the shapes of the laws engineers meet, each with a scale s (fitted): Coulomb friction and
#: saturation (tanh, x/sqrt(1+(x/s)^2)), sinh and exp(x/s) - 1 (diodes, Shockley; exponential
#: growth), a soft dead zone x - s tanh(x/s), the Stribeck bump tanh(x/s) exp(-(x/s)^2), and the
#: signed square root of orifices and Torricelli outflows, sqrt(|x|) tanh(x/s) (s small: the
#: rounding at 0)
_SHAPES = ("tanh({x}/{s})", "sinh({x}/{s})", "{x}/sqrt(1 + ({x}/{s})^2)", "exp({x}/{s}) - 1",
           "{x} - {s}*tanh({x}/{s})", "tanh({x}/{s})*exp(-({x}/{s})^2)", "sqrt(abs({x}))*tanh({x}/{s})")


def basis(x: np.ndarray, name: str) -> list[tuple[str, float | None]]:
    """Candidate terms in the variable ``name`` for a law visited over ``x``, as (pattern, scale):
    polynomials, |x| x, and the shapes of friction, saturation and exponential laws at scales
    spread over the visited span (the scale of a chosen shape is then fitted)."""
    span = float(np.max(np.abs(x))) or 1.0
    terms = [(t, None) for t in ("{x}", "{x}^2", "{x}^3", "{x}*abs({x})", "sqrt(abs({x}))*sign({x})")]
    return terms + [(shape, k * span) for k in (0.05, 0.1, 0.2, 0.5, 1.0) for shape in _SHAPES]


def _text(term, name: str, scale=None, digits: int = 4) -> str:
    pattern, s = term
    if s is None:
        return pattern.format(x=name)
    return pattern.format(x=name, s=f"{(scale if scale is not None else s):.{digits}g}")


def _values(term, x, name, scale=None) -> np.ndarray:
    from ..templates import Monomial

    with np.errstate(all="ignore"):
        return Monomial.parse(_text(term, name, scale, digits=17)).value({name: x})


def _fit_scales(chosen, x, f, name):
    """Fitted scales of the shapes among ``chosen`` (variable projection: least squares in the
    coefficients inside); returns (rms error, scales by position, coefficients)."""
    from scipy.optimize import least_squares

    shaped = [k for k, t in enumerate(chosen) if t[1] is not None]

    def design(log_s):
        s = dict(zip(shaped, np.exp(log_s)))
        return np.column_stack([_values(t, x, name, s.get(k)) for k, t in enumerate(chosen)])

    def solve(log_s):
        A = design(log_s)
        if not np.all(np.isfinite(A)):
            return np.full(len(f), 1e6 * (np.ptp(f) + 1.0)), None
        c, *_ = np.linalg.lstsq(A, f, rcond=None)
        return f - A @ c, c

    log_s = np.log([chosen[k][1] for k in shaped])
    if shaped:
        log_s = least_squares(lambda ls: solve(ls)[0], log_s, x_scale=1.0, diff_step=1e-6).x
    r, c = solve(log_s)
    return float(np.sqrt(np.mean(r**2))), dict(zip(shaped, np.exp(log_s))), c


def distillations(x: np.ndarray, f: np.ndarray, name: str, max_terms: int = 3,
                  refine_best: int = 6) -> list[tuple[list[str], np.ndarray, float]]:
    """Sparse laws f(x) ~ sum_k c_k phi_k(x) over :func:`basis`, the best of one, two, ...
    ``max_terms`` terms: every subset is fitted by least squares at the grid's scales, the
    ``refine_best`` best of each size get their shapes' scales fitted. Returns (terms, c, rms
    error) per size; a simulation fit of each then decides (the curve is only a network's
    reading of the data). Each law is a dict: terms (scales named s1, s2, ...), scales, c, err."""
    import heapq
    from itertools import combinations

    x, f = np.asarray(x, float), np.asarray(f, float)
    ok = np.isfinite(f)
    x, f = x[ok], f[ok]
    terms = basis(x, name)
    Phi = np.column_stack([_values(t, x, name) for t in terms])
    usable = [k for k in range(len(terms)) if np.all(np.isfinite(Phi[:, k])) and np.ptp(Phi[:, k]) > 0]
    Phi = Phi / np.where(np.abs(Phi).max(axis=0) > 0, np.abs(Phi).max(axis=0), 1.0)   # conditioning
    scale = float(np.ptp(f)) or 1.0
    span = float(np.max(np.abs(x))) or 1.0
    out = []
    for size in range(1, max_terms + 1):
        errs = []
        for combo in combinations(usable, size):
            A = Phi[:, combo]
            c, *_ = np.linalg.lstsq(A, f, rcond=None)
            errs.append((float(np.sqrt(np.mean((f - A @ c) ** 2))), combo))
        best = (np.inf, None)
        for _, combo in heapq.nsmallest(refine_best, errs):
            chosen = [terms[k] for k in combo]
            err, scales, c = _fit_scales(chosen, x, f, name)
            # at equal fit the plainer law: a shape is a small cost, one whose scale ran far
            # beyond the visited span (a tanh become linear) a large one
            score = err / scale + 1e-4 * len(scales) + sum(s > 20 * span for s in scales.values())
            if score < best[0]:
                best = (score, _law(chosen, name, scales, c, err))
        if best[1] is not None:
            out.append(best[1])
    return out


def _law(chosen, name: str, scales: dict, c, err: float) -> dict:
    """A distilled law: its terms with named scales (s1, s2, ...: fitted further by simulation),
    their values, the coefficients and the curve error."""
    terms, named = [], {}
    for k, (pattern, s) in enumerate(chosen):
        if s is None:
            terms.append(pattern.format(x=name))
            continue
        key = f"s{len(named) + 1}"
        named[key] = float(scales.get(k, s))
        terms.append(pattern.format(x=name, s=key))
    return {"terms": terms, "scales": named, "c": np.asarray(c, float), "err": err}
