"""Blame the part whose role the effect fits: parallel parts explain the data alike, so a force in
the position is the spring's, a force in the speed the damper's, a current in the voltage the
resistor's (not a capacitor's leak); the others are named as equivalent.

The systems are MSL parts written as an engineer writes them; the data come from their ODEs
written by hand and solved by SciPy.
"""
import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from helpers import msl_path, needs_msl
from mcl.cli import main

MSL = msl_path()
pytestmark = [pytest.mark.slow, needs_msl()]

SUSPENSION = """
model Suspension "a mass on a spring and a damper in parallel, pushed by a force"
  import Modelica.Mechanics.Translational.Components.{Mass, Spring, Damper, Fixed};
  import Modelica.Mechanics.Translational.Sources.Force;
  import Modelica.Mechanics.Translational.Sensors.{PositionSensor, SpeedSensor};
  Modelica.Blocks.Interfaces.RealInput F "force";
  Modelica.Blocks.Interfaces.RealOutput {out} "measured";
  Fixed wall;
  Force push;
  Mass M(m = 1.0);
  Spring S(c = 4);
  Damper D(d = 0.6);
  {sensor} sensor;
initial equation
  M.s = 0;
  M.v = 0;
equation
  connect(F, push.f);
  connect(push.flange, M.flange_a);
  connect(wall.flange, S.flange_a);
  connect(S.flange_b, M.flange_a);
  connect(wall.flange, D.flange_a);
  connect(D.flange_b, M.flange_a);
  connect(M.flange_b, sensor.flange);
  connect(sensor.{out}, {out});
end Suspension;
"""


def excitation(seed, amplitude, lo, hi):
    rng = np.random.default_rng(seed)
    w, ph = rng.uniform(lo, hi, 4), rng.uniform(0, 6, 4)
    return lambda s: sum(amplitude * np.sin(a * s + b) for a, b in zip(w, ph)), rng


def suspension_data(path, seed, spring, damper, measure):
    F, rng = excitation(seed, 2.0, 0.4, 2.5)
    t = np.linspace(0, 30, 1201)
    x = solve_ivp(lambda s, x: [x[1], F(s) - spring(x[0]) - damper(x[1])], (0, 30), [0, 0], t_eval=t,
                  rtol=1e-10, atol=1e-12).y
    y = x[0] if measure == "s" else x[1]
    y = y + rng.normal(0, 0.01 * np.std(y), len(t))
    path.write_text(f"time,F,{measure}\n" + "\n".join(f"{float(a)!r},{float(b)!r},{float(c)!r}" for a, b, c in zip(t, F(t), y)) + "\n")


def discover(tmp_path, source: str, name: str) -> dict:
    (tmp_path / "run.yaml").write_text(
        f"model: {{sources: [{source}], name: {name}, libraries: [{MSL}]}}\n"
        "data: {train: train.csv, validate: validate.csv}\noutput: out\n")
    assert main(["--quiet", "run", str(tmp_path / "run.yaml")]) == 0
    return json.loads((tmp_path / "out" / "report.json").read_text())


def curve_error(cause, truth) -> float:
    xs, fs = np.array(cause["law"]["curve"]).T
    return float(np.max(np.abs(fs - truth(xs))) / np.max(np.abs(truth(xs))))


@pytest.mark.parametrize("measure", ["s", "v"])
def test_a_stiffening_spring_is_the_springs_fault_not_the_parallel_dampers(tmp_path, measure):
    sensor = {"s": "PositionSensor", "v": "SpeedSensor"}[measure]
    (tmp_path / "Suspension.mo").write_text(SUSPENSION.replace("{out}", measure).replace("{sensor}", sensor))
    spring, damper = (lambda s: 4 * s + 3 * s**3), (lambda v: 0.6 * v)
    suspension_data(tmp_path / "train.csv", 1, spring, damper, measure)
    suspension_data(tmp_path / "validate.csv", 2, spring, damper, measure)
    cause = discover(tmp_path, "Suspension.mo", "Suspension")["cause"]
    assert cause["component"] == "S", cause["effect"]
    assert cause["law"]["equation"].startswith("S.f = ") and "S.s_rel^3" in cause["law"]["equation"]
    assert curve_error(cause, spring) < 0.05
    assert [e["component"] for e in cause["equivalents"]] == ["D"]
    assert "parallel to S" in cause["equivalents"][0]["reason"]


def test_a_damper_cubic_in_the_speed_is_the_dampers_fault(tmp_path):
    (tmp_path / "Suspension.mo").write_text(SUSPENSION.replace("{out}", "s").replace("{sensor}", "PositionSensor"))
    spring, damper = (lambda s: 4 * s), (lambda v: 0.6 * v + 0.8 * v**3)
    suspension_data(tmp_path / "train.csv", 3, spring, damper, "s")
    suspension_data(tmp_path / "validate.csv", 4, spring, damper, "s")
    cause = discover(tmp_path, "Suspension.mo", "Suspension")["cause"]
    assert cause["component"] == "D", cause["effect"]
    assert curve_error(cause, damper) < 0.05
    assert [e["component"] for e in cause["equivalents"]] == ["S"]


SHUNT = """
model Shunted "a source through a resistor into a capacitor with a resistor across it"
  import Modelica.Electrical.Analog.{Basic, Sources, Sensors};
  Modelica.Blocks.Interfaces.RealInput u "source voltage";
  Modelica.Blocks.Interfaces.RealOutput y "capacitor voltage";
  Sources.SignalVoltage V;
  Basic.Resistor R1(R = 1);
  Basic.Capacitor C(C = 0.5, v(start = 0, fixed = true));
  Basic.Resistor Rp(R = 2) "the load across the capacitor";
  Basic.Ground G;
  Sensors.VoltageSensor S;
equation
  connect(u, V.v);
  connect(V.p, R1.p);
  connect(R1.n, C.p);
  connect(C.p, Rp.p);
  connect(Rp.n, G.p);
  connect(C.n, G.p);
  connect(V.n, G.p);
  connect(S.p, C.p);
  connect(S.n, G.p);
  connect(S.v, y);
end Shunted;
"""


def shunt_data(path, seed, load):
    u, rng = excitation(seed, 1.5, 0.3, 2.0)
    t = np.linspace(0, 30, 1201)
    v = solve_ivp(lambda s, v: [((u(s) - v[0]) / 1.0 - load(v[0])) / 0.5], (0, 30), [0.0], t_eval=t,
                  rtol=1e-10, atol=1e-12).y[0]
    y = v + rng.normal(0, 0.01 * np.std(v), len(t))
    path.write_text("time,u,y\n" + "\n".join(f"{float(a)!r},{float(b)!r},{float(c)!r}" for a, b, c in zip(t, u(t), y)) + "\n")


def test_a_current_in_the_voltage_is_the_resistors_not_a_capacitor_leak(tmp_path):
    (tmp_path / "Shunted.mo").write_text(SHUNT)
    load = lambda v: 0.5 * v + 0.3 * v**3
    shunt_data(tmp_path / "train.csv", 5, load)
    shunt_data(tmp_path / "validate.csv", 6, load)
    cause = discover(tmp_path, "Shunted.mo", "Shunted")["cause"]
    assert cause["component"] == "Rp", cause["effect"]
    assert curve_error(cause, load) < 0.05
    assert [e["component"] for e in cause["equivalents"]] == ["C"]


AXIS = """
model Axis "a carriage pushed by its motor's force along guides with friction; the position is measured"
  import Modelica.Mechanics.Translational.Components.{Mass, Damper, Fixed};
  import Modelica.Mechanics.Translational.Sources.Force;
  import Modelica.Mechanics.Translational.Sensors.PositionSensor;
  Modelica.Blocks.Interfaces.RealInput F(unit = "N") "motor force";
  Modelica.Blocks.Interfaces.RealOutput s(unit = "m") "encoder";
  Fixed frame;
  Force motor;
  Mass M(m = 1.0);
  Damper D(d = 1.5) "viscous friction of the guides";
  PositionSensor encoder;
initial equation
  M.s = 0;
  M.v = 0;
equation
  connect(F, motor.f);
  connect(motor.flange, M.flange_a);
  connect(frame.flange, D.flange_a);
  connect(D.flange_b, M.flange_a);
  connect(M.flange_b, encoder.flange);
  connect(encoder.s, s);
end Axis;
"""


def test_friction_with_an_offset_force_is_the_dampers_law_with_its_constant(tmp_path):
    """A positioning axis's friction, f = Fv v + Fc tanh(v/0.05) + offset (the EMPS benchmark's
    law): the position drifts off under a constant force the nominal viscous damper cannot give;
    the damper's law is learned with its constant."""
    (tmp_path / "Axis.mo").write_text(AXIS)
    friction = lambda v: 1.5 * v + 0.6 * np.tanh(v / 0.05) + 0.3
    for seed, file in ((5, "train.csv"), (6, "validate.csv")):      # the suspension without its spring
        suspension_data(tmp_path / file, seed, lambda s: 0.0 * s, friction, "s")
    report = discover(tmp_path, "Axis.mo", "Axis")
    cause = report["cause"]
    assert cause["component"] == "D", cause["effect"]
    assert curve_error(cause, friction) < 0.1, cause["law"]["equation"]
    assert "missing from the nominal law: a constant" in cause["effect"], cause["effect"]
    g = report["gain"]
    assert g["validation_rms_after"] < 0.2 * g["validation_rms_before"]
