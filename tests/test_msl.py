"""Real Modelica in: Modelica Standard Library examples compile through the rumoca front end,
give FMUs that FMPy validates, and simulate like rumoca's own simulator."""
import os
from pathlib import Path

import numpy as np
import pytest

from mcl.cli import main
from helpers import FAULTS, probed
from test_discover import rc_data
from test_xorshift import xorshift64star, xorshift128plus
from mcl.compile.fmu.export import validate_fmu

MSL = Path(__file__).resolve().parents[2] / "shared" / "msl"
pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(not (MSL / "Modelica" / "package.mo").is_file(),
                                 reason=f"the Modelica Standard Library is not at {MSL}")]

#: model -> end time; None where rumoca's simulator cannot run the model (Modelica.Math.sin)
EXAMPLES = {
    "Modelica.Electrical.Analog.Examples.CauerLowPassAnalog": 60.0,
    "Modelica.Electrical.Analog.Examples.ChuaCircuit": 100.0,
    "Modelica.Mechanics.Translational.Examples.Damper": 1.0,
    "Modelica.Mechanics.Rotational.Examples.First": 1.0,
    "Modelica.Thermal.HeatTransfer.Examples.TwoMasses": 1.0,
    "Modelica.Blocks.Examples.PID_Controller": 4.0,
    # tanks started by their level and temperature (T = H/(m*c)); pipes whose flow passes 0
    "Modelica.Thermal.FluidHeatFlow.Examples.TwoTanks": 1.5,
    "Modelica.Thermal.FluidHeatFlow.Examples.ParallelCooling": 1.0,
    # filters whose coefficients come from multi-output functions and mod(order, 2)
    "Modelica.Blocks.Examples.FilterWithRiseTime": 4.0,
    # a Dy01 transformer: its windings' connections picked by comparing its vector group's letters
    "Modelica.Electrical.Machines.Examples.Transformers.TransformerTestbench": 0.1,
}


@pytest.fixture(scope="module")
def msl_path():
    before = os.environ.get("MODELICAPATH")
    os.environ["MODELICAPATH"] = str(MSL)
    yield MSL
    if before is None:
        os.environ.pop("MODELICAPATH", None)
    else:
        os.environ["MODELICAPATH"] = before


def _rumoca_states(name, t_end, names):
    import rumoca

    model = rumoca.Session([str(MSL)]).loads(f"model RefEntry_\n  extends {name};\nend RefEntry_;\n",
                                             model="RefEntry_", filename="/mcl-test/RefEntry_.mo")
    try:
        res = model.simulate((0.0, t_end), dt=t_end / 4000)
    except rumoca.RumocaError:
        return None
    return res.time, {n: np.asarray(res[n]) for n in names if n in res.names}


@pytest.mark.parametrize("name", list(EXAMPLES))
def test_msl_example_compiles_validates_and_matches_rumoca(msl_path, tmp_path, capsys, name):
    from fmpy import simulate_fmu

    fmu = tmp_path / "m.fmu"
    assert main(["compile", "--model", name, "-o", str(fmu)]) == 0, capsys.readouterr().err
    assert validate_fmu(fmu) == []
    from fmpy import read_model_description

    states = [d.variable.derivative.name for d in read_model_description(str(fmu)).derivatives]
    t_end = EXAMPLES[name]
    res = simulate_fmu(str(fmu), stop_time=t_end, output_interval=t_end / 4000, relative_tolerance=1e-8,
                       output=states)
    assert abs(res["time"][-1] - t_end) < 1e-9 and all(np.all(np.isfinite(res[s])) for s in states)
    ref = _rumoca_states(name, t_end, states)
    if ref is None:              # rumoca's runtime cannot evaluate Modelica.Math.sin: finite is all we check
        return
    t_ref, ref_states = ref
    compared = [s for s in states if s in ref_states]
    assert compared
    for s in compared:       # on FMPy's grid: rumoca's also has the event instants (a kink at a step)
        theirs = np.interp(res["time"], t_ref, ref_states[s])
        span = max(np.ptp(ref_states[s]), 1e-12)
        assert np.max(np.abs(res[s] - theirs)) <= 2e-3 * span, f"{s} differs from rumoca's simulation"


USER_RC = (FAULTS.parent / "UserRC.mo").read_text()   # MSL parts: input voltage, sensor output


def test_a_user_model_of_msl_parts_takes_its_connectors_as_data_columns(msl_path, tmp_path):
    """RealInput/RealOutput connectors at the top are the model's inputs and outputs; units
    come along. Checked against the circuit's ODE solved by SciPy."""
    from scipy.integrate import solve_ivp

    from mcl import compile_model, simulate
    from mcl.data import TimeSeries

    (tmp_path / "UserRC.mo").write_text(USER_RC)
    model = compile_model([tmp_path / "UserRC.mo"], "UserRC")
    assert model.input_names == ["u"] and model.output_names == ["y"]
    assert model.info["units"]["C.v"] == "V"
    t = np.linspace(0, 5, 501)
    u = np.sin(2 * t) + 0.5
    res = simulate(model, TimeSeries(t, u[:, None], ["u"]), options={"rtol": 1e-10, "atol": 1e-12})
    truth = solve_ivp(lambda s, v: [((np.sin(2 * s) + 0.5 - v[0]) / 1.0 - v[0] / 2.0) / 0.5], (0, 5), [0.0],
                      t_eval=t, rtol=1e-11, atol=1e-13).y[0]
    assert np.max(np.abs(res.output("y") - truth)) < 1e-4 * np.ptp(truth)


def test_discovery_on_a_user_model_of_msl_parts(msl_path, tmp_path, capsys):
    """RealInput source, sensor output, a hidden cubic in one MSL resistor: named, learned, put
    back as a class extending the MSL's own interface, exported with uses(Modelica(...))."""
    import json

    (tmp_path / "UserRC.mo").write_text(USER_RC)
    # the same circuit as test_discover's RC (R1 = 1, C = 0.5, the load follows i = v/2 + 0.3 v^3)
    rc_data(tmp_path / "train.csv", 1, 0.3)
    rc_data(tmp_path / "validate.csv", 2, 0.3)
    (tmp_path / "run.yaml").write_text("model: {sources: [UserRC.mo], name: UserRC}\n"
                                       "data: {train: train.csv, validate: validate.csv}\noutput: out\n")
    assert main(["run", str(tmp_path / "run.yaml")]) == 0, capsys.readouterr().err
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    cause = report["cause"]
    assert cause["component"] == "R2" and cause["class"] == "Modelica.Electrical.Analog.Basic.Resistor"
    assert {c["component"] for c in report["screening"]} == {"R1", "C", "R2"}   # not the source, sensor, ground
    xs, fs = np.array(cause["law"]["curve"]).T
    truth = 0.5 * xs + 0.3 * xs**3
    assert np.max(np.abs(fs - truth)) <= 0.05 * np.max(np.abs(truth))
    g = report["gain"]
    assert g["validation_rms_after"] <= 0.2 * g["validation_rms_before"]
    extended = (tmp_path / "out" / cause["modelica"]).read_text()
    # native: the MSL's own interface (its connectors, v and i), the law in its variables
    assert "extends Modelica.Electrical.Analog.Interfaces.OnePort;" in extended and "i = c1*v + c2*v^3;" in extended
    assert 'annotation(uses(Modelica(version="4.0.0")))' in extended
    assert main(["export", str(tmp_path / "out"), "-o", str(tmp_path / "lib"), "--name", "Parts"]) == 0
    assert 'uses(Modelica(version="4.0.0"))' in (tmp_path / "lib" / "Parts" / "package.mo").read_text()


def test_an_initial_system_holding_loop_solves_compiles_and_simulates(msl_path):
    """The op amp's initial system holds the solves of nested algebraic loops: the fallback of
    its Newton solve takes its Jacobian in MX (in SX the compile failed: no eval_sx for QR)."""
    import mcl
    from mcl.data import TimeSeries

    model = mcl.compile_model([], "Modelica.Electrical.Analog.Examples.AmplifierWithOpAmpDetailed")
    t = np.linspace(0.0, 1e-3, 101)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []))
    assert res.ok, res.reason
    assert np.all(np.isfinite(res.states))


CART = """
model Cart "a cart pulling a trailer, both rolling on wheels whose drive trains have no inertia (J = 0)"
  import Modelica.Mechanics.Rotational;
  import Modelica.Mechanics.Translational;
  parameter Real J = 0 "inertia of each drive train";
  parameter Real R = 0.25 "wheel radius";
  parameter Real m = 100 "mass of the cart and of the trailer";
  Modelica.Blocks.Interfaces.RealInput tau "drive torque of the cart";
  Rotational.Sources.Torque torque;
  Rotational.Components.Inertia inertia(J = J);
  Rotational.Components.IdealRollingWheel wheel(radius = R);
  Translational.Components.Mass mass(m = m, s(start = 0, fixed = true), v(start = 0, fixed = true));
  Translational.Sensors.ForceSensor hitch;
  Rotational.Components.Inertia trailerInertia(J = J);
  Rotational.Components.IdealRollingWheel trailerWheel(radius = R);
  Translational.Components.Mass trailer(m = m);
  Modelica.Blocks.Interfaces.RealOutput v = mass.v;
  Modelica.Blocks.Interfaces.RealOutput f = hitch.f;
equation
  connect(tau, torque.tau);
  connect(torque.flange, inertia.flange_a);
  connect(inertia.flange_b, wheel.flangeR);
  connect(wheel.flangeT, mass.flange_a);
  connect(mass.flange_b, hitch.flange_a);
  connect(hitch.flange_b, trailer.flange_a);
  connect(trailer.flange_b, trailerWheel.flangeT);
  connect(trailerWheel.flangeR, trailerInertia.flange_a);
end Cart;
"""


def test_a_drive_train_without_inertia_is_no_division_by_zero(msl_path, tmp_path):
    """J*a = tau with J = 0 (the MSL's Vehicle example sets it): solved for a, it was inf; the
    pair accelerates at tau / (2 R m) and the hitch pulls the trailer with m a, by hand."""
    import mcl
    from mcl.data import TimeSeries

    (tmp_path / "Cart.mo").write_text(CART)
    model = mcl.compile_model([tmp_path / "Cart.mo"], "Cart")
    t = np.linspace(0.0, 2.0, 21)
    res = mcl.simulate(model, TimeSeries(t, np.full((len(t), 1), 5.0), ["tau"]))
    assert res.ok, res.reason
    a = 5.0 / (0.25 * 2 * 100)
    np.testing.assert_allclose(res.output("v"), a * t, atol=1e-6)
    np.testing.assert_allclose(res.output("f"), 100 * a, atol=1e-6)


CONVEYOR = """
model Conveyor "A belt pushed back and forth against a regularised Coulomb force"
  import Modelica.Mechanics.Translational;
  Translational.Components.Mass belt(m = 2, s(fixed = true, start = 0), v(fixed = true, start = 0));
  Translational.Sources.SignForce friction(f_nominal = -5, v0 = 0.01);
  Translational.Sources.Force drive;
  Modelica.Blocks.Sources.Sine push(amplitude = 40, f = 0.5);
  output Real v = belt.v;
equation
  connect(push.y, drive.f);
  connect(drive.flange, belt.flange_a);
  connect(belt.flange_b, friction.flange);
end Conveyor;
"""


def test_a_regularised_sign_force_runs_backwards(msl_path, tmp_path):
    """SignForce's 2/(1 + exp(-v/(0.01 v0))) - 1: once the belt runs backwards faster than 0.7 m/s
    exp overflows, and its derivative inf/inf stopped the solver (CV_CONV_FAILURE: IMC_Conveyor).
    The speed follows m v' = 40 sin(pi t) - 5 tanh(v/(0.02 v0)), integrated here by SciPy."""
    from scipy.integrate import solve_ivp

    import mcl
    from mcl.data import TimeSeries

    (tmp_path / "Conveyor.mo").write_text(CONVEYOR)
    model = mcl.compile_model([tmp_path / "Conveyor.mo"], "Conveyor")
    t = np.linspace(0.0, 4.0, 401)
    span = np.array([0.0, 10.0])
    res = mcl.simulate(model, TimeSeries(span, np.zeros((2, 0)), []), t_out=t)
    assert res.ok, res.reason
    ref = solve_ivp(lambda _t, v: (40 * np.sin(np.pi * _t) - 5 * np.tanh(v / 2e-4)) / 2, (0, 4), [0.0],
                    method="Radau", t_eval=t, rtol=1e-8, atol=1e-10)
    assert res.output("v").min() < -4
    np.testing.assert_allclose(res.output("v"), ref.y[0], atol=1e-3)


def test_a_hysteresis_core_starts_between_its_branches_and_stays_there(msl_path):
    """The Tellinen hysteresis: its branches h_R(H), h_F(H) are states (the model takes their
    der()) with no start value of their own, and its slope divides by h_F - h_R, 0 at those
    starts: they are taken from the equations that give them. Its der(h - mu0*H) is split by
    an overlay, its if initial() branch holds at the start. rumoca's simulator cannot run it:
    the check is the model's own invariant, B between the branches."""
    import mcl
    from mcl.data import TimeSeries

    model = mcl.compile_model([], "Modelica.Magnetic.FluxTubes.Examples.Hysteresis.InductorWithHysteresis")
    t = np.linspace(0.0, 0.02, 201)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []))
    assert res.ok, res.reason
    names = model.ode.x_names
    B, low, high = (res.states[:, names.index(f"core.{n}")] for n in ("B", "hystR", "hystF"))
    assert np.all(high - low > 0)
    assert np.all((B >= low - 1e-6) & (B <= high + 1e-6))
    assert np.ptp(res.states[:, names.index("core.Hstat")]) > 10      # the field moves


def test_a_loop_without_a_solution_at_a_trial_step_shortens_the_step(msl_path):
    """A Schmitt trigger: an op amp's limited output in a loop with positive feedback. Where
    Newton's method finds no solution at a point the integrator tries, the loop gives NaN and
    the integrator retries with a shorter step (an exception used to stop the run). Against
    rumoca's simulation, as the MSL sweep compares."""
    import mcl
    from mcl.data import TimeSeries

    name = "Modelica.Electrical.Analog.Examples.OpAmps.SchmittTrigger"
    model = mcl.compile_model([], name)
    ref = _rumoca_states(name, 1.0, model.ode.x_names)
    t = np.unique(np.round(ref[0], 12)) if ref else np.linspace(0.0, 1.0, 2001)
    span = np.array([0.0, 10.0])
    res = mcl.simulate(model, TimeSeries(span, np.zeros((2, 0)), []), t_out=t)
    assert res.ok, res.reason
    if ref is None:
        return
    for k, n in enumerate(model.ode.x_names):
        if n in ref[1]:
            theirs, ours = np.interp(t, ref[0], ref[1][n]), res.states[:, k]
            err = np.abs(ours - theirs)      # an event instant may fall one sample either side
            err[1:] = np.minimum(err[1:], np.abs(ours[1:] - theirs[:-1]))
            err[:-1] = np.minimum(err[:-1], np.abs(ours[:-1] - theirs[1:]))
            assert np.max(err) <= 2e-3 * max(np.ptp(theirs), 1e-12), n


def test_tanks_with_an_overflow_pipe_run_to_their_stop_time(msl_path, tmp_path):
    """TanksWithOverflow, its 25 000 s. The overflow pipe joins two tank ports above the liquid,
    both closed: its loop leaves the pipe's pressure level open, and the fallback's
    least-squares steps must find one of the solutions (their direction was reversed: NaN at
    the first step). Where the upper level reaches the overflow port, its port relation (the
    pressure pushes the closed port open; open, the flow leaves) and the level's relation
    cross at the same instant, and the first kept flipping until the second had crossed (the
    run stopped at t = 2025 s). The pump, switched by the pressure's hysteresis, fills the
    upper tank past the overflow twice; the water is conserved while it is off; the lower
    level rises past the overflow port by the end, as the model's documentation says. The FMU
    (Co-Simulation) runs past the first overflow as the in-process engine does."""
    import mcl
    from mcl.data import TimeSeries

    model = mcl.compile_model([], "Modelica.Fluid.Examples.Tanks.TanksWithOverflow")
    t = np.linspace(0.0, 25000.0, 501)
    res = mcl.simulate(model, TimeSeries(np.array([0.0, 25000.0]), np.zeros((2, 0)), []), t_out=t)
    assert res.ok, res.reason
    x = probed(model, res).__getitem__      # (the volumes are no states: declared never)
    mass = x("upperTank.m") + x("lowerTank.m")
    upper, lower = x("upperTank.V") / 0.2, x("lowerTank.V") / 1.0
    assert np.all(np.diff(mass) >= -1e-6 * mass[0])                 # the source only adds water
    off = (x("hysteresis.y")[1:] > 0.5) & (x("hysteresis.y")[:-1] > 0.5)
    assert np.max(np.abs(np.diff(mass)[off])) <= 1e-6 * mass[0]      # and none while it is off
    fills = np.flatnonzero((upper[1:] > 6) & (upper[:-1] <= 6))
    assert len(fills) == 2 and upper.max() < 20, upper              # the overflow's port at 6 m
    assert np.all(np.diff(lower) >= -1e-9) and lower[0] < 6 < lower[-1], lower

    from fmpy import simulate_fmu       # the FMU's solver carries its states on the same way
    from mcl.compile.fmu.export import build_fmu

    build_fmu(model, tmp_path / "Tanks.fmu")
    theirs = simulate_fmu(str(tmp_path / "Tanks.fmu"), fmi_type="CoSimulation", stop_time=3000.0,
                          output_interval=50.0, output=["upperTank.V"])
    ours = np.interp(theirs["time"], t, upper)
    assert theirs["time"][-1] == 3000.0 and theirs["upperTank.V"].max() / 0.2 > 6
    assert np.max(np.abs(theirs["upperTank.V"] / 0.2 - ours)) <= 1e-3 * np.ptp(ours)


def test_an_equation_that_looks_dependent_at_the_start_values_is_still_met(msl_path):
    """A permanent-magnet machine fed by currents: at rotor angle 0 one of the invariants that
    index reduction keeps (a rotation's) has a Jacobian row dependent on the others, so the
    square initial system chosen there left it out and the run started 3.9 off it. The
    equations are chosen again next to the start where one is left unmet."""
    import mcl
    from mcl.data import TimeSeries

    model = mcl.compile_model([], "Modelica.Electrical.Machines.Examples.SynchronousMachines.SMPM_CurrentSource")
    t = np.linspace(0.0, 2.0, 401)
    span = np.array([0.0, 10.0])
    res = mcl.simulate(model, TimeSeries(span, np.zeros((2, 0)), []), t_out=t)
    assert res.ok, res.reason          # (the invariants are checked at every output point)
    drift = np.array(model.ode.drift(res.states[0], np.zeros(0), model.ode.p_values, 0.0)).item()
    assert drift < 1e-6


def test_a_heating_loop_started_in_steady_state_stays_there(msl_path):
    """MSL's HeatingSystem starts in steady state (der(p) = der(T) = 0 in every volume), from
    start values with all its water at one pressure: no flow, so no heat carried, and Newton's
    method on the initial system has no step (its Jacobian had rank 8 of 11; the run stopped
    with three equations 0.06 off). The start is found where implicit Euler steps of the
    model's own dynamics lead (pseudo-transient continuation), then solved there. Until the
    valve opens at 2000 s nothing moves, water flows, and the heat the burner gives leaves
    through the radiator and the tank."""
    import mcl
    from mcl.data import TimeSeries

    model = mcl.compile_model([], "Modelica.Fluid.Examples.HeatingSystem")
    t = np.linspace(0.0, 1500.0, 16)
    res = mcl.simulate(model, TimeSeries(t[[0, -1]], np.zeros((2, 0)), []), t_out=t)
    assert res.ok, res.reason
    v = probed(model, res)
    for name in ("tank.medium.T", "heater.mediums[1].T", "radiator.mediums[1].T", "T_forward", "T_return"):
        assert np.ptp(v[name]) < 1e-3, (name, v[name])
    assert v["T_forward"][0] > v["T_return"][0] + 10.0
    assert v["m_flow"][0] > 1e-3
    # the energy balance of the whole loop: the heater's heat and the pump's work leave through
    # the radiator and the open tank
    flows = [v[n][0] for n in ("heater.heatTransfer.Q_flows[1]", "pump.W_total",
                               "radiator.heatTransfer.Q_flows[1]", "tank.heatTransfer.Q_flows[1]")]
    assert flows[0] > 100.0 and abs(sum(flows)) < 1e-4 * flows[0], flows


def test_a_mechanism_whose_frames_start_at_zero_is_initialised_down_its_chains(msl_path):
    """PlanarLoops_analytic: three analytically solved loops, 417 states with no state
    selection, every orientation started at 0. A rod's direction (its vector over its length)
    was then 0/0 and the initial system had no solve. The starts are carried down the chains of
    frames, each state after the ones its equation reads, and the equations chosen again
    there. Each loop's branch (a Boolean parameter fixed at initialisation) then stays the one
    chosen: at the solver's rounding (1e-26) it had flipped at the first step."""
    import mcl
    from mcl.data import TimeSeries

    model = mcl.compile_model([], "Modelica.Mechanics.MultiBody.Examples.Loops.PlanarLoops_analytic")
    ode = model.ode
    x0 = np.array(ode.init(ode.u_start, ode.p_values, 0.0)).ravel()
    assert np.all(np.isfinite(x0))
    assert np.array(ode.drift(x0, ode.u_start, ode.p_values, 0.0)).item() < 1e-8
    # the loops closed: the joints' frames moved off their start values of 0
    r0 = [x0[k] for k, n in enumerate(ode.x_names) if n.endswith("jointUSR.frame_b.r_0[1]")]
    assert len(r0) == 3 and min(map(abs, r0)) > 1e-3
    # driven by phi = 0.7 sin(2 pi t) through a 50 Hz filter: the crank follows it
    t = np.linspace(0.0, 1.0, 201)
    span = np.array([0.0, 10.0])
    res = mcl.simulate(model, TimeSeries(span, np.zeros((2, 0)), []), t_out=t)
    assert res.ok, res.reason
    phi = res.states[:, ode.x_names.index("rev.phi")]
    assert np.interp(0.25, t, phi) == pytest.approx(0.7, abs=2e-3)
    assert np.interp(0.75, t, phi) == pytest.approx(-0.7, abs=2e-3)


SEALED = """
model Sealed "air heated in a closed volume that has no ports"
  import Modelica.Fluid.Vessels.ClosedVolume;
  replaceable package Medium = Modelica.Media.Air.SimpleAir;
  parameter Modelica.Units.SI.HeatFlowRate Q = 100;
  ClosedVolume v(redeclare package Medium = Medium, V = 1, nPorts = 0, use_portsData = false,
    use_HeatTransfer = true, p_start = 1e5, T_start = 300);
  Modelica.Thermal.HeatTransfer.Sources.FixedHeatFlow heater(Q_flow = Q);
  inner Modelica.Fluid.System system(energyDynamics = Modelica.Fluid.Types.Dynamics.FixedInitial);
  output Real T = v.medium.T;
  output Real p = v.medium.p;
equation
  connect(heater.port, v.heatPort);
end Sealed;
"""


def test_a_sealed_vessel_heats_as_an_ideal_gas_and_its_medium_limit_is_reported(msl_path, tmp_path):
    """A vessel with nPorts = 0: its port arrays (and their parameters) are empty. Heated, the
    air's temperature rises by Q t / (m cv) and its pressure with it (ideal gas at constant
    volume); past SimpleAir's 373.15 K, the medium's assert fails the run in its own words."""
    import mcl
    from mcl.data import TimeSeries

    (tmp_path / "Sealed.mo").write_text(SEALED)
    model = mcl.compile_model([tmp_path / "Sealed.mo"], "Sealed")
    t = np.linspace(0.0, 100.0, 11)
    inputs = TimeSeries(t, np.zeros((len(t), 0)), [])
    res = mcl.simulate(model, inputs, t_out=t)
    assert res.ok, res.reason
    R, cp = 287.0512249529787, 1005.45               # SimpleAir's constants
    m = 1e5 / (R * 300.0)
    expected = 300.0 + 100.0 * t / (m * (cp - R))
    assert np.max(np.abs(res.output("T") - expected)) < 1e-4 * 12.0
    assert np.max(np.abs(res.output("p") / 1e5 - expected / 300.0)) < 1e-6
    hot = mcl.simulate(model, inputs, params={"Q": 1000.0}, t_out=t)
    assert not hot.ok
    assert "Temperature T" in hot.reason and "T <= 373.15 K" in hot.reason, hot.reason


VESSEL = """
model Vessel "a heated gas vessel: the balances integrate mass and energy; pressure and
  temperature, declared preferred, carry the start values"
  import Modelica.Units.SI;
  parameter SI.Volume V = 0.5;
  parameter Real b(unit = "1/Pa2") = 1e-12 "compressibility correction";
  parameter SI.SpecificHeatCapacity cv = 718;
  parameter SI.SpecificHeatCapacity R = 287;
  parameter Real k = 1e-7 "outflow conductance";
  parameter SI.Pressure p_amb = 1e5;
  parameter SI.HeatFlowRate Q = 500;
  SI.Pressure p(start = 3e5, stateSelect = StateSelect.prefer);
  SI.Temperature T(start = 320, stateSelect = StateSelect.prefer);
  SI.Density rho;
  SI.Mass m;
  SI.InternalEnergy U;
  SI.MassFlowRate m_out;
  Modelica.Blocks.Interfaces.RealOutput p_out;
equation
  p = rho*R*T*(1 + b*p^2) "equation of state, implicit in p";
  m = rho*V;
  U = m*cv*T;
  m_out = k*(p - p_amb);
  der(m) = -m_out;
  der(U) = Q - m_out*(cv + R)*T;
  p_out = p;
end Vessel;
"""


def test_a_vessel_starts_from_its_preferred_pressure_and_temperature(msl_path, tmp_path):
    """Mass and energy are the states and have no start values; pressure and temperature,
    declared ``stateSelect = prefer``, have. The run starts where p and T take their start
    values (at m = 0, U = 0 the temperature U/(m cv) is 0/0 and the loop for p has no
    solution), and follows the balances as a hand-written integration of them does."""
    from scipy.integrate import solve_ivp
    from scipy.optimize import brentq

    import mcl
    from mcl.data import TimeSeries

    (tmp_path / "Vessel.mo").write_text(VESSEL)
    model = mcl.compile_model([tmp_path / "Vessel.mo"], "Vessel")
    t = np.linspace(0.0, 200.0, 201)
    span = np.array([0.0, 10.0])
    res = mcl.simulate(model, TimeSeries(span, np.zeros((2, 0)), []), t_out=t)
    assert res.ok, res.reason
    V, b, cv, R, k, p_amb, Q = 0.5, 1e-12, 718.0, 287.0, 1e-7, 1e5, 500.0

    def pressure(m, U):          # the equation of state solved for p at rho = m/V, T = U/(m cv)
        rho, T = m / V, U / (m * cv)
        # (the smaller of its two roots: the other, near 1/(b rho R T), is not a gas)
        return brentq(lambda p: p - rho * R * T * (1 + b * p * p), 1.0, 2 * rho * R * T, xtol=1e-9), T

    def rhs(_, y):
        p, T = pressure(*y)
        m_out = k * (p - p_amb)
        return [-m_out, Q - m_out * (cv + R) * T]

    rho0 = 3e5 / (R * 320.0 * (1 + b * 9e10))
    m0 = rho0 * V
    ref = solve_ivp(rhs, (0.0, 200.0), [m0, m0 * cv * 320.0], t_eval=t, rtol=1e-10, atol=1e-8)
    p_ref = np.array([pressure(m, U)[0] for m, U in ref.y.T])
    assert abs(res.output("p_out")[0] - 3e5) < 1e-3
    assert np.max(np.abs(res.output("p_out") - p_ref)) < 1e-4 * 3e5


def test_a_robot_axis_starts_at_rest_and_ends_where_it_terminates(msl_path):
    """RobotR3.OneAxis: its bearing friction at rest starts neither forward nor backward (the
    initial system leaves the motor's speed at +-6e-9, and the friction's discrete values
    alternate with its sign: the run starts from the last), the axis moves through its
    120 degrees, and TerminateSimulation ends the run swingTime after the path's end, with its
    text, before the 1.6 s stop time."""
    from mcl import compile_model, simulate
    from mcl.data import TimeSeries

    model = compile_model([], "Modelica.Mechanics.MultiBody.Examples.Systems.RobotR3.OneAxis")
    for n in (321, 2001):       # (from the last alternating values, the 2001-point run's first event did not settle)
        t = np.linspace(0, 1.6, n)
        res = simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
        assert res.ok, res.reason
        assert "End condition reached" in res.terminated and 1.45 < res.time[-1] < 1.55 < 1.6
        phi = res.states[:, model.ode.x_names.index("load.phi")]
        assert abs(phi[0]) < 1e-6 and abs(phi[-1] - np.radians(120)) < 2e-3


NOISY = """
model NoisySensor "a first-order lag read through a sensor with sampled noise"
  import Modelica.Blocks;
  inner Blocks.Noise.GlobalSeed globalSeed(fixedSeed = 4711);
  Blocks.Sources.Constant level(k = 2);
  Blocks.Continuous.FirstOrder lag(T = 0.5, initType = Blocks.Types.Init.InitialState, y_start = 0);
  Blocks.Noise.NormalNoise noise(samplePeriod = 0.01, mu = 0, sigma = 0.1);
  Blocks.Noise.UniformNoise drift(samplePeriod = 0.05, y_min = -1, y_max = 3,
    useAutomaticLocalSeed = false, fixedLocalSeed = 10);
  Blocks.Math.Add sensor;
  Blocks.Interfaces.RealOutput y "the sensor's reading";
  Blocks.Interfaces.RealOutput e "its noise";
  Blocks.Interfaces.RealOutput d "the uniform noise";
equation
  connect(level.y, lag.u);
  connect(lag.y, sensor.u1);
  connect(noise.y, sensor.u2);
  connect(sensor.y, y);
  connect(noise.y, e);
  connect(drift.y, d);
end NoisySensor;
"""

def _initial_state_128(local_seed, global_seed):
    """Xorshift128plus.initialState: ten xorshift64* steps from the seeds, then one more for
    the second word (Modelica.Math.Random, written from its documentation)."""
    first = [local_seed, global_seed] if local_seed or global_seed else [126247697, 0]
    for _ in range(10):
        _, first = xorshift64star(first)
    _, second = xorshift64star(first)
    return first + second


def test_noise_blocks_draw_the_msl_generators_numbers_in_process_and_in_the_fmu(msl_path, tmp_path):
    """The MSL's noise blocks (xorshift128+, seeded by xorshift64*: their C code as expressions):
    a uniform noise with a fixed local seed draws exactly the numbers of the generators written
    here from their definitions; a normal noise has its mean and deviation over 1000 samples;
    the noise is added to a lag's response, not mixed into it; the FMU draws the same."""
    import mcl
    from fmpy import simulate_fmu
    from mcl.data import TimeSeries

    (tmp_path / "NoisySensor.mo").write_text(NOISY)
    model = mcl.compile_model([tmp_path / "NoisySensor.mo"], "NoisySensor")
    t = np.round(np.arange(0.0, 10.0, 0.01), 6)        # at each draw of the normal noise, after it
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    state = _initial_state_128(10, 4711)
    expected = []
    for _ in range(20):                # a draw at t = 0 (the first tick), then every 0.05 s
        r, state = xorshift128plus(state)
        expected.append(-1 + 4 * r)
    np.testing.assert_allclose(res.output("d")[::5][:20], expected, rtol=0, atol=1e-12)
    e = res.output("e")
    assert abs(e.mean()) < 3 * 0.1 / np.sqrt(len(e)) and abs(e.std() / 0.1 - 1) < 0.1
    np.testing.assert_allclose(res.output("y") - e, 2 * (1 - np.exp(-t / 0.5)), atol=1e-3)

    fmu = tmp_path / "noisy.fmu"
    assert main(["compile", str(tmp_path / "NoisySensor.mo"), "--model", "NoisySensor", "-o", str(fmu)]) == 0
    assert validate_fmu(fmu) == []
    out = simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.01, output=["d", "e"])
    at = np.round(out["time"], 6)
    between = np.abs((at * 100) % 5) > 0.5          # away from the uniform draws' instants
    np.testing.assert_allclose(out["d"][between], np.interp(at[between], t, res.output("d")), atol=1e-12)


GEARBOX = """
model Gearbox "a lossy gear between two inertias, a bearing friction on the motor side"
  import Modelica.Mechanics.Rotational;
  Rotational.Components.LossyGear gear(ratio = 2, lossTable = [0, 0.5, 0.5, 0, 0], useSupport = true);
  Rotational.Components.Inertia motor(J = 1);
  Rotational.Components.Inertia load(J = 1.5, phi(fixed = true, start = 0), w(fixed = true, start = 0));
  Rotational.Components.BearingFriction bearing(tau_pos = [0, 0.5; 1, 1], useSupport = true);
  Rotational.Sources.Torque drive(useSupport = true);
  Rotational.Sources.Torque brake(useSupport = true);
  Rotational.Components.Fixed fixed;
  Modelica.Blocks.Sources.Sine push(amplitude = 10, f = 1);
  Modelica.Blocks.Sources.Ramp pull(height = 5, duration = 2, offset = -10);
  output Real w_motor = motor.w;
  output Real w_load = load.w;
  output Real loss = gear.flange_a.tau*motor.w + gear.flange_b.tau*load.w "power into the gear";
equation
  connect(push.y, drive.tau);
  connect(pull.y, brake.tau);
  connect(drive.flange, bearing.flange_a);
  connect(bearing.flange_b, motor.flange_a);
  connect(motor.flange_b, gear.flange_a);
  connect(gear.flange_b, load.flange_a);
  connect(load.flange_b, brake.flange);
  connect(gear.support, fixed.flange);
  connect(bearing.support, fixed.flange);
  connect(drive.support, fixed.flange);
  connect(brake.support, fixed.flange);
end Gearbox;
"""


def test_a_gear_and_its_bearing_both_locked_share_a_torque_the_equations_leave_open(msl_path, tmp_path):
    """LossyGearDemo2's parts: at rest, the gear and the bearing both lock, and the torque they
    share has no unique split (the mode's linear block is singular). Sparse QR refused the
    pivot and the run failed at its start; any split holds, as OpenModelica's total-pivot
    fallback takes it. The gear then slips and sticks with the sine: its ratio holds, it never
    gives power back (efficiency 0.5 both ways), and its FMU validates and runs the same."""
    import mcl
    from mcl.compile.fmu.export import build_fmu
    from mcl.data import TimeSeries

    (tmp_path / "Gearbox.mo").write_text(GEARBOX)
    model = mcl.compile_model([tmp_path / "Gearbox.mo"], "Gearbox")
    t = np.linspace(0.0, 2.0, 801)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    w_motor, w_load = res.output("w_motor"), res.output("w_load")
    np.testing.assert_allclose(w_motor, 2 * w_load, atol=1e-9)
    assert np.abs(w_load).max() > 1e-3                    # it moves, both ways
    assert w_load.min() < 0 < w_load.max()
    assert np.sum(np.abs(w_load) < 1e-9) > 50             # and sticks between
    assert res.output("loss").min() > -1e-6 * np.abs(res.output("loss")).max()
    build_fmu(model, tmp_path / "Gearbox.fmu")
    assert validate_fmu(str(tmp_path / "Gearbox.fmu")) == []
    from fmpy import simulate_fmu       # and runs as in process (its C holds the same solve)
    fmu = simulate_fmu(str(tmp_path / "Gearbox.fmu"), stop_time=2.0, output_interval=0.0025,
                       fmi_type="CoSimulation", output=["w_load"])
    np.testing.assert_allclose(np.interp(t, fmu["time"], fmu["w_load"]), w_load, atol=2e-3 * np.ptp(w_load))


def test_a_fluid_example_whose_functions_stay_calls_is_an_fmu_that_runs_as_in_process(msl_path, tmp_path):
    """A tank emptying through a pipe (StandardWater, IF97): its right-hand side would be 2
    million SX instructions expanded, and the compile keeps it as calls. Expanded for the FMU's
    parametric split, its C was 34 MB, past the limit; kept as calls, the FMU builds, FMPy
    validates it and it runs as the model does in process."""
    import mcl
    from fmpy import simulate_fmu
    from mcl.compile.fmu.export import build_fmu
    from mcl.data import TimeSeries

    model = mcl.compile_model([], "Modelica.Fluid.Examples.AST_BatchPlant.Test.TankWithEmptyingPipe1")
    build_fmu(model, tmp_path / "Tank.fmu")
    assert validate_fmu(str(tmp_path / "Tank.fmu")) == []
    t = np.linspace(0.0, 35.0, 71)
    ours = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert ours.ok, ours.reason
    k = model.ode.x_names.index("tank1.m")
    theirs = simulate_fmu(str(tmp_path / "Tank.fmu"), stop_time=35.0, output_interval=0.5, output=["tank1.m"])
    m = np.interp(t, theirs["time"], theirs["tank1.m"])
    assert np.ptp(ours.states[:, k]) > 100.0          # the tank empties
    np.testing.assert_allclose(m, ours.states[:, k], atol=1e-3 * np.ptp(ours.states[:, k]))


OPEN_TANK = """
model FilledTank "an open tank of IF97 water, filled and drained by a pump's flow"
  import Modelica.Fluid.Vessels.OpenTank;
  import Modelica.Fluid.Sources.MassFlowSource_T;
  replaceable package Medium = Modelica.Media.Water.StandardWater;
  inner Modelica.Fluid.System system(energyDynamics = Modelica.Fluid.Types.Dynamics.FixedInitial);
  Modelica.Blocks.Interfaces.RealInput m_flow "pumped in (+) or out (-), kg/s";
  OpenTank tank(redeclare package Medium = Medium, height = 2, crossArea = 2, level_start = 1,
    nPorts = 1, portsData = {Modelica.Fluid.Vessels.BaseClasses.VesselPortsData(diameter = 0.05)});
  MassFlowSource_T pump(redeclare package Medium = Medium, nPorts = 1, use_m_flow_in = true, T = 300);
  output Real m = tank.m;
  output Real level = tank.level;
  output Real h = tank.medium.h;
  output Real h_in = pump.medium.h;
equation
  connect(m_flow, pump.m_flow_in);
  connect(pump.ports[1], tank.ports[1]);
end FilledTank;
"""


def test_an_open_tank_of_if97_water_fills_and_drains_as_its_balances_say(msl_path, tmp_path):
    """IF97's density reads the medium's phase, a discrete value the modes set; the
    right-hand side's derivatives with respect to the discrete values and pre(x), taken
    through the model's loop solve, were NaN, a NaN in every Newton matrix, and the run failed
    at its first step (as MSL's HeatingSystem, PumpingSystem and MeasuringTemperature did). The run follows the balances integrated by hand: the mass is
    the pumped flow's integral; the enthalpy mixes toward the warmer inflow and holds while
    the tank drains."""
    from scipy.integrate import solve_ivp

    import mcl
    from mcl.data import TimeSeries

    (tmp_path / "FilledTank.mo").write_text(OPEN_TANK)
    model = mcl.compile_model([tmp_path / "FilledTank.mo"], "FilledTank")
    t = np.linspace(0.0, 2.0, 81)
    flow = lambda s: 2.0 * np.sin(2 * np.pi * s)      # noqa: E731
    res = mcl.simulate(model, TimeSeries(t, flow(t)[:, None], ["m_flow"]), t_out=t)
    assert res.ok, res.reason
    m, h, h_in = res.output("m"), res.output("h"), res.output("h_in")
    pumped = np.concatenate([[0.0], np.cumsum(np.diff(t) * (flow(t)[1:] + flow(t)[:-1]) / 2)])
    # (the input between samples is a straight line, as the trapezoids take it; the mass,
    # 2 t, is integrated to the solver's relative tolerance of it: 2e-3 kg a step)
    assert np.max(np.abs(m - m[0] - pumped)) < 2e-2 * np.ptp(pumped)
    ref = solve_ivp(lambda s, y: [max(flow(s), 0.0) * (h_in[0] - y[0]) / np.interp(s, t, m)],
                    (0.0, 2.0), [h[0]], t_eval=t, rtol=1e-10, atol=1e-6, max_step=0.01)
    assert h[-1] - h[0] > 10.0                               # (J/kg: it warms)
    assert np.max(np.abs(h - ref.y[0])) < 1e-2 * (h[-1] - h[0])
    level = res.output("level")
    assert abs(level[0] - 1.0) < 1e-9 and np.all(np.abs(level - m / m[0]) < 1e-4)


VALVED_TANKS = """
model ValvedTanks "two open tanks between valves that stay shut until a schedule opens them"
  import Modelica.Fluid.Vessels.OpenTank;
  import Modelica.Fluid.Valves.ValveDiscrete;
  import Modelica.Fluid.Vessels.BaseClasses.VesselPortsData;
  replaceable package Medium = Modelica.Media.Water.ConstantPropertyLiquidWater;
  inner Modelica.Fluid.System system;
  Modelica.Fluid.Sources.FixedBoundary supply(redeclare package Medium = Medium, p = 2.5e5, nPorts = 1);
  Modelica.Fluid.Sources.FixedBoundary drain(redeclare package Medium = Medium, p = system.p_ambient, nPorts = 1);
  ValveDiscrete fill(redeclare package Medium = Medium, m_flow_nominal = 40, dp_nominal = 1e5);
  ValveDiscrete transfer(redeclare package Medium = Medium, m_flow_nominal = 100, dp_nominal = 1);
  ValveDiscrete empty(redeclare package Medium = Medium, m_flow_nominal = 10, dp_nominal = 1);
  OpenTank upper(redeclare package Medium = Medium, crossArea = 6, height = 4, level_start = 0.05, nPorts = 2,
    portsData = {VesselPortsData(diameter = 0.2, height = 4, zeta_in = 1), VesselPortsData(diameter = 0.2, zeta_in = 1)});
  OpenTank lower(redeclare package Medium = Medium, crossArea = 6, height = 4, level_start = 0.05, nPorts = 2,
    portsData = {VesselPortsData(diameter = 0.2, height = 4, zeta_in = 1), VesselPortsData(diameter = 0.2, zeta_in = 1)});
  Modelica.Blocks.Sources.BooleanStep openFill(startTime = 20);
  Modelica.Blocks.Sources.BooleanStep openTransfer(startTime = 60);
  Modelica.Blocks.Sources.BooleanConstant keepShut(k = false);
  output Real level_upper = upper.level;
  output Real level_lower = lower.level;
  output Real m_total = upper.m + lower.m;
  output Real m_flow_fill = fill.port_a.m_flow;
equation
  connect(supply.ports[1], fill.port_a);
  connect(fill.port_b, upper.ports[1]);
  connect(upper.ports[2], transfer.port_a);
  connect(transfer.port_b, lower.ports[1]);
  connect(lower.ports[2], empty.port_a);
  connect(empty.port_b, drain.ports[1]);
  connect(openFill.y, fill.open);
  connect(openTransfer.y, transfer.open);
  connect(keepShut.y, empty.open);
end ValvedTanks;
"""


def test_tanks_between_shut_valves_wait_then_fill_and_transfer_as_their_balances_say(msl_path, tmp_path):
    """A pipe between shut valves fixes its pressure only to what its head allows: the loop's
    Jacobian is singular, and the Newton step the solver's Jacobian was taken from was
    infinite there (a NaN in every Jacobian: ControlledTanks failed after 3.6 s of shut
    valves, this model at 0.5 s). And the system's default dynamics leave the tanks' mass and
    energy free at the start: the level's start value (a preferred state) is where they start,
    as in other tools (it started empty). Checked against the valve's law by hand: the supply
    fills at 40 kg/s per bar of head over the ambient, until the transfer valve opens."""
    import mcl
    from mcl.data import TimeSeries

    (tmp_path / "ValvedTanks.mo").write_text(VALVED_TANKS)
    model = mcl.compile_model([tmp_path / "ValvedTanks.mo"], "ValvedTanks")
    t = np.linspace(0.0, 120.0, 241)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    up, low, m = res.output("level_upper"), res.output("level_lower"), res.output("m_total")
    shut, filling = t < 20, t >= 20
    assert np.all(np.abs(up[shut] - 0.05) < 1e-9) and np.all(np.abs(low[t < 60] - 0.05) < 1e-6)
    flow = 40.0 * (2.5e5 - 101325.0) / 1e5           # (the supply's port is above the level: ambient there)
    assert np.all(np.abs(res.output("m_flow_fill")[filling] - flow) < 1e-6 * flow)
    assert np.max(np.abs(m - m[0] - flow * np.maximum(t - 20, 0.0))) < 1e-4 * flow * 100
    after = t > 60          # the transfer valve open: the upper tank drains into the lower one
    assert np.all(np.diff(up[after]) < 0) and np.all(np.diff(low[after]) > 0)


def test_a_stategraph_composite_step_is_suspended_and_resumed_on_its_transitions_timers(msl_path):
    """StateGraph.Examples.ShowExceptions: the composite step, entered after 1 s, is suspended
    by a transition that waits 2 s and resumed by one that waits 1 s, over and over: active on
    [1, 3), [4, 6), [7, 9), ... Its count of active inner steps is integer() of a sum of flows,
    and 'count > 0' kept the band a continuous relation has: at count = 0 it stayed true, and
    the step was never suspended."""
    import mcl
    from mcl.data import TimeSeries

    model = mcl.compile_model([], "Modelica.StateGraph.Examples.ShowExceptions")
    t = np.linspace(0.0, 20.0, 401)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    active = res.states[:, model.ode.x_names.index("compositeStep.active")]
    phase = np.mod(t - 1.0, 3.0)
    expected = ((t >= 1.0) & (phase < 2.0)).astype(float)
    edges = np.isclose(phase, 0.0, atol=1e-9) | np.isclose(phase, 2.0, atol=1e-9)   # (the value after the event)
    assert np.array_equal(active[~edges], expected[~edges])


def test_a_stategraph_alternative_whose_timers_run_out_together_takes_its_first_branch(msl_path):
    """StateGraph.Examples.ShowCompositeStep: the composite step's alternative has three
    branches whose transitions wait 1 s each, so all three may fire at t = 2; the first has
    priority (step3, which its transition leaves after 2 s). Two of the three timers were held
    relations, banded at an event, and one was read live: only the third fired, and step4a was
    entered instead."""
    import mcl
    from mcl.data import TimeSeries

    model = mcl.compile_model([], "Modelica.StateGraph.Examples.ShowCompositeStep")
    t = np.linspace(0.0, 15.0, 301)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    active = {n: res.states[:, model.ode.x_names.index(f"compositeStep.{n}.localActive")]
              for n in ("step3", "step4", "step4a")}
    inside = ((t > 2.01) & (t < 3.99)) | ((t > 9.06) & (t < 10.99))
    assert np.all(active["step3"][inside] == 1.0)
    assert not active["step4"].any() and not active["step4a"].any()


MAINS_LOAD = """
model MainsLoad "a winding on the mains, as a phasor circuit of the MSL's quasi-static parts"
  import Modelica.Electrical.QuasiStatic.SinglePhase;
  import Modelica.ComplexMath;
  parameter Real R = 10 "winding resistance";
  parameter Real L = 0.05 "winding inductance";
  SinglePhase.Sources.VoltageSource mains(f = 50, V = 230, phi = 0, gamma(fixed = true, start = 0));
  SinglePhase.Sensors.CurrentSensor ammeter;
  SinglePhase.Basic.Resistor winding(R_ref = R);
  SinglePhase.Basic.Inductor reactance(L = L);
  SinglePhase.Basic.Ground ground;
  output Real I = ComplexMath.abs(ammeter.i) "RMS current";
  output Real phase = ComplexMath.arg(ammeter.i) "current's phase";
  output Real P = winding.LossPower;
equation
  connect(mains.pin_p, ammeter.pin_p);
  connect(ammeter.pin_n, winding.pin_p);
  connect(winding.pin_n, reactance.pin_p);
  connect(reactance.pin_n, ground.pin);
  connect(mains.pin_n, ground.pin);
end MainsLoad;
"""


def test_a_phasor_circuit_of_quasi_static_parts_draws_the_current_its_impedance_says(msl_path, tmp_path):
    """The MSL's QuasiStatic parts write their equations in Complex arithmetic (``v = R*i``,
    ``pin_p.i + pin_n.i = Complex(0)``), which rumoca 0.10 translates one equation short: mcl
    writes the operators as the record's calls (:mod:`mcl.compile.complexops`). The winding's
    current and loss are those of its impedance R + jwL, in process and in the FMU."""
    import mcl
    from fmpy import simulate_fmu
    from mcl.data import TimeSeries

    (tmp_path / "MainsLoad.mo").write_text(MAINS_LOAD)
    model = mcl.compile_model([tmp_path / "MainsLoad.mo"], "MainsLoad")
    t = np.linspace(0.0, 0.1, 11)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []))
    assert res.ok, res.reason
    z = 10 + 2j * np.pi * 50 * 0.05
    current = 230 / z
    assert np.allclose(res.output("I"), abs(current)) and np.allclose(res.output("phase"), np.angle(current))
    assert np.allclose(res.output("P"), abs(current) ** 2 * 10)
    fmu = tmp_path / "load.fmu"
    assert main(["compile", str(tmp_path / "MainsLoad.mo"), "--model", "MainsLoad", "-o", str(fmu)]) == 0
    assert validate_fmu(fmu) == []
    out = simulate_fmu(str(fmu), stop_time=0.1, output=["I", "P"])
    assert np.allclose(out["I"], abs(current)) and np.allclose(out["P"], abs(current) ** 2 * 10)


WINDING = """
model Winding "a three-phase winding on a reluctance, fed from the mains, with its currents' symmetrical components"
  import Modelica.Electrical.QuasiStatic.Polyphase;
  import Modelica.Electrical.QuasiStatic.SinglePhase;
  import Modelica.Magnetic.QuasiStatic.FundamentalWave;
  parameter Integer m = 3;
  parameter Real V = 100 "RMS phase voltage";
  parameter Real turns = 5 "effective turns";
  parameter Real Rm = 40 "the core's reluctance";
  Polyphase.Sources.VoltageSource mains(m = m, f = 50, V = fill(V, m), gamma(fixed = true, start = 0));
  Polyphase.Basic.Star star(m = m);
  SinglePhase.Basic.Ground ground;
  Polyphase.Sensors.CurrentSensor ammeter(m = m);
  FundamentalWave.Components.PolyphaseElectroMagneticConverter winding(m = m, effectiveTurns = turns);
  FundamentalWave.Components.Reluctance core(R_m(d = Rm, q = Rm));
  FundamentalWave.Components.Ground magneticGround;
  Polyphase.Blocks.SymmetricalComponents components(m = m);
  output Real I1re = ammeter.i[1].re, I1im = ammeter.i[1].im;
  output Real positive = Modelica.ComplexMath.abs(components.y[1]) "the positive sequence";
  output Real others = sum(Modelica.ComplexMath.abs(components.y[k]) for k in 2:m);
equation
  connect(mains.plug_p, ammeter.plug_p);
  connect(ammeter.plug_n, winding.plug_p);
  connect(winding.plug_n, mains.plug_n);
  connect(mains.plug_n, star.plug_p);
  connect(star.pin_n, ground.pin);
  connect(winding.port_p, core.port_p);
  connect(winding.port_n, core.port_n);
  connect(winding.port_n, magneticGround.port_p);
  connect(ammeter.i, components.u);
end Winding;
"""

SIX_PHASES = """
model SixPhases "a six-phase source on an unbalanced resistive star: the currents' symmetrical components"
  import Modelica.Electrical.QuasiStatic.Polyphase;
  import Modelica.Electrical.QuasiStatic.SinglePhase;
  parameter Integer m = 6 "two three-phase systems";
  Polyphase.Sources.VoltageSource mains(m = m, f = 50, V = {100 + 10*k for k in 1:m}, gamma(fixed = true, start = 0));
  Polyphase.Basic.Resistor load(m = m, R_ref = {1 + 0.5*k for k in 1:m});
  Polyphase.Basic.Star star(m = m);
  SinglePhase.Basic.Ground ground;
  Polyphase.Sensors.CurrentSensor ammeter(m = m);
  Polyphase.Blocks.SymmetricalComponents components(m = m);
  Polyphase.Blocks.FromSymmetricalComponents phases(m = m);
  output Real back = sum(Modelica.ComplexMath.abs(phases.y[k] - ammeter.i[k]) for k in 1:m);
equation
  connect(mains.plug_p, ammeter.plug_p);
  connect(ammeter.plug_n, load.plug_p);
  connect(load.plug_n, star.plug_p);
  connect(mains.plug_n, star.plug_p);
  connect(star.pin_n, ground.pin);
  connect(ammeter.i, components.u);
  connect(components.y, phases.u);
end SixPhases;
"""


def _symmetric_orientation(m: int) -> np.ndarray:
    """Modelica.Electrical.Polyphase.Functions.symmetricOrientation, as the MSL writes it."""
    if m % 2:
        return np.arange(m) * 2 * np.pi / m
    if m == 2:
        return np.array([0.0, np.pi / 2])
    half = _symmetric_orientation(m // 2)
    return np.concatenate([half, half - np.pi / m])


def _symmetric_transformation(m: int) -> np.ndarray:
    """Polyphase.Functions.symmetricTransformationMatrix (through symmetricOrientationMatrix)."""
    n_base = 1
    k = m
    while k % 2 == 0 and k != 2:
        n_base, k = n_base * 2, k // 2
    m_base = m // n_base
    o = _symmetric_orientation(m)
    oM = np.zeros((m, m))
    oM[:m_base, :m_base] = [o[:2], -o[:2]] if m_base == 2 else [j * o[:m_base] for j in range(1, m_base + 1)]
    for i in range(1, n_base):
        s = slice(i * m_base, (i + 1) * m_base)
        oM[s, s] = oM[:m_base, :m_base] + o[i * m_base]
    same = np.kron(np.eye(n_base), np.ones((m_base, m_base)))
    return same * n_base / m * np.exp(1j * oM)


def test_a_winding_on_a_quasi_static_fundamental_wave_core_and_symmetrical_components(msl_path, tmp_path):
    """The QuasiStatic FundamentalWave converter and the symmetrical-components blocks compute
    their transformation matrices and sequence indices with functions whose output sizes are
    calls (numberOfSymmetricBaseSystems), which rumoca cannot size: mcl's overlays write them
    as comprehensions and a local function (:mod:`mcl.compile.overlays`). A three-phase winding
    of N turns on a reluctance R_m is the inductance m N^2 / (2 R_m) on each phase, drawing a
    positive sequence only; six unbalanced phases (two base systems) have the symmetrical
    components of the MSL's matrix, and transformed back they are the phase currents."""
    import mcl
    from mcl.data import TimeSeries

    t = np.linspace(0.0, 0.02, 3)
    none = TimeSeries(t, np.zeros((len(t), 0)), [])
    (tmp_path / "Winding.mo").write_text(WINDING)
    res = mcl.simulate(mcl.compile_model([tmp_path / "Winding.mo"], "Winding"), none)
    assert res.ok, res.reason
    current = 100 / (1j * 2 * np.pi * 50 * (3 * 5 ** 2 / 2 / 40))
    assert np.allclose(res.output("I1re"), current.real, atol=1e-9) and np.allclose(res.output("I1im"), current.imag)
    assert np.allclose(res.output("positive"), abs(current)) and np.allclose(res.output("others"), 0.0, atol=1e-9)

    (tmp_path / "SixPhases.mo").write_text(SIX_PHASES)
    model = mcl.compile_model([tmp_path / "SixPhases.mo"], "SixPhases")
    back = mcl.simulate(model, none)
    assert back.ok, back.reason
    # (only variables that are not outputs: once an internal error, an empty vertcat)
    names = [f"components.y[{k}].{p}" for k in range(1, 7) for p in ("re", "im")]
    res = mcl.simulate(model.with_outputs(names, only=True), none)
    assert res.ok, res.reason
    k = np.arange(1, 7)
    currents = (100 + 10 * k) * np.exp(-1j * _symmetric_orientation(6)) / (1 + 0.5 * k)
    expected = _symmetric_transformation(6) @ currents
    got = np.array([res.output(f"components.y[{j}].re")[-1] + 1j * res.output(f"components.y[{j}].im")[-1]
                    for j in k])
    assert np.allclose(got, expected) and np.allclose(back.output("back"), 0.0, atol=1e-9)


def test_an_unbalanced_star_load_balanced_by_reactances_draws_no_neutral_current(msl_path):
    """The MSL's BalancingStar: a resistor, an inductor and a capacitor in star on three phases,
    sized so that the source sees a balanced resistive load. Its phasors are arrays of Complex
    records, their equations written element by element and its power sensor's sum of products
    as the sum of the parts (:mod:`mcl.compile.complexops`). No current in the neutral; the
    apparent power is the resistor's V^2/R, with no reactive part."""
    import mcl
    from mcl.data import TimeSeries

    model = mcl.compile_model([], "Modelica.Electrical.QuasiStatic.Polyphase.Examples.BalancingStar")
    model = model.with_outputs([f"{name}.{part}" for name in ("currentSensor0.i", "powerSensor.apparentPower")
                                for part in ("re", "im")], only=True)
    t = np.linspace(0.0, 1.0, 5)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []))
    assert res.ok, res.reason
    for part in ("re", "im"):
        assert np.allclose(res.output(f"currentSensor0.i.{part}"), 0.0, atol=1e-9)
    assert np.allclose(res.output("powerSensor.apparentPower.re"), 100.0 ** 2 / 10.0)
    assert np.allclose(res.output("powerSensor.apparentPower.im"), 0.0, atol=1e-9)


STEADY_TANK = """
model SteadyTank "a tank fed at a fixed rate, draining through a pipe, started in steady state"
  import Modelica.Fluid;
  import Modelica.Units.SI;
  replaceable package Medium = Modelica.Media.Water.ConstantPropertyLiquidWater;
  parameter SI.MassFlowRate m_in = 0.5 "feed";
  inner Fluid.System system(energyDynamics = Modelica.Fluid.Types.Dynamics.FixedInitial);
  Fluid.Sources.MassFlowSource_T feed(redeclare package Medium = Medium, m_flow = m_in, nPorts = 1);
  Fluid.Vessels.OpenTank tank(redeclare package Medium = Medium, height = 5, crossArea = 0.5,
    level_start = 2, nPorts = 2, massDynamics = Modelica.Fluid.Types.Dynamics.SteadyStateInitial,
    portsData = {Fluid.Vessels.BaseClasses.VesselPortsData(diameter = 0.1),
                 Fluid.Vessels.BaseClasses.VesselPortsData(diameter = 0.1)});
  Fluid.Pipes.StaticPipe drain(redeclare package Medium = Medium, length = 10, diameter = 0.05);
  Fluid.Sources.Boundary_pT sink(redeclare package Medium = Medium, p = system.p_ambient, nPorts = 1);
  output SI.Height level = tank.level;
  output SI.MassFlowRate m_out = -drain.port_b.m_flow;
equation
  connect(feed.ports[1], tank.ports[1]);
  connect(tank.ports[2], drain.port_a);
  connect(drain.port_b, sink.ports[1]);
end SteadyTank;
"""


def test_a_tank_of_msl_parts_started_in_steady_state_stays_there(msl_path, tmp_path):
    """An OpenTank fed at 0.5 kg/s, its mass steady at the start. Its ports' relation
    (level >= port height) held false shut them: no steady state with the feed running, the
    level left at its start value of 2 m, and the tank drained from there (6.2 kg/s out at
    t = 0). Started as the start values make it (open), the level is the pipe's: constant,
    a few centimetres, and all the feed flows out."""
    import mcl
    from mcl.data import TimeSeries

    (tmp_path / "SteadyTank.mo").write_text(STEADY_TANK)
    model = mcl.compile_model([tmp_path / "SteadyTank.mo"], "SteadyTank")
    t = np.linspace(0.0, 100.0, 11)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    level, m_out = res.output("level"), res.output("m_out")
    assert 0.0 < level[0] < 0.1 and np.ptp(level) < 1e-9
    assert np.max(np.abs(m_out - 0.5)) < 1e-9


PIPES_FROM_REST = """
model PipesFromRest "Water pushed through two pipes in series into a vessel, from rest"
  import Modelica.Fluid;
  import Modelica.Fluid.Pipes.BaseClasses.FlowModels.DetailedPipeFlow;
  replaceable package Medium = Modelica.Media.Water.ConstantPropertyLiquidWater;
  inner Fluid.System system(energyDynamics = Modelica.Fluid.Types.Dynamics.FixedInitial,
    massDynamics = Modelica.Fluid.Types.Dynamics.FixedInitial);
  Modelica.Blocks.Sources.Ramp ramp(height = 0.2e5, duration = 1, offset = 1e5, startTime = 0.5);
  Fluid.Sources.Boundary_pT source(redeclare package Medium = Medium, use_p_in = true, T = 300, nPorts = 1);
  Fluid.Pipes.StaticPipe pipe1(redeclare package Medium = Medium, length = 10, diameter = 0.05,
    redeclare model FlowModel = DetailedPipeFlow);
  Fluid.Pipes.StaticPipe pipe2(redeclare package Medium = Medium, length = 10, diameter = 0.05,
    redeclare model FlowModel = DetailedPipeFlow);
  Fluid.Vessels.ClosedVolume vessel(redeclare package Medium = Medium, V = 0.01, nPorts = 2,
    use_portsData = false, p_start = 1e5, T_start = 300);
  Fluid.Pipes.StaticPipe pipe3(redeclare package Medium = Medium, length = 10, diameter = 0.05,
    redeclare model FlowModel = DetailedPipeFlow);
  Fluid.Sources.FixedBoundary sink(redeclare package Medium = Medium, p = 1e5, T = 300, nPorts = 1);
  Modelica.Blocks.Interfaces.RealOutput p_vessel "measured vessel pressure";
equation
  p_vessel = vessel.medium.p;
  connect(ramp.y, source.p_in);
  connect(source.ports[1], pipe1.port_a);
  connect(pipe1.port_b, pipe2.port_a);
  connect(pipe2.port_b, vessel.ports[1]);
  connect(vessel.ports[2], pipe3.port_a);
  connect(pipe3.port_b, sink.ports[1]);
end PipesFromRest;
"""


def test_a_pipe_network_started_at_rest_has_finite_sensitivities(msl_path, tmp_path):
    """Pipes with the detailed wall friction, started with no flow. The friction law's turbulent
    branch divides by |m_flow|: not taken at rest, its value masked, but the sensitivities went
    through it by reverse mode (0 * inf), and the run with sensitivities failed at t = 0. They
    now agree with finite differences of two runs."""
    import mcl
    from mcl.data import TimeSeries

    (tmp_path / "PipesFromRest.mo").write_text(PIPES_FROM_REST)
    model = mcl.compile_model([tmp_path / "PipesFromRest.mo"], "PipesFromRest")
    t = np.linspace(0.0, 3.0, 31)
    none = TimeSeries(t, np.zeros((len(t), 0)), [])
    names = ["pipe1.roughness", "pipe1.diameter"]
    res = mcl.simulate(model, none, t_out=t, sensitivities=names)
    assert res.ok, res.reason
    S = res.sensitivities[:, 0, :]          # d p_vessel / d (roughness, diameter)
    assert np.all(np.isfinite(S))
    assert abs(res.output("p_vessel")[-1] - 1.0e5) > 1e3          # (the water flows at the end)
    for j, (name, h) in enumerate(zip(names, (1e-6, 1e-4))):
        v = model.ode.p_values[model.ode.p_names.index(name)]
        up, down = (mcl.simulate(model, none, params={name: v + s * h}, t_out=t).output("p_vessel")
                    for s in (1, -1))
        fd = (up - down) / (2 * h)
        assert np.allclose(S[-1, j], fd[-1], rtol=0.02), (name, S[-1, j], fd[-1])


def test_pumping_system_keeps_its_reservoir_level_around_two_metres(msl_path):
    """MSL's PumpingSystem, as its documentation says: once the users' valve opens at t = 200 s,
    'the pump starts turning on and off to keep the reservoir level around 2 meters'. Its
    pump's 0.05 l of IF97 water has pressure and temperature as states (stateSelect = prefer;
    with mass and energy the run was stiff: 411 000 steps in 5 s), its check valve in an
    algebraic loop shuts each time the controller stops the pump (a call integrated past the
    valve's shutting, on as if open, into zero speed: every loop solve failed)."""
    from mcl import compile_model, simulate

    model = compile_model([], "Modelica.Fluid.Examples.PumpingSystem")
    t = np.linspace(0, 2000, 501)
    res = simulate(model, None, t_out=t)
    assert res.ok, res.reason
    names = model.ode.x_names
    level = res.states[:, names.index("reservoir.V")] / 50          # (its cross-section: 50 m2)
    assert 1.7 < level[t > 400].min() < 2.0 < level[t > 400].max() < 2.4
    on = res.states[:, names.index("controller.y")]
    assert np.count_nonzero(np.diff(on)) >= 4                         # on and off twice at least
