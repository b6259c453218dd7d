"""homotopy(actual, simplified): the model is the actual one, and an algebraic loop with several
solutions starts on the one the simplified model leads to, as Modelica's initialisation by
homotopy does. Without it Newton's method from the start values picks whichever solution is
nearest them: a Schmitt trigger's amplifier at its unstable middle, and the oscillator never
starts."""
import numpy as np

from helpers import msl_path, needs_msl, unforced_run
from mcl import compile_model

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

GENERATOR = """
model Triangle "a Schmitt trigger and an integrator: square and triangle waves"
  import Modelica.Electrical.Analog.Basic;
  import Modelica.Electrical.Analog.Ideal.IdealizedOpAmpLimited;
  import Modelica.Blocks.Types.LimiterHomotopy;
  parameter Real Vs = 12 "supply";
  parameter Real A = 8 "triangle amplitude";
  parameter Real f = 25 "designed frequency";
  parameter Real R1 = 1000, R2 = R1*Vs/A, R = 1000;
  parameter Real C = Vs/A/(4*f*R);
  IdealizedOpAmpLimited trigger(Vps = Vs, Vns = -Vs, strict = false,
    homotopyType = LimiterHomotopy.UpperLimit);
  IdealizedOpAmpLimited integrator(Vps = Vs, Vns = -Vs, strict = false);
  Basic.Ground ground;
  Basic.Resistor r1(R = R1);
  Basic.Resistor r2(R = R2);
  Basic.Resistor r(R = R);
  Basic.Capacitor c(C = C, v(start = 0, fixed = true));
  output Real triangle = integrator.out.v;
equation
  connect(trigger.out, r2.n);
  connect(trigger.in_p, r2.p);
  connect(trigger.in_n, ground.p);
  connect(trigger.out, r.p);
  connect(r.n, c.n);
  connect(c.p, integrator.out);
  connect(ground.p, integrator.in_p);
  connect(c.n, integrator.in_n);
  connect(r2.p, r1.p);
  connect(integrator.out, r1.n);
end Triangle;
"""


def test_a_loop_with_three_solutions_starts_where_its_simplified_law_leads(tmp_path):
    starts = {}
    for case, law in (("plain", "y^3 - 3*y - 0.1*x"),
                      ("homotopy", "homotopy(actual = y^3 - 3*y - 0.1*x, simplified = y - 2)")):
        (tmp_path / "Bistable.mo").write_text(BISTABLE.format(law=law))
        model = compile_model([tmp_path / "Bistable.mo"], "Bistable")
        t, res = unforced_run(model, 1.0, 11)
        y, x = res.output("yo"), np.exp(-t)
        assert np.max(np.abs(y**3 - 3 * y - 0.1 * x)) < 1e-6      # the actual law holds throughout
        starts[case] = y[0]
    assert abs(starts["plain"]) < 0.1                  # nearest the start value 0
    assert abs(starts["homotopy"] - 1.75) < 0.02       # sqrt(3) + a little: the branch from y = 2


@needs_msl()
def test_a_triangle_generator_starts_at_its_triggers_declared_limit(tmp_path):
    """With the capacitor empty, the trigger's middle solution (output 0) is an equilibrium: a
    Newton method from zero guesses stays there and the generator never starts. Its declared
    start at the upper limit (homotopyType) starts it; it then swings +-A at f."""
    (tmp_path / "Triangle.mo").write_text(GENERATOR)
    model = compile_model([tmp_path / "Triangle.mo"], "Triangle", libraries=[msl_path()])
    t, res = unforced_run(model, 0.2, 4001)
    v = res.output("triangle")
    assert -8.1 < v.min() < -7.9 and 7.9 < v.max() < 8.1
    assert v[np.searchsorted(t, 0.005)] < -0.9        # first down: the trigger starts high
    rising = t[1:][(v[:-1] < 0) & (v[1:] >= 0)]
    period = np.diff(rising).mean()
    assert len(rising) >= 3 and abs(period - 1 / 25) < 0.01 / 25
