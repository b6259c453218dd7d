"""Outputs in different units: each is fitted in units of its noise.

A source feeds two branches: a slow one whose capacitor voltage is logged in volts (hundreds
of volts, 1 V noise) and a high-impedance one whose current is logged in amperes (a fraction
of a milliampere, 2 uA noise). The high-impedance resistor conducts more than Ohm's law says
at high voltage (a cubic term), which only the current shows. Pooled raw, the current's misfit
is 1e-8 of the voltage's noise: no law could win on it. The data come from the circuit's ODEs
written by hand and solved by SciPy.
"""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from helpers import discovered, msl_path, needs_msl
from mcl.discovery.run import MISFIT_SHARE, WEIGHED_WHEN, output_weights, overall
from mcl.stats import NoiseEstimate

MSL = msl_path()

BRANCHES = """
model Branches "a source feeding an RC branch (voltage logged) and a high-impedance branch (current logged)"
  import Modelica.Electrical.Analog.Basic;
  import Modelica.Electrical.Analog.Sources;
  import Modelica.Electrical.Analog.Sensors;
  Modelica.Blocks.Interfaces.RealInput u(unit = "V") "source voltage";
  Modelica.Blocks.Interfaces.RealOutput v1(unit = "V") "capacitor voltage";
  Modelica.Blocks.Interfaces.RealOutput i2(unit = "A") "high-impedance branch current";
  Sources.SignalVoltage src;
  Basic.Ground gnd;
  Basic.Resistor R1(R = 1e3);
  Basic.Capacitor C1(C = 1e-3);
  Basic.Resistor R2(R = 1e6);
  Basic.Capacitor C2(C = 1e-6);
  Sensors.VoltageSensor vs;
  Sensors.CurrentSensor cs;
initial equation
  C1.v = 0;
  C2.v = 0;
equation
  connect(u, src.v);
  connect(src.n, gnd.p);
  connect(src.p, R1.p);
  connect(R1.n, C1.p);
  connect(C1.n, gnd.p);
  connect(src.p, cs.p);
  connect(cs.n, R2.p);
  connect(R2.n, C2.p);
  connect(C2.n, gnd.p);
  connect(vs.p, C1.p);
  connect(vs.n, gnd.p);
  connect(vs.v, v1);
  connect(cs.i, i2);
end Branches;
"""

G3 = 2e-12      # the hidden cubic conductance of R2 (A/V^3): as much as Ohm's current at 700 V


def branches_data(path, seed: int, g3: float) -> None:
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 12.0, 1201)
    w, a, ph = rng.uniform(0.4, 3.0, 4), rng.uniform(150, 300, 4), rng.uniform(0, 2 * np.pi, 4)
    u = lambda s: np.sum(a * np.sin(w * np.atleast_1d(s)[:, None] + ph), axis=1)  # noqa: E731
    i2 = lambda s, v2: (u(s) - v2) / 1e6 + g3 * (u(s) - v2) ** 3                 # noqa: E731
    rhs = lambda s, x: [((u(s) - x[0]) / 1e3 / 1e-3)[0], (i2(s, x[1]) / 1e-6)[0]]  # noqa: E731
    x = solve_ivp(rhs, (t[0], t[-1]), [0.0, 0.0], t_eval=t, rtol=1e-10, atol=1e-12, method="LSODA").y
    v1 = x[0] + rng.normal(0, 1.0, len(t))
    cur = i2(t, x[1]) + rng.normal(0, 2e-6, len(t))
    path.write_text("time,u,v1,i2\n" + "\n".join(
        f"{a_:.10g},{b:.10g},{c:.10g},{d:.10g}" for a_, b, c, d in zip(t, u(t), v1, cur)) + "\n")


def test_weights_are_set_only_where_the_outputs_noise_levels_differ():
    y = np.random.default_rng(0).normal(size=(100, 2))
    alike = {"a": NoiseEstimate(1.0, "given"), "b": NoiseEstimate(1.5, "given")}
    assert output_weights(alike, y, ["a", "b"]) is None
    assert output_weights({"a": alike["a"]}, y[:, :1], ["a"]) is None
    apart = {"a": NoiseEstimate(100.0, "given"), "b": NoiseEstimate(0.1, "given")}
    w = output_weights(apart, y * [1e4, 1.0], ["a", "b"])
    overall = np.sqrt((100.0**2 + 0.1**2) / 2)
    assert w["a"] * 100.0 == pytest.approx(overall) and w["b"] * 0.1 == pytest.approx(overall)
    # a noiseless output does not outweigh the others without bound: its noise is taken as at
    # least 1e-4 of its spread
    silent = {"a": NoiseEstimate(1.0, "given"), "b": NoiseEstimate(0.0, "given")}
    w = output_weights(silent, y, ["a", "b"])
    assert w["b"] / w["a"] == pytest.approx(1.0 / (1e-4 * np.nanstd(y[:, 1])), rel=1e-9)
    assert WEIGHED_WHEN > 1


def encoder_and_force():
    """(t, y, noise, nominal misfit) of a position (m) with an encoder's noise beside a force
    (N), the nominal model missing them by 1000x and 200x their noise."""
    t = np.linspace(0.0, 10.0, 1001)
    y = np.column_stack([0.1 * np.sin(t), 50.0 * np.cos(t)])
    return t, y, {"q": NoiseEstimate(1e-8, "given"), "f": NoiseEstimate(0.1, "given")}, [1e-5, 20.0]


def test_a_fine_output_the_nominal_misses_by_far_is_not_floored_at_its_spread():
    """An encoder's noise is far below 1e-4 of its spread: where the nominal model misses it by
    far, its noise is floored at MISFIT_SHARE of that misfit instead, and its misfit weighs as
    much as a noisy output's that the nominal misses as far in its own noise."""
    t, y, noise, misfit = encoder_and_force()
    before = output_weights(noise, y, ["q", "f"])
    after = output_weights(noise, y, ["q", "f"], misfit)
    spread_floor = 1e-4 * np.std(y[:, 0])
    assert before["q"] / before["f"] == pytest.approx(0.1 / spread_floor)
    assert after["q"] / after["f"] == pytest.approx(0.1 / (MISFIT_SHARE * 1e-5))
    # in noise units the position's misfit now counts 100 (MISFIT_SHARE's), the force's 200
    assert after["q"] * misfit[0] / (after["f"] * misfit[1]) == pytest.approx(0.5)
    # a misfit within 1/MISFIT_SHARE of the noise changes nothing; nor does one of 0
    assert output_weights(noise, y, ["q", "f"], [5e-7, 0.0]) == output_weights(noise, y, ["q", "f"], [0.0, 0.0]) == before


@pytest.mark.slow
@needs_msl()
def test_a_fault_only_the_small_unit_output_shows_is_found(tmp_path):
    branches_data(tmp_path / "train.csv", 1, G3)
    branches_data(tmp_path / "validate.csv", 2, G3)
    report = discovered(tmp_path, "Branches.mo", "Branches", BRANCHES)
    assert report["misfit"]["significant"] and set(report["misfit"]["weights"]) == {"v1", "i2"}
    cause = report["cause"]
    assert cause is not None and cause["component"] == "R2", cause and cause["component"]
    assert "R2.v^3" in cause["effect"]
    each = report["gain_per_output"]["i2"]
    assert each["validation_before"] >= 3 * each["noise"]
    assert each["validation_after"] <= 1.3 * each["noise"]
    xs, fs = np.array(cause["law"]["curve"]).T
    truth = xs / 1e6 + G3 * xs**3
    assert np.max(np.abs(fs - truth)) <= 0.1 * np.max(np.abs(truth))


@pytest.mark.slow
@needs_msl()
def test_without_the_fault_mixed_units_find_nothing(tmp_path):
    branches_data(tmp_path / "train.csv", 1, 0.0)
    branches_data(tmp_path / "validate.csv", 2, 0.0)
    report = discovered(tmp_path, "Branches.mo", "Branches", BRANCHES)
    assert not report["misfit"]["significant"] and report["cause"] is None


def test_each_outputs_residual_is_drawn_against_its_own_noise():
    """The report's residual plots draw each output's 3 x noise band in its own units (the
    overall noise over its weight): a position's band of micrometres, not the overall noise."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mcl.discovery.report import _outputs_figure, output_noise

    t, y, noise, misfit = encoder_and_force()
    weights = output_weights(noise, y, ["q", "f"], misfit)
    report = {"misfit": {"noise_estimate": overall(noise), "weights": weights}}
    each = output_noise(report, ["q", "f"])
    assert each["q"] == pytest.approx(MISFIT_SHARE * 1e-5) and each["f"] == pytest.approx(0.1)
    assert output_noise({"misfit": {"noise_estimate": 0.3, "weights": None}}, ["q"]) == {"q": 0.3}
    nominal = y + [misfit]
    fig = _outputs_figure(plt, t, y, nominal, None, ["q", "f"], {}, each, "training data")
    q_residual, f_residual = fig.axes[1], fig.axes[3]
    assert q_residual.get_ylim()[1] < 1e-4 and f_residual.get_ylim()[1] > 1.0
    plt.close(fig)
