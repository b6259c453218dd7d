"""A component that gives its losses to a heat port (``useHeatPort = true``) takes a law between
its two pins (or flow ports) like any other; its heat port stays with its own equations, and its
learned class holds the nominal component (with the model's modifiers) and the learned law's
extra flow beside it.

A heating element on a plate held at a fixed temperature is fed through a lead; a capacitor
buffers the node. The element conducts more than Ohm's law says at higher voltage (a cubic
term). The data come from the circuit's ODE written by hand and solved by SciPy: the same
circuit as test_discover's RC, its load a heating element.
"""
import numpy as np

from helpers import discovered, needs_msl
from test_discover import rc_data       # the element conducts i = 0.5 v + cubic v^3 there as here
from mcl.compile.components import Connector, law_pair

HEATER = """
model Heater "a heating element on a plate at a fixed temperature, fed through a lead"
  import Modelica.Electrical.Analog.Basic;
  import Modelica.Electrical.Analog.Sources;
  import Modelica.Electrical.Analog.Sensors;
  import Modelica.Thermal.HeatTransfer;
  Modelica.Blocks.Interfaces.RealInput u(unit = "V") "supply voltage";
  Modelica.Blocks.Interfaces.RealOutput y(unit = "V") "voltage across the element";
  Sources.SignalVoltage supply;
  Basic.Ground gnd;
  Basic.Resistor lead(R = 1);
  Basic.Capacitor C(C = 0.5);
  Basic.Resistor element(R = 2, useHeatPort = true) "its losses heat the plate";
  HeatTransfer.Sources.FixedTemperature plate(T = 320);
  Sensors.VoltageSensor vs;
initial equation
  C.v = 0;
equation
  connect(u, supply.v);
  connect(supply.p, lead.p);
  connect(lead.n, C.p);
  connect(C.p, element.p);
  connect(C.n, gnd.p);
  connect(element.n, gnd.p);
  connect(supply.n, gnd.p);
  connect(element.heatPort, plate.port);
  connect(vs.p, C.p);
  connect(vs.n, gnd.p);
  connect(vs.v, y);
end Heater;
"""


def test_a_heat_port_beside_two_pins_leaves_the_pins_to_the_law():
    pin = lambda n: Connector(n, "Pin", ("v",), ("i",))                 # noqa: E731
    heat = Connector("heatPort", "HeatPort_a", ("T",), ("Q_flow",))
    assert law_pair([pin("p"), pin("n"), heat]) == ([pin("p"), pin("n")], [heat])
    assert law_pair([pin("p"), pin("n")]) == ([pin("p"), pin("n")], [])
    # two heat ports are the law's own pair (a thermal conductor); a heat port and one pin are not a pair
    a, b = Connector("port_a", "HeatPort_a", ("T",), ("Q_flow",)), Connector("port_b", "HeatPort_b", ("T",), ("Q_flow",))
    assert law_pair([a, b]) == ([a, b], [])
    assert law_pair([pin("p"), heat]) == ([pin("p"), heat], [])


@needs_msl()
def test_a_resistor_with_its_heat_port_on_is_named_and_its_law_learned(tmp_path):
    rc_data(tmp_path / "train.csv", 1, 0.3)
    rc_data(tmp_path / "validate.csv", 2, 0.3)
    report = discovered(tmp_path, "Heater.mo", "Heater", HEATER)
    assert report["misfit"]["significant"]
    cause = report["cause"]
    names = {cause["component"], *(e["component"] for e in cause["evidence"].get("equivalents", []))}
    assert "element" in names, (cause["component"], names)
    if cause["component"] == "element":
        xs, fs = np.array(cause["law"]["curve"]).T
        truth = 0.5 * xs + 0.3 * xs**3
        assert np.max(np.abs(fs - truth)) <= 0.05 * np.max(np.abs(truth))
    g = report["gain"]
    assert g["validation_rms_after"] <= 0.2 * g["validation_rms_before"]
    # written back: the nominal element inside the learned class, with the model's modifiers and
    # its heat port; the written model compiled again runs as the discovery ran it
    ext = report["extended"]
    assert "error" not in ext and ext["recompiled_difference"] < 1e-3, ext
    if cause["component"] == "element":
        written = (tmp_path / "out" / "extended" / "Heater.mo").read_text()
        assert "element(nominal(R = 2, useHeatPort = true))" in written
        assert (tmp_path / "out" / ext["fmu"]).exists()


def test_the_extra_flow_of_a_pipe_carries_its_enthalpy_from_the_side_it_comes_from():
    """A FluidHeatFlow port carries the enthalpy with the mass flow: the extra flow's enthalpy
    flow is taken from the side it comes from (semiLinear), as the discovery simulated it."""
    from mcl.compile.components import Component
    from mcl.discovery.modelica import _flow_between

    port = lambda n: Connector(n, "FlowPort", ("p", "h"), ("m_flow", "H_flow"))      # noqa: E731
    heat = Connector("heatPort", "HeatPort_a", ("T",), ("Q_flow",))
    pipe = Component("radiator", "Modelica.Thermal.FluidHeatFlow.Components.Pipe", [port("flowPort_a"), port("flowPort_b")],
                     ports=[heat])
    text = _flow_between("radiator_deviation", pipe, {"flowPort_a": "FP_a", "flowPort_b": "FP_b"})
    assert "flowPort_a.m_flow = f;" in text and "0 = flowPort_a.m_flow + flowPort_b.m_flow;" in text
    assert "flowPort_a.H_flow = semiLinear(f, flowPort_a.h, flowPort_b.h);" in text
    assert "FP_a flowPort_a;" in text and "heatPort" not in text
