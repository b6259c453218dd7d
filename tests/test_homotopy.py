"""homotopy(actual, simplified): the model is the actual one, and an algebraic loop with several
solutions starts on the one the simplified model leads to, as Modelica's initialisation by
homotopy does. Without it Newton's method from the start values picks whichever solution is
nearest them: a Schmitt trigger's amplifier at its unstable middle, and the oscillator never
starts."""
import numpy as np

from helpers import msl_path, needs_msl
from mcl import compile_model, simulate
from mcl.data import TimeSeries

BISTABLE = """
model Bistable "y^3 - 3 y = 0.1 x has three solutions; the simplified y = 2 leads to the largest"
  Real x(start = 1, fixed = true);
  Real y(start = 0);
  output Real yo = y;
equation
  der(x) = -x;
  0 = {law};
end Bistable;
"""

MULTIVIBRATOR = """
model Flasher "an astable multivibrator: a Schmitt trigger fed back through R and C"
  import Modelica.Electrical.Analog.Basic;
  import Modelica.Electrical.Analog.Ideal.IdealizedOpAmpLimited;
  import Modelica.Blocks.Types.LimiterHomotopy;
  parameter Real f = 50 "designed frequency";
  parameter Real R1 = 2000, R2 = 1000, R = 10000;
  parameter Real C = 1/f/(2*R*log(1 + 2*R1/R2));
  IdealizedOpAmpLimited amp(Vps = 12, Vns = -12, homotopyType = LimiterHomotopy.LowerLimit);
  Basic.Ground ground;
  Basic.Resistor r1(R = R1);
  Basic.Resistor r2(R = R2);
  Basic.Resistor r(R = R);
  Basic.Capacitor c(C = C, v(start = 0.5, fixed = true));
  output Real vc = c.v;
equation
  connect(amp.out, r.p);
  connect(r.n, c.p);
  connect(c.n, ground.p);
  connect(r.n, amp.in_n);
  connect(amp.out, r2.p);
  connect(r2.n, amp.in_p);
  connect(amp.in_p, r1.p);
  connect(r1.n, ground.p);
end Flasher;
"""


def _run(model, t_end, n):
    t = np.linspace(0.0, t_end, n)
    res = simulate(model, TimeSeries(t, np.zeros((n, 0)), []), t_out=t)
    assert res.ok, res.reason
    return t, res


def test_a_loop_with_three_solutions_starts_where_its_simplified_law_leads(tmp_path):
    starts = {}
    for case, law in (("plain", "y^3 - 3*y - 0.1*x"),
                      ("homotopy", "homotopy(actual = y^3 - 3*y - 0.1*x, simplified = y - 2)")):
        (tmp_path / "Bistable.mo").write_text(BISTABLE.format(law=law))
        model = compile_model([tmp_path / "Bistable.mo"], "Bistable")
        t, res = _run(model, 1.0, 11)
        y, x = res.output("yo"), np.exp(-t)
        assert np.max(np.abs(y**3 - 3 * y - 0.1 * x)) < 1e-6      # the actual law holds throughout
        starts[case] = y[0]
    assert abs(starts["plain"]) < 0.1                  # nearest the start value 0
    assert abs(starts["homotopy"] - 1.75) < 0.02       # sqrt(3) + a little: the branch from y = 2


@needs_msl()
def test_a_schmitt_trigger_multivibrator_oscillates_at_its_designed_frequency(tmp_path):
    (tmp_path / "Flasher.mo").write_text(MULTIVIBRATOR)
    model = compile_model([tmp_path / "Flasher.mo"], "Flasher", libraries=[msl_path()])
    t, res = _run(model, 0.1, 4001)
    v = res.output("vc")
    assert -8.1 < v.min() < -7.5 and 7.5 < v.max() < 8.1     # the thresholds: +-12 R1/(R1 + R2)
    rising = t[1:][(v[:-1] < 0) & (v[1:] >= 0)]
    period = np.diff(rising).mean()
    assert len(rising) >= 3 and abs(period - 1 / 50) < 0.01 / 50
