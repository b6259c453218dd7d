"""Discovery on the engineer's model as written, compiled once: MSL parts used through imports,
initial equations, several faults at once, and a model with nothing wrong.

Every model is written as an engineer writes one (imports, RealInput/RealOutput, sensors,
initial equations); every data set comes from the system's ODE written out by hand and solved by
SciPy (examples/ladder/ladder.py, or below), never from mcl.
"""
import json
import sys

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from helpers import ROOT, msl_path, needs_msl, write_uy
from mcl.cli import main

sys.path.insert(0, str(ROOT / "examples" / "ladder"))
from ladder import values, write_data, write_model  # noqa: E402

MSL = msl_path()
pytestmark = [pytest.mark.slow, needs_msl()]


def run(tmp_path, source: str, model: str, extra: str = "") -> dict:
    (tmp_path / "run.yaml").write_text(
        f"model: {{sources: [{source}], name: {model}, libraries: [{MSL}]}}\n"
        "data: {train: train.csv, validate: validate.csv}\noutput: out\n" + extra)
    assert main(["--quiet", "run", str(tmp_path / "run.yaml")]) == 0
    return json.loads((tmp_path / "out" / "report.json").read_text())


def curve_error(cause, truth) -> float:
    xs, fs = np.array(cause["law"]["curve"]).T
    return float(np.max(np.abs(fs - truth(xs))) / np.max(np.abs(truth(xs))))


def ladder(tmp_path, n, cubic=None, leak=None, v0=0.0) -> str:
    name = write_model(n, tmp_path / f"Ladder{n}.mo", v0=v0)
    write_data(n, tmp_path / "train.csv", 1, cubic, leak, v0=v0)
    write_data(n, tmp_path / "validate.csv", 2, cubic, leak, v0=v0)
    return name


def test_a_model_with_imports_and_initial_equations_keeps_them(tmp_path):
    """The ladder imports ``Modelica.Electrical.Analog`` and starts every capacitor at 1 V in an
    initial equation: the candidates start there too (a rewritten model would lose both)."""
    n = 4
    name = ladder(tmp_path, n, cubic={2: 0.8}, v0=1.0)
    report = run(tmp_path, f"{name}.mo", name)
    cause = report["cause"]
    R, _ = values(n)
    assert cause["component"] == "R2" and cause["class"] == "Modelica.Electrical.Analog.Basic.Resistor"
    assert curve_error(cause, lambda v: v / R + 0.8 * v**3) < 0.05
    g = report["gain"]
    assert g["validation_rms_after"] < 0.3 * g["validation_rms_before"]
    # the learned class is put back into a copy of the user's file, imports and all
    text = (tmp_path / "out" / report["extended"]["sources"][0]).read_text()
    assert "import Modelica.Electrical.Analog;" in text and "Learned.R2_polynomial R2" in text
    assert report["extended"]["recompiled_difference"] < 1e-3


def test_a_long_record_is_searched_on_its_head_and_judged_on_all(tmp_path):
    """``fitting.max_samples``: the search and its fits see the first 300 of 601 samples; the
    law is still found, and the gain is measured on the whole record."""
    n = 4
    name = ladder(tmp_path, n, cubic={2: 0.8})
    report = run(tmp_path, f"{name}.mo", name, "fitting: {max_samples: 300}\n")
    R, _ = values(n)
    assert report["cause"]["component"] == "R2"
    assert curve_error(report["cause"], lambda v: v / R + 0.8 * v**3) < 0.05
    assert report["settings"]["samples searched"] == 300
    g = report["gain"]
    assert g["train_rms_after"] < 0.3 * g["train_rms_before"]
    assert g["validation_rms_after"] < 0.3 * g["validation_rms_before"]


def test_two_faults_are_both_named(tmp_path):
    n = 4
    name = ladder(tmp_path, n, cubic={2: 0.8}, leak={4: 0.3})
    report = run(tmp_path, f"{name}.mo", name)
    causes = {c["component"]: c for c in report["causes"]}
    assert set(causes) == {"R2", "C4"}, [c["effect"] for c in report["causes"]]
    R, C = values(n)
    assert curve_error(causes["R2"], lambda v: v / R + 0.8 * v**3) < 0.05
    law = causes["C4"]["law"]["template_equation"]       # i = C der(v) + 0.3 v: the leak is found
    terms = dict(zip(causes["C4"]["parameters"], causes["C4"]["w"]))
    assert "der(v)" in law and abs(terms["w5"] - 0.3) < 0.05 * 0.3 + 1e-3, (law, terms)
    assert abs(terms["w2"] - C) < 0.05 * C
    assert report["causes"][-1]["after"]["misfit_left"] == "at the noise level"


def test_a_model_with_nothing_wrong_gets_no_cause(tmp_path):
    name = ladder(tmp_path, 4)
    report = run(tmp_path, f"{name}.mo", name)
    assert not report["misfit"]["significant"]
    assert report["cause"] is None and report["causes"] == []


DRIVE = """
model Drive "a motor's torque into an inertia, a shaft to the load inertia on its bearing"
  import Modelica.Mechanics.Rotational.Components;
  import Modelica.Mechanics.Rotational.Sources.Torque;
  import Modelica.Mechanics.Rotational.Sensors.SpeedSensor;
  Modelica.Blocks.Interfaces.RealInput tau "motor torque";
  Modelica.Blocks.Interfaces.RealOutput w "load speed";
  Torque motor;
  Components.Inertia J1(J = 0.5);
  Components.Spring shaft(c = 20);
  Components.Inertia J2(J = 1.0);
  Components.Damper bearing(d = 0.4) "viscous bearing friction";
  Components.Fixed housing;
  SpeedSensor sensor;
initial equation
  J1.phi = 0;
  J1.w = 0;
  J2.phi = 0;
  J2.w = 0;
equation
  connect(tau, motor.tau);
  connect(motor.flange, J1.flange_a);
  connect(J1.flange_b, shaft.flange_a);
  connect(shaft.flange_b, J2.flange_a);
  connect(J2.flange_b, bearing.flange_a);
  connect(bearing.flange_b, housing.flange);
  connect(J2.flange_b, sensor.flange);
  connect(sensor.w, w);
end Drive;
"""


def drive_data(path, seed, friction):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 20, 801)
    wk, ph = rng.uniform(0.5, 3.0, 4), rng.uniform(0, 6, 4)
    tau = lambda s: sum(1.2 * np.sin(a * s + b) for a, b in zip(wk, ph))

    def rhs(s, x):      # phi1, w1, phi2, w2
        spring = 20 * (x[0] - x[2])
        return [x[1], (tau(s) - spring) / 0.5, x[3], (spring - friction(x[3])) / 1.0]

    x = solve_ivp(rhs, (0, 20), [0, 0, 0, 0], t_eval=t, rtol=1e-10, atol=1e-12).y
    w = x[3] + rng.normal(0, 0.01 * np.std(x[3]), len(t))
    path.write_text("time,tau,w\n" + "\n".join(f"{float(a)!r},{float(b)!r},{float(c)!r}" for a, b, c in zip(t, tau(t), w)) + "\n")


def test_rotational_msl_model_with_imports_bearing_friction(tmp_path):
    friction = lambda w: 0.4 * w + 0.5 * np.tanh(w / 0.5)
    (tmp_path / "Drive.mo").write_text(DRIVE)
    drive_data(tmp_path / "train.csv", 1, friction)
    drive_data(tmp_path / "validate.csv", 2, friction)
    report = run(tmp_path, "Drive.mo", "Drive")
    cause = report["cause"]
    assert cause["component"] == "bearing" and cause["class"] == "Modelica.Mechanics.Rotational.Components.Damper"
    assert cause["law"]["equation"].startswith("bearing.tau = ") and "tanh" in cause["law"]["equation"]
    assert "Coulomb-like friction" in cause["effect"], cause["effect"]      # named as an engineer does
    assert curve_error(cause, friction) < 0.05
    g = report["gain"]
    assert g["validation_rms_after"] < 0.2 * g["validation_rms_before"]


COIL = """
model Coil "a coil on an iron core, driven by a voltage amplifier; the core is taken as linear"
  import Modelica.Electrical.Analog;
  import Modelica.Magnetic.FluxTubes;
  import Modelica.Units.SI;
  parameter SI.Resistance R = 2.0 "winding resistance";
  parameter Real N = 200 "turns";
  parameter SI.Reluctance R_core = 2.0e6 "core and air gap";
  Modelica.Blocks.Interfaces.RealInput u "amplifier voltage";
  Modelica.Blocks.Interfaces.RealOutput i "coil current";
  Analog.Sources.SignalVoltage amplifier;
  Analog.Basic.Resistor winding(R = R);
  Analog.Basic.Ground ground;
  Analog.Sensors.CurrentSensor ammeter;
  FluxTubes.Basic.ElectroMagneticConverter coil(N = N);
  FluxTubes.Basic.ConstantReluctance core(R_m = R_core);
  FluxTubes.Basic.Ground magneticGround;
initial equation
  coil.Phi = 0;
equation
  connect(u, amplifier.v);
  connect(amplifier.p, winding.p);
  connect(winding.n, ammeter.p);
  connect(ammeter.n, coil.p);
  connect(coil.n, amplifier.n);
  connect(amplifier.n, ground.p);
  connect(coil.port_p, core.port_p);
  connect(core.port_n, coil.port_n);
  connect(coil.port_n, magneticGround.port);
  connect(ammeter.i, i);
end Coil;
"""


def coil_data(path, seed, reluctance):
    """u = R i + N dPhi/dt and N i = V_m(Phi), the amplifier's voltage a random ramp."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2, 2001)
    knots, volts = np.linspace(0, 2, 21), rng.uniform(-6, 6, 21)
    u = lambda s: np.interp(s, knots, volts)
    sol = solve_ivp(lambda s, phi: (u(s) - 2.0 * reluctance(phi) / 200) / 200, (0, 2), [0.0], t_eval=t,
                    rtol=1e-10, atol=1e-15, max_step=0.005)
    i = reluctance(sol.y[0]) / 200 + rng.normal(0, 0.002, len(t))
    path.write_text("time,u,i\n" + "\n".join(f"{float(a)!r},{float(b)!r},{float(c)!r}" for a, b, c in zip(t, u(t), i)) + "\n")


def test_a_saturating_core_is_its_magnetic_potential_in_the_flux(tmp_path):
    """The core saturates: its magnetic potential grows with the cube of the flux, so the flux
    is a cube root of the potential, which no cubic in the potential follows (its fit folds
    and fails on the validation record). The law the other way round, the potential in the
    flux, is the core's; it is found with the default families."""
    saturating = lambda phi: 2.0e6 * phi * (1 + (phi / 8e-5) ** 2)
    (tmp_path / "Coil.mo").write_text(COIL)
    coil_data(tmp_path / "train.csv", 1, saturating)
    coil_data(tmp_path / "validate.csv", 2, saturating)
    report = run(tmp_path, "Coil.mo", "Coil")
    cause = report["cause"]
    assert cause["component"] == "core" and cause["template"]["family"] == "inverse"
    assert cause["law"]["equation"].startswith("core.dV_m = ") and "core.Phi^3" in cause["law"]["equation"]
    assert curve_error(cause, saturating) < 0.02
    g = report["gain"]
    assert g["validation_rms_after"] < 1.5 * 0.002 < 0.1 * g["validation_rms_before"]


DRAIN = """
within ;
package Drain "a tank fed by a pump, drained through a pipe"
  model Plant "pump -> open tank -> drain pipe -> ambient; the level is measured"
    import Modelica.Thermal.FluidHeatFlow;
    import Modelica.Units.SI;
    parameter FluidHeatFlow.Media.Medium water = FluidHeatFlow.Media.Water() "coolant";
    Modelica.Blocks.Interfaces.RealInput u(unit = "m3/s") "pump volume flow";
    Modelica.Blocks.Interfaces.RealOutput y(unit = "m") "measured level";
    FluidHeatFlow.Sources.Ambient supply(medium = water, constantAmbientPressure = 0, constantAmbientTemperature = 293.15);
    FluidHeatFlow.Sources.VolumeFlow pump(medium = water, m = 0, useVolumeFlowInput = true);
    FluidHeatFlow.Components.OpenTank tank(medium = water, ATank = 0.5, hTank = 3, pAmbient = 0,
      level(start = 0.5, fixed = true), T0 = 293.15, T0fixed = true);
    FluidHeatFlow.Components.Pipe drain(medium = water, m = 0, h_g = 0, V_flowLaminar = 1, dpLaminar = 2.44e6,
      V_flowNominal = 2, dpNominal = 4.88e6) "laminar: the engineer's linear guess";
    FluidHeatFlow.Sensors.PressureSensor bottom(medium = water) "read by no one";
    FluidHeatFlow.Sources.Ambient sink(medium = water, constantAmbientPressure = 0, constantAmbientTemperature = 293.15);
  equation
    connect(u, pump.volumeFlow);
    connect(supply.flowPort, pump.flowPort_a);
    connect(pump.flowPort_b, tank.flowPort);
    connect(tank.flowPort, drain.flowPort_a);
    connect(tank.flowPort, bottom.flowPort);
    connect(drain.flowPort_b, sink.flowPort);
    y = tank.level;
  end Plant;
end Drain;
"""
RHO, G, A_TANK, K_TURBULENT = 995.6, 9.80665, 0.5, 1.22e9


def drain_flow(dp):
    """The pipe's mass flow when its pressure drop is turbulent, dp = k V|V|."""
    return RHO * np.sign(dp) * np.sqrt(np.abs(dp) / K_TURBULENT)


def drain_data(path, seed: int, stop: float = 1500.0, step: float = 3.0, mass: bool = False):
    """The level of the tank the pump fills (steps of its volume flow, or with ``mass`` its
    mass flow, ramped over 20 s)."""
    rng = np.random.default_rng(seed)
    flows = rng.uniform(0.0, 0.004, int(stop // 150) + 2) * (RHO if mass else 1.0)

    def u(t):
        k = int(t // 150)
        prev = flows[max(k - 1, 0)]
        return prev + (flows[k] - prev) * min(1.0, (t - 150 * k) / 20.0)

    rhs = lambda t, x: [(u(t) / (RHO if mass else 1.0) - drain_flow(RHO * G * x[0]) / RHO) / A_TANK]   # noqa: E731
    t = np.arange(0.0, stop + 1e-9, step)
    level = solve_ivp(rhs, (0, stop), [0.5], t_eval=t, rtol=1e-9, atol=1e-12, max_step=1.0).y[0]
    write_uy(path, t, [u(a) for a in t], level + rng.normal(0, 1e-3, t.size))


def drained(tmp_path, source: str, model: str, pipe: str, mass: bool = False) -> dict:
    """The drain's run on SciPy's data: ``pipe`` named with a root of its pressure drop, the
    curve within 5 %, the validation error at the noise and the extended model recompiled."""
    (tmp_path / "Drain.mo").write_text(source)
    drain_data(tmp_path / "train.csv", 1, mass=mass)
    drain_data(tmp_path / "validate.csv", 2, mass=mass)
    report = run(tmp_path, "Drain.mo", model)
    cause = report["cause"]
    assert cause["component"] == pipe and f"sqrt(abs({pipe}.dp" in cause["law"]["equation"]
    assert curve_error(cause, drain_flow) < 0.05
    g = report["gain"]
    assert g["validation_rms_after"] < 5e-3 < 0.1 * g["validation_rms_before"]
    assert report["extended"]["recompiled_difference"] < 1e-3
    return report


def test_a_fluidheatflow_drain_is_a_root_of_its_pressure_drop(tmp_path):
    """MSL FluidHeatFlow, whose ports carry two pairs (pressure and mass flow; enthalpy and
    enthalpy flow), and whose pipe declares outputs no one reads: the pipe is questioned by its
    first pair, its turbulent flow (a root of the pressure drop) is found where the model has a
    laminar one, and the learned class, which carries the enthalpy with the flow, compiles back
    into the model."""
    report = drained(tmp_path, DRAIN, "Drain.Plant", "drain")
    assert [c for c in report["candidates"] if c["component"] == "bottom"] == []


FLUID_DRAIN = """
within ;
package FluidDrain "an open tank filled by a pump, drained through a pipe (Modelica.Fluid)"
  model Plant "pump -> tank -> pipe -> ambient; the level is measured"
    import Modelica.Fluid;
    replaceable package Medium = Modelica.Media.Water.ConstantPropertyLiquidWater;
    Modelica.Blocks.Interfaces.RealInput u(unit = "kg/s") "pump mass flow";
    Modelica.Blocks.Interfaces.RealOutput y(unit = "m") "level";
    inner Fluid.System system(energyDynamics = Modelica.Fluid.Types.Dynamics.FixedInitial);
    Fluid.Sources.MassFlowSource_T pump(redeclare package Medium = Medium, use_m_flow_in = true, nPorts = 1,
      T = 293.15);
    Fluid.Vessels.OpenTank tank(redeclare package Medium = Medium, height = 3, crossArea = 0.5, level_start = 0.5,
      nPorts = 2, use_portsData = false);
    Fluid.Pipes.StaticPipe pipe(redeclare package Medium = Medium, length = 2, diameter = 0.05,
      redeclare model FlowModel = Fluid.Pipes.BaseClasses.FlowModels.NominalLaminarFlow(
        dp_nominal = 2.44e3, m_flow_nominal = 1)) "laminar: the engineer's linear guess";
    Fluid.Sources.Boundary_pT sink(redeclare package Medium = Medium, nPorts = 1, p = 101325, T = 293.15);
  equation
    connect(u, pump.m_flow_in);
    connect(pump.ports[1], tank.ports[1]);
    connect(tank.ports[2], pipe.port_a);
    connect(pipe.port_b, sink.ports[1]);
    y = tank.level;
  end Plant;
end FluidDrain;
"""


def test_a_modelica_fluid_pipe_is_a_root_of_its_pressure_drop(tmp_path):
    """The same drain in Modelica.Fluid: a stream connector's pipe, whose laminar flow model is
    redeclared with its nominal point (modifiers rumoca alone would drop), learns its root law,
    and the learned class is a transport between two ports as the MSL's valves are, taking the
    pipe's medium, and compiles back into the model."""
    drained(tmp_path, FLUID_DRAIN, "FluidDrain.Plant", "pipe", mass=True)
    learned = (tmp_path / "out" / "extended" / "Learned.mo").read_text()
    assert "extends Modelica.Fluid.Interfaces.PartialTwoPortTransport;" in learned
    assert "redeclare package Medium = Medium" in (tmp_path / "out" / "extended" / "Drain.mo").read_text()


HEATED_LOOP = """
within ;
package Loop "a pump pushes water through a valve pipe and a heated pipe; the outlet temperature is measured"
  model Plant
    import Modelica.Thermal.FluidHeatFlow;
    import Modelica.Thermal.HeatTransfer;
    parameter FluidHeatFlow.Media.Medium water = FluidHeatFlow.Media.Water();
    Modelica.Blocks.Interfaces.RealInput u(unit = "Pa") "pump pressure rise";
    Modelica.Blocks.Interfaces.RealOutput y(unit = "K") "outlet temperature";
    FluidHeatFlow.Sources.Ambient supply(medium = water, constantAmbientPressure = 0, constantAmbientTemperature = 293.15);
    FluidHeatFlow.Sources.PressureIncrease pump(medium = water, m = 0, usePressureIncreaseInput = true);
    FluidHeatFlow.Components.Pipe valve(medium = water, m = 0, h_g = 0, V_flowLaminar = 1, dpLaminar = 5e7,
      V_flowNominal = 2, dpNominal = 1e8) "laminar: the engineer's guess";
    FluidHeatFlow.Components.Pipe heater(medium = water, m = 5, T0 = 293.15, T0fixed = true, h_g = 0,
      V_flowLaminar = 1, dpLaminar = 0, V_flowNominal = 2, dpNominal = 0, useHeatPort = true);
    HeatTransfer.Sources.FixedHeatFlow heat(Q_flow = 2e4);
    FluidHeatFlow.Sensors.TemperatureSensor outlet(medium = water);
    FluidHeatFlow.Sources.Ambient sink(medium = water, constantAmbientPressure = 0, constantAmbientTemperature = 293.15);
  equation
    connect(u, pump.pressureIncrease);
    connect(supply.flowPort, pump.flowPort_a);
    connect(pump.flowPort_b, valve.flowPort_a);
    connect(valve.flowPort_b, heater.flowPort_a);
    connect(heater.flowPort_b, sink.flowPort);
    connect(heat.port, heater.heatPort);
    connect(heater.flowPort_b, outlet.flowPort);
    connect(outlet.y, y);
  end Plant;
end Loop;
"""


def heated_loop_data(path, seed: int, stop: float = 1200.0):
    """The heated pipe's outlet temperature, m cp T' = Q + m_flow cp (T_in - T), behind a valve
    whose flow is turbulent, m_flow = rho sqrt(dp/k); the pump's pressure rise in steps."""
    rng = np.random.default_rng(seed)
    rises = rng.uniform(2e4, 8e4, int(stop // 60) + 2)

    def u(t):
        k = int(t // 60)
        prev = rises[max(k - 1, 0)]
        return prev + (rises[k] - prev) * min(1.0, (t - 60 * k) / 5.0)

    cp, k_valve, heat, mass = 4177.0, 5e10, 2e4, 5.0
    rhs = lambda t, x: [(heat + RHO * np.sqrt(u(t) / k_valve) * cp * (293.15 - x[0])) / (mass * cp)]   # noqa: E731
    t = np.arange(0.0, stop + 1e-9, 1.0)
    temp = solve_ivp(rhs, (0, stop), [293.15], t_eval=t, rtol=1e-10, atol=1e-10, max_step=0.5).y[0]
    write_uy(path, t, [u(a) for a in t], temp + rng.normal(0, 0.05, t.size))


def test_a_valve_is_found_from_the_temperature_its_flow_leaves(tmp_path):
    """Only the outlet temperature of a heated pipe is measured: the valve's flow is seen
    through the heat the water takes away, and its root law is found within 1 %."""
    (tmp_path / "Loop.mo").write_text(HEATED_LOOP)
    heated_loop_data(tmp_path / "train.csv", 1)
    heated_loop_data(tmp_path / "validate.csv", 2)
    report = run(tmp_path, "Loop.mo", "Loop.Plant")
    cause = report["cause"]
    assert cause["component"] == "valve" and "sqrt(abs(valve.dp" in cause["law"]["equation"]
    assert curve_error(cause, lambda dp: RHO * np.sign(dp) * np.sqrt(np.abs(dp) / 5e10)) < 0.01
    assert report["gain"]["validation_rms_after"] < 0.06 < 0.1 * report["gain"]["validation_rms_before"]


MOUNT = """within ;
package Mount
  model Isolated "a machine on a rubber mount, shaken by a force"
    import Modelica.Mechanics.Translational.Components;
    import Modelica.Mechanics.Translational.Sources;
    import Modelica.Mechanics.Translational.Sensors;
    Modelica.Blocks.Interfaces.RealInput u(unit = "N");
    Modelica.Blocks.Interfaces.RealOutput y(unit = "m");
    Components.Fixed floor;
    Components.Mass machine(m = 5);
    Components.Spring rubber(c = 5e4) "the mount's stiffness at small strokes";
    Components.Damper loss(d = 20);
    Sources.Force shaker;
    Sensors.PositionSensor gauge;
  initial equation
    machine.s = 0;
    machine.v = 0;
  equation
    connect(u, shaker.f);
    connect(shaker.flange, machine.flange_a);
    connect(floor.flange, rubber.flange_a);
    connect(rubber.flange_b, machine.flange_a);
    connect(floor.flange, loss.flange_a);
    connect(loss.flange_b, machine.flange_a);
    connect(machine.flange_b, gauge.flange);
    connect(gauge.s, y);
  end Isolated;
end Mount;
"""
#: the mount's truth: a Bouc-Wen force k x + alpha z, dz/dt = v - b1 |v| z - b2 v |z| (1/m)
K_MOUNT, ALPHA, B1, B2 = 2e4, 3e4, 1500.0, 500.0


def mount_data(path, seed: int, n: int, fs: float = 400.0):
    """The machine's position (noise 2 um) under a multisine force of 2-40 Hz."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    u = sum(np.cos(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) for f in np.arange(2.0, 40.0, 0.75))
    u = 40.0 * u / np.std(u)

    def rhs(tt, s):
        x, v, z = s
        return [v, (np.interp(tt, t, u) - K_MOUNT * x - 20.0 * v - ALPHA * z) / 5.0,
                v - B1 * abs(v) * z - B2 * v * abs(z)]
    x = solve_ivp(rhs, (0, t[-1]), [0, 0, 0], t_eval=t, method="DOP853", rtol=1e-10, atol=1e-13, max_step=1 / fs).y[0]
    write_uy(path, t, u, x + rng.normal(0, 2e-6, n))


def test_a_rubber_mount_is_found_to_remember_its_path(tmp_path):
    """A mount whose force has a hysteretic part (Bouc-Wen, saturating both ways), modelled as a
    linear spring: its best polynomial law reads the speed beside the stroke, so a hysteresis is
    fitted there, and its four constants are found within 1 %; the learned class, with its own
    state, recompiles and exports."""
    (tmp_path / "Mount.mo").write_text(MOUNT)
    mount_data(tmp_path / "train.csv", 1, 3000)
    mount_data(tmp_path / "validate.csv", 2, 1500)
    report = run(tmp_path, "Mount.mo", "Mount.Isolated")
    cause = report["cause"]
    assert cause["component"] == "rubber" and cause["template"]["name"] == "hysteresis"
    coef = dict(zip(["w1", "k", "c", "alpha", "h1", "h2"], cause["w"]))
    span = cause["template"]["span"]
    found = np.array([coef["k"], coef["alpha"], coef["h1"] / span, coef["h2"] / span])
    assert np.allclose(found, [K_MOUNT, ALPHA, B1, B2], rtol=0.01), found
    assert "hysteresis" in cause["effect"] and "der(z)" in (tmp_path / "out" / report["extended"]["modelica"]).read_text()
    assert report["gain"]["validation_rms_after"] < 4e-6 and report["extended"]["recompiled_difference"] < 1e-4
    assert report["extended"]["fmu"]


THERMOSTAT_ROOM = """
model Room "a room heated by an on-off thermostat; the wall's loss is a thermal conductor"
  import Modelica.Thermal.HeatTransfer;
  import Modelica.Blocks;
  parameter Modelica.Units.SI.HeatCapacity C = 2e5 "air and furniture";
  Blocks.Interfaces.RealInput T_amb(unit = "K") "outdoor temperature";
  Blocks.Interfaces.RealOutput T_room(unit = "K") "measured room temperature";
  HeatTransfer.Components.HeatCapacitor room(C = C, T(start = 290, fixed = true));
  HeatTransfer.Components.ThermalConductor wall(G = 20);
  HeatTransfer.Sources.PrescribedTemperature ambient;
  HeatTransfer.Sources.PrescribedHeatFlow heater;
  HeatTransfer.Sensors.TemperatureSensor sensor;
  Blocks.Logical.OnOffController thermostat(bandwidth = 2);
  Blocks.Sources.Constant setpoint(k = 294.15);
  Blocks.Math.BooleanToReal power(realTrue = 1500, realFalse = 0);
equation
  connect(T_amb, ambient.T);
  connect(ambient.port, wall.port_b);
  connect(wall.port_a, room.port);
  connect(heater.port, room.port);
  connect(sensor.port, room.port);
  connect(sensor.T, T_room);
  connect(setpoint.y, thermostat.reference);
  connect(sensor.T, thermostat.u);
  connect(thermostat.y, power.u);
  connect(power.y, heater.Q_flow);
end Room;
"""


def heated(path, seed, rhs, n):
    """A room heated by an on-off thermostat, by hand: ``rhs(s, x, on, T_amb)`` of ``n`` states
    from 290 K, the air's temperature x[0] first; the heater on below 293.15 K until 295.15 K
    (the controller's band), solved by SciPy from switch to switch; the outdoor temperature
    three slow sines about 280 K; 0.05 K of noise, a sample every 30 s for 6 h."""
    rng = np.random.default_rng(seed)
    w, ph = rng.uniform(2e-4, 1.5e-3, 3), rng.uniform(0, 6, 3)
    amb = lambda s: 280 + sum(3 * np.sin(wk * s + pk) for wk, pk in zip(w, ph))
    t = np.arange(0, 6 * 3600 + 1, 30.0)
    t0, x0, on, ts, xs = 0.0, [290.0] * n, True, [], []
    while t0 < t[-1]:
        edge = lambda s, x, on=on: x[0] - (295.15 if on else 293.15)
        edge.terminal, edge.direction = True, (1 if on else -1)
        sol = solve_ivp(lambda s, x, on=on: rhs(s, x, on, amb(s)), (t0, t[-1]), x0, events=edge,
                        rtol=1e-10, atol=1e-10, dense_output=True)
        end = sol.t_events[0][0] if len(sol.t_events[0]) else t[-1]
        keep = t[(t > t0) & (t <= end)]
        ts, xs = ts + list(keep), xs + list(sol.sol(keep)[0])
        t0, x0, on = end, list(sol.sol(end)), not on
    T = np.interp(t, [0.0, *ts], [290.0, *xs]) + rng.normal(0, 0.05, len(t))
    path.write_text("time,T_amb,T_room\n" + "\n".join(f"{a:.10g},{b:.10g},{c:.10g}" for a, b, c in
                                                       zip(t, amb(t), T)) + "\n")


def thermostat_room(path, seed, k):
    """The room: C T' = P on - (20 dT + k dT |dT|) (:func:`heated`)."""
    heated(path, seed, lambda s, x, on, Ta: [((1500.0 if on else 0.0) - 20 * (x[0] - Ta)
                                              - k * (x[0] - Ta) * abs(x[0] - Ta)) / 2e5], 1)


def test_a_thermostats_room_is_found_to_lose_heat_faster_than_its_wall_says(tmp_path):
    """A switched system: the heater's power jumps where the temperature crosses the band, so
    the switching times move with every parameter, and the phase of the room's sawtooth drifts
    over the record. The wall's loss has a convective part (1.5 dT|dT| beside 20 dT): the
    wall is named with its law (within 1 % over the range the room visits) and the validation
    error comes down to the noise. The fit's derivatives jump at the switches and its refits on
    growing windows start from the record's first 32nd (with the linearisation's derivatives,
    which leave the switches out, it stalled at 0.79 K against 0.83 K). With nothing hidden,
    nothing is found."""
    from helpers import discovered

    thermostat_room(tmp_path / "train.csv", 1, 1.5)
    thermostat_room(tmp_path / "validate.csv", 2, 1.5)
    report = discovered(tmp_path, "Room.mo", "Room", THERMOSTAT_ROOM)
    assert report["cause"]["component"] == "wall"
    assert curve_error(report["cause"], lambda dT: 20 * dT + 1.5 * dT * np.abs(dT)) < 0.01
    g = report["gain"]
    assert g["validation_rms_after"] < 2 * 0.05 < 0.2 * g["validation_rms_before"]
    null = tmp_path / "null"
    null.mkdir()
    thermostat_room(null / "train.csv", 3, 0.0)
    thermostat_room(null / "validate.csv", 4, 0.0)
    assert discovered(null, "Room.mo", "Room", THERMOSTAT_ROOM).get("cause") is None


FURNISHED_ROOM = """
model House "a room with its furniture, heated by an on-off thermostat; it loses heat through a
  wall and a window"
  import Modelica.Thermal.HeatTransfer;
  import Modelica.Blocks;
  import Modelica.Units.SI;
  parameter SI.HeatCapacity C_air = 2e5 "air";
  parameter SI.HeatCapacity C_mass = 1e6 "furniture and inner walls";
  Blocks.Interfaces.RealInput T_amb(unit = "K") "outdoor temperature";
  Blocks.Interfaces.RealOutput T_room(unit = "K") "measured room temperature";
  HeatTransfer.Components.HeatCapacitor air(C = C_air, T(start = 290, fixed = true));
  HeatTransfer.Components.HeatCapacitor mass(C = C_mass, T(start = 290, fixed = true));
  HeatTransfer.Components.ThermalConductor surface(G = 100) "air to furniture";
  HeatTransfer.Components.ThermalConductor wall(G = 20);
  HeatTransfer.Components.ThermalConductor window(G = 8);
  HeatTransfer.Sources.PrescribedTemperature ambient;
  HeatTransfer.Sources.PrescribedHeatFlow heater;
  HeatTransfer.Sensors.TemperatureSensor sensor;
  Blocks.Logical.OnOffController thermostat(bandwidth = 2);
  Blocks.Sources.Constant setpoint(k = 294.15);
  Blocks.Math.BooleanToReal power(realTrue = 2000, realFalse = 0);
equation
  connect(T_amb, ambient.T);
  connect(ambient.port, wall.port_b);
  connect(ambient.port, window.port_b);
  connect(wall.port_a, air.port);
  connect(window.port_a, air.port);
  connect(surface.port_a, air.port);
  connect(surface.port_b, mass.port);
  connect(heater.port, air.port);
  connect(sensor.port, air.port);
  connect(sensor.T, T_room);
  connect(setpoint.y, thermostat.reference);
  connect(sensor.T, thermostat.u);
  connect(thermostat.y, power.u);
  connect(power.y, heater.Q_flow);
end House;
"""


def furnished_room(path, seed):
    """The furnished room: the air gives heat to the furniture by convection, 100 dT + 30 dT|dT|."""
    def rhs(s, x, on, Ta):
        q = 100 * (x[0] - x[1]) + 30 * (x[0] - x[1]) * abs(x[0] - x[1])
        return [((2000.0 if on else 0.0) - 28 * (x[0] - Ta) - q) / 2e5, q / 1e6]

    heated(path, seed, rhs, 2)


def test_a_furnished_rooms_convection_is_found_among_its_parts(tmp_path):
    """A switched system of several parts (air, furniture, the surface between them, a wall
    and a window): the screening's linear responses jump at the switches and are read over
    the record's first windows as well, where they still hold (without the jumps, over the
    6 h, the surface's and the wall's laws were predicted to remove 0.5 % and 0.2 % of the
    misfit; with them, 14 % and 11 %; over the windows too, 68 % and 66 %); its fits run at
    a tolerance that puts the switches where they are (at the fits' usual one the 4th switch
    came 3 s late, and the surface's law stalled at 0.22 K against 0.05 K of noise). The
    surface is named alone, its law within 5 % of the truth over the range the run visits,
    and the validation error comes down to the noise."""
    from helpers import discovered

    furnished_room(tmp_path / "train.csv", 1)
    furnished_room(tmp_path / "validate.csv", 2)
    report = discovered(tmp_path, "House.mo", "House", FURNISHED_ROOM)
    assert [c["component"] for c in report["causes"]] == ["surface"], report["causes"]
    assert curve_error(report["cause"], lambda dT: 100 * dT + 30 * dT * np.abs(dT)) < 0.05
    g = report["gain"]
    assert g["validation_rms_after"] < 1.5 * 0.05 < 0.1 * g["validation_rms_before"]
