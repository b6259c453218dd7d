"""State selection: variables declared ``stateSelect = prefer`` that the balances would leave to
a nonlinear loop become states, as in Modelica tools. Checked against a solution computed
without mcl."""
import numpy as np

from helpers import probed
from mcl import compile_model
from mcl.data import TimeSeries
from mcl.engine_casadi import CasadiEngine
from mcl.simulation import SimulationOptions


TANK = """
model HeatedTank "gas filled through a valve and heated, the heater turned down above 350 K; its
  heat capacity grows with temperature"
  parameter Real V = 0.1 "volume";
  parameter Real R = 287 "gas constant";
  parameter Real c0 = 700 "u = c0*T + c1*T^2";
  parameter Real c1 = 0.5;
  parameter Real k = 2e-6 "valve conductance";
  parameter Real p_in = 5e5;
  parameter Real T_in = 300;
  parameter Real Q_max = 200 "heater";
  parameter Real T_turn = 350 "heater turned down above";
  Real m "mass";
  Real U "internal energy";
  Real p(%s start = 1e5) "pressure";
  Real T(%s start = 300) "temperature";
  Real u "specific internal energy";
  Real mdot "inflow";
  Real Q "heat flow";
initial equation
  p = 1e5;
  T = 300;
equation
  der(m) = mdot;
  der(U) = mdot*(c0*T_in + c1*T_in^2 + R*T_in) + Q;
  Q = if T > T_turn then Q_max/2 else Q_max;
  mdot = k*(p_in - p);
  m = p*V/(R*T);
  u = c0*T + c1*T^2;
  U = m*u;
end HeatedTank;
"""

PREFER = "stateSelect = StateSelect.prefer,"


def _reference(t):
    """(m, T) of the tank integrated in mass and energy, the temperature from the caloric law's
    root, the heater turned down where the temperature crosses 350 K (scipy, an event)."""
    from scipy.integrate import solve_ivp

    V, R, c0, c1, k, p_in, T_in, Q_max = 0.1, 287, 700, 0.5, 2e-6, 5e5, 300, 200
    temperature = lambda y: (-c0 + np.sqrt(c0 ** 2 + 4 * c1 * y[1] / y[0])) / (2 * c1)     # noqa: E731

    def rhs(Q):
        def f(_, y):
            mdot = k * (p_in - y[0] * R * temperature(y) / V)
            return [mdot, mdot * (c0 * T_in + c1 * T_in ** 2 + R * T_in) + Q]
        return f

    def hot(_, y):
        return temperature(y) - 350
    hot.terminal, hot.direction = True, 1
    m0 = 1e5 * V / (R * 300)
    y0 = [m0, m0 * (c0 * 300 + c1 * 300 ** 2)]
    first = solve_ivp(rhs(Q_max), (t[0], t[-1]), y0, events=hot, rtol=1e-11, atol=1e-11, dense_output=True)
    t_hot = first.t_events[0][0]
    second = solve_ivp(rhs(Q_max / 2), (t_hot, t[-1]), first.y_events[0][0], rtol=1e-11, atol=1e-11,
                       dense_output=True)
    y = np.where(t <= t_hot, first.sol(np.minimum(t, t_hot)), second.sol(np.maximum(t, t_hot)))
    return y[0], temperature(y)


def _compiled(tmp_path, declared: str):
    (tmp_path / "HeatedTank.mo").write_text(TANK % (declared, declared))
    return compile_model([tmp_path / "HeatedTank.mo"], "HeatedTank")


def test_a_preferred_variable_a_loop_would_solve_for_is_integrated_as_a_state(tmp_path):
    """Temperature from mass and energy is a Newton solve (the caloric law is quadratic) whose
    result decides an event (the heater turned down); declared preferred, temperature is a
    state, the loop is gone, and the run matches scipy's."""
    model = _compiled(tmp_path, PREFER)
    ode = model.ode
    assert "T" in ode.x_names
    assert ode.nonlinear_blocks == 0
    t = np.linspace(0, 200, 41)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []),
                                  options=SimulationOptions(rtol=1e-9, atol=1e-9))
    assert res.ok, res.reason
    m_ref, T_ref = _reference(t)
    at = probed(model, res)
    m, T = at["m"], at["T"]
    assert np.abs(m / m_ref - 1).max() < 1e-6
    assert np.abs(T / T_ref - 1).max() < 1e-6
    assert T_ref[-1] - T_ref[0] > 20          # (it moved: the check is not of a constant)


def test_without_the_declaration_the_balances_states_and_their_loop_are_kept(tmp_path):
    """The same tank with no stateSelect: mass and energy are the states, temperature a loop."""
    model = _compiled(tmp_path, "")
    assert "T" not in model.ode.x_names
    assert model.ode.nonlinear_blocks >= 1
