"""The MSL's interpolation tables (CombiTimeTable, CombiTable1Ds) simulate as the C library
computes them, checked against references written here with NumPy and SciPy; and conditions on
algebraic variables (the tables' segment choice, a time event read from a discrete variable)."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.interpolate import Akima1DInterpolator

from helpers import msl_path, series
from mcl.api import compile_model, simulate

MSL = msl_path()
needs_msl = pytest.mark.skipif(MSL is None, reason="the MSL is not on MODELICAPATH nor at ../shared/msl")


def run(tmp_path, name, text, t):
    src = tmp_path / f"{name}.mo"
    src.write_text(text)
    model = compile_model([src], name, libraries=[MSL] if MSL else [])
    res = simulate(model, series(t), t_out=t, options={"rtol": 1e-9, "atol": 1e-11})
    assert res.ok, res.reason
    return model, res


@needs_msl
def test_a_time_table_feeds_a_lookup_table_into_a_lag(tmp_path):
    """Linear time table with a start, a shift, a time scale and an offset, extrapolated
    through its last two points; a 1-D table of constant segments; a first-order lag."""
    text = """model Profile
  import Modelica.Blocks.Sources;
  import Modelica.Blocks.Tables;
  import Modelica.Blocks.Types.Smoothness;
  Sources.CombiTimeTable profile(table = [0, 0; 1, 1; 2, 1; 3, 0], smoothness = Smoothness.LinearSegments,
    startTime = 0.5, shiftTime = 0.25, timeScale = 2, offset = {0.1});
  Tables.CombiTable1Ds curve(table = [0, 0; 1, 2; 2, 3], smoothness = Smoothness.ConstantSegments);
  Modelica.Blocks.Continuous.FirstOrder lag(T = 0.5, initType = Modelica.Blocks.Types.Init.InitialOutput);
  output Real y = lag.y;
equation
  connect(profile.y[1], curve.u);
  connect(curve.y[1], lag.u);
end Profile;
"""
    t = np.linspace(0.0, 8.0, 161)
    model, res = run(tmp_path, "Profile", text, t)
    assert model.info["library_subset"] is True

    def profile(s):                    # time scaled by 2: start 0.25, shift 0.125
        ts = s / 2
        if ts < 0.25:
            return 0.1
        u = ts - 0.125
        return 0.1 + (np.interp(u, [0, 1, 2, 3], [0, 1, 1, 0]) if u <= 3 else 3 - u)

    def curve(u):                      # constant segments; a line through the last two rows outside
        if u < 0:
            return 2 * u
        if u > 2:
            return 3 + (u - 2)
        return [0, 2, 3][np.searchsorted([0, 1, 2], u, side="right") - 1]

    ref = solve_ivp(lambda s, y: [(curve(profile(s)) - y[0]) / 0.5], (0, 8), [0.0], t_eval=t,
                    rtol=1e-10, atol=1e-12, max_step=0.002).y[0]
    assert np.max(np.abs(res.output("y") - ref)) < 2e-3 * np.ptp(ref)


@needs_msl
def test_a_periodic_table_of_constant_segments_switches_at_its_events(tmp_path):
    text = """model Duty
  Modelica.Blocks.Sources.CombiTimeTable losses(table = [0, 100; 360, 1000; 600, 100],
    extrapolation = Modelica.Blocks.Types.Extrapolation.Periodic,
    smoothness = Modelica.Blocks.Types.Smoothness.ConstantSegments);
  output Real y = losses.y[1];
end Duty;
"""
    t = np.arange(0.0, 1900.0, 30.0) + 7.0
    _, res = run(tmp_path, "Duty", text, t)
    expected = np.where(np.mod(t, 600.0) < 360.0, 100.0, 1000.0)
    np.testing.assert_array_equal(res.output("y"), expected)


@needs_msl
def test_an_akima_table_matches_akimas_spline(tmp_path):
    x, v = [0.0, 1.0, 2.0, 3.0, 4.5, 6.0], [0.0, 0.5, 2.0, 1.5, 1.0, 3.0]
    rows = "; ".join(f"{a}, {b}" for a, b in zip(x, v))
    text = f"""model Spline
  Modelica.Blocks.Tables.CombiTable1Ds f(table = [{rows}],
    smoothness = Modelica.Blocks.Types.Smoothness.ContinuousDerivative);
  output Real y = f.y[1];
equation
  f.u = time - 1;
end Spline;
"""
    t = np.linspace(0.0, 8.5, 69)
    _, res = run(tmp_path, "Spline", text, t)
    u = t - 1
    spline = Akima1DInterpolator(x, v)
    inside = (u >= 0) & (u <= 6)
    np.testing.assert_allclose(res.output("y")[inside], spline(u[inside]), atol=1e-9)
    # outside: the line along the end tangent (LastTwoPoints)
    right = u > 6
    np.testing.assert_allclose(res.output("y")[right], 3.0 + spline(6.0, 1) * (u[right] - 6), atol=1e-9)
    left = u < 0
    np.testing.assert_allclose(res.output("y")[left], spline(0.0, 1) * u[left], atol=1e-9)


def test_a_condition_on_an_algebraic_variable_is_not_folded_away(tmp_path):
    """y = if a < 1 then 10 else 20 reads a only in its condition (a zero derivative): it is
    no alias of a constant, and a time event read from a discrete variable fires."""
    text = """model Cond
  Real a = 2 * time;
  discrete Real next(start = 0, fixed = true);
  Real x(start = 0, fixed = true);
  output Real y = if a < 1 then 10 else 20;
  output Real n = next;
  output Real z = x;
equation
  when {time >= pre(next), initial()} then
    next = floor(time + 0.5) + 1;
  end when;
  der(x) = next;
end Cond;
"""
    t = np.linspace(0.0, 3.0, 13)
    _, res = run(tmp_path, "Cond", text, t)
    # (at the crossing itself, t = 0.5, y still reads 10: a held relation changes once past its
    # band, 3e-10 later, so that rounding cannot flip it back and forth at the event)
    off = t != 0.5
    np.testing.assert_array_equal(res.output("y")[off], np.where(2 * t < 1, 10.0, 20.0)[off])
    np.testing.assert_array_equal(res.output("n"), np.floor(t) + 1)     # after the event at t = 1, 2, 3
    # x' = next: 1 on [0, 1), 2 on [1, 2), 3 on [2, 3)
    np.testing.assert_allclose(res.output("z"), np.interp(t, [0, 1, 2, 3], [0, 1, 3, 6]), atol=1e-6)
