"""Forward sensitivities of the in-process engine against central finite differences."""
import numpy as np

from helpers import compiled, msl_path, multisine, needs_msl, rel_err, series
from mcl.api import compile_model, simulate

OPTS = {"rtol": 1e-12, "atol": 1e-14}  # finite differences need it: their noise is rtol / h


def finite_difference(model, u, name, value, h):
    up = simulate(model, u, {name: value + h}, options=OPTS).outputs
    down = simulate(model, u, {name: value - h}, options=OPTS).outputs
    return (up - down) / (2 * h)


def test_sensitivities_of_mass_spring_damper():
    model = compiled("MCL.Examples.MassSpringDamper")
    t = np.linspace(0, 10, 201)
    u = series(t, u=np.sin(1.3 * t) + 0.5)
    names = ["spring.c", "damper.d", "mass.m"]
    res = simulate(model, u, sensitivities=names, options=OPTS)
    assert res.sensitivity_names == names and res.sensitivities.shape == (201, 1, 3)
    for j, n in enumerate(names):
        fd = finite_difference(model, u, n, model.parameters[n], 1e-3)
        assert rel_err(res.sensitivities[:, :, j], fd) < 1e-5


def test_sensitivity_through_algebraic_loop_and_index_reduction(cauer):
    t = np.linspace(0, 20, 201)
    u = series(t, u=multisine(t))
    res = simulate(cauer, u, sensitivities=["Rnl.w3", "c3"], options=OPTS)
    assert res.ok
    for j, n in enumerate(["Rnl.w3", "c3"]):
        fd = finite_difference(cauer, u, n, cauer.parameters[n], 1e-3 * cauer.parameters[n])
        assert rel_err(res.sensitivities[:, :, j], fd) < 1e-5


def test_newton_form_gives_the_solvers_derivatives(cauer):
    """The linearisation through the algebraic loop's Newton form (one solve per point, then SX
    algebra) equals the one through the solver's own derivatives."""
    import dataclasses

    import casadi as ca

    import mcl.sensitivity as sens

    assert cauer.ode.loops is not None and cauer.ode.given.is_a("SXFunction")
    t = np.linspace(0, 20, 201)
    u = series(t, u=multisine(t))
    res = simulate(cauer, u)
    params = ["Rnl.w3", "c3"]
    newton = sens.Linearisation(cauer, res.states, res.time, u, cauer.parameter_vector(), params)
    out = cauer.ode.out      # a new function object: the linearisation's cache knows the other
    args = out.mx_in()
    plain = dataclasses.replace(cauer.ode, loops=None, given=None, out=ca.Function("out", args, out.call(args)))
    solver = sens.Linearisation(type(cauer)(cauer.name, plain, cauer.info), res.states, res.time, u,
                                cauer.parameter_vector(), params)
    assert newton.fun.n_in() == 5 and solver.fun.n_in() == 4
    for a, b in zip(newton.jacobians(0, len(t)), solver.jacobians(0, len(t))):
        assert np.max(np.abs(a - b)) <= 1e-9 * (np.max(np.abs(b)) + 1e-12)


def test_the_low_rank_steps_equal_the_blocked_scan(monkeypatch):
    """The rule taken one step after another with a fixed matrix's factors and Woodbury's
    correction for the rows that vary (larger models) gives the blocked scan's sensitivities."""
    from mcl import sensitivity

    rng = np.random.default_rng(3)
    nx, ny, nq, N = 20, 2, 3, 700
    A0 = -np.diag(rng.uniform(1, 40, nx)) + 0.3 * rng.normal(size=(nx, nx))
    B, C, E = rng.normal(size=(N, nx, nq)), rng.normal(size=(N, ny, nx)), rng.normal(size=(N, ny, nq))
    S0 = rng.normal(size=(nx, nq))
    wobble = np.sin(np.linspace(0, 9, N))                     # a law varying along the run, in rows 3 and 7
    A = np.repeat(A0[None], N, 0)
    A[:, [3, 7], :] += 2.0 * wobble[:, None, None] * rng.normal(size=(2, nx))[None]

    class Along(sensitivity.Linearisation):
        def __init__(self):
            self.time, self.nx, self.ny, self.nq, self.chunk = np.linspace(0, 7, N), nx, ny, nq, 97

        def jacobians(self, k0, k1):
            return A[k0:k1], B[k0:k1], C[k0:k1], E[k0:k1]

        def initial(self):                                    # parameters that set the initial state
            return S0

    at = np.arange(0, N, 7)
    fast = Along().parameters(at)
    monkeypatch.setattr(sensitivity, "LOW_RANK_MIN_STATES", 10**9)
    blocked = Along().parameters(at)
    assert np.max(np.abs(fast - blocked)) < 1e-9 * np.max(np.abs(blocked))


INITIAL_STATE = """
model Heated "a body warming from a start temperature the engineer does not know"
  import Modelica.Units.SI;
  import Modelica.Thermal.HeatTransfer;
  Modelica.Blocks.Interfaces.RealInput Q(unit = "W") "heater power";
  Modelica.Blocks.Interfaces.RealOutput T(unit = "K") "measured temperature";
  parameter SI.Temperature T0 = 300 "temperature at the start";
  parameter SI.ThermalConductance G = 2.0;
  HeatTransfer.Components.HeatCapacitor body(C = 50);
  HeatTransfer.Components.ThermalConductor wall(G = G);
  HeatTransfer.Sources.FixedTemperature ambient(T = 293.15);
  HeatTransfer.Sources.PrescribedHeatFlow heater;
  HeatTransfer.Sensors.TemperatureSensor sensor;
initial equation
  body.T = T0;
equation
  connect(Q, heater.Q_flow);
  connect(heater.port, body.port);
  connect(body.port, wall.port_a);
  connect(wall.port_b, ambient.port);
  connect(body.port, sensor.port);
  connect(sensor.T, T);
end Heated;
"""


@needs_msl()
def test_a_parameter_of_an_initial_equation_has_its_sensitivity(tmp_path):
    """A parameter that only sets a state in an initial equation (T0 in body.T = T0) moves the
    outputs through the initial state: the fits' linearised sensitivities follow central finite
    differences for it as for a parameter of the equations (they were 0: the initial state's own
    dependence was dropped)."""
    from mcl.fit import FitProblem

    (tmp_path / "Heated.mo").write_text(INITIAL_STATE)
    model = compile_model([tmp_path / "Heated.mo"], "Heated", libraries=[msl_path()])
    t = np.linspace(0, 60, 301)
    u = series(t, Q=20 + 10 * np.sin(0.3 * t), T=np.zeros_like(t))
    names = ["T0", "G"]
    problem = FitProblem(model, u, names, options=OPTS)
    res = problem.simulate([300.0, 2.0], gradient=True)
    assert res.ok
    for j, (n, v) in enumerate(zip(names, [300.0, 2.0])):
        fd = finite_difference(model, u.select(["Q"]), n, v, 1e-3 * v)
        assert rel_err(res.sensitivities[:, :, j], fd) < 1e-3, n
    assert np.allclose(res.sensitivities[:, 0, 0], np.exp(-2.0 / 50 * t), atol=1e-3)


@needs_msl()
def test_the_parameters_only_initial_equations_read_are_told_apart(tmp_path):
    """T0 only sets the body's start (the calibration fits it after the physics); G and the
    capacitor's C are read by the equations of the run."""
    (tmp_path / "Heated.mo").write_text(INITIAL_STATE)
    model = compile_model([tmp_path / "Heated.mo"], "Heated", libraries=[msl_path()])
    assert "T0" in model.initial_parameters, model.parameters
    assert not {"G", "body.C", "wall.G"} & set(model.initial_parameters)


THERMOSTAT = """
model Thermostat "a room heated between two thresholds"
  parameter Real G = 20;
  parameter Real C = 2e4;
  parameter Real P = 1500;
  Real T(start = 290, fixed = true);
  Boolean on(start = true, fixed = true);
  input Real Ta;
  output Real y = T;
equation
  when T > 295 then
    on = false;
  elsewhen T < 293 then
    on = true;
  end when;
  C*der(T) = (if on then P else 0) - G*(T - Ta);
end Thermostat;
"""


def test_a_switching_systems_sensitivities_move_its_switching_times(tmp_path):
    """Each switch's time moves with the parameters (dtau/dp = -S/f- where T crosses its
    threshold), and past it the temperature's slope is another: its sensitivity jumps by
    (f- - f+) dtau/dp. Carried through unchanged (and, until stop 83, read at the integration
    points instead of the output points, which an event's detection points outnumber), the
    sensitivities of a thermostat's room were off by 100 % after the first switch."""
    (tmp_path / "Thermostat.mo").write_text(THERMOSTAT)
    model = compile_model([tmp_path / "Thermostat.mo"], "Thermostat")
    t = np.linspace(0, 2000, 41)          # about ten switches
    u = series(t, Ta=np.full(len(t), 280.0))
    res = simulate(model, u, sensitivities=["G", "P"])
    assert res.ok, res.reason
    for j, (name, h) in enumerate((("G", 1e-4), ("P", 1e-3))):
        fd = finite_difference(model, u, name, model.parameters[name], h)
        assert np.max(np.abs(res.sensitivities[:, :, j] - fd)) < 0.01 * np.max(np.abs(fd)), name


def test_the_linearisation_along_a_switching_run_jumps_at_its_switches(tmp_path):
    """The screening's and the fits' sensitivities come from the model linearised along one
    plain run (:class:`mcl.sensitivity.Linearisation`): the run reports the events where the
    right-hand side jumped, and the linearisation's sensitivities jump there as the engine's
    do, the grid step a switch falls in taken in two (within 0.4 %; without the switches
    60-110 % off, and 45 % with the trapezoidal rule across them)."""
    from mcl.sensitivity import Linearisation, fine_grid

    (tmp_path / "Thermostat.mo").write_text(THERMOSTAT)
    model = compile_model([tmp_path / "Thermostat.mo"], "Thermostat")
    t = np.linspace(0, 2000, 41)
    u = series(t, Ta=np.full(len(t), 280.0))
    fine, at = fine_grid(t, 8)
    run = simulate(model, u, t_out=fine, options=OPTS)
    assert run.ok and run.switched and len(run.switches) >= 8, run.switches
    fd = np.stack([finite_difference(model, u, n, model.parameters[n], h) for n, h in (("G", 1e-4), ("P", 1e-3))], -1)
    err = {}
    for name, switches in (("with", run.switches), ("without", [])):
        S = Linearisation(model, run.states, fine, u, model.parameter_vector(), ["G", "P"], switches).parameters(at)
        err[name] = [np.max(np.abs(S[:, :, j] - fd[:, :, j])) / np.max(np.abs(fd[:, :, j])) for j in range(2)]
    assert max(err["with"]) < 0.01 and min(err["without"]) > 0.3, err
