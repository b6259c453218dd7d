"""Discovery of the faults a user does not announce: ``unknown: auto`` and no templates.

Each truth is a hand-derived ODE solved by SciPy (never by mcl), with one hidden effect:
a damper cubic in the speed, Coulomb-like friction (tanh), a capacitor whose capacitance depends
on its voltage, a capacitor that leaks, a shunt with a sinh law; then data the way logs come:
two outputs at different rates (blank cells), a column naming a model variable that is not a
declared output. Each test names the component, checks the law over the visited range where it
is a function of one variable, and the gain on held-out data; an effect that is not a component's
(a sensor artefact in the training data only) gives no cause.
"""
import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from helpers import LIB
from mcl import hookimpl
from mcl.cli import main

SYSTEMS = """
package Faults
  model Slider "a mass on a spring and a damper, pushed by a force"
    input Real u;
    output Real y "position";
    MCL.Translational.Fixed wall;
    MCL.Translational.Force push;
    MCL.Translational.Mass M(m = 1.2);
    MCL.Translational.Spring S(c = 3);
    MCL.Translational.Damper D(d = 0.5);
  equation
    push.u = u;
    connect(wall.flange, push.flange_a);
    connect(push.flange_b, M.flange_a);
    connect(wall.flange, S.flange_a);
    connect(S.flange_b, M.flange_a);
    connect(wall.flange, D.flange_a);
    connect(D.flange_b, M.flange_a);
    y = M.s;
  end Slider;
  model SliderUnmeasured "the same, with no declared output: the data names M.v"
    input Real u;
    MCL.Translational.Fixed wall;
    MCL.Translational.Force push;
    MCL.Translational.Mass M(m = 1.2);
    MCL.Translational.Spring S(c = 3);
    MCL.Translational.Damper D(d = 0.5);
  equation
    push.u = u;
    connect(wall.flange, push.flange_a);
    connect(push.flange_b, M.flange_a);
    connect(wall.flange, S.flange_a);
    connect(S.flange_b, M.flange_a);
    connect(wall.flange, D.flange_a);
    connect(D.flange_b, M.flange_a);
  end SliderUnmeasured;
  model Ladder "two RC sections: u - R1 - n1 (C1) - R2 - n2 (C2)"
    input Real u;
    output Real y1 "voltage of n1";
    output Real y2 "voltage of n2";
    MCL.Electrical.VoltageSource V;
    MCL.Electrical.Ground G;
    MCL.Electrical.Resistor R1(R = 1);
    MCL.Electrical.Capacitor C1(C = 0.5);
    MCL.Electrical.Resistor R2(R = 2);
    MCL.Electrical.Capacitor C2(C = 1);
  equation
    V.u = u;
    connect(V.p, R1.p);
    connect(R1.n, C1.p);
    connect(C1.p, R2.p);
    connect(R2.n, C2.p);
    connect(C1.n, G.p);
    connect(C2.n, G.p);
    connect(V.n, G.p);
    y1 = C1.v;
    y2 = C2.v;
  end Ladder;
  model Shunt "u - R1 - node (C) with a shunt conductor Gs"
    input Real u;
    output Real y;
    MCL.Electrical.VoltageSource V;
    MCL.Electrical.Ground G;
    MCL.Electrical.Resistor R1(R = 1);
    MCL.Electrical.Capacitor C(C = 0.2);
    MCL.Electrical.Conductor Gs(G = 0.5);
  equation
    V.u = u;
    connect(V.p, R1.p);
    connect(R1.n, C.p);
    connect(R1.n, Gs.p);
    connect(C.n, G.p);
    connect(Gs.n, G.p);
    connect(V.n, G.p);
    y = C.v;
  end Shunt;
end Faults;
"""


def excitation(rng, amplitude, n=4, lo=0.3, hi=2.0):
    w, ph = rng.uniform(lo, hi, n), rng.uniform(0, 6, n)
    return lambda s: sum(amplitude * np.sin(wk * s + pk) for wk, pk in zip(w, ph))


def save(path, columns: dict):
    """A CSV file; NaN is written as a blank cell (not measured)."""
    names = list(columns)
    rows = np.column_stack([columns[n] for n in names])
    lines = [",".join(names)] + [",".join("" if np.isnan(v) else repr(float(v)) for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")


def noisy(rng, y, level=0.01):
    return y + rng.normal(0, level * np.std(y), len(y))


def slider_data(path, seed, friction, measure="y"):
    """m x'' = u - 3 x - friction(x'), x(0) = x'(0) = 0."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 30, 1201)
    u = excitation(rng, 1.5)
    sol = solve_ivp(lambda s, x: [x[1], (u(s) - 3 * x[0] - friction(x[1])) / 1.2], (0, 30), [0, 0],
                    t_eval=t, rtol=1e-10, atol=1e-12)
    y = sol.y[0] if measure == "y" else sol.y[1]
    save(path, {"time": t, "u": u(t), measure: noisy(rng, y)})
    return sol.y[1]


def ladder_data(path, seed, c2_current, slow=1):
    """C1 v1' = (u - v1)/1 - (v1 - v2)/2;  c2_current(v2, v2') = (v1 - v2)/2, solved for v2'."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 30, 1201)
    u = excitation(rng, 1.2, lo=0.2, hi=1.5)

    def rhs(s, x):
        v1, v2 = x
        i2 = (v1 - v2) / 2
        return [((u(s) - v1) - i2) / 0.5, c2_current(v2, i2)]

    sol = solve_ivp(rhs, (0, 30), [0, 0], t_eval=t, rtol=1e-10, atol=1e-12)
    y1, y2 = noisy(rng, sol.y[0]), noisy(rng, sol.y[1])
    y1[np.arange(len(t)) % slow != 0] = np.nan          # logged at 1/slow of the rate
    save(path, {"time": t, "u": u(t), "y1": y1, "y2": y2})


def shunt_data(path, seed, shunt):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 20, 1001)
    u = excitation(rng, 1.0, lo=0.3, hi=2.5)
    sol = solve_ivp(lambda s, v: [((u(s) - v[0]) - shunt(v[0])) / 0.2], (0, 20), [0], t_eval=t,
                    rtol=1e-10, atol=1e-12)
    save(path, {"time": t, "u": u(t), "y": noisy(rng, sol.y[0])})


def discover(tmp_path, name, extra: str = "") -> dict:
    (tmp_path / "Faults.mo").write_text(SYSTEMS)
    (tmp_path / "run.yaml").write_text(
        f"model:\n  sources: [Faults.mo, {LIB}]\n  name: Faults.{name}\n"
        "data:\n  train: train.csv\n  validate: validate.csv\nunknown: auto\noutput: out\n" + extra)
    assert main(["run", str(tmp_path / "run.yaml")]) == 0
    return json.loads((tmp_path / "out/report.json").read_text())


def law_error(cause, truth) -> float:
    """Largest deviation of the learned curve from the truth over the visited range, relative."""
    xs, fs = np.array(cause["law"]["curve"]).T
    return float(np.max(np.abs(fs - truth(xs))) / np.max(np.abs(truth(xs))))


def assert_gain(report, factor=0.2):
    g = report["gain"]
    assert g["validation_rms_after"] <= factor * g["validation_rms_before"], g


def test_damper_cubic_in_the_speed(tmp_path):
    f = lambda v: 0.5 * v + 0.6 * v**3
    slider_data(tmp_path / "train.csv", 1, f)
    slider_data(tmp_path / "validate.csv", 2, f)
    report = discover(tmp_path, "Slider")
    cause = report["cause"]
    assert cause["component"] == "D" and cause["law"]["variable"] == "der(across)"
    assert "D.v_rel^3" in cause["law"]["equation"] and cause["law"]["equation"].startswith("D.f = ")
    # template orientation: dv = der(a.s - b.s) = -speed, i = a.f = -f: the odd law is the same
    assert law_error(cause, f) < 0.05
    assert_gain(report)


def test_coulomb_like_friction_gets_a_tanh_law(tmp_path):
    f = lambda v: 0.2 * v + 0.4 * np.tanh(v / 0.3)
    slider_data(tmp_path / "train.csv", 3, f)
    slider_data(tmp_path / "validate.csv", 4, f)
    report = discover(tmp_path, "Slider")
    cause = report["cause"]
    assert cause["component"] == "D" and "tanh" in cause["law"]["equation"]
    assert law_error(cause, f) < 0.05
    assert_gain(report)


def test_voltage_dependent_capacitance(tmp_path):
    # C2(v) = 1 + 0.8 v^2: i = C2(v) v'
    law = lambda v2, i2: i2 / (1 + 0.8 * v2**2)
    ladder_data(tmp_path / "train.csv", 5, law)
    ladder_data(tmp_path / "validate.csv", 6, law)
    report = discover(tmp_path, "Ladder")
    cause = report["cause"]
    assert cause["component"] == "C2" and cause["law"]["family"] == "storage"
    assert "C2.v^2*der(C2.v)" in cause["law"]["equation"]
    assert_gain(report)


def test_leaky_capacitor(tmp_path):
    # i = C v' + G v with G = 0.4: an element missing from the model
    law = lambda v2, i2: i2 - 0.4 * v2
    ladder_data(tmp_path / "train.csv", 7, law)
    ladder_data(tmp_path / "validate.csv", 8, law)
    report = discover(tmp_path, "Ladder")
    cause = report["cause"]
    assert cause["component"] == "C2" and "der(C2.v)" in cause["law"]["equation"]
    assert_gain(report)


def test_sinh_shunt_is_distilled_from_a_neural_law(tmp_path):
    shunt = lambda v: 0.1 * np.sinh(v / 0.35)
    shunt_data(tmp_path / "train.csv", 9, shunt)
    shunt_data(tmp_path / "validate.csv", 10, shunt)
    report = discover(tmp_path, "Shunt")
    cause = report["cause"]
    assert cause["component"] == "Gs" and cause["law"]["family"] == "shape"
    assert law_error(cause, shunt) < 0.05
    assert_gain(report)


@pytest.mark.parametrize("method,irregular", [("simulation", False), ("full-discretisation", True)])
def test_outputs_at_two_rates(tmp_path, method, irregular):
    # y1 logged at a quarter of the rate of y2 (blank cells), on a regular or an irregular time
    # grid, fitted by simulation or by full discretisation; the fault is a cubic in R2
    def data(path, seed):
        rng = np.random.default_rng(seed)
        t = np.sort(np.r_[0, rng.uniform(0, 30, 1199), 30]) if irregular else np.linspace(0, 30, 1201)
        u = excitation(rng, 1.2, lo=0.2, hi=1.5)

        def rhs(s, x):
            v1, v2 = x
            d = v1 - v2
            i2 = d / 2 + 0.3 * d**3                   # the hidden effect in R2
            return [((u(s) - v1) - i2) / 0.5, i2 / 1.0]

        sol = solve_ivp(rhs, (0, 30), [0, 0], t_eval=t, rtol=1e-10, atol=1e-12)
        y1, y2 = noisy(rng, sol.y[0]), noisy(rng, sol.y[1])
        y1[np.arange(len(t)) % 4 != 0] = np.nan
        save(path, {"time": t, "u": u(t), "y1": y1, "y2": y2})

    data(tmp_path / "train.csv", 11)
    data(tmp_path / "validate.csv", 12)
    report = discover(tmp_path, "Ladder", f"refinement: {{method: {method}}}\n")
    cause = report["cause"]
    assert cause["component"] == "R2"
    assert law_error(cause, lambda d: d / 2 + 0.3 * d**3) < 0.05
    assert_gain(report)


def test_a_measured_column_may_name_any_model_variable(tmp_path):
    f = lambda v: 0.5 * v + 0.6 * v**3
    slider_data(tmp_path / "train.csv", 13, f, measure="M.v")
    slider_data(tmp_path / "validate.csv", 14, f, measure="M.v")
    report = discover(tmp_path, "SliderUnmeasured")
    assert report["outputs"] == ["M.v"]
    cause = report["cause"]
    assert cause["component"] == "D" and law_error(cause, f) < 0.05
    assert_gain(report)


def test_no_cause_when_the_best_candidate_does_not_help_on_validation(tmp_path):
    # the model is right; the training log carries a slow sensor drift that no component makes
    f = lambda v: 0.5 * v
    slider_data(tmp_path / "train.csv", 15, f)
    slider_data(tmp_path / "validate.csv", 16, f)
    data = np.genfromtxt(tmp_path / "train.csv", delimiter=",", names=True)
    drift = 0.3 * np.std(data["y"]) * np.sin(2 * np.pi * data["time"] / 30)
    save(tmp_path / "train.csv", {"time": data["time"], "u": data["u"], "y": data["y"] + drift})
    report = discover(tmp_path, "Slider")
    assert report["misfit"]["significant"]
    assert report["cause"] is None and report.get("no_cause")
    assert report["candidates"]          # the best candidates are still listed


def test_every_builtin_template_runs_through_mcl_run(tmp_path):
    """Pinned templates: the neural one (an equation in v and i, solved for i) and the memory
    one go through the same run as the families do."""
    from mcl.api import registry

    f = lambda v: 0.5 * v + 0.6 * v**3
    slider_data(tmp_path / "train.csv", 17, f)
    slider_data(tmp_path / "validate.csv", 18, f)
    (tmp_path / "Faults.mo").write_text(SYSTEMS)
    specs = {"polynomial": "{name: polynomial, lhs: [i], rhs: [dv, dv^3]}",
             "memory": "{name: memory, lhs: [i], rhs: [dv, dv^3]}",
             "neural": "{name: neural, hidden: 2, x: dv}"}
    assert set(specs) == set(registry().templates)          # a new built-in needs a line here
    for name, spec in specs.items():
        (tmp_path / "run.yaml").write_text(
            f"model:\n  sources: [Faults.mo, {LIB}]\n  name: Faults.Slider\n"
            f"data:\n  train: train.csv\n  validate: validate.csv\nunknown: D\noutput: out-{name}\n"
            f"templates:\n  - {spec}\n")
        assert main(["run", str(tmp_path / "run.yaml")]) == 0, name
        report = json.loads((tmp_path / f"out-{name}/report.json").read_text())
        assert report["cause"]["component"] == "D", name
        assert_gain(report, 0.5)


class KeepAllTerms:
    """A third-party candidate fitter (hook mcl_fitters): the simulation route without pruning."""

    @hookimpl
    def mcl_fitters(self):
        from mcl.discovery.fitters import SimulationFitter

        class NoPrune(SimulationFitter):
            name = "keep-all-terms"

            def fit(self, *args, **kw):
                return super().fit(*args, **{**kw, "prune": False})

        return [NoPrune]


def test_a_third_party_fitter_is_chosen_by_the_run_file(tmp_path, monkeypatch):
    import mcl.api
    from mcl.registry import Registry

    monkeypatch.setattr(mcl.api, "_registry", Registry(extra=[KeepAllTerms()]))
    f = lambda v: 0.5 * v + 0.6 * v**3
    slider_data(tmp_path / "train.csv", 19, f)
    slider_data(tmp_path / "validate.csv", 20, f)
    report = discover(tmp_path, "Slider", "refinement: {method: keep-all-terms}\n")
    assert report["cause"]["component"] == "D"
    assert all(all(c["active"]) for c in report["candidates"] if c.get("family") != "shape")
