"""State selection by dummy derivatives: a model whose constraints are nonlinear keeps its
independent states alone and holds the constraints exactly, where integrating every
differentiated variable with the constraints dropped drifts off them."""
import numpy as np
from scipy.special import ellipk

from helpers import msl_path, needs_msl, probed, unforced_run
from mcl import compile_model

PENDULUM = """
model Pendulum "a point mass on a rod, in Cartesian coordinates (index 3), its horizontal
  position and speed declared the states: y is then algebraic, below the pivot"
  import Modelica.Units.SI;
  parameter SI.Length L = 0.8;
  parameter SI.Mass m = 2;
  parameter SI.Acceleration g = 9.81;
  parameter SI.Angle theta0 = 0.6 "released from rest at this angle";
  SI.Position x(start = L*sin(theta0), fixed = true, stateSelect = StateSelect.prefer);
  SI.Position y(start = -L*cos(theta0));
  SI.Velocity vx(start = 0, fixed = true, stateSelect = StateSelect.prefer);
  SI.Velocity vy;
  Real F "rod force per length";
  output Real radius = sqrt(x^2 + y^2);
  output Real energy = m*(vx^2 + vy^2)/2 + m*g*y;
equation
  der(x) = vx;
  der(y) = vy;
  m*der(vx) = -F*x;
  m*der(vy) = -F*y - m*g;
  x^2 + y^2 = L^2;
end Pendulum;
"""


@needs_msl()
def test_a_cartesian_pendulum_keeps_two_states_on_its_rod(tmp_path):
    (tmp_path / "Pendulum.mo").write_text(PENDULUM)
    model = compile_model([tmp_path / "Pendulum.mo"], "Pendulum", libraries=[msl_path()])
    assert len(model.ode.x_names) == 2 and "x" in model.ode.x_names and model.ode.index == 3
    _, res = unforced_run(model, 20.0, 2001)
    radius, energy = res.outputs[:, 0], res.outputs[:, 1]
    assert np.max(np.abs(radius - 0.8)) < 1e-9      # (1.4e-4 with the constraint dropped)
    assert np.ptp(energy) < 1e-4 * 2 * 9.81 * 0.8     # (4e-4 with the constraint dropped)
    # the period of a pendulum of amplitude theta0: 4 sqrt(L/g) K(sin^2(theta0/2))
    period = 4 * np.sqrt(0.8 / 9.81) * ellipk(np.sin(0.3) ** 2)
    x = probed(model, res)["x"]
    up = np.nonzero((x[:-1] < 0) & (x[1:] >= 0))[0]
    crossings = [res.time[k] - x[k] * (res.time[k + 1] - res.time[k]) / (x[k + 1] - x[k]) for k in up]
    assert len(crossings) >= 5
    assert abs(np.mean(np.diff(crossings)) - period) < 1e-5 * period     # (2.6e-5 dropped)


@needs_msl()
def test_an_msl_four_bar_integrates_its_declared_joint_alone():
    """The MSL's Fourbar1: a kinematic loop of five joints, its driving joint declared
    ``stateSelect = always`` and started at 300 deg/s. Its two states are that joint's angle
    and speed, and the speed starts where it is declared; with every variable index reduction
    differentiates a state (279) and the loop's constraints as invariants, the constraints
    chose the start and the mechanism started at rest."""
    model = compile_model([], "Modelica.Mechanics.MultiBody.Examples.Loops.Fourbar1", libraries=[msl_path()])
    assert len(model.ode.x_names) == 2
    _, res = unforced_run(model, 5.0, 501)
    w = probed(model, res)["j1.w"]
    assert abs(w[0] - np.radians(300)) < 1e-9
    assert np.all(np.isfinite(probed(model, res)["j2.s"]))


@needs_msl()
def test_states_the_declarations_leave_open_are_not_chosen_at_the_start(tmp_path):
    """Without stateSelect, x and y are equally good states at the start; which one stays valid
    depends on how far the pendulum swings (y cannot tell the left swing from the right one),
    so none is chosen: every differentiated variable stays a state, the rod checked as an
    invariant."""
    (tmp_path / "Pendulum.mo").write_text(PENDULUM.replace(", stateSelect = StateSelect.prefer", ""))
    model = compile_model([tmp_path / "Pendulum.mo"], "Pendulum", libraries=[msl_path()])
    assert len(model.ode.x_names) > 2
    _, res = unforced_run(model, 5.0, 501)
    assert np.max(np.abs(res.outputs[:, 0] - 0.8)) < 1e-3


@needs_msl()
def test_a_model_with_discrete_variables_selects_its_states_too(tmp_path):
    """The pendulum with a counter of its swings (a when-equation on x, a discrete Integer):
    its states are selected as without the counter, and the counter counts the swings the
    period makes in the time run."""
    counted = PENDULUM.replace("equation\n", """  discrete Integer swings(start = 0, fixed = true) "swings through the bottom to the right";
equation
  when x > 0 then
    swings = pre(swings) + 1;
  end when;
""").replace("output Real energy", "output Real n = swings;\n  output Real energy")
    (tmp_path / "Pendulum.mo").write_text(counted)
    model = compile_model([tmp_path / "Pendulum.mo"], "Pendulum", libraries=[msl_path()])
    kept = [n for n in model.ode.x_names if not n.startswith("$")]     # (not the relation held)
    assert len(kept) == 3 and "x" in kept and "swings" in kept        # x, its speed, the counter
    t, res = unforced_run(model, 20.0, 2001)
    assert np.max(np.abs(res.outputs[:, 0] - 0.8)) < 1e-9
    # released at x > 0 and swinging left first: x rises through 0 at 3/4 of each period
    period = 4 * np.sqrt(0.8 / 9.81) * ellipk(np.sin(0.3) ** 2)
    expected = np.floor(t / period - 0.75) + 1
    counted = res.outputs[:, 1]
    near = np.abs((t / period - 0.75) - np.round(t / period - 0.75)) < 1e-3     # (at a crossing)
    assert np.array_equal(counted[~near], expected[~near])


@needs_msl()
def test_a_reinit_of_a_state_selection_would_make_algebraic_keeps_every_state(tmp_path):
    """A stop that reinit()s the pendulum's y (declared a state nowhere, y is algebraic where
    the states are selected): the model is built with every differentiated variable a state,
    and the stop acts."""
    stopped = PENDULUM.replace("equation\n", """equation
  when x < 0 then
    reinit(vy, 0);
    reinit(y, -L);
  end when;
""")
    (tmp_path / "Pendulum.mo").write_text(stopped)
    model = compile_model([tmp_path / "Pendulum.mo"], "Pendulum", libraries=[msl_path()])
    assert "y" in model.ode.x_names
    _, res = unforced_run(model, 1.0, 101)
    assert np.all(np.isfinite(res.outputs))


@needs_msl()
def test_a_path_piecewise_in_time_beside_the_pendulum_leaves_its_states_selected(tmp_path):
    """The pendulum on a turntable's frame while the table makes a point-to-point move (the
    MSL's KinematicPTP2, whose path is piecewise in time, differentiated twice to drive the
    table's exact position, as a robot's reference path is): the path's equations switch only
    in what no choice of states reads, so the pendulum keeps its two states, on its rod, and
    the table moves as the path says, its torque J qdd_max at the steepest."""
    rig = PENDULUM.replace("equation\n", """  Modelica.Mechanics.Rotational.Components.Inertia table(J = 2);
  Modelica.Mechanics.Rotational.Sources.Position drive(exact = true);
  Modelica.Mechanics.Rotational.Sensors.TorqueSensor torque;
  Modelica.Blocks.Sources.KinematicPTP2 path(q_end = {1.5}, qd_max = {1}, qdd_max = {4}, startTime = 0.5);
  output Real tau = torque.tau;
  output Real angle = table.phi;
equation
  connect(path.q[1], drive.phi_ref);
  connect(drive.flange, torque.flange_a);
  connect(torque.flange_b, table.flange_a);
""")
    (tmp_path / "Pendulum.mo").write_text(rig)
    model = compile_model([tmp_path / "Pendulum.mo"], "Pendulum", libraries=[msl_path()])
    kept = [n for n in model.ode.x_names if not n.startswith("$")]     # (not the relations held)
    assert len(kept) == 2 and "x" in kept       # x and its speed (12 with every differentiated variable kept)
    _, res = unforced_run(model, 30.0, 3001)
    out = dict(zip(model.ode.y_names, res.outputs.T))
    assert np.max(np.abs(out["radius"] - 0.8)) < 1e-9       # (9e-4 with the constraints dropped)
    assert abs(out["angle"][-1] - 1.5) < 1e-9 and abs(out["angle"][0]) < 1e-12
    assert abs(np.max(np.abs(out["tau"])) - 2 * 4) < 1e-6


def test_a_tank_whose_energy_follows_its_mass_keeps_its_mass_and_temperature(tmp_path):
    """An open tank written as the MSL's vessels are: mass and energy balances, the volume's work
    p*der(V) (which differentiates m = V*d(T)), V declared never a state and T preferred. Its
    energy U = m*u(T) could be kept in place of its mass, but U is then given by a constant
    coefficient: no choice that the run could make singular, where a pendulum's x*x' + y*y' = 0
    is one. It keeps m and T and holds both constraints exactly (with every differentiated
    variable kept and the constraints dropped, U drifted 0.35 J), filling to the level where
    the outflow k*level meets the inflow, at the inflow's temperature."""
    (tmp_path / "HeatedTank.mo").write_text("""
model HeatedTank "an open tank of water filled from a heater; its density falls as it warms"
  parameter Real A = 0.01 "cross section, m2";
  parameter Real k = 0.05 "outflow per level, kg/(s.m)";
  parameter Real w_in = 0.02 "inflow, kg/s";
  parameter Real T_in = 350 "inflow temperature, K";
  parameter Real cp = 4184;
  parameter Real rho0 = 1000;
  parameter Real beta = 5e-4;
  parameter Real T0 = 293.15;
  parameter Real p_amb = 1e5;
  Real m(start = 3, fixed = true) "mass, kg";
  Real T(start = 300, fixed = true, stateSelect = StateSelect.prefer) "temperature, K";
  Real U "internal energy, J";
  Real V(stateSelect = StateSelect.never) "volume, m3";
  Real level;
  Real d;
  Real u;
  Real w_out;
equation
  der(m) = w_in - w_out;
  der(U) = w_in*cp*(T_in - T0) - w_out*cp*(T - T0) - p_amb*der(V);
  w_out = k*level;
  m = V*d;
  d = rho0*(1 - beta*(T - T0));
  U = m*u;
  u = cp*(T - T0) - p_amb/d;
  V = A*level;
end HeatedTank;
""")
    model = compile_model([tmp_path / "HeatedTank.mo"], "HeatedTank")
    assert sorted(model.ode.x_names) == ["T", "m"]
    _, res = unforced_run(model, 3000.0, 31)
    v = probed(model, res)
    assert np.max(np.abs(v["m"] - v["V"] * v["d"])) < 1e-12 * np.max(v["m"])
    assert np.max(np.abs(v["U"] - v["m"] * v["u"])) < 1e-12 * np.max(np.abs(v["U"]))
    assert abs(v["level"][-1] - 0.02 / 0.05) < 1e-6 and abs(v["T"][-1] - 350) < 1e-4


@needs_msl()
def test_a_machine_whose_air_gap_turns_with_its_rotor_selects_its_states_and_runs_as_its_twin():
    """The MSL's fundamental-wave permanent-magnet machine on a voltage source: its air-gap flux
    in the rotor's frame is the stator's turned by the rotor's angle. Which of the two stays a
    state the declarations leave open, but the choice of dummies keeps its determinant's sign
    whatever the angle (unlike the pendulum's x or y), so it is made: with every differentiated
    variable kept and the constraints dropped, they drifted 0.26 by t = 0.36 s and the run
    failed. Its speed and torque are its Electrical.Machines twin's."""
    runs = []
    for lib in ("Magnetic.FundamentalWave.Examples.BasicMachines", "Electrical.Machines.Examples"):
        model = compile_model([], f"Modelica.{lib}.SynchronousMachines.SMPM_VoltageSource", libraries=[msl_path()])
        _, res = unforced_run(model.with_outputs(["smpm.wMechanical", "smpm.tauElectrical"]), 2.0, 2001)
        runs.append(res.outputs)
    fundamental, twin = runs
    assert np.ptp(twin[:, 0]) > 100.0                 # (it starts to 157 rad/s)
    assert np.max(np.abs(fundamental - twin) / np.ptp(twin, axis=0)) < 1e-3
