"""Algebraic loops: torn (tearing variables iterated, the rest computed from them), checked
against solutions computed without mcl."""
import numpy as np

from mcl import compile_model
from mcl.data import TimeSeries
from mcl.engine_casadi import CasadiEngine

from helpers import msl_path, needs_msl


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
    Checked against scipy with the junction solved by bracketing next to its last solution:
    below x = 0.97 the junction has three balances, and a run stays on the one it was on."""
    from scipy.integrate import solve_ivp
    from scipy.optimize import brentq

    (tmp_path / "Junction.mo").write_text(JUNCTION)
    model = compile_model([tmp_path / "Junction.mo"], "Junction")
    t = np.linspace(0, 2.5, 26)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    length = lambda x, p: max(np.sqrt((x - p) ** 2 + 0.01), 1e-3)

    last = [0.0]

    def rhs(_, y):
        x, v = y
        balance = (lambda q: (x - q) / length(x, q) * 4 * (length(x, q) - 1) - 2 * q ** 3)
        h = 1e-3
        while np.sign(balance(last[0] - h)) == np.sign(balance(last[0] + h)):
            h *= 2
        last[0] = p = brentq(balance, last[0] - h, last[0] + h)
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


OSCILLATOR = """
model RelaxationOscillator "an op-amp astable multivibrator: a Schmitt trigger charging its own capacitor"
  import Modelica.Electrical.Analog.Basic;
  import Modelica.Electrical.Analog.Ideal.IdealizedOpAmpLimited;
  import Modelica.Units.SI;
  parameter SI.Resistance R = 1000 "charging resistor";
  parameter SI.Resistance R1 = 1000 "feedback divider, to ground";
  parameter SI.Resistance R2 = 2000 "feedback divider, from the output";
  parameter SI.Capacitance C = 1e-5;
  IdealizedOpAmpLimited opAmp(Vps = 15, Vns = -15,
    homotopyType = Modelica.Blocks.Types.LimiterHomotopy.LowerLimit);
  Basic.Resistor r(R = R);
  Basic.Resistor r1(R = R1);
  Basic.Resistor r2(R = R2);
  Basic.Capacitor c(C = C, v(start = 1, fixed = true));
  Basic.Ground ground;
  Modelica.Blocks.Interfaces.RealOutput vc "capacitor voltage";
equation
  connect(opAmp.out, r.p);
  connect(r.n, c.p);
  connect(c.n, ground.p);
  connect(opAmp.in_n, c.p);
  connect(opAmp.out, r2.p);
  connect(r2.n, opAmp.in_p);
  connect(r1.p, opAmp.in_p);
  connect(r1.n, ground.p);
  vc = c.v;
end RelaxationOscillator;
"""


@needs_msl()
def test_a_relaxation_oscillator_keeps_its_amplifier_on_its_branch(tmp_path, monkeypatch):
    """The amplifier's limits are noEvent branches of an algebraic loop with positive feedback:
    between its thresholds +-15 R1/(R1 + R2) it has three solutions, and solved anew it flips
    back to the branch just left (the solver chatters there). Held on the branch it is on
    (``HOLD_BRANCHES``), the capacitor swings between the thresholds with the textbook period
    2 R C ln((1 + k)/(1 - k)), k = R1/(R1 + R2)."""
    from mcl.compile import structure

    monkeypatch.setenv("MODELICAPATH", str(msl_path()))
    monkeypatch.setattr(structure, "HOLD_BRANCHES", True)       # (off by default: its cost)
    monkeypatch.setenv("MCL_CACHE_DIR", str(tmp_path / "cache"))
    (tmp_path / "RelaxationOscillator.mo").write_text(OSCILLATOR)
    model = compile_model([tmp_path / "RelaxationOscillator.mo"], "RelaxationOscillator")
    t = np.linspace(0, 0.15, 3001)
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []))
    assert res.ok, res.reason
    vc = res.outputs[:, 0]
    k = 1000 / 3000
    assert abs(vc[t > 0.03].max() - 15 * k) < 0.01 and abs(vc[t > 0.03].min() + 15 * k) < 0.01
    i = np.flatnonzero((vc[1:] > 0) & (vc[:-1] <= 0))       # upward zero crossings, one a period
    up = t[i] - vc[i] * (t[i + 1] - t[i]) / (vc[i + 1] - vc[i])
    period = 2 * 1000 * 1e-5 * np.log((1 + k) / (1 - k))
    assert len(up) >= 5
    assert np.abs(np.diff(up) - period).max() < 1e-3 * period
