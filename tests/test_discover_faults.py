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
import sys

import numpy as np
import pytest

from helpers import FAULTS, LIB
from mcl import hookimpl
from mcl.cli import main

sys.path.insert(0, str(FAULTS.parent))
from truths import ladder, save, shunt, slider  # noqa: E402  (examples/faults)


def discover(tmp_path, name, extra: str = "") -> dict:
    (tmp_path / "run.yaml").write_text(
        f"model:\n  sources: [{FAULTS}, {LIB}]\n  name: Faults.{name}\n"
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
    slider(tmp_path / "train.csv", 1, f)
    slider(tmp_path / "validate.csv", 2, f)
    report = discover(tmp_path, "Slider")
    cause = report["cause"]
    assert cause["component"] == "D" and cause["law"]["variable"] == "der(across)"
    assert "D.v_rel^3" in cause["law"]["equation"] and cause["law"]["equation"].startswith("D.f = ")
    # template orientation: dv = der(a.s - b.s) = -speed, i = a.f = -f: the odd law is the same
    assert law_error(cause, f) < 0.05
    assert_gain(report)


def test_coulomb_like_friction_gets_a_tanh_law(tmp_path):
    f = lambda v: 0.2 * v + 0.4 * np.tanh(v / 0.3)
    slider(tmp_path / "train.csv", 3, f)
    slider(tmp_path / "validate.csv", 4, f)
    report = discover(tmp_path, "Slider")
    cause = report["cause"]
    assert cause["component"] == "D" and "tanh" in cause["law"]["equation"]
    assert law_error(cause, f) < 0.05
    assert_gain(report)


def test_dry_friction_with_a_sharp_step_gets_a_tanh_law_at_its_component_alone(tmp_path):
    """Coulomb friction whose step at rest is far narrower than the speeds visited (0.01 m/s):
    the law is the damper's, with a Coulomb-like term, and right away from the step; no other
    component is blamed for what the rounded step leaves."""
    f = lambda v: 0.2 * v + 0.4 * np.tanh(v / 0.01)
    slider(tmp_path / "train.csv", 11, f)
    slider(tmp_path / "validate.csv", 12, f)
    report = discover(tmp_path, "Slider")
    cause = report["cause"]
    assert cause["component"] == "D" and "tanh" in cause["law"]["equation"]
    assert [c["component"] for c in report["causes"]] == ["D"]
    xs, fs = np.array(cause["law"]["curve"]).T
    away = np.abs(xs) > 0.1
    assert np.max(np.abs(fs - f(xs))[away]) < 0.05 * np.max(np.abs(f(xs)))
    assert_gain(report)


def test_voltage_dependent_capacitance(tmp_path):
    # C2(v) = 1 + 0.8 v^2: i = C2(v) v'
    law = lambda v2, i2: i2 / (1 + 0.8 * v2**2)
    ladder(tmp_path / "train.csv", 5, c2_rate=law)
    ladder(tmp_path / "validate.csv", 6, c2_rate=law)
    report = discover(tmp_path, "Ladder")
    cause = report["cause"]
    assert cause["component"] == "C2" and cause["law"]["family"] == "storage"
    assert "C2.v^2*der(C2.v)" in cause["law"]["equation"]
    assert_gain(report)


def test_leaky_capacitor(tmp_path):
    # i = C v' + G v with G = 0.4: an element missing from the model
    law = lambda v2, i2: i2 - 0.4 * v2
    ladder(tmp_path / "train.csv", 7, c2_rate=law)
    ladder(tmp_path / "validate.csv", 8, c2_rate=law)
    report = discover(tmp_path, "Ladder")
    cause = report["cause"]
    assert cause["component"] == "C2" and "der(C2.v)" in cause["law"]["equation"]
    assert_gain(report)


def test_sinh_shunt_is_distilled_from_a_neural_law(tmp_path):
    law = lambda v: 0.1 * np.sinh(v / 0.35)
    shunt(tmp_path / "train.csv", 9, law)
    shunt(tmp_path / "validate.csv", 10, law)
    report = discover(tmp_path, "Shunt")
    cause = report["cause"]
    assert cause["component"] == "Gs" and cause["law"]["family"] == "shape"
    assert law_error(cause, law) < 0.05
    assert_gain(report)


@pytest.mark.parametrize("method,irregular", [("simulation", False), ("full-discretisation", True)])
def test_outputs_at_two_rates(tmp_path, method, irregular):
    # y1 logged at a quarter of the rate of y2 (blank cells), on a regular or an irregular time
    # grid, fitted by simulation or by full discretisation; the fault is a cubic in R2
    r2 = lambda d: d / 2 + 0.3 * d**3
    ladder(tmp_path / "train.csv", 11, r2_current=r2, every=4, irregular=irregular)
    ladder(tmp_path / "validate.csv", 12, r2_current=r2, every=4, irregular=irregular)
    report = discover(tmp_path, "Ladder", f"refinement: {{method: {method}}}\n")
    cause = report["cause"]
    assert cause["component"] == "R2"
    assert law_error(cause, r2) < 0.05
    assert_gain(report)


def test_a_measured_column_may_name_any_model_variable(tmp_path):
    f = lambda v: 0.5 * v + 0.6 * v**3
    slider(tmp_path / "train.csv", 13, f, measure="M.v")
    slider(tmp_path / "validate.csv", 14, f, measure="M.v")
    report = discover(tmp_path, "SliderUnmeasured")
    assert report["outputs"] == ["M.v"]
    cause = report["cause"]
    assert cause["component"] == "D" and law_error(cause, f) < 0.05
    assert_gain(report)


def test_no_cause_when_the_best_candidate_does_not_help_on_validation(tmp_path):
    # the model is right; the training log carries a slow sensor drift that no component makes
    f = lambda v: 0.5 * v
    slider(tmp_path / "train.csv", 15, f)
    slider(tmp_path / "validate.csv", 16, f)
    data = np.genfromtxt(tmp_path / "train.csv", delimiter=",", names=True)
    drift = 0.3 * np.std(data["y"]) * np.sin(2 * np.pi * data["time"] / 30)
    save(tmp_path / "train.csv", {"time": data["time"], "u": data["u"], "y": data["y"] + drift})
    report = discover(tmp_path, "Slider")
    assert report["misfit"]["significant"]
    assert report["cause"] is None and report.get("no_cause")
    assert report["candidates"]          # the best candidates are still listed


def test_every_builtin_template_runs_through_mcl_run(tmp_path):
    """Pinned templates: the neural one (an equation in v and i, solved for i), the memory one
    and the hysteresis (a state of its own) go through the same run as the families do."""
    from mcl.api import registry

    f = lambda v: 0.5 * v + 0.6 * v**3
    slider(tmp_path / "train.csv", 17, f)
    slider(tmp_path / "validate.csv", 18, f)
    specs = {"polynomial": "{name: polynomial, lhs: [i], rhs: [dv, dv^3]}",
             "memory": "{name: memory, lhs: [i], rhs: [dv, dv^3]}",
             "neural": "{name: neural, hidden: 2, x: dv}",
             "hysteresis": "{name: hysteresis, rhs: [dv, dv^3, z], span: 0.5}"}
    assert set(specs) == set(registry().templates)          # a new built-in needs a line here
    for name, spec in specs.items():
        (tmp_path / "run.yaml").write_text(
            f"model:\n  sources: [{FAULTS}, {LIB}]\n  name: Faults.Slider\n"
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
    import mcl.services
    from mcl.registry import Registry

    monkeypatch.setattr(mcl.services, "_registry", Registry(extra=[KeepAllTerms()]))
    f = lambda v: 0.5 * v + 0.6 * v**3
    slider(tmp_path / "train.csv", 19, f)
    slider(tmp_path / "validate.csv", 20, f)
    report = discover(tmp_path, "Slider", "refinement: {method: keep-all-terms}\n")
    assert report["cause"]["component"] == "D"
    assert all(all(c["active"]) for c in report["candidates"] if c.get("family") != "shape")
