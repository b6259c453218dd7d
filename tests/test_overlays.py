"""MSL components that rumoca 0.10.2 misreads, run through mcl's overlays (equivalent rewrites of
the library's text in mcl's own link tree), each checked against a solution derived by hand."""
from pathlib import Path

import numpy as np
import pytest

import mcl
from mcl.data import TimeSeries

MSL = Path(__file__).resolve().parents[2] / "shared" / "msl"
pytestmark = pytest.mark.skipif(not (MSL / "Modelica" / "package.mo").is_file(), reason=f"the MSL is not at {MSL}")


def _run(tmp_path, monkeypatch, text: str, name: str, t):
    monkeypatch.setenv("MODELICAPATH", str(MSL))
    (tmp_path / f"{name}.mo").write_text(text)
    model = mcl.compile_model([tmp_path / f"{name}.mo"], name)
    res = mcl.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), t_out=t)
    assert res.ok, res.reason
    return lambda n: res.states[:, model.ode.x_names.index(n)]


def test_a_sliding_mass_with_coulomb_friction_stops_and_sticks(tmp_path, monkeypatch):
    """MassWithStopAndFriction extends a class nested in itself, which rumoca misreads; the
    overlay writes that class's contents in the model. A block launched at 3 m/s on a surface
    with 4 N of Coulomb friction (m = 2 kg) decelerates at 2 m/s², stops at 1.5 s after
    2.25 m, and stays stuck."""
    state = _run(tmp_path, monkeypatch, """
model Slide
  import Modelica.Mechanics.Translational;
  Translational.Components.MassWithStopAndFriction brick(m = 2, F_prop = 0, F_Coulomb = 4,
    F_Stribeck = 0, fexp = 0, L = 0, smax = 100, smin = -100,
    s(start = 0, fixed = true), v(start = 3, fixed = true));
end Slide;
""", "Slide", t := np.linspace(0.0, 3.0, 31))
    tc = np.minimum(t, 1.5)
    assert np.abs(state("brick.v") - (3 - 2 * tc)).max() < 1e-6
    assert np.abs(state("brick.s") - (3 * tc - tc ** 2)).max() < 1e-4        # of 2.25 m (the default tolerances)


def test_a_lossy_gear_passes_half_the_power(tmp_path, monkeypatch):
    """LossyGear's parameters bound to the two-output Vectors.interpolate, which rumoca evaluates
    as arrays; the overlay calls it through a one-output function. A torque of 3 N.m on J1 = 1
    drives J2 = 1 through a gear of efficiency 0.5 (ratio 1): J1 w' = 3 - tau_a and
    J2 w' = 0.5 tau_a, so once it moves both accelerate at 3/(J1 + J2/0.5) = 1 rad/s²."""
    state = _run(tmp_path, monkeypatch, """
model Gearbox
  import Modelica.Mechanics.Rotational;
  Rotational.Sources.ConstantTorque drive(tau_constant = 3);
  Rotational.Components.Inertia J1(J = 1, phi(start = 0, fixed = true), w(start = 0, fixed = true));
  Rotational.Components.LossyGear gear(ratio = 1, lossTable = [0, 0.5, 0.5, 0, 0]);
  Rotational.Components.Inertia J2(J = 1);
equation
  connect(drive.flange, J1.flange_a);
  connect(J1.flange_b, gear.flange_a);
  connect(gear.flange_b, J2.flange_a);
end Gearbox;
""", "Gearbox", t := np.linspace(0.0, 2.0, 21))
    assert np.polyfit(t[t > 0.5], state("J1.w")[t > 0.5], 1)[0] == pytest.approx(1.0, rel=1e-4)
