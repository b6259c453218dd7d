"""Candidate component templates: parameterised constitutive laws G(xi; w) = 0 (paper 000, sec. II).

A template describes a two-connector component whose connectors each carry one potential x and
one flow f, in any domain and library. With v = x_a - x_b (across) and i = f_a (flow into
connector a), every template keeps flow balance f_a + f_b = 0 and adds one law in (v, i) and
optionally their time derivatives (dv = der(v), di = der(i)) for components with memory:

- ``polynomial``: linear in w over monomial features, e.g. paper 000's w1 i = w2 v^2 + w3 v^3;
- ``memory``: the same with derivative features (a damper's law is in dv, not v);
- ``neural``: a small tanh network read as an equation G(v, i; w) = 0, not an assignment.

Third parties add templates through the ``mcl_templates`` hook.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from .errors import ConfigError
from .graph import Component

VARIABLES = ("v", "i", "dv", "di")


@dataclass(frozen=True)
class Monomial:
    """A product of powers of the template variables, e.g. v^2*i; the empty product is 1."""

    powers: tuple[tuple[str, int], ...]

    @classmethod
    def parse(cls, text: str) -> "Monomial":
        text = text.replace(" ", "").replace("**", "^")
        if text in ("", "1"):
            return cls(())
        powers: dict[str, int] = {}
        for factor in text.split("*"):
            m = re.fullmatch(r"(der\((v|i)\)|dv|di|v|i)(?:\^(\d+))?", factor)
            if not m:
                raise ConfigError(f"template term '{text}': '{factor}' is not v, i, dv, di or a power "
                                  "of them (e.g. v^3, v*i, dv)")
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

    @property
    def variables(self) -> set[str]:
        return {n for n, _ in self.powers}

    @property
    def degree(self) -> int:
        return sum(p for _, p in self.powers)


class Template:
    """Base of templates. Constructors store options; learned values live outside (in w)."""

    name = ""
    description = ""
    #: index of a parameter whose sign can be fixed without loss (laws linear in w: G(w) = -G(-w))
    symmetric_axis: int | None = None

    def parameter_names(self) -> list[str]:
        raise NotImplementedError

    def start(self) -> np.ndarray:
        raise NotImplementedError

    def law(self) -> str:
        """The law as a Modelica equation in v, i, dv, di and the parameters."""
        raise NotImplementedError

    def residual(self, w, env: dict) -> np.ndarray:
        """G(xi; w) evaluated on arrays of v, i (and dv, di): zero where the law holds."""
        raise NotImplementedError

    def equation(self, w, across: str = "v", flow: str = "i", digits: int = 4) -> str:
        raise NotImplementedError

    @property
    def uses(self) -> set[str]:
        """Which of v, i, dv, di the law uses."""
        return {"v", "i"}

    def modelica_class(self, class_name: str, component: Component, w=None) -> str:
        """A component class implementing the template, with the connectors of ``component``."""
        a, b = component.connectors
        xa, fa, xb, fb = a.potential[0], a.flow[0], b.potential[0], b.flow[0]
        w = self.start() if w is None else np.asarray(w, dtype=float)
        params = "\n".join(f"  parameter Real {n} = {float(v)!r};" for n, v in zip(self.parameter_names(), w))
        memory = ""
        if "dv" in self.uses:
            memory += "  Real dv \"der(v)\";\n"
        if "di" in self.uses:
            memory += "  Real di \"der(i)\";\n"
        mem_eq = ("  dv = der(v);\n" if "dv" in self.uses else "") + \
                 ("  di = der(i);\n" if "di" in self.uses else "")
        return (f'model {class_name} "{self.description} (mcl template {self.name})"\n'
                f"  {a.cls} {a.name};\n  {b.cls} {b.name};\n"
                f'  Real v "across: {a.name}.{xa} - {b.name}.{xb}";\n'
                f'  Real i "flow into {a.name}";\n{memory}{params}\n'
                f"equation\n  v = {a.name}.{xa} - {b.name}.{xb};\n"
                f"  0 = {a.name}.{fa} + {b.name}.{fb};\n  i = {a.name}.{fa};\n{mem_eq}"
                f"  {self.law()};\nend {class_name};\n")

    def flow_of(self, w, v: np.ndarray, dv: np.ndarray | None = None) -> np.ndarray:
        """Solve the law for the flow at each across value (memoryless in i), for plots and curves."""
        v = np.atleast_1d(np.asarray(v, dtype=float))
        out = np.full(v.shape, np.nan)
        for k, vk in enumerate(v):
            env = {"v": vk, "dv": 0.0 if dv is None else dv[k], "di": 0.0}
            g = lambda i: float(np.ravel(self.residual(w, {**env, "i": i}))[0])
            scale = 1.0 + abs(vk)
            for span in (1e-3, 1e-1, 1e1, 1e3, 1e5):
                lo, hi = -span * scale, span * scale
                if np.sign(g(lo)) != np.sign(g(hi)):
                    out[k] = brentq(g, lo, hi, xtol=1e-14, rtol=1e-12)
                    break
        return out


class PolynomialTemplate(Template):
    """Linear in w: w1*lhs_1 + ... = w_k*rhs_1 + ... over monomials of v, i (paper 000, sec. II).

    Options: ``lhs`` and ``rhs`` term lists (e.g. lhs=["i"], rhs=["v^2", "v^3"], the paper's
    w1 i = w2 v^2 + w3 v^3), or ``degree`` for lhs=["i"], rhs = v, v^2, ..., v^degree.
    ``start`` gives the initial w (default 0.1 for every parameter, as in Table I).
    """

    name = "polynomial"
    description = "polynomial constitutive law"
    symmetric_axis = 0

    def __init__(self, lhs=None, rhs=None, degree: int = 3, start=None, prefix: str = "w"):
        self.lhs = [Monomial.parse(t) for t in (lhs or ["i"])]
        self.rhs = [Monomial.parse(t) for t in (rhs or [f"v^{k}" if k > 1 else "v"
                                                        for k in range(1, degree + 1)])]
        self.prefix = prefix
        n = len(self.lhs) + len(self.rhs)
        self._start = np.full(n, 0.1) if start is None else np.asarray(start, dtype=float)
        if self._start.shape != (n,):
            raise ConfigError(f"template start has {self._start.size} values for {n} parameters")

    @property
    def terms(self) -> list[Monomial]:
        return self.lhs + self.rhs

    @property
    def uses(self) -> set[str]:
        return set().union(*(m.variables for m in self.terms)) | {"v", "i"}

    def parameter_names(self) -> list[str]:
        return [f"{self.prefix}{k + 1}" for k in range(len(self.terms))]

    def start(self) -> np.ndarray:
        return self._start.copy()

    def _side(self, names, terms) -> str:
        return " + ".join(f"{n}*{m.modelica()}" if m.powers else n for n, m in zip(names, terms)) or "0"

    def law(self) -> str:
        names = self.parameter_names()
        k = len(self.lhs)
        return f"{self._side(names[:k], self.lhs)} = {self._side(names[k:], self.rhs)}"

    def features(self, env: dict) -> np.ndarray:
        """Signed features phi with G = phi @ w (lhs positive, rhs negative): columns per term."""
        cols = [m.value(env) for m in self.lhs] + [-m.value(env) for m in self.rhs]
        return np.column_stack([np.broadcast_to(c, np.shape(env["v"])) for c in cols])

    def residual(self, w, env: dict) -> np.ndarray:
        return self.features(env) @ np.asarray(w, dtype=float)

    def equation(self, w, across: str = "v", flow: str = "i", digits: int = 4) -> str:
        rename = {"v": across, "i": flow, "dv": f"der({across})", "di": f"der({flow})"}

        def side(ws, terms):
            parts = []
            for c, m in zip(ws, terms):
                if c == 0:  # a term removed by pruning
                    continue
                mono = "*".join(rename[n] if p == 1 else f"{rename[n]}^{p}" for n, p in m.powers)
                parts.append(f"{c:.{digits}g}" + (f"*{mono}" if mono else ""))
            return " + ".join(parts).replace("+ -", "- ") or "0"

        w = np.asarray(w, dtype=float)
        k = len(self.lhs)
        return f"{side(w[:k], self.lhs)} = {side(w[k:], self.rhs)}"


class MemoryTemplate(PolynomialTemplate):
    """Polynomial law with time derivatives among the features (default: w1 i = w2 v + w3 dv)."""

    name = "memory"
    description = "constitutive law with memory (time derivatives)"

    def __init__(self, lhs=None, rhs=None, degree: int = 1, start=None, prefix: str = "w"):
        rhs = rhs or ["v", "dv"] + [f"v^{k}" for k in range(2, degree + 1)]
        super().__init__(lhs=lhs, rhs=rhs, start=start, prefix=prefix)


class NeuralTemplate(Template):
    """G(v, i; w) = c*i - sum_j a_j tanh(b_j v + d_j i + e_j): a tanh network read as an equation.

    ``hidden`` units; parameters c, then (a_j, b_j, d_j, e_j) per unit. Start values break the
    symmetry between units deterministically (seeded).
    """

    name = "neural"
    description = "neural-network constitutive law"

    def __init__(self, hidden: int = 3, start=None, seed: int = 0):
        self.hidden = int(hidden)
        rng = np.random.default_rng(seed)
        n = 1 + 4 * self.hidden
        default = np.concatenate([[1.0], rng.normal(0, 0.5, 4 * self.hidden)])
        self._start = default if start is None else np.asarray(start, dtype=float)
        if self._start.shape != (n,):
            raise ConfigError(f"neural template start has {self._start.size} values for {n} parameters")

    def parameter_names(self) -> list[str]:
        names = ["c"]
        for j in range(1, self.hidden + 1):
            names += [f"a{j}", f"b{j}", f"d{j}", f"e{j}"]
        return names

    def start(self) -> np.ndarray:
        return self._start.copy()

    def law(self) -> str:
        units = " + ".join(f"a{j}*tanh(b{j}*v + d{j}*i + e{j})" for j in range(1, self.hidden + 1))
        return f"c*i = {units}"

    def residual(self, w, env: dict) -> np.ndarray:
        w = np.asarray(w, dtype=float)
        v, i = np.asarray(env["v"], dtype=float), np.asarray(env["i"], dtype=float)
        out = w[0] * i
        for j in range(self.hidden):
            a, b, d, e = w[1 + 4 * j: 5 + 4 * j]
            out = out - a * np.tanh(b * v + d * i + e)
        return out

    def equation(self, w, across: str = "v", flow: str = "i", digits: int = 4) -> str:
        w = np.asarray(w, dtype=float)
        units = " + ".join(f"{w[1 + 4 * j]:.{digits}g}*tanh({w[2 + 4 * j]:.{digits}g}*{across} + "
                           f"{w[3 + 4 * j]:.{digits}g}*{flow} + {w[4 + 4 * j]:.{digits}g})"
                           for j in range(self.hidden))
        return f"{w[0]:.{digits}g}*{flow} = {units}".replace("+ -", "- ")


def make_template(registry_templates: dict[str, type], spec) -> Template:
    """A template from a name or a dict ``{name: polynomial, lhs: [...], rhs: [...], ...}``."""
    spec = {"name": spec} if isinstance(spec, str) else dict(spec)
    name = spec.pop("name", "polynomial")
    if name not in registry_templates:
        from .registry import did_you_mean

        raise ConfigError(f"unknown template '{name}'{did_you_mean(name, registry_templates)} "
                          f"(installed: {', '.join(registry_templates)})")
    try:
        return registry_templates[name](**spec)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"template '{name}': {exc}") from None
