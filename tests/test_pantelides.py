"""Index reduction where CasADi's own fails: a variable differentiated twice that is not a
state (a multibody chain's joint quantities; here a pendulum whose length is constrained through
an algebraic r2). mcl's Pantelides gives the same reduced DAE as CasADi's where that works."""
import casadi as ca
import numpy as np
from scipy.integrate import solve_ivp

from mcl import compile_model, simulate
from mcl.compile.pantelides import reduce_index
from mcl.data import TimeSeries

PENDULUM = """
model CartPendulum "a pendulum in Cartesian coordinates; its length constrained through r2"
  parameter Real L = 1, g = 9.81;
  Real x(start = 1, fixed = true), y(start = 0), vx(start = 0, fixed = true), vy, lam, r2(start = 1);
  output Real xo = x;
equation
  der(x) = vx;
  der(y) = vy;
  der(vx) = -lam*x;
  der(vy) = -lam*y - g;
  r2 = x^2 + y^2;
  sqrt(r2) = L;
end CartPendulum;
"""


def test_a_twice_differentiated_algebraic_is_reduced_and_the_pendulum_swings(tmp_path):
    (tmp_path / "CartPendulum.mo").write_text(PENDULUM)
    model = compile_model([tmp_path / "CartPendulum.mo"], "CartPendulum")
    assert model.ode.index == 3
    t = np.linspace(0.0, 2.0, 201)
    res = simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    # released horizontally at rest: theta'' = -g cos(theta) (L = 1), x = cos(theta)
    theta = solve_ivp(lambda _t, s: [s[1], -9.81 * np.cos(s[0])], (0, 2), [0.0, 0.0], t_eval=t,
                      rtol=1e-11, atol=1e-12).y[0]
    assert np.max(np.abs(res.output("xo") - np.cos(theta))) < 1e-4


def _cartesian_pendulum():
    x, y, vx, vy = (ca.SX.sym(n) for n in ("x", "y", "vx", "vy"))
    dx, dy, dvx, dvy = (ca.SX.sym("d" + n) for n in ("x", "y", "vx", "vy"))
    lam, t, g = ca.SX.sym("lam"), ca.SX.sym("t"), ca.SX.sym("g")
    alg = ca.vertcat(dx - vx, dy - vy, dvx + lam * x, dvy + lam * y + g, x**2 + y**2 - 1)
    return dict(x_impl=ca.vertcat(x, y, vx, vy), dx_impl=ca.vertcat(dx, dy, dvx, dvy), z=lam, alg=alg,
                t=t, p=g)


def test_the_reduced_dae_is_casadis_where_casadis_works():
    impl = _cartesian_pendulum()
    theirs, their_stats = ca.dae_reduce_index(impl, {})
    ours, our_stats = reduce_index(impl)
    assert our_stats["index"] == their_stats["index"] == 3
    for key in ("x", "x_impl", "z", "I"):
        assert ca.is_equal(ca.simplify(ours[key]), ca.simplify(theirs[key]), 5), key
    # the same equations, up to their order and the names of the new derivatives
    values = []
    for red in (theirs, ours):
        syms = sorted(ca.symvar(ca.vertcat(red["alg"], red["I"])), key=lambda s: s.name())
        point = np.random.default_rng(0).normal(size=len(syms))
        values.append(np.sort(np.array(ca.Function("f", syms, [red["alg"]])(*point)).ravel()))
    np.testing.assert_allclose(values[0], values[1], rtol=1e-12)


ZERO_CAP = """
package Circuit
  connector Pin
    Real v;
    flow Real i;
  end Pin;
  model Capacitor
    parameter Real C(unit = "F");
    Real v(start = 0);
    Real i;
    Pin p, n;
  equation
    v = p.v - n.v;
    i = p.i;
    0 = p.i + n.i;
    i = C*der(v);
  end Capacitor;
  model Resistor
    parameter Real R(unit = "Ohm") = 1;
    Pin p, n;
  equation
    p.v - n.v = R*p.i;
    0 = p.i + n.i;
  end Resistor;
  model Source
    input Real u;
    Pin p, n;
  equation
    p.v - n.v = u;
    0 = p.i + n.i;
  end Source;
  model Ground
    Pin p;
  equation
    p.v = 0;
  end Ground;
  model LowPass "an RC low pass; a parasitic capacitance switched off the way the MSL's
    NOR gate examples do it: final C = CapVal, CapVal = 0 evaluated"
    parameter Real CapVal = 0 annotation(Evaluate = true);
    input Real u;
    output Real y = c.v;
    Source s(u = u);
    Resistor r(R = 1);
    Capacitor c(C = 1, v(fixed = true));
    Capacitor parasitic(final C = CapVal);
    Ground g;
  equation
    connect(s.p, r.p);
    connect(r.n, c.p);
    connect(r.n, parasitic.p);
    connect(c.n, g.p);
    connect(parasitic.n, g.p);
    connect(s.n, g.p);
  end LowPass;
end Circuit;
"""


def test_a_capacitance_evaluated_to_zero_is_no_term_and_its_voltage_no_state(tmp_path):
    """A parameter the model evaluates (Evaluate = true, or final and bound to one) is a constant
    of its structure, as in other tools: C*der(v) with C = 0 is no term at all, so der(v) is not
    solved from a singular system (before: the least-squares fallback let the voltages drift
    apart, 0.03 V per second in the MSL's HeatingNPN_NORGate). Neither is a parameter to fit."""
    (tmp_path / "Circuit.mo").write_text(ZERO_CAP)
    model = compile_model([tmp_path / "Circuit.mo"], "Circuit.LowPass")
    assert "CapVal" not in model.ode.p_names and "parasitic.C" not in model.ode.p_names
    assert "c.C" in model.ode.p_names and "r.R" in model.ode.p_names
    t, fine = np.linspace(0, 5, 51), np.linspace(0, 5, 5001)     # (sin sampled finely: a line between)
    res = simulate(model, TimeSeries(fine, np.sin(fine)[:, None], ["u"]), t_out=t)
    assert res.ok, res.reason
    exact = (np.sin(t) - np.cos(t) + np.exp(-t)) / 2      # v' = u - v, v(0) = 0
    assert np.max(np.abs(res.output("y") - exact)) < 1e-5
