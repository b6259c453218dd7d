"""Discovery in the rotational and thermal domains, with data from SciPy truths.

Rotational: the load bearing's friction has a cubic term in the *speed* (a law in a derivative
of the across variable, angle) and only the motor speed is measured, on the far side of the shaft.
Thermal: the surface film conducts more than linearly (a convection-like quadratic term).
"""
import json

import numpy as np
from scipy.integrate import solve_ivp

from helpers import LIB
from mcl.cli import main

SYSTEMS = """
package Plants
  model Drive "two inertias on a shaft; the model believes the load bearing is a linear damper"
    input Real u;
    output Real y "motor speed";
    MCL.Rotational.Fixed housing;
    MCL.Rotational.Torque motor;
    MCL.Rotational.Inertia J1(J = 0.5);
    MCL.Rotational.Spring shaft(c = 20);
    MCL.Rotational.Inertia J2(J = 1.5);
    MCL.Rotational.Damper bearing(d = 0.4);
  equation
    motor.u = u;
    connect(housing.flange, motor.flange_a);
    connect(motor.flange_b, J1.flange_a);
    connect(J1.flange_b, shaft.flange_a);
    connect(shaft.flange_b, J2.flange_a);
    connect(J2.flange_b, bearing.flange_b);
    connect(housing.flange, bearing.flange_a);
    y = J1.w;
  end Drive;
  model Wall "heated two-layer wall; the model believes the surface film is linear"
    input Real u;
    input Real T_amb;
    output Real y;
    MCL.Thermal.PrescribedHeatFlow heater;
    MCL.Thermal.HeatCapacitor core(C = 200, T(start = 293.15));
    MCL.Thermal.ThermalConductor wall(G = 5);
    MCL.Thermal.HeatCapacitor surface(C = 100, T(start = 293.15));
    MCL.Thermal.ThermalConductor film(G = 2);
    MCL.Thermal.PrescribedTemperature ambient;
  equation
    heater.u = u;
    ambient.u = T_amb;
    connect(heater.port, core.port);
    connect(core.port, wall.port_a);
    connect(wall.port_b, surface.port);
    connect(surface.port, film.port_a);
    connect(film.port_b, ambient.port);
    y = surface.T;
  end Wall;
end Plants;
"""


def drive_data(path, seed):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 20, 801)
    w, ph = rng.uniform(0.3, 2.0, 4), rng.uniform(0, 6, 4)
    u = lambda s: sum(1.5 * np.sin(wk * s + pk) for wk, pk in zip(w, ph))

    def rhs(s, x):
        p1, p2, w1, w2 = x
        shaft = 20 * (p1 - p2)
        friction = 0.4 * w2 + 0.8 * w2**3          # the hidden effect
        return [w1, w2, (u(s) - shaft) / 0.5, (shaft - friction) / 1.5]

    sol = solve_ivp(rhs, (0, 20), np.zeros(4), t_eval=t, rtol=1e-10, atol=1e-12)
    y = sol.y[2] + rng.normal(0, 0.01 * np.std(sol.y[2]), len(t))
    np.savetxt(path, np.column_stack([t, u(t), y]), delimiter=",", header="time,u,y", comments="")
    return sol.y[3]


def wall_data(path, seed):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 3000, 601)
    q = lambda s: 150 + 120 * np.sin(2 * np.pi * s / (900 + 200 * seed))
    amb = lambda s: 283 + 4 * np.sin(2 * np.pi * s / 1700)

    def rhs(s, T):
        flow = 5 * (T[0] - T[1])
        d = T[1] - amb(s)
        film = 2 * d + 0.05 * d**2                    # the hidden effect
        return [(q(s) - flow) / 200, (flow - film) / 100]

    sol = solve_ivp(rhs, (0, 3000), [293.15, 293.15], t_eval=t, rtol=1e-10, atol=1e-10)
    y = sol.y[1] + rng.normal(0, 0.01 * np.std(sol.y[1]), len(t))
    np.savetxt(path, np.column_stack([t, q(t), amb(t), y]), delimiter=",", header="time,u,T_amb,y",
               comments="")


def run(tmp_path, name, templates):
    (tmp_path / "Plants.mo").write_text(SYSTEMS)
    (tmp_path / "run.yaml").write_text(
        f"model:\n  sources: [Plants.mo, {LIB}]\n  name: Plants.{name}\n"
        f"data:\n  train: train.csv\n  validate: validate.csv\nunknown: auto\noutput: out\n"
        f"templates:\n" + "".join(f"  - {t}\n" for t in templates))
    assert main(["run", str(tmp_path / "run.yaml")]) == 0
    return json.loads((tmp_path / "out/report.json").read_text())


def test_rotational_law_in_a_derivative_seen_from_the_far_side(tmp_path):
    drive_data(tmp_path / "train.csv", 1)
    drive_data(tmp_path / "validate.csv", 2)
    report = run(tmp_path, "Drive", ["{name: polynomial, lhs: [i], rhs: [v, v^2, v^3]}",
                                     "{name: memory, lhs: [i], rhs: [dv, dv^2, dv^3]}"])
    cause = report["cause"]
    assert cause["component"] == "bearing" and cause["evidence"]["strength"] in ("decisive", "strong")
    assert "bearing.w_rel" in cause["law"]["equation"] and cause["law"]["variable"] == "der(across)"
    best = report["candidates"][0]
    coef = np.asarray(best["w"]) * np.asarray(best["active"])
    speed = np.linspace(-1, 1, 21)
    # i = flow into flange_a = the bearing torque; in terms of dv = d(a.phi - b.phi)/dt = -w2
    learned = (coef[1] * (-speed) + coef[2] * speed**2 + coef[3] * (-speed) ** 3) / coef[0]
    truth = -(0.4 * speed + 0.8 * speed**3)
    assert np.max(np.abs(learned - truth)) <= 0.05 * np.max(np.abs(truth))
    g = report["gain"]
    assert g["validation_rms_after"] <= 0.2 * g["validation_rms_before"]


def test_thermal_film_law(tmp_path):
    wall_data(tmp_path / "train.csv", 1)
    wall_data(tmp_path / "validate.csv", 2)
    report = run(tmp_path, "Wall", ["{name: polynomial, lhs: [i], rhs: [v, v^2, v^3]}"])
    cause = report["cause"]
    assert cause["component"] == "film"
    xs, fs = np.array(cause["law"]["curve"]).T
    truth = 2 * xs + 0.05 * xs**2
    assert np.max(np.abs(fs - truth)) <= 0.05 * np.max(np.abs(truth))
    g = report["gain"]
    assert g["validation_rms_after"] <= 0.2 * g["validation_rms_before"]
