"""Block diagrams: a static signal block (a Gain, a Limiter, a user's block y = f(u)) is a
component whose law discovery may question, its output in its input.

A speed loop as a control engineer draws it from MSL blocks: a set-point, a feedback, a PI
controller, a power amplifier (a Gain), the motor as a first-order lag and a tachometer (a
Gain). The real amplifier saturates; the model's is linear. The data come from the loop's ODE
written by hand and solved by SciPy; only the speed is measured.
"""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from helpers import discovered, msl_path, needs_msl, write_uy

MSL = msl_path()
pytestmark = [needs_msl()]

SERVO = """
model Servo "a speed loop: PI controller, power amplifier, motor as a first-order lag, speed sensor"
  import Modelica.Blocks;
  import Modelica.Blocks.Types.Init;
  Blocks.Interfaces.RealInput r "speed set-point";
  Blocks.Interfaces.RealOutput w "measured speed";
  Blocks.Math.Feedback error;
  Blocks.Continuous.PI controller(k=2, T=0.5, initType=Init.InitialState, x_start=0);
  Blocks.Math.Gain amplifier(k=5) "power amplifier, V per V";
  Blocks.Continuous.FirstOrder motor(k=1, T=0.3, initType=Init.InitialState, y_start=0);
  Blocks.Math.Gain sensor(k=1) "tachometer";
equation
  connect(r, error.u1);
  connect(error.y, controller.u);
  connect(controller.y, amplifier.u);
  connect(amplifier.y, motor.u);
  connect(motor.y, sensor.u);
  connect(sensor.y, error.u2);
  connect(sensor.y, w);
end Servo;
"""

#: the amplifier as built: 5 V/V, limited to 3 V; and as modelled
SATURATING = lambda v: 3.0 * np.tanh(5.0 * v / 3.0)
LINEAR = lambda v: 5.0 * v


def servo_data(path, seed, amplifier):
    """The measured speed (noise 5e-3) for a set-point moving between random levels every 2 s."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 12, 601)
    levels = rng.uniform(-3, 3, 7)

    def r(s):
        s = np.asarray(s, float)
        moves = sum((levels[k] - levels[k - 1]) * 0.5 * (1 + np.tanh((s - 2 * k) / 0.1)) for k in range(1, 6))
        return levels[0] + moves + 0.3 * np.sin(2.1 * s + seed)

    def rhs(s, x):
        integral, speed = x
        e = r(s) - speed
        return [e / 0.5, (amplifier(2 * (integral + e)) - speed) / 0.3]

    sol = solve_ivp(rhs, (0, 12), [0, 0], t_eval=t, rtol=1e-10, atol=1e-12, max_step=0.01)
    w = sol.y[1] + rng.normal(0, 0.005, len(t))
    path.write_text("time,r,w\n" + "\n".join(f"{a:.10g},{b:.10g},{c:.10g}" for a, b, c in zip(t, r(t), w)) + "\n")


def discover(tmp_path, amplifier) -> dict:
    servo_data(tmp_path / "train.csv", 1, amplifier)
    servo_data(tmp_path / "validate.csv", 2, amplifier)
    return discovered(tmp_path, "Servo.mo", "Servo", SERVO)


def test_the_static_blocks_of_a_loop_are_candidates(tmp_path):
    """The gains and a limiter are; the PI controller and the lag hold states, the feedback
    has two inputs: they are not."""
    from mcl import compile_model

    guarded = SERVO.replace("connect(controller.y, amplifier.u);",
                            "connect(controller.y, guard.u);\n  connect(guard.y, amplifier.u);")
    guarded = guarded.replace("equation", "  Blocks.Nonlinear.Limiter guard(uMax=100);\nequation", 1)
    (tmp_path / "Servo.mo").write_text(guarded)
    model = compile_model([tmp_path / "Servo.mo"], "Servo", libraries=[MSL])
    cands = {c.name: c for c in model.structure.candidates()}
    assert sorted(cands) == ["amplifier", "guard", "sensor"]
    assert all(c.signal for c in cands.values())
    assert cands["amplifier"].across() == ("amplifier.u", None) and cands["amplifier"].flow() == ("amplifier.y", None)


@pytest.mark.slow
def test_a_saturating_amplifier_is_named_and_its_limit_learned(tmp_path):
    report = discover(tmp_path, SATURATING)
    assert report["misfit"]["significant"]
    cause = report["cause"]
    assert cause["component"] == "amplifier", cause["effect"]
    assert "saturation" in cause["effect"], cause["effect"]
    law = cause["law"]
    assert law["equation"].startswith("amplifier.y = ") and "amplifier.u" in law["equation"]
    xs, ys = np.array(law["curve"]).T
    inside = np.abs(xs) <= 1.5          # where the loop drove it (its input stays within about 2)
    err = np.max(np.abs(ys[inside] - SATURATING(xs[inside]))) / 3.0
    assert err < 0.05, (err, law["equation"])
    g = report["gain"]
    assert g["validation_rms_after"] < 0.1 * g["validation_rms_before"], g
    # the learned block is a block of the package, with the amplifier's own connectors, and the
    # model with it compiles again and reproduces the fitted run
    text = (tmp_path / "out" / report["extended"]["modelica"]).read_text()
    assert "block amplifier_" in text and "RealInput u;" in text and "RealOutput y;" in text
    assert report["extended"].get("recompiled_difference", 1.0) < 1e-3, report["extended"]


@pytest.mark.slow
def test_a_linear_amplifier_gets_no_cause(tmp_path):
    report = discover(tmp_path, LINEAR)
    assert not report["misfit"]["significant"]
    assert report["cause"] is None


OSCILLATOR = """
model Oscillator "a mass on a spring and a damper, pushed through a driver, read through a sensor"
  import Modelica.Mechanics.Translational.Components;
  Modelica.Blocks.Interfaces.RealInput u "input voltage";
  Modelica.Blocks.Interfaces.RealOutput y "output voltage";
  Components.Fixed wall;
  Modelica.Mechanics.Translational.Sources.Force push;
  Components.Mass M(m=1, s(fixed=true, start=0), v(fixed=true, start=0));
  Components.Spring S(c=100);
  Components.Damper D(d=2);
  Modelica.Mechanics.Translational.Sensors.PositionSensor position;
  Modelica.Blocks.Math.Gain driver(k=10) "force per volt";
  Modelica.Blocks.Math.Gain sensor(k=1000) "volts per metre";
equation
  connect(u, driver.u);
  connect(driver.y, push.f);
  connect(push.flange, M.flange_a);
  connect(wall.flange, S.flange_a);
  connect(S.flange_b, M.flange_a);
  connect(wall.flange, D.flange_a);
  connect(D.flange_b, M.flange_a);
  connect(M.flange_b, position.flange);
  connect(position.s, sensor.u);
  connect(sensor.y, y);
end Oscillator;
"""


def test_the_gains_of_a_physical_models_measuring_chain_are_not_searched_but_may_be_named(tmp_path):
    """Beside a spring and a damper, the gain from the input voltage to the force and the one from
    the position to the output voltage are the measuring chain (as sensors are): not searched;
    a run file may still name one."""
    from mcl import compile_model
    from mcl.runfile import check_data, parse_runfile

    (tmp_path / "Oscillator.mo").write_text(OSCILLATOR)
    model = compile_model([tmp_path / "Oscillator.mo"], "Oscillator", libraries=[MSL])
    comps = model.structure.components
    assert comps["driver"].chain and comps["sensor"].chain
    assert {"driver", "sensor"}.isdisjoint(c.name for c in model.structure.candidates())
    assert {"S", "D"} <= {c.name for c in model.structure.candidates()}
    (tmp_path / "train.csv").write_text("time,u,y\n0,0,0\n1,0,0\n")
    (tmp_path / "run.yaml").write_text(f"model: {{sources: [Oscillator.mo], name: Oscillator, libraries: [{MSL}]}}\n"
                                       "data: {train: train.csv}\nunknown: sensor\noutput: out\n")
    spec, lines = parse_runfile(tmp_path / "run.yaml")
    check_data(spec, lines)            # no error: the sensor may take a law when named


CHAIN = """
model Chain "a Wiener-Hammerstein chain: a filter, an amplifier stage taken as linear, a filter"
  import Modelica.Blocks;
  import Modelica.Blocks.Types.Init;
  Blocks.Interfaces.RealInput u "input voltage";
  Blocks.Interfaces.RealOutput y "output voltage";
  Blocks.Continuous.FirstOrder G1(k=1, T=0.05, initType=Init.InitialState, y_start=0) "input filter";
  Blocks.Math.Gain stage(k=1) "a diode-clamped stage, taken as linear";
  Blocks.Continuous.SecondOrder G2(k=1, w=20, D=0.4, initType=Init.InitialState, y_start=0, yd_start=0)
    "output filter";
equation
  connect(u, G1.u);
  connect(G1.y, stage.u);
  connect(stage.y, G2.u);
  connect(G2.y, y);
end Chain;
"""

#: the stage as built: a diode clamps its output above about 0.5 V (a knee 0.05 V wide)
CLAMPED = lambda x: x - 0.05 * np.logaddexp(0.0, (x - 0.5) / 0.05)


def chain_data(path, seed):
    """The measured output (noise 2e-3) for an input of five sines of random phase."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 10, 1001)
    parts = [(a, w, p) for a, w, p in zip((0.5, 0.4, 0.3, 0.3, 0.2), (0.7, 1.9, 3.7, 6.1, 9.5), rng.uniform(0, 6.3, 5))]
    u = lambda s: sum(a * np.sin(w * np.asarray(s, float) + p) for a, w, p in parts)

    def rhs(s, x):
        g1, g2, dg2 = x
        return [(u(s) - g1) / 0.05, dg2, 400 * (CLAMPED(g1) - g2) - 16 * dg2]

    sol = solve_ivp(rhs, (0, 10), [0, 0, 0], t_eval=t, rtol=1e-10, atol=1e-12, max_step=0.01)
    y = sol.y[1] + rng.normal(0, 0.002, len(t))
    write_uy(path, t, u(t), y)


@pytest.mark.slow
def test_a_clamp_between_two_filters_is_learned_as_a_knee(tmp_path):
    """The nonlinearity of a Wiener-Hammerstein chain, measured nowhere, is a one-sided limit:
    the stage is named, the law has a knee where the diode starts to conduct, and the curve is
    the clamp's over the range the filter drove it."""
    chain_data(tmp_path / "train.csv", 1)
    chain_data(tmp_path / "validate.csv", 2)
    report = discovered(tmp_path, "Chain.mo", "Chain", CHAIN)
    assert report["misfit"]["significant"]
    cause = report["cause"]
    assert cause["component"] == "stage", cause["effect"]
    assert "knee" in cause["effect"], cause["effect"]
    xs, ys = np.array(cause["law"]["curve"]).T
    err = np.max(np.abs(ys - CLAMPED(xs))) / np.ptp(CLAMPED(xs))
    assert err < 0.03, (err, cause["law"]["equation"])
    g = report["gain"]
    assert g["validation_rms_after"] < 0.1 * g["validation_rms_before"], g
    # the learned block exports as a library of its own, beside its FMU
    from mcl.cli import main

    assert main(["export", str(tmp_path / "out"), "-o", str(tmp_path / "lib"), "--name", "Clamps"]) == 0
    assert f"block {cause['learned_class']}" in (tmp_path / "lib" / "Clamps" / "package.mo").read_text()


def test_what_a_calibrated_model_may_set_and_how_it_is_written(tmp_path):
    """A TransferFunction's bb and a Filter's coefficients are protected, a Filter's nx is final:
    ``free: auto`` leaves them, and the calibrated model is written as a modification that
    sets whole arrays."""
    from mcl.discovery.modelica import _modification, internal_parameters

    (tmp_path / "Filters.mo").write_text("""
model Filters
  import Modelica.Blocks.Continuous;
  parameter Real k = 1;
  Continuous.TransferFunction G(b = {1}, a = {1, 2, 1});
  Continuous.Filter F(order = 2, f_cut = 10);
equation
  F.u = k * sin(time);
  G.u = F.y;
end Filters;
""")
    names = ["k", "G.a[2]", "G.bb[1]", "G.x_start[1]", "F.f_cut", "F.cr[1]", "F.nx", "F.u_nominal"]
    hidden = internal_parameters("Filters", names, [MSL], [tmp_path / "Filters.mo"])
    assert hidden == ["G.bb[1]", "F.cr[1]", "F.nx"]
    params = {"k": 1.0, "G.a[1]": 1.0, "G.a[2]": 2.0, "G.a[3]": 1.0, "F.f_cut": 10.0}
    text, skipped = _modification({"k": 2.5, "G.a[2]": 3.0, "F.f_cut": 12.0}, params)
    assert text == "k = 2.5, G(a = {1.0, 3.0, 1.0}), F(f_cut = 12.0)" and not skipped
    assert _modification({"k": float("nan")}, params) == ("", ["k"])        # no value: not written


def test_sections_of_a_class_are_read_in_order(tmp_path):
    """A protected section holding only a function, then a public one: what follows public is
    settable again; a protected import is an import, a protected extends an extends."""
    from mcl.discovery.modelica import internal_parameters

    (tmp_path / "P.mo").write_text("""
model P
  parameter Real a = 1;
protected
  function f
    input Real x;
    output Real y;
  algorithm
    y := x;
  end f;
public
  parameter Real k = 2;
protected
  import Modelica.Units.SI;
  parameter SI.Time T = 1;
  extends Modelica.Icons.Example;
equation
end P;
""")
    assert internal_parameters("P", ["a", "k", "T"], [MSL], [tmp_path / "P.mo"]) == ["T"]
