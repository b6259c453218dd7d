"""Discovery names a law a person can read, on an MSL model written the way engineers write it.

A geared spindle drive (motor, gear, compliant shaft, load on a bearing, two tachometers) whose
load bearing has dry friction with a sharp step at rest, tau = 0.1 w + 0.15 tanh(w/0.01): the
speeds visited reach about 3 rad/s, so the rate family's Coulomb-like terms at fixed shares of
that span (the sharpest 0.03 rad/s) reach the noise only as several terms; the plainer law
distilled from them, its scale fitted by simulation, is the one named. The truth is the drive's
ODE derived by hand and solved by SciPy, never by mcl.
"""
import numpy as np
from scipy.integrate import solve_ivp

from helpers import discovered, needs_msl

pytestmark = needs_msl()

DRIVE = """within ;
package Drive "a geared spindle drive as the engineer models it"
  model Spindle "torque-controlled motor, gearbox, compliant shaft, load on a bearing; two tachometers"
    import Modelica.Mechanics.Rotational;
    import Modelica.Units.SI;
    Modelica.Blocks.Interfaces.RealInput tauCmd(unit = "N.m") "motor torque command";
    Modelica.Blocks.Interfaces.RealOutput wMotor(unit = "rad/s") "motor tachometer";
    Modelica.Blocks.Interfaces.RealOutput wLoad(unit = "rad/s") "load tachometer";
    parameter SI.Inertia Jmot = 0.002 "rotor inertia";
    parameter Real ratio = 5 "gear ratio";
    Rotational.Sources.Torque motor;
    Rotational.Components.Inertia rotor(J = Jmot);
    Rotational.Components.Damper motorBearing(d = 0.001) "motor bearing viscous loss";
    Rotational.Components.IdealGear gear(ratio = ratio);
    Rotational.Components.SpringDamper shaft(c = 40, d = 0.2) "output shaft";
    Rotational.Components.Inertia load(J = 0.05);
    Rotational.Components.Damper bearing(d = 0.1) "load bearing, taken as viscous";
    Rotational.Components.Fixed frame;
    Rotational.Sensors.SpeedSensor tachMotor;
    Rotational.Sensors.SpeedSensor tachLoad;
  initial equation
    rotor.phi = 0;
    rotor.w = 0;
    load.phi = 0;
    load.w = 0;
  equation
    connect(tauCmd, motor.tau);
    connect(motor.flange, rotor.flange_a);
    connect(rotor.flange_b, gear.flange_a);
    connect(frame.flange, motorBearing.flange_a);
    connect(motorBearing.flange_b, rotor.flange_a);
    connect(gear.flange_b, shaft.flange_a);
    connect(shaft.flange_b, load.flange_a);
    connect(frame.flange, bearing.flange_a);
    connect(bearing.flange_b, load.flange_b);
    connect(rotor.flange_b, tachMotor.flange);
    connect(load.flange_b, tachLoad.flange);
    connect(tachMotor.w, wMotor);
    connect(tachLoad.w, wLoad);
  end Spindle;
end Drive;
"""


def friction(w):
    """The load bearing's true torque: viscous plus dry friction with a sharp step."""
    return 0.1 * w + 0.15 * np.tanh(w / 0.01)


def multisine(t, fmin, fmax, n, amp, rng):
    f = np.exp(np.linspace(np.log(fmin), np.log(fmax), n)) * (1 + 0.05 * rng.standard_normal(n))
    u = sum(np.sin(2 * np.pi * fk * t + pk) for fk, pk in zip(f, rng.uniform(0, 2 * np.pi, n)))
    return amp * u / np.max(np.abs(u))


def drive(path, tau, seed):
    """The drive's measured speeds for the torque command ``tau`` (at 100 Hz, 1% noise)."""
    t = np.arange(0, 20.0001, 0.01)
    u = tau(t)
    J1, r, c, d, J2, dm = 0.002, 5, 40, 0.2, 0.05, 0.001

    def rhs(s, x):
        phm, wm, phl, wl = x
        ts = c * (phl - phm / r) + d * (wl - wm / r)      # the shaft's torque, load side
        return [wm, (np.interp(s, t, u) - dm * wm + ts / r) / J1, wl, (-ts - friction(wl)) / J2]

    x = solve_ivp(rhs, (0, 20), [0, 0, 0, 0], t_eval=t, method="LSODA", rtol=1e-9, atol=1e-11,
                  max_step=0.005).y
    rng = np.random.default_rng(seed)
    wm, wl = (y + rng.normal(0, 0.01 * np.std(y), len(y)) for y in (x[1], x[3]))
    path.write_text("time,tauCmd,wMotor,wLoad\n" + "\n".join(
        f"{a:.10g},{b:.10g},{c_:.10g},{e:.10g}" for a, b, c_, e in zip(t, u, wm, wl)) + "\n")


def test_dry_friction_in_a_geared_drive_comes_as_a_plain_law(tmp_path):
    rng = np.random.default_rng(1)
    train = multisine(np.arange(0, 20.0001, 0.01), 0.05, 2.0, 10, 0.2, rng)
    drive(tmp_path / "train.csv", lambda t: train, 11)
    levels = np.random.default_rng(7).uniform(-0.2, 0.2, 10)
    slow = multisine(np.arange(0, 20.0001, 0.01), 0.1, 1.0, 6, 0.1, np.random.default_rng(8))
    drive(tmp_path / "validate.csv", lambda t: 0.5 * levels[np.minimum((t // 2).astype(int), 9)] + slow, 12)
    report = discovered(tmp_path, "Drive.mo", "Drive.Spindle", DRIVE)
    cause = report["cause"]
    assert [c["component"] for c in report["causes"]] == ["bearing"]
    law = cause["law"]
    assert "tanh" in law["equation"]
    terms = cause["template"]["rhs"]        # the law's coefficients, then its shapes' scales
    assert np.count_nonzero(cause["w"][1:1 + len(terms)]) <= 2, law["equation"]
    # the law right away from the step (the sign convention: the curve is read against the
    # truth's odd law whichever way the flange's speed is counted)
    xs, fs = np.array(law["curve"]).T
    away = np.abs(xs) > 0.1
    truth = friction(xs) if np.dot(fs, friction(xs)) > 0 else -friction(xs)
    assert np.max(np.abs(fs - truth)[away]) < 0.05 * np.max(np.abs(truth))
    g = report["gain"]
    assert g["validation_rms_after"] <= 0.05 * g["validation_rms_before"], g
    assert g["train_rms_after"] < 1.1 * report["misfit"]["noise_estimate"], g     # at the noise
