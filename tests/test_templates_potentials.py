"""Laws in the connectors' own potentials va, vb (and a constant term), from the template to the
words a report uses: parsing, the fit's units ((va/400)^4) and how a law is written, curves of a
law of two potentials, the class a template writes, the orientation flip of mechanical parts,
the roles and families that choose such laws, the nominal form that keeps an affine law's
constant. Every number is computed here by hand from the law's definition."""
import numpy as np
import pytest

from mcl.compile.components import Component, Connector
from mcl.discovery.families import basis, distillations, families, potential_families, role_of
from mcl.discovery.inject import nominal_of
from mcl.discovery.words import in_words, parity, words
from mcl.errors import ConfigError
from mcl.templates import Monomial, NeuralTemplate, PolynomialTemplate, scaled_power, unscaled

SIGMA = 5.67e-8


def pin(name, x="T", f="Q_flow"):
    return Connector(name, "HeatPort", (x,), (f,))


RAD = Component("Rad", "Modelica.Thermal.HeatTransfer.Components.ThermalConductor", [pin("port_a"), pin("port_b")])
SLIDE = Component("D", "Modelica.Mechanics.Translational.Components.Damper",
                  [pin("flange_a", "s", "f"), pin("flange_b", "s", "f")])


def test_potentials_and_the_constant_are_law_variables():
    assert Monomial.parse("va^4*vb").powers == (("va", 4), ("vb", 1))
    assert Monomial.parse("1").value({}) == 1.0
    term = Monomial.parse("(va/400)^4")
    assert term.variables == {"va"} and term.value({"va": np.array([400.0, 800.0])}).tolist() == [1.0, 16.0]
    with pytest.raises(ConfigError, match="'vc' is not one of v, i, dv, di, va, vb"):
        Monomial.parse("vc^2")
    with pytest.raises(ConfigError, match="at = "):
        PolynomialTemplate(rhs=["va"], at={"vc": 1.0})


def test_a_term_in_units_of_its_span_is_written_plainly():
    assert scaled_power(Monomial.parse("(va/400)^4")) == ("va", 400.0, 4)
    assert scaled_power(Monomial.parse("vb/1.5e+03")) == ("vb", 1500.0, 1)
    assert scaled_power(Monomial.parse("tanh(v/0.3)")) is None
    assert unscaled("(vb/500)^4") == ("vb^4", 1 / 500**4)
    tpl = PolynomialTemplate(lhs=["i"], rhs=["v", "(va/500)^4", "(vb/500)^4", "1"])
    w = [1.0, 0.0, SIGMA * 500**4, -SIGMA * 500**4, 0.5]
    text = tpl.equation(w, "Rad.dT", "Rad.Q_flow", potentials=("Rad.port_a.T", "Rad.port_b.T"))
    assert text == "Rad.Q_flow = 5.67e-08*Rad.port_a.T^4 - 5.67e-08*Rad.port_b.T^4 + 0.5"
    assert in_words(tpl, w, RAD) == text
    # the fit's columns stay near 1 at 300..500 K, where va^4 is ~1e10
    env = {"v": np.full(3, 10.0), "i": np.zeros(3), "va": np.array([300.0, 400, 500]), "vb": np.full(3, 290.0)}
    assert np.max(np.abs(tpl.features(env))) <= 10.0


def test_which_variable_a_law_is_drawn_against():
    assert PolynomialTemplate(rhs=["1", "va", "va^2"]).law_variable == "va"
    assert PolynomialTemplate(rhs=["(vb/300)^4"]).law_variable == "vb"
    assert PolynomialTemplate(rhs=["v", "va^4", "vb^4"]).law_variable == "v"
    assert PolynomialTemplate(rhs=["dv", "dv^3"]).law_variable == "dv"
    assert NeuralTemplate(x="va").law_variable == "va"
    with pytest.raises(ConfigError, match="x must be v, dv, va or vb"):
        NeuralTemplate(x="vc")


def test_curves_of_a_law_in_both_potentials():
    """Radiation drawn against v = T_a - T_b with T_b held (given, or the template's own), against
    T_a with T_b held; an outflow in its upstream level alone."""
    w = [1.0, 0.0, SIGMA * 500**4, -SIGMA * 500**4]
    rad = PolynomialTemplate(rhs=["v", "(va/500)^4", "(vb/500)^4"], at={"vb": 300.0})
    dT = np.array([0.0, 50.0, 200.0])
    assert np.allclose(rad.curve(w, dT), SIGMA * ((300 + dT) ** 4 - 300**4), rtol=1e-9, atol=1e-9)
    assert np.allclose(rad.curve(w, dT, at={"vb": 400.0}), SIGMA * ((400 + dT) ** 4 - 400**4), rtol=1e-9)
    tank = PolynomialTemplate(rhs=["sqrt(abs(va))*sign(va)"])
    h = np.array([0.04, 0.25, 1.0])
    assert np.allclose(tank.curve([1.0, 0.5], h), 0.5 * np.sqrt(h), rtol=1e-9)
    neural = NeuralTemplate(hidden=4, x="va", coupled=False)
    xs = np.linspace(300, 500, 41)                      # a range far from 0: units about its middle
    fs = 2e-8 * xs**4
    wn = neural.fit_curve(xs, fs)
    assert np.max(np.abs(neural.curve(wn, xs) - fs)) < 0.01 * np.ptp(fs)


def test_a_template_class_reads_the_connectors_own_potentials():
    tpl = PolynomialTemplate(lhs=["i"], rhs=["1", "va", "va^2"])
    comp = Component("Outlet1", "Outlet", [Connector("a", "Tanks.Port", ("h",), ("q",)),
                                           Connector("b", "Tanks.Port", ("h",), ("q",))])
    text = tpl.modelica_class("Outlet1_learned", comp, [1.0, 0.1, 0.4, -0.1])
    assert 'Real va "potential at a";' in text and "va = a.h;" in text and "vb" not in text
    assert "w1*i = w2 + w3*va + w4*va^2;" in text
    assert words(comp).potentials == ("Outlet1.a.h", "Outlet1.b.h")
    assert in_words(tpl, [1.0, 0.1, 0.4, -0.1], comp) == "Outlet1.q = 0.1 + 0.4*Outlet1.a.h - 0.1*Outlet1.a.h^2"


def test_potentials_keep_their_sign_when_a_mechanical_part_is_flipped():
    """A damper's s_rel = flange_b.s - flange_a.s and f = flange_b.f: the template's v and i
    change sign, flange_a.s does not. i = c1 v + c2 va^2 reads f = c1 s_rel - c2 flange_a.s^2."""
    assert parity(Monomial.parse("va^2")) == 1 and parity(Monomial.parse("va*v")) == -1
    tpl = PolynomialTemplate(lhs=["i"], rhs=["v", "va^2"])
    assert in_words(tpl, [1.0, 2.0, 3.0], SLIDE) == "D.f = 2*D.s_rel - 3*D.flange_a.s^2"
    # checked numerically: the flipped law at a point against the template's
    s_a, s_b = 0.7, 0.2
    i = 2.0 * (s_a - s_b) + 3.0 * s_a**2
    assert np.isclose(-i, 2.0 * (s_b - s_a) - 3.0 * s_a**2)


def test_a_flipped_part_keeps_its_own_names_for_a_term_that_is_neither_even_nor_odd():
    """i = c0 + c1 tanh(dv/s1) + c2 (exp(dv/s2) - 1) on a damper (v = -s_rel, i = -f): the
    constant and the tanh change sign, the exponential is written in -v_rel; the law reads
    f = ... in the damper's names, not (-f) = ... der(-s_rel). Checked at a point."""
    tpl = PolynomialTemplate(lhs=["i"], rhs=["1", "tanh(dv/s1)", "exp(dv/s2)-1"], scales={"s1": 0.01, "s2": 0.2})
    w = [1.0, 1.5, 18.0, 17.5, 0.01, 0.2]
    text = in_words(tpl, w, SLIDE)
    assert text.startswith("D.f = ") and "der(" not in text and "(-D.f)" not in text, text
    assert "(-D.v_rel)" in text and "tanh(D.v_rel/0.01)" in text, text
    # the written law, evaluated, gives the template's force at b for a speed of b against a
    v_rel = 0.05
    rhs = text.split(" = ", 1)[1].replace("D.v_rel", repr(v_rel)).replace("^", "**")
    f_b = eval(rhs, {"tanh": np.tanh, "exp": np.exp})
    i = 1.5 + 18.0 * np.tanh(-v_rel / 0.01) + 17.5 * (np.exp(-v_rel / 0.2) - 1)
    assert np.isclose(f_b, -i)


def test_roles_and_families_for_laws_in_a_potential():
    t = np.linspace(0, 50, 400)
    h1, h2 = 0.5 + 0.3 * np.sin(0.3 * t), 0.3 + 0.1 * np.cos(0.2 * t)
    env = {"v": h1 - h2, "i": (h1 + 0.4) / 2.53, "dv": np.gradient(h1 - h2, t), "di": np.zeros_like(t),
           "va": h1, "vb": h2}
    assert role_of(env) == "absolute"
    assert families("absolute", env) == [{"name": "polynomial", "lhs": ["i"], "rhs": ["1", "va", "va^2", "va^3"],
                                          "family": "absolute"},
                                         {"name": "polynomial", "lhs": ["i"], "rhs": ["1", "sqrt(abs(va))*sign(va)"],
                                          "family": "absolute"}]
    # a linear conductor between two bodies whose temperatures both vary: radiation is tried,
    # in units of the span; not where one side is held, nor for potentials that cross 0
    Ta, Tb = 400 + 80 * np.sin(0.01 * t), 330 + 30 * np.cos(0.013 * t)
    rad = {"v": Ta - Tb, "i": 7.0 * (Ta - Tb), "va": Ta, "vb": Tb}
    assert role_of({**rad, "dv": np.gradient(Ta - Tb, t), "di": np.zeros_like(t)}) == "static"
    fam = potential_families(rad)
    unit = float(f"{np.max(Ta):.2g}")
    assert fam[0]["rhs"][0] == "v" and [scaled_power(t) for t in fam[0]["rhs"][1:]] == [("va", unit, 4), ("vb", unit, 4)]
    assert abs(fam[0]["at"]["vb"] - np.mean(Tb)) < 0.1
    assert potential_families({**rad, "vb": np.full_like(t, 300.0)}) == []
    assert potential_families({**rad, "va": Ta - 400, "vb": Tb - 400}) == []
    # a conductor whose nominal law has a constant: so may its law
    affine = {**rad, "i": 7.0 * (Ta - Tb) + 50.0, "dv": np.zeros_like(t), "di": np.zeros_like(t)}
    assert role_of(affine) == "static" and families("static", affine)[0]["rhs"][0] == "1"


def test_the_square_root_of_a_level_is_distilled():
    h = np.linspace(0.02, 0.9, 201)
    assert ("1", None) in basis(h, "va") and ("1", None) not in basis(h, "v")
    best = distillations(h, 0.5 * np.sqrt(h), "va")[0]
    assert best["terms"] == ["sqrt(abs(va))*sign(va)"] and abs(best["c"][0] - 0.5) < 1e-9


def test_an_affine_nominal_law_keeps_its_constant():
    """q = (h_a + 0.4)/2.53: in the law's difference variable it is not exact; in its potential
    with the constant it is, and v (= va - vb, with vb held) is not repeated."""
    t = np.linspace(0, 50, 400)
    h1 = 0.5 + 0.3 * np.sin(0.3 * t)
    env = {"v": h1 - 0.2, "i": (h1 + 0.4) / 2.53, "dv": np.gradient(h1, t), "va": h1, "vb": np.full_like(t, 0.2)}
    form = nominal_of(env, {"v", "i", "va", "vb"})
    assert form.exact and set(form.coefficients) == {"va", "1"}
    assert np.isclose(form.coefficients["va"], 1 / 2.53) and np.isclose(form.coefficients["1"], 0.4 / 2.53)
    plain = nominal_of({**env, "i": (h1 - 0.2) / 2.0}, {"v", "i", "va", "vb"})
    assert plain.exact and plain.coefficients == pytest.approx({"v": 0.5})


def test_a_learned_class_leaves_out_the_terms_pruned_to_zero():
    """A pruned sqrt(|v|) term written as 0*sqrt(|v|)*... would still be differentiated where the
    law runs: its Jacobian 0*inf = NaN at v = 0 stopped a recompiled model at its first step.
    A class still to be fitted keeps every term (its 0 is a start value)."""
    tpl = PolynomialTemplate(lhs=["i"], rhs=["v", "sqrt(abs(v))*tanh(v/s1)", "s3*log(1 + exp((v - s2)/s3))"],
                             scales={"s1": 0.2, "s2": 0.5, "s3": 0.05})
    comp = Component("Outlet1", "Outlet", [Connector("a", "Tanks.Port", ("h",), ("q",)),
                                           Connector("b", "Tanks.Port", ("h",), ("q",))])
    w = [1.0, 0.9, 0.0, -1.0, 0.2, 0.5, 0.05]
    learned = tpl.modelica_class("Outlet1_learned", comp, w, learned=True)
    assert "w1*i = w2*v + w4*s3*log(1+exp((v-s2)/s3));" in learned and "sqrt" not in learned.split("equation")[1]
    assert "w1*i = w2*v + w3*sqrt(abs(v))*tanh(v/s1) + w4*" in tpl.modelica_class("Outlet1_learned", comp, w)


def test_a_knee_is_distilled_with_its_place_and_width():
    """A clamp (slope 1 below 0.5, then 0, rounded over 0.05): the line through 0 and one knee,
    its place and width fitted, named as a knee; far past the knee it is finite (a width of
    1e-4: exp((v - s)/w) alone overflows)."""
    from mcl.discovery.families import shape_words

    x = np.linspace(-1.5, 1.4, 201)
    f = x - 0.05 * np.logaddexp(0.0, (x - 0.5) / 0.05)
    law = next(law for law in distillations(x, f, "v") if len(law["terms"]) == 2)
    assert law["terms"] == ["v", "(v - s1 + abs(v - s1))/2 + s2*log(1 + exp(-abs(v - s1)/s2))"], law
    assert abs(law["scales"]["s1"] - 0.5) < 1e-3 and abs(law["scales"]["s2"] - 0.05) < 1e-3, law
    assert shape_words(law["terms"][1]).startswith("a knee on one side")
    knee = Monomial.parse(law["terms"][1], ("s1", "s2"))
    assert knee.value({"v": np.array([2.0]), "s1": 0.5, "s2": 1e-4})[0] == pytest.approx(1.5)


def test_a_curve_with_a_fitted_wiggle_also_gives_its_polynomial_laws():
    """A damper's 0.5 v + 0.6 v^3 as a law that fitted noise with sharp tanh terms reads it: a
    small step at 0 that a shape follows better on the curve than the line does. Asked for
    plain laws too, the distillation also gives the best law of polynomial terms alone, which
    a simulation fit then judges (the data preferred v + v^3 by 11 BIC); not asked, none."""
    v = np.linspace(-1.6, 1.6, 201)
    f = 0.5 * v + 0.6 * v**3 + 0.09 * np.tanh(v / 0.047) - 0.09 * np.tanh(v / 0.24)
    plain = [law for law in distillations(v, f, "v", plain=True)
             if all("s1" not in t for t in law["terms"])]
    two = next(law for law in plain if len(law["terms"]) == 2)
    assert sorted(two["terms"]) == ["v", "v^3"], two
    np.testing.assert_allclose(two["c"], [0.5, 0.6] if two["terms"][0] == "v" else [0.6, 0.5], atol=0.02)
    assert not any(set(law["terms"]) == {"v", "v^3"} for law in distillations(v, f, "v"))


def test_a_missing_term_is_named_in_the_components_own_variable():
    """What a law adds to the nominal law is written in the variable the law itself is written
    in (the term k*x of a balance: sinh(x/s1), not the template's sinh(v/s1)); a name that is
    not a plain identifier (a negated one) leaves the template's."""
    from mcl.discovery.extend import _named
    from mcl.discovery.families import shape_words

    said = shape_words("sinh(v/s1)")
    assert _named(said, "v", "x") == said.replace("sinh(v/s1)", "sinh(x/s1)") and said.endswith("sinh(v/s1)")
    assert _named("v^2*tanh(v/s2)", "v", "phi_rel") == "phi_rel^2*tanh(phi_rel/s2)"
    assert _named("v^2", "v", "(-s_rel)") == "v^2"


def test_the_stribeck_effect_is_named_only_in_a_speed():
    """A term that rises and fades (tanh(x/s) exp(-(x/s)^2)) is the Stribeck effect in a
    friction's law of its speed; in a tank's law of its level it is only that shape."""
    from mcl.discovery.families import shape_words

    term = "tanh(v/s1)*exp(-(v/s1)^2)"
    assert shape_words(term).startswith("the Stribeck effect")
    assert shape_words(term, speed=False).startswith("a bump that fades") and shape_words(term, speed=False).endswith(term)
