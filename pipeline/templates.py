"""Candidate component templates: parameterised constitutive laws G(xi; w) = 0 (paper 000, sec. II).

A template describes a two-connector component whose connectors each carry one potential x and
one flow f, in any domain and library. With v = x_a - x_b (across) and i = f_a (flow into
connector a), every template keeps flow balance f_a + f_b = 0 and adds one law in (v, i) and
optionally their time derivatives (dv = der(v), di = der(i)) for components with memory, and
the connectors' own potentials va = x_a, vb = x_b for laws that depend on more than their
difference (a tank's free outflow q = c sqrt(h_a), radiation Q = G (T_a^4 - T_b^4)); the
constant term is ``1`` (an affine law):

- ``polynomial``: linear in w over monomial features, e.g. paper 000's w1 i = w2 v^2 + w3 v^3;
- ``memory``: the same with derivative features (a damper's law is in dv, not v);
- ``neural``: a small tanh network read as an equation G(v, i; w) = 0, not an assignment.

Third parties add templates through the ``mcl_templates`` hook.
"""
from __future__ import annotations

import ast
import functools
import re
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from .errors import ConfigError
from .graph import Component

VARIABLES = ("v", "i", "dv", "di", "va", "vb")
#: the variables' names in messages
_VARIABLE_WORDS = "v, i, dv, di, va, vb"


@dataclass(frozen=True)
class Monomial:
    """A product of powers of the template variables, e.g. v^2*i or va^4; the empty product is 1."""

    powers: tuple[tuple[str, int], ...]

    @classmethod
    def parse(cls, text: str, names=()) -> "Monomial":
        """A monomial, or an :class:`Expression` (which may also use the parameter ``names``)."""
        text = text.replace(" ", "").replace("**", "^")
        if text in ("", "1"):
            return cls(())
        powers: dict[str, int] = {}
        for factor in text.split("*"):
            m = re.fullmatch(r"(der\((v|i)\)|dv|di|va|vb|v|i)(?:\^(\d+))?", factor)
            if not m:
                return Expression.parse(text, names)
            name = {"der(v)": "dv", "der(i)": "di"}.get(m.group(1), m.group(1))
            powers[name] = powers.get(name, 0) + int(m.group(3) or 1)
        return cls(tuple(sorted(powers.items(), key=lambda kv: VARIABLES.index(kv[0]))))

    def __str__(self) -> str:
        return "*".join(n if p == 1 else f"{n}^{p}" for n, p in self.powers) or "1"

    def modelica(self) -> str:
        return "*".join(n if p == 1 else f"{n}^{p}" for n, p in self.powers) or "1"

    def value(self, env: dict) -> np.ndarray:
        out = 1.0
        for n, p in self.powers:
            out = out * np.asarray(env[n], dtype=float) ** p
        return out

    def sx(self, env: dict):
        """The term as a CasADi expression of ``env``'s symbols (a law put into a model)."""
        out = 1.0
        for n, p in self.powers:
            out = out * env[n] ** p
        return out

    @property
    def variables(self) -> set[str]:
        return {n for n, _ in self.powers}

    @property
    def degree(self) -> int:
        return sum(p for _, p in self.powers)


_FUNCTIONS = {"tanh": np.tanh, "sinh": np.sinh, "cosh": np.cosh, "exp": np.exp, "abs": np.abs, "sign": np.sign,
              "sqrt": np.sqrt, "atan": np.arctan, "log": np.log}
_BINOPS = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide, ast.Pow: np.power}


@functools.lru_cache(maxsize=1024)
def _tree(text: str) -> ast.expr:
    """The parsed body of an expression term (``^`` as power), parsed once per text: laws are
    evaluated point by point when their curves are solved."""
    return ast.parse(text.replace("^", "**"), mode="eval").body


@dataclass(frozen=True)
class Expression:
    """A term that is not a monomial: an arithmetic expression of v, i, dv, di, va, vb, numbers
    and tanh, sinh, cosh, exp, abs, sqrt, atan, log (e.g. ``tanh(v/0.3)``, ``v*abs(v)``,
    ``v/sqrt(1 + (v/0.5)^2)``, ``(va/400)^4``); the same text is valid Modelica."""

    text: str
    powers: tuple = ()       # not a monomial: degree 0 for refinement's stage order

    @classmethod
    def parse(cls, text: str, names=()) -> "Expression":
        text = text.replace(" ", "").replace("**", "^").replace("der(v)", "dv").replace("der(i)", "di")
        try:
            tree = ast.parse(text.replace("^", "**"), mode="eval")
        except SyntaxError:
            tree = None
        bad = cls._check(tree.body, set(names)) if tree else "not an expression"
        if bad:
            raise ConfigError(f"template term '{text}': {bad} (use {_VARIABLE_WORDS}, numbers, + - * / ^ and "
                              f"{', '.join(_FUNCTIONS)}, e.g. v^3, v*i, tanh(v/0.3), va^4, 1)")
        return cls(text)

    @classmethod
    def _check(cls, node, names: set) -> str | None:
        if isinstance(node, ast.Name):
            return None if node.id in VARIABLES or node.id in names else f"'{node.id}' is not one of {_VARIABLE_WORDS}"
        if isinstance(node, ast.Constant):
            return None if isinstance(node.value, (int, float)) and not isinstance(node.value, bool) else "not a number"
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            return cls._check(node.operand, names)
        if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
            return cls._check(node.left, names) or cls._check(node.right, names)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCTIONS \
                and len(node.args) == 1 and not node.keywords:
            return cls._check(node.args[0], names)
        return f"'{ast.unparse(node)}' is not allowed"

    def __str__(self) -> str:
        return self.text

    def modelica(self) -> str:
        """The text, in parentheses where a coefficient in front would bind wrongly (a sum)."""
        body = _tree(self.text)
        loose = isinstance(body, ast.UnaryOp) or (isinstance(body, ast.BinOp) and isinstance(body.op, (ast.Add, ast.Sub)))
        return f"({self.text})" if loose else self.text

    def value(self, env: dict) -> np.ndarray:
        def ev(node):
            if isinstance(node, ast.Name):
                return np.asarray(env[node.id], dtype=float)
            if isinstance(node, ast.Constant):
                return float(node.value)
            if isinstance(node, ast.UnaryOp):
                return -ev(node.operand) if isinstance(node.op, ast.USub) else ev(node.operand)
            if isinstance(node, ast.BinOp):
                return _BINOPS[type(node.op)](ev(node.left), ev(node.right))
            return _FUNCTIONS[node.func.id](ev(node.args[0]))

        with np.errstate(all="ignore"):
            return ev(_tree(self.text))

    def sx(self, env: dict):
        """The term as a CasADi expression of ``env``'s symbols (variables and scale names)."""
        import casadi as ca

        # sqrt's derivative is infinite at 0, and sqrt(|v|) tanh(v/s) at v = 0 (the start of
        # many runs) differentiates to inf * 0 = NaN: offset by 1e-200 it is 5e99 * 0 = 0
        funcs = {"tanh": ca.tanh, "sinh": ca.sinh, "cosh": ca.cosh, "exp": ca.exp, "abs": ca.fabs, "sign": ca.sign,
                 "sqrt": lambda a: ca.sqrt(a + 1e-200), "atan": ca.atan, "log": ca.log}
        ops = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
               ast.Div: lambda a, b: a / b, ast.Pow: lambda a, b: a ** b}

        def ev(node):
            if isinstance(node, ast.Name):
                return env[node.id]
            if isinstance(node, ast.Constant):
                return float(node.value)
            if isinstance(node, ast.UnaryOp):
                return -ev(node.operand) if isinstance(node.op, ast.USub) else ev(node.operand)
            if isinstance(node, ast.BinOp):
                return ops[type(node.op)](ev(node.left), ev(node.right))
            return funcs[node.func.id](ev(node.args[0]))

        return ev(_tree(self.text))

    @property
    def variables(self) -> set[str]:
        return {n.id for n in ast.walk(_tree(self.text)) if isinstance(n, ast.Name) and n.id in VARIABLES}

    @property
    def degree(self) -> int:
        return 0


_NUMBER = r"(\d+(?:\.\d*)?(?:e[+-]?\d+)?)"
_VARIABLE = r"(va|vb|dv|di|v|i)"


def scaled_power(term) -> tuple[str, float, int] | None:
    """(x, s, p) of a term ``(x/s)^p`` or ``x/s``: a variable in units of s, so that the fit's
    columns stay near 1 (va^4 at 300 K is 1e10, beside v of a few kelvin); its coefficient c is
    c/s^p on x^p, and laws are written that way. None for any other term."""
    m = re.fullmatch(rf"\({_VARIABLE}/{_NUMBER}\)\^(\d+)|{_VARIABLE}/{_NUMBER}", str(term))
    if not m:
        return None
    if m.group(1):
        return m.group(1), float(m.group(2)), int(m.group(3))
    return m.group(4), float(m.group(5)), 1


def unscaled(term) -> tuple[str, float]:
    """A term as a law is written (:func:`scaled_power`: (va/550)^4 reads va^4) and the factor
    its coefficient takes there (1/550^4)."""
    folded = scaled_power(term)
    if folded is None:
        return str(term), 1.0
    x, s, p = folded
    return (x if p == 1 else f"{x}^{p}"), 1.0 / s**p


def scaled(x: str, power: int, s: float) -> str:
    """The term x^power in units of s (:func:`scaled_power`); plain x^power when s is 1."""
    if s == 1:
        return x if power == 1 else f"{x}^{power}"
    return f"{x}/{s:.3g}" if power == 1 else f"({x}/{s:.3g})^{power}"


class Template:
    """Base of templates: the contract discovery relies on. Constructors store options; learned
    values live outside (in w).

    A template must give
    - :meth:`parameter_names` and :meth:`start`; parameter 0 is the **scale** of the law (the
      weight of its left-hand side: G(w) = 0 and G(k w) = 0 are the same law), kept at its start;
    - :meth:`law`: the law as a Modelica equation in v, i, dv, di, va, vb and the parameters;
    - :meth:`residual` (G on arrays) and, for laws linear in w, ``features`` with G = features @ w;
    - :meth:`start_from`: w fitted to a law observed along a simulation (the nominal component's),
      so a candidate's first simulation reproduces the nominal model;
    - :meth:`equation`: the fitted law, readable, with the component's own variable names;
    - ``terms`` (optional): the readable terms, one per parameter, for pruning and reports;
    - :attr:`uses`: which of v, i, dv, di, va, vb the law needs (dv, di make the class declare
      them and need the states to set the across value or flow; va, vb are the connectors' own
      potentials).
    """

    name = ""
    description = ""
    #: index of a parameter whose sign can be fixed without loss (laws linear in w: G(w) = -G(-w))
    symmetric_axis: int | None = None
    #: the potentials held where a law of several variables is drawn against one (``{"vb": 300.0}``)
    at: dict = {}

    def parameter_names(self) -> list[str]:
        raise NotImplementedError

    def start(self) -> np.ndarray:
        raise NotImplementedError

    def law(self) -> str:
        """The law as a Modelica equation in v, i, dv, di, va, vb and the parameters."""
        raise NotImplementedError

    def written_law(self, w) -> str:
        """The law as a learned class states it for the fitted ``w`` (:meth:`modelica_class`)."""
        return self.law()

    def residual(self, w, env: dict) -> np.ndarray:
        """G(xi; w) evaluated on arrays of v, i (and dv, di, va, vb): zero where the law holds."""
        raise NotImplementedError

    def sx_residual(self, w, env: dict):
        """G(xi; w) as a CasADi expression: ``w`` a list of parameter symbols, ``env`` symbols
        (or expressions) of v, i, dv, di, va, vb. This is how a law is put into a compiled model."""
        raise NotImplementedError(f"template {self.name} cannot be put into a compiled model")

    @property
    def explicit(self) -> str | None:
        """``i`` when the law gives the flow from the other variables (i = f(v, dv)), ``v`` when it
        gives the across value (v = g(i, di)), None for an implicit law G(v, i, ...) = 0."""
        return None

    def sx_explicit(self, w, env: dict):
        """The value of :attr:`explicit` the law gives, as a CasADi expression."""
        raise NotImplementedError

    def start_from(self, env: dict) -> np.ndarray:
        """w with the scale at 1, fitted to the law observed in ``env`` (arrays v, i, dv, di, va, vb)."""
        phi = self.features(env)
        w_rest, *_ = np.linalg.lstsq(phi[:, 1:], -phi[:, 0], rcond=None)
        return np.concatenate([[1.0], w_rest])

    def features(self, env: dict) -> np.ndarray:
        raise NotImplementedError(f"template {self.name} is not linear in its parameters: "
                                  "it must define start_from")

    def equation(self, w, across: str = "v", flow: str = "i", digits: int = 4,
                 potentials: tuple[str, str] = ("va", "vb")) -> str:
        """The fitted law, readable: v, i named ``across``, ``flow`` and va, vb ``potentials``."""
        raise NotImplementedError

    @property
    def uses(self) -> set[str]:
        """Which of v, i, dv, di, va, vb the law uses."""
        return {"v", "i"}

    def uses_where(self, active) -> set[str]:
        """Which of v, i, dv, di, va, vb the law uses with only the ``active`` parameters (a
        pruned law: a term pruned away needs no rate)."""
        return self.uses

    def parameter_descriptions(self) -> list[str]:
        """What each parameter is, for the Modelica class (one per parameter name)."""
        return ["scale of the law" if k == 0 else "" for k in range(len(self.parameter_names()))]

    def modelica_class(self, class_name: str, component: Component, w=None, note: str = "",
                       learned: bool = False) -> str:
        """A component class implementing the template, with the connectors of ``component``;
        ``note`` goes into the class description (e.g. the range the law was learned on). A
        ``learned`` law is written without the terms pruned to 0 (:meth:`written_law`); a law
        still to be fitted keeps every term (a 0 is a start value)."""
        a, b = component.connectors
        w = self.start() if w is None else np.asarray(w, dtype=float)
        law = self.written_law(w) if learned else self.law()
        params = "\n".join(f"  parameter Real {n} = {float(v)!r}" + (f' "{d}"' if d else "") + ";"
                           for n, v, d in zip(self.parameter_names(), w, self.parameter_descriptions()))
        if getattr(component, "signal", False):       # a block: its output i in its input v
            return (f'block {class_name} "{self.description} (mcl template {self.name}){note}"\n'
                    f"  {a.cls} {a.name};\n  {b.cls} {b.name};\n"
                    f'  Real v "the input";\n  Real i "the output";\n{params}\n'
                    f"equation\n  v = {a.name};\n  i = {b.name};\n  {law};\nend {class_name};\n")
        xa, fa, xb, fb = a.potential[0], a.flow[0], b.potential[0], b.flow[0]
        memory = ""
        if "dv" in self.uses:
            memory += "  Real dv \"der(v)\";\n"
        if "di" in self.uses:
            memory += "  Real di \"der(i)\";\n"
        mem_eq = ("  dv = der(v);\n" if "dv" in self.uses else "") + \
                 ("  di = der(i);\n" if "di" in self.uses else "")
        for name, conn, x in (("va", a, xa), ("vb", b, xb)):     # the connectors' own potentials
            if name in self.uses:
                memory += f'  Real {name} "potential at {conn.name}";\n'
                mem_eq += f"  {name} = {conn.name}.{x};\n"
        mem_eq += _carried(a, b)
        return (f'model {class_name} "{self.description} (mcl template {self.name}){note}"\n'
                f"  {a.cls} {a.name};\n  {b.cls} {b.name};\n"
                f'  Real v "across: {a.name}.{xa} - {b.name}.{xb}";\n'
                f'  Real i "flow into {a.name}";\n{memory}{params}\n'
                f"equation\n  v = {a.name}.{xa} - {b.name}.{xb};\n"
                f"  0 = {a.name}.{fa} + {b.name}.{fb};\n  i = {a.name}.{fa};\n{mem_eq}"
                f"  {law};\nend {class_name};\n")

    @property
    def law_variable(self) -> str:
        """The variable the law is a function of, for its curve: ``v`` (static), ``dv`` (a law
        in the rate, e.g. a damper in the speed), ``i`` (a law giving v from the flow), or ``va``
        / ``vb`` (a law in one connector's own potential, e.g. a tank's free outflow)."""
        return "v"

    def curve(self, w, xs: np.ndarray, at: dict | None = None) -> np.ndarray:
        """The law at ``xs`` of :attr:`law_variable` (the other derivatives 0): the flow, or for
        a law in i the across value. A law that also reads a connector's own potential is drawn
        with the other potential held at ``at`` (default :attr:`at`, else 0): against v with vb
        held (va = vb + v), against va with vb held, against vb with va held."""
        xs = np.atleast_1d(np.asarray(xs, dtype=float))
        held = {**self.at, **(at or {})}
        var = self.law_variable
        if var == "i":
            vb = held.get("vb", 0.0)
            return _solve(lambda k, v: self.residual(w, {"v": v, "i": xs[k], "dv": 0.0, "di": 0.0,
                                                         "va": vb + v, "vb": vb}), xs)
        if var == "va":
            vb = np.full_like(xs, held.get("vb", 0.0))
            return self.flow_of(w, xs - vb, va=xs, vb=vb)
        if var == "vb":
            va = np.full_like(xs, held.get("va", 0.0))
            return self.flow_of(w, va - xs, va=va, vb=xs)
        vb = np.full_like(xs, held.get("vb", 0.0))
        if var == "dv":
            return self.flow_of(w, np.zeros_like(xs), dv=xs, va=vb, vb=vb)
        return self.flow_of(w, xs, va=vb + xs, vb=vb)

    def flow_of(self, w, v: np.ndarray, dv: np.ndarray | None = None, va: np.ndarray | None = None,
                vb: np.ndarray | None = None) -> np.ndarray:
        """Solve the law for the flow at each across value (memoryless in i), for plots and
        curves; ``va``, ``vb`` the potentials there (default: v at a, 0 at b)."""
        v = np.atleast_1d(np.asarray(v, dtype=float))
        va = v if va is None else np.broadcast_to(np.asarray(va, float), v.shape)
        vb = np.zeros_like(v) if vb is None else np.broadcast_to(np.asarray(vb, float), v.shape)
        return _solve(lambda k, i: self.residual(w, {"v": v[k], "i": i, "dv": 0.0 if dv is None else dv[k],
                                                     "di": 0.0, "va": va[k], "vb": vb[k]}), v)


def _solve(g, xs: np.ndarray) -> np.ndarray:
    """For each k, a root y of g(k, y) (bracketed on growing spans; NaN where none is found)."""
    out = np.full(xs.shape, np.nan)
    for k, xk in enumerate(xs):
        f = lambda y: float(np.ravel(g(k, y))[0])
        scale = 1.0 + abs(xk)
        for span in (1e-3, 1e-1, 1e1, 1e3, 1e5):
            lo, hi = -span * scale, span * scale
            try:
                if np.sign(f(lo)) != np.sign(f(hi)):
                    out[k] = brentq(f, lo, hi, xtol=1e-14, rtol=1e-12)
                    break
            except (ValueError, FloatingPointError):
                break
    return out


#: parameters a template may have: each costs one sensitivity per simulation of every fit
MAX_PARAMETERS = 40


def _scale(name, value) -> float:
    """A scale's start value: a finite number other than 0 (it divides a variable: tanh(v/s1))."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = None
    if isinstance(value, bool) or v is None or not np.isfinite(v) or not 1e-12 <= abs(v) <= 1e12:
        raise ConfigError(f"template scale {name} = {value!r}: must be a number in the variable's units, "
                          "not 0 and between 1e-12 and 1e12 in size")
    return v


def _finite(values, what: str) -> np.ndarray:
    try:
        out = np.asarray(values, dtype=float).ravel()
    except (TypeError, ValueError):
        raise ConfigError(f"template {what}: {values!r} is not a list of numbers") from None
    if not np.all(np.isfinite(out)):
        raise ConfigError(f"template {what}: every value must be a finite number")
    return out


class PolynomialTemplate(Template):
    """Linear in w: w1*lhs_1 + ... = w_k*rhs_1 + ... over monomials of v, i (paper 000, sec. II).

    Options: ``lhs`` and ``rhs`` term lists (e.g. lhs=["i"], rhs=["v^2", "v^3"], the paper's
    w1 i = w2 v^2 + w3 v^3), or ``degree`` for lhs=["i"], rhs = v, v^2, ..., v^degree.
    ``start`` gives the initial w (default 0.1 for every parameter, as in Table I).
    ``scales`` names parameters used inside terms with their start values (``rhs: [v,
    tanh(v/s1)]``, ``scales: {s1: 0.3}``): they are fitted with the coefficients (the law is
    then not linear in them) but never pruned. Terms may read the connectors' own potentials
    va, vb and the constant 1 (``rhs: [1, va, va^2]``; ``(va/400)^4``: va^4 in units of 400,
    written c/400^4*va^4); ``at`` gives the potentials held where such a law is drawn against
    one variable (:meth:`Template.curve`).
    """

    name = "polynomial"
    description = "polynomial constitutive law"
    symmetric_axis = 0

    def __init__(self, lhs=None, rhs=None, degree: int = 3, start=None, prefix: str = "w", family: str = "",
                 scales: dict | None = None, at: dict | None = None):
        self.family = family     # which law family discovery chose it as (static, rate, storage, shape)
        self.scales = {str(k): _scale(k, v) for k, v in (scales or {}).items()}
        if not isinstance(at or {}, dict) or any(k not in ("va", "vb") for k in (at or {})):
            raise ConfigError(f"template at = {at!r}: must map va or vb to a potential")
        self.at = {str(k): float(_finite([v], f"at.{k}")[0]) for k, v in (at or {}).items()}
        if rhs is None and (isinstance(degree, bool) or not isinstance(degree, (int, np.integer))
                            or not 1 <= degree < MAX_PARAMETERS):
            raise ConfigError(f"template degree = {degree!r}: must be a whole number from 1 to {MAX_PARAMETERS - 1}")
        if len(lhs or ()) + len(rhs or ()) + len(self.scales) > MAX_PARAMETERS:
            raise ConfigError(f"template has {len(lhs or ()) + len(rhs or ()) + len(self.scales)} parameters; "
                              f"at most {MAX_PARAMETERS} are fitted (each costs a sensitivity per simulation): "
                              "give fewer terms")
        bad = [k for k in self.scales if not re.fullmatch(r"[A-Za-z_]\w*", k) or k in VARIABLES
               or k in _FUNCTIONS or re.fullmatch(rf"{re.escape(prefix)}\d+", k)]
        if bad:
            raise ConfigError(f"template scale name '{bad[0]}' is not free to use")
        self.lhs = [Monomial.parse(t, self.scales) for t in (lhs or ["i"])]
        self.rhs = [Monomial.parse(t, self.scales) for t in (rhs or [f"v^{k}" if k > 1 else "v"
                                                                     for k in range(1, degree + 1)])]
        self.prefix = prefix
        n = len(self.lhs) + len(self.rhs)
        self._start = np.full(n, 0.1) if start is None else _finite(start, "start")
        if self._start.shape == (n + len(self.scales),):
            self._start = self._start[:n]
        if self._start.shape != (n,):
            raise ConfigError(f"template start has {self._start.size} values for {n} parameters")

    @property
    def terms(self) -> list[Monomial]:
        return self.lhs + self.rhs

    @property
    def uses(self) -> set[str]:
        return set().union(*(m.variables for m in self.terms)) | {"v", "i"}

    def uses_where(self, active) -> set[str]:
        kept = [m for m, a in zip(self.terms, active) if a]
        return set().union(*(m.variables for m in kept)) | {"v", "i"}

    def parameter_names(self) -> list[str]:
        return [f"{self.prefix}{k + 1}" for k in range(len(self.terms))] + list(self.scales)

    def _env(self, env: dict, w=None) -> dict:
        """``env`` with the scale parameters' values (from w, else their start values)."""
        if not self.scales:
            return env
        vals = self.scales if w is None else dict(zip(self.scales, np.asarray(w, float)[len(self.terms):]))
        return {**vals, **env}

    def parameter_descriptions(self) -> list[str]:
        side = ["left"] * len(self.lhs) + ["right"] * len(self.rhs)
        return ([f"coefficient of {m} ({s}-hand side)" for m, s in zip(self.terms, side)]
                + [f"scale inside the terms using {n}" for n in self.scales])

    @property
    def law_variable(self) -> str:
        if [str(m) for m in self.lhs] == ["v"]:
            return "i"
        rhs = set().union(*(m.variables for m in self.rhs)) if self.rhs else set()
        if rhs and rhs <= {"va"}:
            return "va"
        if rhs and rhs <= {"vb"}:
            return "vb"
        return "dv" if "dv" in rhs and "v" not in rhs else "v"

    def start(self) -> np.ndarray:
        return np.concatenate([self._start, list(self.scales.values())])

    def start_from(self, env: dict) -> np.ndarray:
        return np.concatenate([super().start_from(env), list(self.scales.values())])

    def _side(self, names, terms) -> str:
        return " + ".join(f"{n}*{m.modelica()}" if str(m) != "1" else n for n, m in zip(names, terms)) or "0"

    def law(self) -> str:
        return self.written_law(np.ones(len(self.terms)))

    def written_law(self, w) -> str:
        """The law without the terms pruned to 0: a term that is gone is not written, since it
        may still not be evaluable where the law runs (0*sqrt(|v|) has a Jacobian of 0*inf =
        NaN at v = 0, and a recompiled model fails its first step)."""
        names, w = self.parameter_names(), np.asarray(w, float)
        k, n = len(self.lhs), len(self.terms)
        kept = [j for j in range(n) if w[j] != 0.0]
        side = lambda js: self._side([names[j] for j in js], [self.terms[j] for j in js])
        return f"{side([j for j in kept if j < k])} = {side([j for j in kept if j >= k])}"

    def features(self, env: dict, w=None) -> np.ndarray:
        """Signed features phi with G = phi @ w (lhs positive, rhs negative): columns per term,
        with the scales taken from ``w`` (default: their start values)."""
        env = self._env(env, w)
        cols = [m.value(env) for m in self.lhs] + [-m.value(env) for m in self.rhs]
        return np.column_stack([np.broadcast_to(c, np.shape(env["v"])) for c in cols])

    def residual(self, w, env: dict) -> np.ndarray:
        w = np.asarray(w, dtype=float)
        return self.features(env, w) @ w[:len(self.terms)]

    def _sx_env(self, w, env: dict) -> dict:
        return {**dict(zip(self.scales, list(w)[len(self.terms):])), **env}

    def sx_residual(self, w, env: dict):
        e, k = self._sx_env(w, env), len(self.lhs)
        return (sum(wk * m.sx(e) for wk, m in zip(w[:k], self.lhs))
                - sum(wk * m.sx(e) for wk, m in zip(w[k:len(self.terms)], self.rhs)))

    @property
    def explicit(self) -> str | None:
        lhs = [str(m) for m in self.lhs]
        rhs = set().union(*(m.variables for m in self.rhs)) if self.rhs else set()
        return lhs[0] if lhs in (["i"], ["v"]) and lhs[0] not in rhs else None

    def sx_explicit(self, w, env: dict):
        e, k = self._sx_env(w, env), len(self.lhs)
        return sum(wk * m.sx(e) for wk, m in zip(w[k:len(self.terms)], self.rhs)) / w[0]

    def equation(self, w, across: str = "v", flow: str = "i", digits: int = 4,
                 potentials: tuple[str, str] = ("va", "vb"), negated=()) -> str:
        """The fitted law, readable; the terms whose indices are in ``negated`` are written in
        -across and -flow (a flipped component's term that is neither even nor odd)."""
        rename = {"v": across, "i": flow, "dv": f"der({across})", "di": f"der({flow})",
                  "va": potentials[0], "vb": potentials[1]}
        minus = {**rename, "v": f"(-{across})", "i": f"(-{flow})", "dv": f"der(-{across})",
                 "di": f"der(-{flow})"}

        def side(ws, terms, first=0):
            parts = []
            for j, (c, m) in enumerate(zip(ws, terms), first):
                if c == 0:  # a term removed by pruning
                    continue
                names = minus if j in negated else rename
                unit = scaled_power(m)
                if unit is not None:   # (x/s)^p: c/s^p on x^p
                    x, s_, p = unit
                    c, m = c / s_**p, Monomial(((x, p),))
                mono = (re.sub(r"\b(va|vb|dv|di|v|i)\b", lambda g: names[g.group(1)], m.modelica())
                        if isinstance(m, Expression) else
                        "*".join(names[n] if p == 1 else f"{names[n]}^{p}" for n, p in m.powers))
                coef = f"{c:.{digits}g}"
                parts.append(mono if coef == "1" and mono else coef + (f"*{mono}" if mono else ""))
            return " + ".join(parts).replace("+ -", "- ") or "0"

        w = np.asarray(w, dtype=float)
        k, n = len(self.lhs), len(self.terms)
        text = f"{side(w[:k], self.lhs)} = {side(w[k:n], self.rhs, k)}"
        for name, value in zip(self.scales, w[n:]):      # scales by their fitted values
            text = re.sub(rf"\b{name}\b", f"{value:.{digits}g}", text)
        for r in [*rename.values(), *minus.values()]:   # a value written as a difference: once in parentheses
            if r.startswith("(") and r.endswith(")"):
                text = text.replace(f"({r})", r)
        return re.sub(r"([+-])([+-])(?=[0-9.])", lambda g: "-" if g[1] != g[2] else "+", text)   # x+-0.1: x-0.1


class MemoryTemplate(PolynomialTemplate):
    """Polynomial law with time derivatives among the features (default: w1 i = w2 v + w3 dv)."""

    name = "memory"
    description = "constitutive law with memory (time derivatives)"

    def __init__(self, lhs=None, rhs=None, degree: int = 1, start=None, prefix: str = "w", family: str = ""):
        rhs = rhs or ["v", "dv"] + [f"v^{k}" for k in range(2, degree + 1)]
        super().__init__(lhs=lhs, rhs=rhs, start=start, prefix=prefix, family=family)


class NeuralTemplate(Template):
    """G(x, i; w) = c*i - sum_j a_j tanh(b_j x + d_j i + e_j): a tanh network read as an equation.

    ``x`` is the across variable ``v`` (default), its derivative ``dv`` (a damper's law is in
    the speed) or a connector's own potential ``va`` / ``vb`` (a tank's free outflow).
    ``coupled`` (default) lets the flow enter the units (d_j i): the law is an equation solved
    for i; ``coupled: false`` drops d_j and adds a linear term g*x, so the law is explicit in i
    (cheaper to simulate; discovery uses it to find a law's shape before distilling it).
    ``hidden`` units; start values break the symmetry between units deterministically (seeded).
    A neural law the user names is a candidate like any other; the one discovery fits to find a
    law's shape (``family: reference``) is only distilled.
    """

    name = "neural"
    description = "neural-network constitutive law"

    def __init__(self, hidden: int = 3, start=None, seed: int = 0, x: str = "v", coupled: bool = True,
                 family: str = ""):
        if x not in ("v", "dv", "va", "vb"):
            raise ConfigError(f"neural template: x must be v, dv, va or vb, not {x!r}")
        if isinstance(hidden, bool) or not isinstance(hidden, (int, np.integer)) or not 1 <= hidden <= 64:
            raise ConfigError(f"neural template: hidden = {hidden!r} must be a whole number from 1 to 64")
        self.hidden, self.x, self.coupled = int(hidden), x, bool(coupled)
        self.family = family     # "reference": discovery's shape stage, distilled, never a cause
        self.per_unit = 4 if self.coupled else 3
        rng = np.random.default_rng(seed)
        n = len(self.parameter_names())
        default = np.concatenate([[1.0], rng.normal(0, 0.5, n - 1)])
        self._start = default if start is None else _finite(start, "start")
        if self._start.shape != (n,):
            raise ConfigError(f"neural template start has {self._start.size} values for {n} parameters")

    @property
    def uses(self) -> set[str]:
        return {"v", "i", self.x}

    @property
    def law_variable(self) -> str:
        return self.x

    def _units(self) -> list[list[str]]:
        keys = "abde" if self.coupled else "abe"
        return [[f"{k}{j}" for k in keys] for j in range(1, self.hidden + 1)]

    def parameter_names(self) -> list[str]:
        return ["c"] + ([] if self.coupled else ["g"]) + [n for unit in self._units() for n in unit]

    def start(self) -> np.ndarray:
        return self._start.copy()

    def _split(self, w):
        w = np.asarray(w, dtype=float)
        k = 1 if self.coupled else 2
        units = w[k:].reshape(self.hidden, self.per_unit)
        return w[0], (0.0 if self.coupled else w[1]), units

    def law(self) -> str:
        x = self.x
        if self.coupled:
            units = " + ".join(f"a{j}*tanh(b{j}*{x} + d{j}*i + e{j})" for j in range(1, self.hidden + 1))
            return f"c*i = {units}"
        units = " + ".join(f"a{j}*tanh(b{j}*{x} + e{j})" for j in range(1, self.hidden + 1))
        return f"c*i = g*{x} + {units}"

    def residual(self, w, env: dict) -> np.ndarray:
        c, g, units = self._split(w)
        x, i = np.asarray(env[self.x], dtype=float), np.asarray(env["i"], dtype=float)
        out = c * i - g * x
        for u in units:
            a, b, e = u[0], u[1], u[-1]
            out = out - a * np.tanh(b * x + (u[2] * i if self.coupled else 0.0) + e)
        return out

    def _sx_units(self, w, env: dict):
        import casadi as ca

        k, n = (1 if self.coupled else 2), self.per_unit
        x = env[self.x]
        return sum(w[k + j * n] * ca.tanh(w[k + j * n + 1] * x + (w[k + j * n + 2] * env["i"] if self.coupled else 0.0)
                                          + w[k + j * n + n - 1]) for j in range(self.hidden))

    def sx_residual(self, w, env: dict):
        return w[0] * env["i"] - (0.0 if self.coupled else w[1] * env[self.x]) - self._sx_units(w, env)

    @property
    def explicit(self) -> str | None:
        return None if self.coupled else "i"

    def sx_explicit(self, w, env: dict):
        return (w[1] * env[self.x] + self._sx_units(w, env)) / w[0]

    def start_from(self, env: dict) -> np.ndarray:
        """w reproducing the law observed in ``env`` (c = 1).

        The law's slope k = i/x is carried by the linear term g (uncoupled) or by the first unit
        in its linear range (coupled: b_1 = 0.3/max|x|, a_1 = k/b_1, within 3% of linear); the
        other units are silent (a_j = 0) with their centres spread over the visited range
        (-e_j/b_j at -1/2 ... +1/2 of the largest |x|, width 1/b_j a third of it). So the first
        simulation is (nearly) the nominal model and every unit can bend the law where the
        data go.
        """
        x, i = np.asarray(env[self.x], float), np.asarray(env["i"], float)
        k = float(x @ i / (x @ x)) if np.any(x) else 0.0
        span = float(np.max(np.abs(x))) or 1.0
        centres = np.linspace(-0.5, 0.5, self.hidden) * span if self.hidden > 1 else np.zeros(1)
        b = np.full(self.hidden, 3.0 / span)
        a = np.zeros(self.hidden)
        if self.coupled:
            centres[0], b[0] = 0.0, 0.3 / span
            a[0] = k / b[0]
            units = np.column_stack([a, b, np.zeros(self.hidden), -b * centres])
            return np.concatenate([[1.0], units.ravel()])
        units = np.column_stack([a, b, -b * centres])
        return np.concatenate([[1.0, k], units.ravel()])

    def fit_curve(self, xs: np.ndarray, fs: np.ndarray, tries: int = 4) -> np.ndarray:
        """w (c = 1) of the uncoupled network closest to the curve i = f(x) given at ``xs``: least
        squares from a few seeded starts with the units spread over the range (the start of a
        network that must first do what a known law does, then better; a start needs no more
        than a few 1e-4 of the curve's span, so each fit stops after 50 Jacobians per unknown)."""
        from scipy.optimize import least_squares

        xs, fs = np.asarray(xs, float), np.asarray(fs, float)
        span, scale = float(np.max(np.abs(xs))) or 1.0, float(np.std(fs)) or 1.0
        # a potential's range lies away from 0 (a level, a temperature): the units about its middle
        mid = 0.5 * float(np.min(xs) + np.max(xs)) if self.x in ("va", "vb") else 0.0
        if mid:
            span = 0.5 * float(np.ptp(xs)) or span
        best = None
        for seed in range(tries):
            rng = np.random.default_rng(seed)
            # widths from a third of the range down to 1/30 of it (a friction law's step at 0)
            centres = mid + rng.uniform(-0.6, 0.6, self.hidden) * span
            centres[0] = mid
            b = np.exp(rng.uniform(np.log(1.0), np.log(30.0), self.hidden)) / span
            units = np.column_stack([rng.normal(0, scale, self.hidden), b, -b * centres])
            slope = float(np.polyfit(xs, fs, 1)[0]) if mid else float(xs @ fs / (xs @ xs)) if np.any(xs) else 0.0
            r0 = np.concatenate([[slope], units.ravel()])
            fun = lambda r: self.residual(np.concatenate([[1.0], r]), {self.x: xs, "i": fs}) / scale
            sol = least_squares(fun, r0, jac=lambda r: self._curve_jacobian(r, xs) / scale, max_nfev=50 * len(r0))
            if best is None or sol.cost < best.cost:
                best = sol
        return np.concatenate([[1.0], best.x])

    def _curve_jacobian(self, r, xs: np.ndarray) -> np.ndarray:
        """d residual / d (g, a_j, b_j, e_j) of the uncoupled network with c = 1 (exact: a curve
        fit with finite differences spends most of its time on them)."""
        units = np.asarray(r[1:], float).reshape(self.hidden, 3)
        t = np.tanh(xs[:, None] * units[:, 1] + units[:, 2])
        slope = units[:, 0] * (1.0 - t**2)
        J = np.empty((len(xs), 1 + 3 * self.hidden))
        J[:, 0], J[:, 1::3], J[:, 2::3], J[:, 3::3] = -xs, -t, -slope * xs[:, None], -slope
        return J

    def equation(self, w, across: str = "v", flow: str = "i", digits: int = 4,
                 potentials: tuple[str, str] = ("va", "vb")) -> str:
        c, g, units = self._split(w)
        x = {"v": across, "dv": f"der({across})", "va": potentials[0], "vb": potentials[1]}[self.x]
        fmt = lambda z: f"{z:.{digits}g}"
        parts = [f"{fmt(u[0])}*tanh({fmt(u[1])}*{x}" + (f" + {fmt(u[2])}*{flow}" if self.coupled else "")
                 + f" + {fmt(u[-1])})" for u in units]
        if not self.coupled:
            parts.insert(0, f"{fmt(g)}*{x}")
        return f"{fmt(c)}*{flow} = {' + '.join(parts)}".replace("+ -", "- ")


def make_template(registry_templates: dict[str, type], spec) -> Template:
    """A template from a name or a dict ``{name: polynomial, lhs: [...], rhs: [...], ...}``."""
    spec = {"name": spec} if isinstance(spec, str) else dict(spec)
    name = spec.pop("name", "polynomial")
    if name not in registry_templates:
        from .errors import did_you_mean

        raise ConfigError(f"unknown template '{name}'{did_you_mean(name, registry_templates)} "
                          f"(installed: {', '.join(registry_templates)})")
    try:
        return registry_templates[name](**spec)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"template '{name}': {exc}") from None


def _carried(a, b) -> str:
    """Equations for the pairs a connector carries after its first (FluidHeatFlow's port: the
    enthalpy and the enthalpy flow, after the pressure and the mass flow): each flow passes
    through unchanged, taken from the side it comes from (``semiLinear`` in the first flow), as
    a pipe without heat exchange carries its medium's enthalpy."""
    out = ""
    for x, f in zip(a.potential[1:], a.flow[1:]):
        out += (f"  0 = {a.name}.{f} + {b.name}.{f};\n"
                f"  {a.name}.{f} = semiLinear({a.name}.{a.flow[0]}, {a.name}.{x}, {b.name}.{x});\n")
    return out
