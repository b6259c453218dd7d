"""MSL components that rumoca 0.10.2 misreads, run through mcl's overlays (equivalent rewrites of
the library's text in mcl's own link tree), each checked against a solution derived by hand."""
from pathlib import Path

import numpy as np
import pytest

import mcl
from mcl.data import TimeSeries

from helpers import probed

MSL = Path(__file__).resolve().parents[2] / "shared" / "msl"
pytestmark = pytest.mark.skipif(not (MSL / "Modelica" / "package.mo").is_file(), reason=f"the MSL is not at {MSL}")


def _simulated(tmp_path, monkeypatch, text: str, name: str, t):
    """(model, its run over ``t``) of the model ``name`` in ``text``, checked to succeed."""
    monkeypatch.setenv("MODELICAPATH", str(MSL))
    (tmp_path / f"{name}.mo").write_text(text)
    model = mcl.compile_model([tmp_path / f"{name}.mo"], name)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    return model, res


def _run(tmp_path, monkeypatch, text: str, name: str, t):
    """The run's states, by name."""
    model, res = _simulated(tmp_path, monkeypatch, text, name, t)
    return lambda n: res.states[:, model.ode.x_names.index(n)]


def test_a_sliding_mass_with_coulomb_friction_stops_and_sticks(tmp_path, monkeypatch):
    """MassWithStopAndFriction extends a class nested in itself, which rumoca misreads; the
    overlay writes that class's contents in the model. A block launched at 3 m/s on a surface
    with 4 N of Coulomb friction (m = 2 kg) decelerates at 2 m/s², stops at 1.5 s after
    2.25 m, and stays stuck."""
    state = _run(tmp_path, monkeypatch, """
model Slide
  import Modelica.Mechanics.Translational;
  Translational.Components.MassWithStopAndFriction brick(m = 2, F_prop = 0, F_Coulomb = 4,
    F_Stribeck = 0, fexp = 0, L = 0, smax = 100, smin = -100,
    s(start = 0, fixed = true), v(start = 3, fixed = true));
end Slide;
""", "Slide", t := np.linspace(0.0, 3.0, 31))
    tc = np.minimum(t, 1.5)
    assert np.abs(state("brick.v") - (3 - 2 * tc)).max() < 1e-6
    # (of 2.25 m at the default tolerances; each call's restart adds to it: 1.25e-4 since stop 101)
    assert np.abs(state("brick.s") - (3 * tc - tc ** 2)).max() < 2e-4


@pytest.mark.parametrize("table", ["[0, 0.5, 0.5, 0, 0]", "[0, 0.5, 0.5, 0, 0; 10, 0.5, 0.5, 0, 0]"])
def test_a_lossy_gear_passes_half_the_power(tmp_path, monkeypatch, table):
    """LossyGear's parameters bound to the two-output Vectors.interpolate, which rumoca evaluates
    as arrays; the overlay calls it through a one-output function. A loss table of two rows
    (HeatLosses') made rumoca count those bindings as equations (unbalanced by 2). A torque of
    3 N.m on J1 = 1 drives J2 = 1 through a gear of efficiency 0.5 (ratio 1): J1 w' = 3 - tau_a
    and J2 w' = 0.5 tau_a, so once it moves both accelerate at 3/(J1 + J2/0.5) = 1 rad/s²."""
    state = _run(tmp_path, monkeypatch, """
model Gearbox
  import Modelica.Mechanics.Rotational;
  Rotational.Sources.ConstantTorque drive(tau_constant = 3);
  Rotational.Components.Inertia J1(J = 1, phi(start = 0, fixed = true), w(start = 0, fixed = true));
  Rotational.Components.LossyGear gear(ratio = 1, lossTable = """ + table + """);
  Rotational.Components.Inertia J2(J = 1);
equation
  connect(drive.flange, J1.flange_a);
  connect(J1.flange_b, gear.flange_a);
  connect(gear.flange_b, J2.flange_a);
end Gearbox;
""", "Gearbox", t := np.linspace(0.0, 2.0, 21))
    assert np.polyfit(t[t > 0.5], state("J1.w")[t > 0.5], 1)[0] == pytest.approx(1.0, rel=1e-4)


@pytest.mark.parametrize("kind, order", [("Butterworth", 3), ("ChebyshevI", 3), ("ChebyshevI", 4)])
def test_normalized_filters_match_scipy(tmp_path, monkeypatch, kind, order):
    """Blocks.Continuous.Filter: a normalized Chebyshev filter finds its -3 dB correction with
    two while-loops and a Streams.error, and odd orders fill arrays in branches on their size,
    which rumoca cannot lower; the overlays bound the loops and merge the branches. The step
    response of each filter matches scipy's analog prototype scaled to the MSL's -3 dB
    (10^(-3/20)) at f_cut, with the MSL's gain 1 at DC."""
    from scipy import optimize, signal

    f_cut, t = 2.0, np.linspace(0.0, 1.5, 151)
    monkeypatch.setenv("MODELICAPATH", str(MSL))
    (tmp_path / "Lowpass.mo").write_text(f"""
model Lowpass
  import Modelica.Blocks;
  Blocks.Sources.Step step(startTime = 0.5);
  Blocks.Continuous.Filter F(analogFilter = Blocks.Types.AnalogFilter.{kind}, order = {order},
    f_cut = {f_cut}, A_ripple = 0.5);
  output Real y = F.y;
equation
  connect(step.y, F.u);
end Lowpass;
""")
    model = mcl.compile_model([tmp_path / "Lowpass.mo"], "Lowpass")
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    proto = signal.butter(order, 1.0, analog=True) if kind == "Butterworth" else signal.cheby1(order, 0.5, 1.0, analog=True)
    proto = (proto[0] * proto[1][-1] / proto[0][-1], proto[1])       # the MSL's filters pass DC at gain 1
    gain = lambda w: abs(np.polyval(proto[0], 1j * w) / np.polyval(proto[1], 1j * w))  # noqa: E731
    w3 = 1.0 if kind == "Butterworth" else optimize.brentq(lambda w: gain(w) - 10 ** (-3 / 20), 1.0, 10.0)
    b, a = signal.butter(order, 2 * np.pi * f_cut, analog=True) if kind == "Butterworth" else \
        signal.lp2lp(*proto, wo=2 * np.pi * f_cut / w3)
    late = t >= 0.5
    _, ref = signal.step((b, a), T=t[late] - 0.5)
    assert np.abs(res.output("y")[late] - ref).max() < 1e-3
    assert np.abs(res.output("y")[~late]).max() < 1e-9


def test_a_filters_output_differentiated_three_times(tmp_path, monkeypatch):
    """MSL's FilterWithDifferentiation, as an engineer would write it: Der blocks differentiate
    a third-order Bessel filter's output three times (an index-4 DAE; the filter's coefficients
    are parameters computed in its initial equations, which become dependent parameters).
    Each Der block's output is the time derivative of its input (central differences)."""
    monkeypatch.setenv("MODELICAPATH", str(MSL))
    (tmp_path / "Smooth.mo").write_text("""
model Smooth
  import Modelica.Blocks;
  Blocks.Sources.Sine source(f = 0.5);
  Blocks.Continuous.Filter F(analogFilter = Blocks.Types.AnalogFilter.Bessel, order = 3, f_cut = 2);
  Blocks.Continuous.Der d1;
  Blocks.Continuous.Der d2;
  output Real y = F.y;
  output Real dy = d1.y;
  output Real ddy = d2.y;
equation
  connect(source.y, F.u);
  connect(F.y, d1.u);
  connect(d1.y, d2.u);
end Smooth;
""")
    model = mcl.compile_model([tmp_path / "Smooth.mo"], "Smooth")
    t = np.linspace(0.0, 2.0, 2001)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    y, dy, ddy = (res.output(n) for n in ("y", "dy", "ddy"))
    assert np.ptp(y) > 0.5
    assert np.abs(np.gradient(y, t) - dy)[5:-5].max() < 1e-3 * np.ptp(dy)
    assert np.abs(np.gradient(dy, t) - ddy)[5:-5].max() < 1e-3 * np.ptp(ddy)


def test_a_current_controlled_dc_drive_holds_its_current_reference(monkeypatch):
    """The MSL's ControlledDCDrives declare their drive data as a replaceable record holding a
    record, which rumoca cannot flatten; the overlay declares it a plain parameter (no example
    redeclares it). CurrentControlledDCPM steps its torque reference to tauNominal at 0.2 s,
    which the drive data turn into the current reference tauNominal/kPhi = IaNominal (100 A):
    the armature current is 0 before and holds 100 A after, while the load speeds up."""
    monkeypatch.setenv("MODELICAPATH", str(MSL))
    model = mcl.compile_model([], "Modelica.Electrical.Machines.Examples.ControlledDCDrives.CurrentControlledDCPM")
    t = np.linspace(0.0, 2.0, 21)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    state = lambda n: res.states[:, model.ode.x_names.index(n)]     # noqa: E731
    assert np.abs(state("dcpm.la.i")[t < 0.2]).max() < 1e-6
    np.testing.assert_allclose(state("dcpm.la.i")[t >= 0.4], 100.0, rtol=1e-3)
    assert np.all(np.diff(state("loadInertia.w")[t >= 0.3]) > 0)


def test_two_tanks_of_a_simple_liquid_level_out_through_a_pipe(tmp_path, monkeypatch):
    """Media on PartialSimpleMedium (ConstantPropertyLiquidWater) size a function's input by the
    package's nX, which rumoca cannot prove when BaseProperties calls it; the overlay sizes it
    X[:]. Two open tanks of 1 m² joined at their floors by a horizontal pipe, filled to 2 m and
    0.5 m (the water's 995.586 kg/m³): the water flows from the full one to the other until
    both stand at 1.25 m, and none is lost. Both ports start open, then the held relations of
    their flow direction follow the flow."""
    state = _run(tmp_path, monkeypatch, """
model Levels
  replaceable package Medium = Modelica.Media.Water.ConstantPropertyLiquidWater;
  inner Modelica.Fluid.System system(energyDynamics = Modelica.Fluid.Types.Dynamics.FixedInitial);
  Modelica.Fluid.Vessels.OpenTank full(redeclare package Medium = Medium, crossArea = 1, height = 3,
    level_start = 2, nPorts = 1, portsData = {Modelica.Fluid.Vessels.BaseClasses.VesselPortsData(diameter = 0.1)});
  Modelica.Fluid.Vessels.OpenTank low(redeclare package Medium = Medium, crossArea = 1, height = 3,
    level_start = 0.5, nPorts = 1, portsData = {Modelica.Fluid.Vessels.BaseClasses.VesselPortsData(diameter = 0.1)});
  Modelica.Fluid.Pipes.StaticPipe pipe(redeclare package Medium = Medium, length = 1, diameter = 0.1);
equation
  connect(full.ports[1], pipe.port_a);
  connect(pipe.port_b, low.ports[1]);
end Levels;
""", "Levels", np.linspace(0.0, 300.0, 7))
    rho = 995.586
    total = state("full.m") + state("low.m")
    np.testing.assert_allclose(total, rho * 2.5, rtol=1e-6)
    assert np.all(np.diff(state("full.m")) <= 1e-3)          # (it settles to 5e-8 of its mass)
    np.testing.assert_allclose([state("full.m")[-1], state("low.m")[-1]], rho * 1.25, rtol=1e-3)


def test_a_heated_pipe_started_in_steady_state_stays_there(tmp_path, monkeypatch):
    """A pipe's volumes started in steady state (``SteadyStateInitial``, set on the ``system``
    as engineers set it): the library writes it der(mediums.T) = zeros(n), which rumoca refused
    (and read as the defaults through the system); the overlay writes it element by element.
    Water from 2 bar and 320 K to 1 bar, 2 kW into the second of two volumes: the flow and the
    temperatures hold from the start, and the heat goes into the flow's enthalpy."""
    model, res = _simulated(tmp_path, monkeypatch, """
model HeatedPipe
  import Modelica.Fluid.Types.Dynamics;
  replaceable package Medium = Modelica.Media.CompressibleLiquids.LinearWater_pT_Ambient;
  inner Modelica.Fluid.System system(energyDynamics = Dynamics.SteadyStateInitial);
  Modelica.Fluid.Sources.Boundary_pT supply(redeclare package Medium = Medium, p = 2e5, T = 320, nPorts = 1);
  Modelica.Fluid.Sources.Boundary_pT drain(redeclare package Medium = Medium, p = 1e5, T = 300, nPorts = 1);
  Modelica.Fluid.Pipes.DynamicPipe pipe(redeclare package Medium = Medium, length = 5, diameter = 0.01,
    nNodes = 2, use_HeatTransfer = true, T_start = 300);
  Modelica.Thermal.HeatTransfer.Sources.FixedHeatFlow heater(Q_flow = 2000);
equation
  connect(supply.ports[1], pipe.port_a);
  connect(pipe.port_b, drain.ports[1]);
  connect(heater.port, pipe.heatPorts[2]);
end HeatedPipe;
""", "HeatedPipe", np.linspace(0.0, 20.0, 5))
    v = probed(model, res)
    np.testing.assert_allclose(res.states, res.states[:1].repeat(len(res.time), 0), rtol=1e-9)
    m_flow = v["pipe.port_a.m_flow"]
    assert np.all(m_flow > 0.1) and np.ptp(m_flow) < 1e-9 * m_flow[0]
    np.testing.assert_allclose(v["pipe.mediums[1].T"], 320.0, rtol=1e-9)       # (the first volume is not heated)
    np.testing.assert_allclose(m_flow * (v["pipe.mediums[2].h"] - v["pipe.mediums[1].h"]), 2000.0, rtol=1e-6)


def test_a_battery_cell_with_one_rc_element_charges_it(tmp_path, monkeypatch):
    """CellRCStack gives its RC elements R and C from the cell's record array (an array modifier
    of a component array, which rumoca misreads; the overlay writes it element by element). A
    cell with one RC element (R = 0.01 Ohm, C = 1000 F) carrying 10 A charges its capacitor to
    I*R*(1 - exp(-t/(R*C))) = 0.1*(1 - exp(-t/10)) V."""
    state = _run(tmp_path, monkeypatch, """
model Cell
  import Modelica.Electrical.Batteries;
  import Modelica.Electrical.Analog;
  parameter Batteries.ParameterRecords.TransientData.CellData data(Qnom = 18000, OCVmax = 4.2,
    OCVmin = 2.5, Ri = 0.02, nRC = 1, rcData = {Batteries.ParameterRecords.TransientData.RCData(R = 0.01, C = 1000)});
  Batteries.BatteryStacks.CellRCStack cell(cellData = data, useHeatPort = false, SOC(fixed = true, start = 0.5));
  Analog.Basic.Ground ground;
  Analog.Sources.ConstantCurrent load(I = 10);
equation
  connect(cell.n, ground.p);
  connect(load.p, ground.p);
  connect(load.n, cell.p);
end Cell;
""", "Cell", t := np.linspace(0.0, 40.0, 41))
    assert np.abs(state("cell.capacitor[1].v") - 0.1 * (1 - np.exp(-t / 10))).max() < 1e-5     # of 0.1 V


def test_the_msl_cccv_charging_example_has_its_two_rc_elements(monkeypatch):
    """CCCVcharging passes its cell record (ExampleData, whose extends modifier sets nRC = 2 and
    the RC elements' R and C) whole to the stack; rumoca sized the stack's RC elements by the
    record class's default (unbalanced by 10). The overlay passes it member by member: two RC
    elements of time constants 60 s and 10 s (R = 0.2 Ri and 0.1 Ri, Ri = 4.2/1200 Ohm), each
    capacitor following C dv/dt = i - v/R with the stack's current."""
    monkeypatch.setenv("MODELICAPATH", str(MSL))
    v, R = ["battery.capacitor[1].v", "battery.capacitor[2].v"], ["battery.resistor[1].R_actual", "battery.resistor[2].R_actual"]
    names = [*v, *R, "battery.r0.i", "battery.cellData.rcData[1].R", "battery.cellData.rcData[1].C",
             "battery.cellData.rcData[2].R", "battery.cellData.rcData[2].C"]
    model = mcl.compile_model([], "Modelica.Electrical.Batteries.Examples.CCCVcharging").with_outputs(names, only=True)
    assert model.ode.y_names == names
    t = np.linspace(0.0, 600.0, 6001)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    y = {n: res.output(n) for n in names}
    Ri = 4.2 / 1200
    for k, (share, tau) in enumerate(((0.2, 60.0), (0.1, 10.0)), 1):
        Rk, Ck = y[f"battery.cellData.rcData[{k}].R"][0], y[f"battery.cellData.rcData[{k}].C"][0]
        assert Rk == pytest.approx(share * Ri) and Rk * Ck == pytest.approx(tau)
        vk, Rs = y[v[k - 1]], y[R[k - 1]]
        dv = np.gradient(vk, t)
        inside = slice(10, -10)     # (the charger's switch from constant current to voltage: a kink)
        assert np.abs(dv - (y["battery.r0.i"] * Rs - vk) / tau)[inside].max() < 1e-2 * np.abs(dv).max()


def test_water_conducts_heat_as_iapws_gives(tmp_path, monkeypatch):
    """IF97 water's thermal conductivity sets its local variables on only some branches (the
    scientific method's), which rumoca refuses; the overlay binds them at their declarations.
    Liquid water at 25 degC and 1 bar conducts 0.6065 W/(m K) (IAPWS 2011, its table of
    reference values); the industrial formulation the MSL uses is within 0.5 % of it."""
    out = _simulated(tmp_path, monkeypatch, """
model Conduction
  package Medium = Modelica.Media.Water.StandardWater;
  Real x(start = 0, fixed = true);
  output Real lambda = Medium.thermalConductivity(Medium.setState_pT(1e5, 298.15));
equation
  der(x) = 1;
end Conduction;
""", "Conduction", np.linspace(0.0, 1.0, 3))[1].output
    assert abs(out("lambda")[0] - 0.6065) < 0.005 * 0.6065


def test_moist_air_has_the_gas_constant_of_its_mixture(tmp_path, monkeypatch):
    """MoistAir reads the gas constants of its package's constant records (dry air's and
    steam's R_s), which rumoca does not resolve; the overlay names their values. Air with 1 %
    steam by mass: R = 0.99 x 287.05 + 0.01 x 461.52 J/(kg K) (R / M of each gas)."""
    out = _simulated(tmp_path, monkeypatch, """
model MoistGas
  package Medium = Modelica.Media.Air.MoistAir;
  Real x(start = 0, fixed = true);
  output Real R = Medium.gasConstant(Medium.setState_pTX(1e5, 300, {0.01, 0.99}));
equation
  der(x) = 1;
end MoistGas;
""", "MoistGas", np.linspace(0.0, 1.0, 3))[1].output
    R = 8.314472        # J/(mol K), CODATA 2006, as the MSL's gas records were computed with
    assert abs(out("R")[0] - (0.99 * R / 0.0289651159 + 0.01 * R / 0.01801528)) < 1e-6 * 288.8


BLOWDOWN = """
model Blowdown "a bottle of nitrogen emptied through a valve"
  import Modelica.Fluid.Vessels.ClosedVolume;
  import Modelica.Fluid.Valves.ValveLinear;
  replaceable package Medium = Modelica.Media.IdealGases.SingleGases.N2;
  inner Modelica.Fluid.System system;
  ClosedVolume bottle(redeclare package Medium = Medium, V = 1, nPorts = 1, use_portsData = false,
    p_start = 2e5, T_start = 300);
  ValveLinear valve(redeclare package Medium = Medium, dp_nominal = 1e5, m_flow_nominal = 0.1);
  Modelica.Fluid.Sources.Boundary_pT outside(redeclare package Medium = Medium, nPorts = 1, p = 1e5, T = 300);
  Modelica.Blocks.Sources.Constant open(k = 1);
  output Real p = bottle.medium.p;
  output Real T = bottle.medium.T;
equation
  connect(bottle.ports[1], valve.port_a);
  connect(valve.port_b, outside.ports[1]);
  connect(open.y, valve.opening);
end Blowdown;
"""


@pytest.mark.parametrize("medium, R, cp", [("IdealGases.SingleGases.N2", 8.314472 / 0.0280134, 1040.0),
                                           ("Air.DryAirNasa", 8.314472 / 0.0289651159, 1005.5)])
def test_a_bottle_of_ideal_gas_blows_down_as_its_energy_balance_says(tmp_path, monkeypatch, medium, R, cp):
    """The NASA ideal gases read the members of their package's constant data records (data.R_s,
    data.MM, ...), which rumoca does not resolve; the overlay reads them through functions. A
    1 m3 bottle at 2 bar and 300 K empties through a linear valve (0.1 kg/s per bar) to 1 bar:
    dm/dt = -w, m cv dT/dt = -w R T (adiabatic), p = m R T / V, with cp near 300 K constant
    (the NASA polynomials' cp moves by 0.2 % between 240 and 300 K)."""
    from scipy.integrate import solve_ivp

    t = np.linspace(0.0, 60.0, 13)
    out = _simulated(tmp_path, monkeypatch, BLOWDOWN.replace("IdealGases.SingleGases.N2", medium),
                     "Blowdown", t)[1].output

    def rhs(_, x):
        m, T = x
        w = 0.1 * (m * R * T - 1e5) / 1e5
        return [-w, -w * R * T / (m * (cp - R))]

    m, T = solve_ivp(rhs, (0, 60), [2e5 / (R * 300), 300.0], t_eval=t, rtol=1e-10, atol=1e-12).y
    assert np.allclose(out("p"), m * R * T, rtol=1e-3)
    assert np.allclose(out("T"), T, atol=0.2)
    assert out("T")[-1] < 250            # (the gas left behind has cooled by 50 K)


ROOM = """
model Room "a room of moist air that holds CO2, open to the outside"
  import Modelica.Fluid.Sources.FixedBoundary;
  import Modelica.Fluid.Vessels.ClosedVolume;
  package Medium = Modelica.Media.Air.MoistAir(extraPropertiesNames = {"CO2"}, C_nominal = {1.519e-3});
  inner Modelica.Fluid.System system;
  ClosedVolume room(redeclare package Medium = Medium, V = 100, nPorts = 1, use_portsData = false,
    X_start = {0.01, 0.99}, C_start = {1.519e-3}, energyDynamics = Modelica.Fluid.Types.Dynamics.FixedInitial);
  FixedBoundary outside(redeclare package Medium = Medium, nPorts = 1);
  output Real C = room.C[1];
  output Real m = room.m;
  output Real Xw = room.medium.Xi[1];
  output Real T = room.medium.T;
equation
  connect(room.ports[1], outside.ports[1]);
end Room;
"""


def test_a_room_of_moist_air_holding_co2_starts_where_its_initial_equations_say(tmp_path, monkeypatch):
    """MoistAir modified for one trace substance, in the fluid library's boundary and vessel:
    rumoca refuses their for-equations on arrays of one element (one mass fraction of water,
    one trace substance; written element by element) and resolves the inherited enthalpy
    function's call in PartialMedium (what it computes written in place). The vessel's states,
    mass and energy, start at 0, where moist air's specific energy U/m is 0/0: its temperature,
    humidity and CO2 are still those its initial equations give, and it holds p V / (R T) of
    air, R moist air's gas constant, which it keeps at rest. Its port is open (its regularFlow
    a tie, 0 >= 0, read as true: see the ventilated room below) and joined straight to the
    boundary, so the boundary fixes its pressure: its mass is then no state of its own (index
    reduction)."""
    t = np.linspace(0.0, 3600.0, 13)
    out = _simulated(tmp_path, monkeypatch, ROOM, "Room", t)[1].output
    R = 0.99 * 287.0512249529787 + 0.01 * 461.5233290850878
    np.testing.assert_allclose(out("T"), 293.15, rtol=1e-9)
    np.testing.assert_allclose(out("Xw"), 0.01, rtol=1e-9)
    np.testing.assert_allclose(out("C"), 1.519e-3, rtol=1e-9)
    np.testing.assert_allclose(out("m"), 101325.0 * 100 / (R * 293.15), rtol=1e-6)


VENTILATED = """
model VentilatedRoom "a room of moist air ventilated by a fan bringing in CO2, the air leaving through a duct"
  import Modelica.Fluid.Sources.{FixedBoundary, MassFlowSource_T};
  import Modelica.Fluid.Vessels.ClosedVolume;
  import Modelica.Fluid.Pipes.StaticPipe;
  import Modelica.Fluid.Types.Dynamics;
  package Medium = Modelica.Media.Air.MoistAir(extraPropertiesNames = {"CO2"}, C_nominal = {1.519e-3});
  inner Modelica.Fluid.System system(energyDynamics = Dynamics.FixedInitial, massDynamics = Dynamics.FixedInitial);
  MassFlowSource_T fan(redeclare package Medium = Medium, m_flow = 0.1, T = 293.15, X = {0.01, 0.99},
    C = {3e-3}, nPorts = 1);
  ClosedVolume room(redeclare package Medium = Medium, V = 100, nPorts = 2, use_portsData = false,
    X_start = {0.01, 0.99}, C_start = {1.519e-3});
  StaticPipe duct(redeclare package Medium = Medium, length = 2, diameter = 0.15);
  FixedBoundary outside(redeclare package Medium = Medium, nPorts = 1);
  output Real C = room.C[1];
  output Real m = room.m;
  output Real T = room.medium.T;
  output Real m_flow = duct.port_a.m_flow;
  output Real dp = room.medium.p - outside.p;
equation
  connect(fan.ports[1], room.ports[1]);
  connect(room.ports[2], duct.port_a);
  connect(duct.port_b, outside.ports[1]);
end VentilatedRoom;
"""


def test_a_ventilated_room_fills_with_the_fans_co2_and_blows_it_out_through_its_duct(tmp_path, monkeypatch):
    """A fan blows 0.1 kg/s of air carrying 3e-3 CO2 into a room of 100 m3 (its ports without
    port data: both at the bottom, as the vessel's fluid level), and the air leaves through a
    duct. The vessel's regularFlow = fluidLevel >= portsData_height is 0 >= 0: held from a start
    of false, it shut the ports, the initial equations had no solution and the room started
    empty; it is constant in time and now read as the parameters make it. The room is well
    mixed: C = C_in + (C0 - C_in) exp(-m_flow t / m), its mass p V / (R T); the duct carries
    the fan's flow and drops the pressure Darcy-Weisbach gives with Swamee and Jain's friction
    factor (the MSL's Detailed wall friction in the turbulent regime; air's viscosity at 20 degC)."""
    t = np.linspace(0.0, 3600.0, 13)
    out = _simulated(tmp_path, monkeypatch, VENTILATED, "VentilatedRoom", t)[1].output
    R = 0.99 * 287.0512249529787 + 0.01 * 461.5233290850878
    m0 = 101325.0 * 100 / (R * 293.15)
    np.testing.assert_allclose(out("m")[0], m0, rtol=1e-6)
    np.testing.assert_allclose(out("C"), 3e-3 + (1.519e-3 - 3e-3) * np.exp(-0.1 * t / m0), rtol=1e-4)
    np.testing.assert_allclose(out("T"), 293.15, atol=5e-3)          # (the fan's air, a little compressed)
    np.testing.assert_allclose(out("m_flow")[-1], 0.1, rtol=1e-5)
    rho, D, L, mu = 101325.0 / (R * 293.15), 0.15, 2.0, 1.82e-5
    v = 0.1 / (rho * np.pi * D**2 / 4)
    lam = 0.25 / np.log10(2.5e-5 / D / 3.7 + 5.74 / (rho * v * D / mu) ** 0.9) ** 2
    np.testing.assert_allclose(out("dp")[-1], lam * L / D * rho * v**2 / 2, rtol=0.02)


PROBE = """
model Probe "a trace substance sensor at a boundary of air carrying two"
  package Medium = Modelica.Media.Air.SimpleAir(extraPropertiesNames = {"CO2", "H2O"});
  inner Modelica.Fluid.System system;
  Modelica.Fluid.Sources.FixedBoundary air(redeclare package Medium = Medium, C = {1e-3, 7e-3}, nPorts = 1);
  Modelica.Fluid.Sensors.TraceSubstances sensor(redeclare package Medium = Medium, substanceName = "H2O");
  Real x(start = 0, fixed = true);
  output Real C = sensor.C;
equation
  der(x) = 1;
  connect(sensor.port, air.ports[1]);
end Probe;
"""


def test_a_trace_substance_sensor_finds_its_substance_by_name(tmp_path, monkeypatch):
    """The sensor's initial algorithm finds its substance among the medium's names with
    Strings.isEqual (compared at compile time: both are constant strings) and reads that one."""
    out = _simulated(tmp_path, monkeypatch, PROBE, "Probe", np.linspace(0.0, 1.0, 3))[1].output
    np.testing.assert_allclose(out("C"), 7e-3, rtol=1e-12)


def test_a_head_curve_fitted_through_four_points_is_numpys_least_squares_fit(tmp_path, monkeypatch):
    """Polynomials.fitting builds its Vandermonde matrix column by column, which rumoca refuses,
    and solves by LAPACK's least squares; the overlay builds it as one comprehension and solves
    the normal equations. A quadratic head curve through four measured points (more points than
    coefficients) is NumPy's polyfit, along a flow ramp."""
    t = np.linspace(0.0, 2.0, 9)
    q_points, h_points = [0.0, 0.4, 0.8, 1.2], [10.0, 9.1, 6.9, 2.8]
    state = _run(tmp_path, monkeypatch, """
model HeadCurve "a pump's head curve fitted from four operating points"
  import Modelica.Math.Polynomials;
  parameter Real V_flow[4] = {0, 0.4, 0.8, 1.2} "measured flows";
  parameter Real head[4] = {10, 9.1, 6.9, 2.8} "measured heads";
  final parameter Real c[3] = Polynomials.fitting(V_flow, head, 2);
  Real q(start = 0, fixed = true) "flow";
  Real h(start = 10, fixed = true) "head, integrated along the ramp";
equation
  der(q) = 0.5;
  der(h) = 0.5 * Polynomials.derivativeValue(c, q);
end HeadCurve;
""", "HeadCurve", t)
    c = np.polyfit(q_points, h_points, 2)
    assert np.allclose(state("h"), np.polyval(c, 0.5 * t) - np.polyval(c, 0.0) + 10.0, atol=1e-6)


def test_the_msls_fmu_adaptors_example_moves_two_coupled_inertias_as_one(monkeypatch):
    """Rotational.Examples.GenerationOfFMUs: its angle adaptor holds two protected functions
    named ``position`` (of 2 and of 3 values); rumoca called the wrong one ("axis 1 requires
    extent 2 but the call site proves 3"), and the overlay renames one. The example's first
    part drives an inertia (1.1 kg m²) by 10 sin(4 pi t) N m, a second (2.2) moved with it
    through the adaptors: together one inertia of 3.3, whose angle is
    10/(3.3 (4 pi)) (t - sin(4 pi t)/(4 pi))."""
    monkeypatch.setenv("MODELICAPATH", str(MSL))
    model = mcl.compile_model([], "Modelica.Mechanics.Rotational.Examples.GenerationOfFMUs")
    t = np.linspace(0.0, 1.0, 11)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    w = 4 * np.pi
    truth = 10 / (3.3 * w) * (t - np.sin(w * t) / w)
    v = probed(model, res)
    np.testing.assert_allclose(v["directInertia.phi"], truth, atol=1e-6 * truth.max())
    np.testing.assert_allclose(v["inverseInertia.phi"], truth, atol=1e-6 * truth.max())
