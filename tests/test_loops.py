"""Algebraic loops: torn (tearing variables iterated, the rest computed from them), checked
against solutions computed without mcl."""
import numpy as np

from mcl import compile_model
from mcl.data import TimeSeries
from mcl.engine_casadi import CasadiEngine


JUNCTION = """
model Junction "a mass on a spring whose other end meets a cubic damper at a massless point p"
  parameter Real k = 4 "spring";
  parameter Real c = 2 "damper at the junction";
  Real x(start = 2, fixed = true) "mass position";
  Real v(start = 0, fixed = true);
  Real p "junction position";
  Real L "spring length";
  Real f "spring force";
  Real e "direction";
equation
  der(x) = v;
  der(v) = -f*e;
  L = max(sqrt((x - p)^2 + 0.01), 1e-3);
  f = k*(L - 1);
  e = (x - p)/L;
  0 = e*f - c*p^3;
end Junction;
"""


def test_a_torn_loop_never_divides_by_an_unknowns_start_value(tmp_path):
    """The loop (p, L, f, e) torn on p: L, f and e are computed from it, so Newton's method never
    starts at L = 0 dividing (x - p); on the whole loop it does, and the first step fails.
    Checked against scipy with the junction solved by bracketing."""
    from scipy.integrate import solve_ivp
    from scipy.optimize import brentq

    (tmp_path / "Junction.mo").write_text(JUNCTION)
    model = compile_model([tmp_path / "Junction.mo"], "Junction")
    t = np.linspace(0, 2.5, 26)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    length = lambda x, p: max(np.sqrt((x - p) ** 2 + 0.01), 1e-3)

    def rhs(_, y):
        x, v = y
        p = brentq(lambda q: (x - q) / length(x, q) * 4 * (length(x, q) - 1) - 2 * q ** 3, -10, 10)
        return [v, -4 * (length(x, p) - 1) * (x - p) / length(x, p)]

    ref = solve_ivp(rhs, (0, 2.5), [2, 0], t_eval=t, rtol=1e-10, atol=1e-12).y
    assert np.abs(res.states[:, model.ode.x_names.index("x")] - ref[0]).max() < 2e-5


def test_a_loop_started_at_a_singularity_is_solved_from_next_to_it(tmp_path):
    """A resistor in series with a square-root element, R i + sqrt(|i|) = 2 + t, with i's start
    value 0, where the loop's Jacobian is infinite: Newton's method has no step there, and its
    fallback starts a hair off the start value. The charge x = int i dt matches quadrature of
    the closed form sqrt(i) = (sqrt(1 + 4 (2 + t)) - 1)/2."""
    from scipy.integrate import quad

    (tmp_path / "Sq.mo").write_text("""
model Sq
  parameter Real R = 1;
  Real i(start = 0);
  Real v;
  Real x(start = 0, fixed = true);
equation
  v = sqrt(abs(i));
  R*i + v = 2 + time;
  der(x) = i;
end Sq;
""")
    model = compile_model([tmp_path / "Sq.mo"], "Sq")
    t = np.linspace(0, 2, 11)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    current = lambda s: ((np.sqrt(1 + 4 * (2 + s)) - 1) / 2) ** 2
    ref = [quad(current, 0, s)[0] for s in t]
    assert np.abs(res.states[:, model.ode.x_names.index("x")] - ref).max() < 1e-4      # of 3.4 (the default tolerances)
