"""The connection graph: built from sources, written back as Modelica that compiles."""
import numpy as np
import pytest

from helpers import LIB, compiled, multisine, rel_err, series
from mcl.api import compile_model, simulate
from mcl.cli import main
from mcl.errors import ModelicaError
from mcl.graph import Component, build_graph
from mcl.swap import write_package


@pytest.fixture(scope="module")
def cauer_graph():
    return build_graph([LIB], "MCL.Examples.CauerFilter")


def test_components_connectors_and_nets(cauer_graph):
    comps = cauer_graph.components
    assert comps["Rnl"].cls == "MCL.Electrical.PolynomialResistor"
    assert [c.name for c in comps["Rnl"].connectors] == ["p", "n"]
    assert comps["Rnl"].connectors[0].potential == ["v"] and comps["Rnl"].connectors[0].flow == ["i"]
    assert not comps["G"].two_connector
    assert {c.name for c in cauer_graph.two_connector_components()} == \
        {"V", "R1", "C1", "C2", "C3", "C4", "C5", "L1", "L2", "Rnl", "R4"}
    nets = cauer_graph.nets()
    assert {"C4.n", "C5.p", "L2.n", "Rnl.p"} in nets and {"R4.p", "Rnl.n"} in nets
    assert cauer_graph.neighbours("Rnl") == {"C4", "C5", "L2", "R4"}


def test_round_trip_compiles_to_the_same_model(cauer_graph, tmp_path, cauer):
    path = write_package(tmp_path, "RoundTrip", [cauer_graph.to_modelica("Cauer")])
    copy = compile_model([LIB, path], "RoundTrip.Cauer")
    t = np.linspace(0, 20, 401)
    u = series(t, u=multisine(t))
    tight = {"rtol": 1e-10, "atol": 1e-12}  # state choice may differ: compare the solutions
    assert rel_err(simulate(copy, u, options=tight).outputs, simulate(cauer, u, options=tight).outputs) < 1e-7


def test_replace_and_add_components(cauer_graph, tmp_path, cauer):
    """Rnl replaced by a linear resistor; a resistor added in parallel to R4."""
    g = cauer_graph.replaced("Rnl", "MCL.Electrical.Resistor", "(R = 2)")
    extra = Component("Rp", "MCL.Electrical.Resistor", g.components["R4"].connectors,
                      "MCL.Electrical.Resistor Rp(R = 3);")
    g = g.with_component(extra, [("Rp.p", "R4.p"), ("Rp.n", "R4.n")])
    path = write_package(tmp_path, "Edited", [g.to_modelica("Cauer")])
    model = compile_model([LIB, path], "Edited.Cauer")
    assert "Rp.R" in model.parameters and "Rnl.w1" not in model.parameters
    t = np.linspace(0, 20, 401)
    u = series(t, u=multisine(t))
    res = simulate(model, u)
    assert res.ok
    assert rel_err(res.outputs, simulate(cauer, u).outputs) > 0.5  # a different circuit now


def test_learned_component_moved_into_a_divider(tmp_path):
    """A component class reused in a different system built from the graph of another one."""
    divider = build_graph([LIB], "MCL.Examples.CauerFilter")
    for name in ("C1", "C2", "C3", "C4", "C5", "L1", "L2"):
        divider = divider.without_component(name)
    g = divider.with_component(Component("Rb", "MCL.Electrical.Resistor", divider.components["R1"].connectors,
                                         "MCL.Electrical.Resistor Rb(R = 1);"),
                               [("Rb.p", "R1.n"), ("Rb.n", "Rnl.p")])
    path = write_package(tmp_path, "Divider", [g.to_modelica("Divider")])
    model = compile_model([LIB, path], "Divider.Divider")
    t = np.linspace(0, 5, 51)
    u = 2.0 + 0 * t
    res = simulate(model, series(t, u=u), options={"rtol": 1e-10, "atol": 1e-12})
    # series R1 + Rb + Rnl + R4 (1 ohm each, Rnl: i = 0.01 v^3): solve for i at u = 2
    from scipy.optimize import brentq

    i = brentq(lambda i: 0.01 * (2 - 3 * i) ** 3 - i, 0, 1)
    assert np.allclose(res.output("y"), i, atol=1e-9)


def test_unknown_component_is_a_clear_error(cauer_graph):
    with pytest.raises(ModelicaError, match="no component 'Nope'"):
        cauer_graph.replaced("Nope", "MCL.Electrical.Resistor")


def test_graph_command_prints_and_draws(tmp_path, capsys):
    png = tmp_path / "g.png"
    assert main(["graph", str(LIB), "-m", "MCL.Examples.TwoInertiaDrive", "--draw", str(png)]) == 0
    out = capsys.readouterr().out
    assert "shaft" in out and "[candidate]" in out and "nets:" in out
    assert png.stat().st_size > 10_000


def test_reference_model_unchanged():
    assert compiled("MCL.Examples.CauerFilter").parameters["Rnl.w3"] == 0.01


def test_a_components_class_is_read_from_a_declaration_of_several():
    """Tank t1, t2; declares both; a name in a call's arguments or a binding is declared by
    nothing; a list of thousands is read in linear time (a pattern over the list backtracked
    without end)."""
    from mcl.compile.components import declared_classes

    text = """
    model Tank Real h; end Tank;
    model Sys
      Tank t1(h(start = f(a, t3))), t2 "the second", t4[2];
      Real x = max(1, t3), t3;
      Real """ + ", ".join(f"a{k}(start = {k})" for k in range(3000)) + """;
    end Sys;
    """
    found = declared_classes(["t1", "t2", "t3", "t4[1]", "a2999", "zz"], "Sys", {"Sys.mo": text})
    assert found == {"t1": "Tank", "t2": "Tank", "t3": "Real", "t4[1]": "Tank", "a2999": "Real"}, found
