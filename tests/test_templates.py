"""Templates swapped into models of any library compile, simulate, and match hand-derived laws."""
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from helpers import LIB, compiled, rel_err, series
from mcl.api import compile_model, registry, simulate
from mcl.errors import ConfigError
from mcl.graph import build_graph
from mcl.swap import swap_component
from mcl.templates import Monomial, NeuralTemplate, PolynomialTemplate

TIGHT = {"rtol": 1e-10, "atol": 1e-12}

# A library written here, with its own connectors: a magnetic-like domain (mmf F, flux rate q).
OWN = """
package Own
  connector Port
    Real F "potential";
    flow Real q "flow";
  end Port;
  model Reluctance
    Port a;
    Port b;
    parameter Real R = 2;
  equation
    a.q + b.q = 0;
    a.F - b.F = R * a.q;
  end Reluctance;
  model Store
    Port a;
    parameter Real C = 1;
    Real F(start = 0, fixed = true);
  equation
    F = a.F;
    C * der(F) = a.q;
  end Store;
  model Drive
    Port a;
    input Real u;
  equation
    a.q = -u;
  end Drive;
  model Earth
    Port a;
  equation
    a.F = 0;
  end Earth;
  model Circuit
    input Real u;
    output Real y;
    Drive d;
    Store s(C = 0.5);
    Reluctance leak(R = 2);
    Earth e;
  equation
    d.u = u;
    connect(d.a, s.a);
    connect(s.a, leak.a);
    connect(leak.b, e.a);
    y = s.F;
  end Circuit;
end Own;
"""


@pytest.fixture(scope="module")
def own(tmp_path_factory):
    path = tmp_path_factory.mktemp("own") / "Own.mo"
    path.write_text(OWN)
    return path


def test_polynomial_template_in_an_unseen_library(own, tmp_path):
    """leak replaced by w1 q = w2 dF + w3 dF^3 with known w; checked against SciPy."""
    graph = build_graph([own], "Own.Circuit")
    tpl = PolynomialTemplate(lhs=["i"], rhs=["v", "v^3"])
    w = np.array([2.0, 1.0, 0.3])
    tm = swap_component(graph, "leak", tpl, tmp_path, w=w)
    assert tm.parameter_names == ["leak.w1", "leak.w2", "leak.w3"]
    model = compile_model(tm.sources, tm.model_name)
    assert model.parameters["leak.w3"] == 0.3
    u = lambda t: 1.5 * np.sin(0.8 * t)
    t = np.linspace(0, 10, 20001)  # fine input table: its interpolation error stays below 1e-7
    res = simulate(model, series(t, u=u(t)), t_out=t[::200], options=TIGHT)
    assert res.ok, res.reason
    ref = solve_ivp(lambda tt, F: [(u(tt) - (w[1] * F[0] + w[2] * F[0] ** 3) / w[0]) / 0.5],
                    (0, 10), [0.0], t_eval=t[::200], rtol=1e-11, atol=1e-13)
    assert rel_err(res.output("y"), ref.y[0]) < 1e-6
    # the same compiled model with other parameters: no recompilation
    res2 = simulate(model, series(t, u=u(t)), {"leak.w3": 0.0, "leak.w1": 1.0, "leak.w2": 0.5},
                    t_out=t[::200], options=TIGHT)
    ref2 = solve_ivp(lambda tt, F: [(u(tt) - 0.5 * F[0]) / 0.5], (0, 10), [0.0], t_eval=t[::200],
                     rtol=1e-11, atol=1e-13)
    assert rel_err(res2.output("y"), ref2.y[0]) < 1e-6


def test_paper_template_in_the_cauer_filter(tmp_path, cauer):
    """w1 i = w2 v^2 + w3 v^3 at the true law (1, 0, 0.01) reproduces the original model."""
    graph = build_graph([LIB], "MCL.Examples.CauerFilter")
    tpl = PolynomialTemplate(lhs=["i"], rhs=["v^2", "v^3"])
    tm = swap_component(graph, "Rnl", tpl, tmp_path)
    model = compile_model(tm.sources, tm.model_name)
    t = np.linspace(0, 30, 601)
    u = series(t, u=np.sin(0.5 * t) * 2)
    a = simulate(model, u, {"Rnl.w1": 1.0, "Rnl.w2": 0.0, "Rnl.w3": 0.01}, options=TIGHT)
    b = simulate(cauer, u, options=TIGHT)
    assert rel_err(a.outputs, b.outputs) < 1e-7


def test_memory_template_reproduces_a_damper(tmp_path):
    """A damper's law is in the velocity: w1 f = w2 s + w3 der(s) with (1, 0, d)."""
    graph = build_graph([LIB], "MCL.Examples.MassSpringDamper")
    tpl = registry().template("memory")
    assert tpl.law() == "w1*i = w2*v + w3*dv"
    tm = swap_component(graph, "damper", tpl, tmp_path, w=[1.0, 0.0, 0.5])
    model = compile_model(tm.sources, tm.model_name)
    t = np.linspace(0, 10, 501)
    u = series(t, u=np.sin(1.3 * t) + 0.5)
    a = simulate(model, u, options=TIGHT)
    b = simulate(compiled("MCL.Examples.MassSpringDamper"), u, options=TIGHT)
    assert a.ok and rel_err(a.outputs, b.outputs) < 1e-7


def test_neural_template_is_an_equation_not_an_assignment(tmp_path):
    graph = build_graph([LIB], "MCL.Examples.CauerFilter")
    tpl = NeuralTemplate(hidden=2)
    tm = swap_component(graph, "Rnl", tpl, tmp_path)
    model = compile_model(tm.sources, tm.model_name)
    assert model.ode.nonlinear_blocks >= 1  # the network is solved for i, not evaluated
    t = np.linspace(0, 10, 201)
    res = simulate(model, series(t, u=np.sin(t)))
    assert res.ok, res.reason
    # the flow the model computes solves the template's own residual
    v = np.linspace(-1, 1, 5)
    i = tpl.flow_of(tpl.start(), v)
    assert np.allclose(tpl.residual(tpl.start(), {"v": v, "i": i}), 0, atol=1e-10)


def test_readable_equations_and_flow_curve():
    tpl = PolynomialTemplate(lhs=["i"], rhs=["v^2", "v^3"])
    assert tpl.law() == "w1*i = w2*v^2 + w3*v^3"
    assert tpl.equation([1, -0.0002, 0.0099], "v", "i") == "i = -0.0002*v^2 + 0.0099*v^3"
    v = np.linspace(-2, 2, 9)
    assert np.allclose(tpl.flow_of([1, 0, 0.01], v), 0.01 * v**3, atol=1e-12)
    assert np.allclose(tpl.features({"v": v, "i": 0 * v}) @ [1, 0, 0.01], -0.01 * v**3)


@pytest.mark.parametrize("term,ok", [("v^2*i", True), ("der(v)", True), ("1", True), ("tanh(v/0.3)", True),
                                     ("va^4", True), ("v*abs(v)", True), ("v/sqrt(1+(v/0.5)^2)", True),
                                     ("x^2", False), ("v^a", False), ("os.system(1)", False),
                                     ("__import__('os')", False), ("v.real", False)])
def test_term_parsing(term, ok):
    if ok:
        assert str(Monomial.parse(term)) in (term.replace("der(v)", "dv"), term)
    else:
        with pytest.raises(ConfigError, match="is not one of v, i, dv, di, va, vb|is not allowed"):
            Monomial.parse(term)


def test_expression_terms_evaluate_and_print_as_modelica():
    tpl = PolynomialTemplate(lhs=["i"], rhs=["v", "tanh(v/0.3)", "exp(v/0.1) - 1"])
    v = np.linspace(-1, 1, 7)
    assert np.allclose(tpl.features({"v": v, "i": 0 * v}) @ [1, -0.2, -0.4, -1e-3],
                       0.2 * v + 0.4 * np.tanh(v / 0.3) + 1e-3 * (np.exp(v / 0.1) - 1))
    assert tpl.law() == "w1*i = w2*v + w3*tanh(v/0.3) + w4*(exp(v/0.1)-1)"
    assert tpl.equation([1, 0.2, 0.4, 1e-3], "D.v", "D.i") == "D.i = 0.2*D.v + 0.4*tanh(D.v/0.3) + 0.001*(exp(D.v/0.1)-1)"


def test_third_party_template_through_the_hook(tmp_path):
    from mcl import hookimpl
    from mcl.registry import Registry

    class TanhLaw(PolynomialTemplate):
        name = "tanh-law"

        def __init__(self, start=None):
            super().__init__(lhs=["i"], rhs=["v"], start=start)

        def law(self):
            return "w1*i = w2*tanh(v)"

    class Plugin:
        @hookimpl
        def mcl_templates(self):
            return [TanhLaw]

    reg = Registry(external=False, extra=[Plugin()])
    tpl = reg.template({"name": "tanh-law", "start": [1.0, 0.5]})
    graph = build_graph([LIB], "MCL.Examples.CauerFilter")
    tm = swap_component(graph, "Rnl", tpl, tmp_path)
    model = compile_model(tm.sources, tm.model_name, reg=reg)
    t = np.linspace(0, 5, 101)
    assert simulate(model, series(t, u=np.sin(t)), reg=reg).ok
    with pytest.raises(ConfigError, match="unknown template 'nope'"):
        reg.template("nope")


def test_a_hysteresis_follows_v_without_shape_and_saturates_with_it():
    """Bouc-Wen's z: v itself where h1 = h2 = 0; bounded by span/(h1 + h2) while v grows; and a
    loop whose rising branch lies above the falling one (each cycle's work is lost in it)."""
    from mcl.hysteresis import HysteresisTemplate

    tpl = HysteresisTemplate(span=0.5, start=[1.0, 2.0, 0.0, 3.0], shape=[1e-9, 1e-9])
    v = np.concatenate([np.linspace(0, 1, 50), np.linspace(1, -1, 100)])
    assert np.allclose(tpl.path(tpl.start(), v), v, atol=1e-6)
    w = np.array([1.0, 2.0, 0.0, 3.0, 1.0, 1.0])
    z = tpl.path(w, np.linspace(0, 5, 200))
    assert z.max() < 0.5 / 2 + 1e-9 and z[-1] > 0.24
    xs = np.linspace(-1, 1, 41)
    rising = tpl.curve(w, xs)
    falling = tpl.branch(w, xs, rising=False)
    assert np.allclose(falling, -rising[::-1], atol=1e-6)      # (an odd law: the loop turned about 0)
    assert np.all(rising[1:-1] > falling[1:-1]) and np.allclose(rising[[0, -1]], falling[[0, -1]], atol=1e-6)
    assert tpl.equation(w, across="s", flow="f") == "f = 2*s + 3*z; der(z) = der(s) - (2*abs(der(s))*z + 2*der(s)*abs(z))"
    assert tpl.uses == {"v", "i", "dv"} and [str(m) for m in tpl.rhs] == ["v", "dv", "z"]


def test_a_hysteresis_class_declares_its_state_and_reproduces_a_spring(tmp_path):
    """The class written for a hysteresis (its own connectors, no library interface) declares z
    and its equation: with z's coefficient 0 it is the spring it replaces, and with a loop it
    runs."""
    graph = build_graph([LIB], "MCL.Examples.MassSpringDamper")
    tpl = registry().template({"name": "hysteresis", "span": 0.5})
    t = np.linspace(0, 10, 501)
    u = series(t, u=np.sin(1.3 * t) + 0.5)
    tm = swap_component(graph, "spring", tpl, tmp_path / "a", w=[1.0, 4.0, 0.0, 0.0, 1.0, -1.0])
    a = simulate(compile_model(tm.sources, tm.model_name), u, options=TIGHT)
    b = simulate(compiled("MCL.Examples.MassSpringDamper"), u, options=TIGHT)
    assert a.ok and rel_err(a.outputs, b.outputs) < 1e-7
    tm = swap_component(graph, "spring", tpl, tmp_path / "b", w=[1.0, 2.0, 0.0, 2.0, 1.0, 1.0])
    text = "".join(Path(p).read_text() for p in tm.sources if str(p).endswith(".mo"))
    assert "Real z(start = 0, fixed = true)" in text and "der(z) = dv - (h1*abs(dv)*z + h2*dv*abs(z))/span;" in text
    c = simulate(compile_model(tm.sources, tm.model_name), u, options=TIGHT)
    assert c.ok and rel_err(c.outputs, b.outputs) > 1e-3
