"""Hysteresis: a law whose flow depends on the path its across value took (Bouc-Wen).

A spring's force, a bearing's presliding friction, a core's magnetising current: where the
data show a force that depends on the direction of motion (discovery's storage law, in v and
dv, beats the static one), the law may remember. Bouc-Wen with exponent 1 is the plainest law
that does, and the one the literature fits to such parts:

    i = w2 v + w3 dv + w4 z,     dz/dt = dv - (h1 |dv| z + h2 dv |z|) / span

z (in v's units) is the hysteretic part of the across value: it turns with v where h1 = h2 = 0
and, where h1 + h2 > 0, it saturates at span/(h1 + h2) while v grows; h1 - h2 sets how fast it
leaves that bound when v turns back. ``span`` is a fixed length in v's units (the visited
span) so that h1 and h2 are of order one. In Bouc-Wen's own parameters (dz/dt = A dv -
beta (gamma |dv| z + delta dv |z|), z a force): A = 1 with z a length and w4 the force per
length, beta gamma = h1/span, beta delta = h2/span.
"""
from __future__ import annotations

import numpy as np

from .errors import ConfigError
from .templates import Expression, Monomial, PolynomialTemplate, _finite, _scale

#: the steps of a curve's sweep per interval of its grid (explicit Euler along v)
_SUBSTEPS = 20


class HysteresisTemplate(PolynomialTemplate):
    """i = w2 v + w3 dv + w4 z with z's Bouc-Wen equation (see the module's note). Options:
    ``rhs`` (terms in v, dv and ``z``; default v, dv, z), ``start`` (the coefficients, or
    with h1 and h2 after them), ``span`` (z's length scale), ``shape`` (h1, h2 to start from).
    The law's state z starts at 0: the part relaxed."""

    name = "hysteresis"
    description = "constitutive law with hysteresis (Bouc-Wen)"
    #: the name of the law's own state (declared in the class written for it)
    STATE = "z"

    def __init__(self, rhs=None, start=None, span: float = 1.0, shape=None, prefix: str = "w",
                 family: str = "hysteresis"):
        rhs = [str(t) for t in (rhs or ["v", "dv", "z"])]
        if "z" not in rhs:
            raise ConfigError("hysteresis template: rhs must have the term z (the hysteretic part of v)")
        self.span = _scale("span", span)
        h = [1.0, 0.5] if shape is None else list(_finite(shape, "shape"))
        if len(h) != 2:
            raise ConfigError(f"hysteresis template: shape = {shape!r} must be two numbers (h1, h2)")
        n = 1 + len(rhs)
        given = None if start is None else _finite(start, "start")
        if given is not None and given.shape == (n + 2,):
            given, h = given[:n], list(given[n:])
        super().__init__(lhs=["i"], rhs=[t for t in rhs if t != "z"], prefix=prefix, family=family,
                         scales={"h1": _scale("h1", h[0]), "h2": _scale("h2", h[1])})
        self.rhs = [Expression("z") if t == "z" else Monomial.parse(t, self.scales) for t in rhs]
        bad = [str(m) for m in self.rhs if not m.variables <= {"v", "dv"} and str(m) != "z"]
        if bad:
            raise ConfigError(f"hysteresis template: term '{bad[0]}' may read only v, dv and z")
        self._start = np.concatenate([[1.0], np.full(n - 1, 0.1)]) if given is None else given
        if self._start.shape != (n,):
            raise ConfigError(f"hysteresis template start has {self._start.size} values for {n} coefficients")

    @property
    def uses(self) -> set[str]:
        return super().uses | {"dv"}          # z's equation reads the rate

    def uses_where(self, active) -> set[str]:
        return super().uses_where(active) | {"dv"}

    @property
    def follows(self) -> dict:
        """z's coefficient (a parameter index) -> h1's and h2's: they act only through z (with
        z removed they are 0, and z turns with v)."""
        n = len(self.terms)
        return {1 + [str(m) for m in self.rhs].index("z"): (n, n + 1)}

    @property
    def law_variable(self) -> str:
        return "v"

    def parameter_descriptions(self) -> list[str]:
        return [*super().parameter_descriptions()[:len(self.terms)],
                "how sharply z saturates (h1/span: Bouc-Wen's beta*gamma)",
                "the asymmetry of loading and unloading (h2/span: Bouc-Wen's beta*delta)"]

    def start_from(self, env: dict) -> np.ndarray:
        """The terms but z fitted to the law observed in ``env`` (z's coefficient 0: the first
        simulation is the nominal model where its law is among the terms), then h1, h2."""
        rest = [k for k, m in enumerate(self.rhs) if str(m) != "z"]
        shape = np.shape(env["v"])
        w = np.zeros(len(self.terms))
        w[0] = 1.0
        if rest:
            X = np.column_stack([np.broadcast_to(self.rhs[k].value(env), shape) for k in rest])
            c, *_ = np.linalg.lstsq(X, np.asarray(env["i"], float), rcond=None)
            w[[1 + k for k in rest]] = c
        return np.concatenate([w, list(self.scales.values())])

    def _shape(self, w) -> tuple:
        n = len(self.terms)
        return w[n], w[n + 1]

    def state_rate(self, w, env: dict):
        """dz/dt as a CasADi expression of ``env``'s dv and z and the parameters ``w``."""
        import casadi as ca

        h1, h2 = self._shape(w)
        dv, z = env["dv"], env[self.STATE]
        return dv - (h1 * ca.fabs(dv) * z + h2 * dv * ca.fabs(z)) / self.span

    def path(self, w, v: np.ndarray, z0: float = 0.0) -> np.ndarray:
        """z along the sequence of across values ``v`` (z0 at the first), by explicit Euler in v:
        dz/dv = 1 - (h1 sign(dv) z + h2 |z|)/span, rate-independent."""
        h1, h2 = self._shape(np.asarray(w, float))
        v = np.asarray(v, float)
        z = np.empty_like(v)
        z[0], zk = z0, z0
        for k in range(1, len(v)):
            step = (v[k] - v[k - 1]) / _SUBSTEPS
            sign = np.sign(step)
            for _ in range(_SUBSTEPS):
                zk += step * (1.0 - (h1 * sign * zk + h2 * abs(zk)) / self.span)
            z[k] = zk
        return z

    def flow_of(self, w, v, dv=None, va=None, vb=None) -> np.ndarray:
        """The flow along the path ``v`` takes in order (z from 0 at its first value)."""
        v = np.atleast_1d(np.asarray(v, float))
        env = {"v": v, "dv": np.zeros_like(v) if dv is None else np.asarray(dv, float), "z": self.path(w, v)}
        return self._explicit(np.asarray(w, float), env)

    def _explicit(self, w, env: dict) -> np.ndarray:
        e = self._env(env, w)
        return sum(c * np.broadcast_to(m.value(e), np.shape(env["v"])) for c, m in zip(w[1:len(self.terms)], self.rhs)) / w[0]

    def curve(self, w, xs, at=None) -> np.ndarray:
        """The loop's rising branch over ``xs`` (ascending): v swept down from its top and up
        again twice, so that z is on the loop it settles to, and read on the last rise."""
        return self.branch(w, xs, rising=True)

    def branch(self, w, xs, rising: bool = True) -> np.ndarray:
        """The flow on the loop's rising (or falling) branch at ``xs`` (ascending), the loop
        swept over their span until z settles on it."""
        xs = np.atleast_1d(np.asarray(xs, float))
        down, up = xs[::-1], xs
        legs = [down, up[1:], down[1:], up[1:]] + ([] if rising else [down[1:]])
        z = self.path(w, np.concatenate(legs))[-len(xs):]
        z = z if rising else z[::-1]
        return self._explicit(np.asarray(w, float), {"v": xs, "dv": np.zeros_like(xs), "z": z})

    def residual(self, w, env: dict) -> np.ndarray:
        if self.STATE not in env:
            env = {**env, self.STATE: self.path(w, np.atleast_1d(env["v"]))}
        return super().residual(w, env)

    def equation(self, w, across: str = "v", flow: str = "i", digits: int = 4,
                 potentials: tuple[str, str] = ("va", "vb"), negated=()) -> str:
        """The law and z's equation, h1 and h2 folded into their coefficients."""
        w = np.asarray(w, float)
        h1, h2 = self._shape(w)
        rate = f"der({across})"
        z = (f"der(z) = {rate} - ({h1 / self.span:.{digits}g}*abs({rate})*z "
             f"+ {h2 / self.span:.{digits}g}*{rate}*abs(z))").replace("+ -", "- ")
        return f"{super().equation(w, across, flow, digits, potentials, negated)}; {z}"

    def hidden_modelica(self, w, rate: str, shape: bool = True) -> tuple[list[str], list[str]]:
        """(declarations, equations) of z in a class whose rate of v is named ``rate``; with
        ``shape``, h1 and h2 declared too (a class that declares the template's parameters
        itself has them)."""
        w = np.asarray(w, float)
        h1, h2 = self._shape(w)
        decls = ([f'  parameter Real h1 = {float(h1)!r} "how sharply z saturates (in units of span)";',
                  f'  parameter Real h2 = {float(h2)!r} "the asymmetry of loading and unloading (in units of span)";']
                 if shape else [])
        decls += [f'  parameter Real span = {self.span!r} "the length z\'s shape parameters are in units of";',
                  '  Real z(start = 0, fixed = true) "the hysteretic part of the deformation (Bouc-Wen)";']
        eqs = [f"der(z) = {rate} - (h1*abs({rate})*z + h2*{rate}*abs(z))/span;"]
        return decls, eqs

    def modelica_class(self, class_name: str, component, w=None, note: str = "", learned: bool = False) -> str:
        w = self.start() if w is None else np.asarray(w, dtype=float)
        text = super().modelica_class(class_name, component, w, note, learned)
        decls, eqs = self.hidden_modelica(w, "dv", shape=False)     # (h1, h2: among the parameters written)
        head, tail = text.split("\nequation\n", 1)
        return f"{head}\n" + "\n".join(decls) + "\nequation\n" + "".join(f"  {e}\n" for e in eqs) + tail
