"""The measuring chain: where no component of the plant explains the misfit, the sensors (and the
blocks at the model's inputs and outputs) are searched, each sensor's law its reading in what it
measures.

Two drives turn a pulley through an elastic belt; the pulley's speed is read by a pulse counter
that cannot tell the direction (the coupled electric drives benchmark's sensor). The engineer's
model has the MSL's SpeedSensor, which gives the signed speed. The data come from the drive's
ODE written by hand and solved by SciPy, the reading |w| plus noise.
"""
import numpy as np
from scipy.integrate import solve_ivp

from helpers import discovered, needs_msl, write_uy

pytestmark = [needs_msl()]

DRIVES = """
model Drives "two motors turn a pulley through an elastic belt; a counter reads the pulley's speed"
  import Modelica.Mechanics.Rotational;
  Modelica.Blocks.Interfaces.RealInput u(unit = "N.m") "the motors' torque";
  Modelica.Blocks.Interfaces.RealOutput y(unit = "rad/s") "the counter's reading";
  Rotational.Sources.Torque motor;
  Rotational.Components.Inertia rotors(J = 0.1, phi(start = 0, fixed = true), w(start = 0, fixed = true));
  Rotational.Components.SpringDamper belt(c = 20, d = 0.05);
  Rotational.Components.Inertia pulley(J = 0.05, w(start = 0, fixed = true));
  Rotational.Components.Damper bearings(d = 0.4);
  Rotational.Components.Fixed frame;
  Rotational.Sensors.SpeedSensor counter "a pulse counter";
equation
  connect(u, motor.tau);
  connect(motor.flange, rotors.flange_a);
  connect(rotors.flange_b, belt.flange_a);
  connect(belt.flange_b, pulley.flange_a);
  connect(pulley.flange_b, counter.flange);
  connect(frame.flange, bearings.flange_a);
  connect(bearings.flange_b, pulley.flange_a);
  connect(counter.w, y);
end Drives;
"""


def drive_data(path, seed: int, reading) -> None:
    """The counter's reading (noise 0.01 rad/s) for a torque of random steps and a sine."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 12, 601)
    levels = rng.choice([-1.0, 1.0], 12) * rng.uniform(0.5, 1.5, 12)

    def u(s):
        s = np.asarray(s, float)
        steps = sum((levels[k] - levels[k - 1]) * 0.5 * (1 + np.tanh((s - k) / 0.05)) for k in range(1, 12))
        return levels[0] + steps + 0.3 * np.sin(3.1 * s + seed)

    def rhs(s, x):
        phi, w1, w2 = x                       # the belt's stretch, the rotors' and the pulley's speed
        tau = 20 * phi + 0.05 * (w1 - w2)
        return [w1 - w2, (u(s) - tau) / 0.1, (tau - 0.4 * w2) / 0.05]

    sol = solve_ivp(rhs, (0, 12), [0, 0, 0], t_eval=t, rtol=1e-10, atol=1e-12, max_step=0.01)
    y = reading(sol.y[2]) + rng.normal(0, 0.01, len(t))
    write_uy(path, t, u(t), y)


def test_a_counter_blind_to_the_direction_is_named_with_its_law(tmp_path):
    """The plant is right; the reading is |w|. No plant law explains it, the counter's does,
    with |w| in it; the extended model declares the counter with its learned class."""
    drive_data(tmp_path / "train.csv", 1, np.abs)
    drive_data(tmp_path / "validate.csv", 2, np.abs)
    report = discovered(tmp_path, "Drives.mo", "Drives", DRIVES)
    cause = report["causes"][0]
    assert cause["component"] == "counter", report["cause"]
    assert "abs(counter.measured)" in cause["law"]["equation"], cause["law"]["equation"]
    assert report["gain"]["validation_rms_after"] < 0.1 * report["gain"]["validation_rms_before"], report["gain"]
    extended = (tmp_path / "out" / "extended" / "Drives.mo").read_text()
    assert "Learned.counter_" in extended
    assert report["extended"]["recompiled_difference"] < 1e-3, report["extended"]


def test_a_declaration_is_rewritten_not_the_words_of_a_description():
    """The learned class takes the component's declaration; a description or a comment that
    names the component (";  a counter reads ...") is left as written."""
    from mcl.discovery.modelica import redeclared

    text = DRIVES.replace('end Drives;', '  // the counter is a pulse counter\nend Drives;')
    out = redeclared(text, "Drives", "counter", "Learned.Counter")
    assert 'Learned.Counter counter "a pulse counter";' in out
    assert "elastic belt; a counter reads" in out and "// the counter is a pulse counter" in out
    assert out.count("Learned.Counter") == 1
