"""`mcl run`: discovery on data generated independently (SciPy), a null case, run-file errors."""
import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from helpers import LIB, RC_MODEL
from mcl.cli import main
from mcl.errors import ConfigError
from mcl.runfile import load_runfile

CIRCUIT = "package Circuit\n" + RC_MODEL + """
  model Divider "a second configuration of the same resistor: no capacitor, a 0.5 ohm feed"
    input Real u;
    output Real y;
    MCL.Electrical.VoltageSource V;
    MCL.Electrical.Ground G;
    MCL.Electrical.Resistor Rs(R = 0.5);
    MCL.Electrical.Resistor Rx(R = 2);
  equation
    V.u = u;
    connect(V.p, Rs.p);
    connect(Rs.n, Rx.p);
    connect(Rx.n, G.p);
    connect(V.n, G.p);
    y = Rx.v;
  end Divider;
end Circuit;
"""


def rc_data(path, seed, cubic):
    """The true circuit: Rx conducts i = 0.5 v + cubic v^3 (the nominal model says v / 2)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 20, 401)
    w, ph = rng.uniform(0.3, 2.5, 4), rng.uniform(0, 6, 4)
    u = lambda s: sum(np.sin(wk * s + pk) for wk, pk in zip(w, ph))
    rhs = lambda s, e: [((u(s) - e[0]) / 1.0 - 0.5 * e[0] - cubic * e[0] ** 3) / 0.5]
    y = solve_ivp(rhs, (0, 20), [0.0], t_eval=t, rtol=1e-10, atol=1e-12).y[0]
    y = y + rng.normal(0, 0.01 * np.std(y), len(y))
    np.savetxt(path, np.column_stack([t, u(t), y]), delimiter=",", header="time,u,y", comments="")


def setup_run(tmp_path, cubic):
    (tmp_path / "Circuit.mo").write_text(CIRCUIT)
    rc_data(tmp_path / "train.csv", 1, cubic)
    rc_data(tmp_path / "validate.csv", 2, cubic)
    (tmp_path / "run.yaml").write_text(
        f"model:\n  sources: [Circuit.mo, {LIB}]\n  name: Circuit.RC\n"
        "data:\n  train: train.csv\n  validate: validate.csv\nunknown: auto\noutput: out/rc\n")
    return tmp_path / "run.yaml"


def test_electrical_discovery_names_the_component_and_learns_the_law(tmp_path, capsys):
    run = setup_run(tmp_path, cubic=0.3)
    assert main(["run", str(run)]) == 0
    report = json.loads((tmp_path / "out/rc/report.json").read_text())
    assert report["misfit"]["significant"]
    cause = report["cause"]
    # Rx is in parallel with C: a capacitor leaking through a cubic conductance fits as well,
    # with a law chosen from a larger family; the evidence says it is not decisive
    assert cause["component"] == "Rx" and cause["evidence"]["strength"] in ("decisive", "strong", "positive")
    assert "Rx.v^3" in cause["effect"] and cause["law"]["equation"].startswith("Rx.i = ")
    xs, fs = np.array(cause["law"]["curve"]).T
    truth = 0.5 * xs + 0.3 * xs**3
    assert np.max(np.abs(fs - truth)) <= 0.05 * np.max(np.abs(truth))
    g = report["gain"]
    assert g["validation_rms_after"] <= 0.2 * g["validation_rms_before"]
    (mine,) = report["gain_per_output"].values()       # each output's own, beside its noise
    assert mine["validation_before"] == pytest.approx(g["validation_rms_before"], rel=1e-9)
    assert mine["train_before"] == pytest.approx(g["train_rms_before"], rel=1e-9)
    assert mine["validation_after"] <= 0.2 * mine["validation_before"] and mine["noise"] > 0
    assert (tmp_path / "out/rc" / cause["fmu"]).exists() and (tmp_path / "out/rc/report.html").exists()
    assert {s["component"] for s in report["screening"]} == {"R1", "C", "Rx"}   # all were tried
    assert {c["component"] for c in report["candidates"]} <= {"R1", "C", "Rx"}
    assert not (tmp_path / "out/rc.partial").exists()
    assert "cause: Rx" in capsys.readouterr().out


def test_null_case_names_no_cause(tmp_path):
    run = setup_run(tmp_path, cubic=0.0)
    run.write_text(run.read_text() + "report: {title: Null case, plots: false}\n")
    assert main(["run", str(run)]) == 0
    assert not (tmp_path / "out/rc/report.html").exists()
    report = json.loads((tmp_path / "out/rc/report.json").read_text())
    assert not report["misfit"]["significant"] and report["cause"] is None


def test_finished_run_is_not_overwritten(tmp_path):
    run = setup_run(tmp_path, cubic=0.0)
    assert main(["run", str(run)]) == 0
    assert main(["run", str(run)]) == 2          # refuses; --force replaces it whole
    assert main(["run", str(run), "--force"]) == 0


def test_run_file_problems_are_reported_together_with_lines(tmp_path):
    (tmp_path / "Circuit.mo").write_text(CIRCUIT)
    (tmp_path / "run.yaml").write_text(
        "model:\n  sources: [Circuit.mo, nope/]\n  name: Circuit.RC\n  colour: red\n"
        "data:\n  train: missing.csv\nunknwn: auto\noutput: out\n")
    with pytest.raises(ConfigError) as err:
        load_runfile(tmp_path / "run.yaml")
    lines = str(err.value).splitlines()
    assert any(":2: model.sources: 'nope/' does not exist" in line for line in lines)
    assert any(":4: model.colour: unknown key" in line for line in lines)
    assert any(":6: data.train: 'missing.csv' does not exist" in line for line in lines)
    assert any(":7: unknwn: unknown key (did you mean 'unknown'?)" in line for line in lines)


def test_data_problems_name_file_and_key(tmp_path):
    run = setup_run(tmp_path, cubic=0.3)
    (tmp_path / "train.csv").write_text("time,x,y\n0,1,2\n1,2,3\n")
    (tmp_path / "validate.csv").write_text("time,u,y\n0,1,2\n0,2,\n")
    with pytest.raises(ConfigError) as err:
        load_runfile(run)
    text = str(err.value)
    assert "data.train: train.csv lacks the model input column(s) u" in text
    assert "column(s) x of train.csv are not inputs or variables of Circuit.RC" in text
    assert "data.validate:" in text and "not strictly increasing" in text


def test_malformed_yaml_is_one_line(tmp_path, capsys):
    (tmp_path / "run.yaml").write_text("model: [unclosed\n")
    assert main(["run", str(tmp_path / "run.yaml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not valid YAML" in err[0] and "run.yaml:" in err[0]


def divider_data(path):
    """The divider with the true resistor: (u - e) / 0.5 = 0.5 e + 0.3 e^3, solved by SciPy."""
    from scipy.optimize import brentq

    t = np.linspace(0, 10, 201)
    u = 2.0 * np.sin(0.7 * t)
    e = np.array([brentq(lambda x: (uk - x) / 0.5 - 0.5 * x - 0.3 * x**3, -5, 5) for uk in u])
    np.savetxt(path, np.column_stack([t, u, e]), delimiter=",", header="time,u,y", comments="")


def test_second_configuration_resume_and_export(tmp_path, capsys):
    run = setup_run(tmp_path, cubic=0.3)
    divider_data(tmp_path / "divider.csv")
    run.write_text(run.read_text() + "second:\n  model: {sources: [Circuit.mo, " + str(LIB) +
                   "], name: Circuit.Divider}\n  data: divider.csv\n")
    assert main(["run", str(run)]) == 0
    out = tmp_path / "out/rc"
    report = json.loads((out / "report.json").read_text())
    second = report["cause"]["second_configuration"]
    assert second["component"] == "Rx" and second["rms_after"] <= 0.05 * second["rms_before"]
    # an interrupted run: the run directory is back to its partial state; the rerun reuses it
    (out / "report.json").unlink()
    out.rename(tmp_path / "out/rc.partial")
    capsys.readouterr()
    assert main(["run", str(run)]) == 0
    assert "already done" in capsys.readouterr().err
    assert json.loads((out / "report.json").read_text())["cause"]["component"] == "Rx"
    # export the learned resistor as a library and use it in a model of one's own
    assert main(["export", str(out), "-o", str(tmp_path / "lib"), "--name", "MyParts"]) == 0
    lib = tmp_path / "lib" / "MyParts"
    text = (lib / "package.mo").read_text()
    # a native class: the nominal interface, coefficients with units, the law and its range
    assert "extends MCL.Interfaces.TwoPin;" in text and "learned for v in [" in text
    assert 'parameter Real c2(unit="A/V3")' in text and '"coefficient of v^3"' in text
    (tmp_path / "Use.mo").write_text(
        "model Use\n  output Real y;\n  MCL.Electrical.Ground G;\n  MCL.Electrical.VoltageSource V;\n"
        f"  MyParts.{report['cause']['learned_class']} R;\nequation\n  V.u = 1;\n"
        "  connect(V.p, R.p);\n  connect(R.n, G.p);\n  connect(V.n, G.p);\n  y = R.i;\nend Use;\n")
    from mcl.api import compile_model, simulate
    from mcl.data import TimeSeries

    model = compile_model([LIB, lib, tmp_path / "Use.mo"], "Use")
    res = simulate(model, TimeSeries(np.linspace(0, 1, 11), np.zeros((11, 0)), []))
    assert res.output("y")[-1] == pytest.approx(0.8, rel=0.02)   # i = 0.5 + 0.3 at v = 1


def test_named_unknown_component(tmp_path):
    run = setup_run(tmp_path, cubic=0.3)
    run.write_text(run.read_text().replace("unknown: auto", "unknown: C"))
    assert main(["run", str(run)]) == 0
    report = json.loads((tmp_path / "out/rc/report.json").read_text())
    assert [c["component"] for c in report["candidates"]] == ["C"]    # only the named one
    # told that C is wrong, discovery finds the law that puts the parallel cubic leak into C
    # (storage family: i = C dv + g(v)), equivalent to the hidden cubic resistor in parallel
    eq = report["cause"]["law"]["equation"]
    assert "der(C.v)" in eq and "C.v^3" in eq
    run.write_text(run.read_text().replace("unknown: C", "unknown: Nope"))
    with pytest.raises(ConfigError, match="unknown: no component 'Nope'"):
        load_runfile(run)


def test_a_named_unknown_that_leaves_misfit_ends_the_search(tmp_path):
    """Told to look at C with a law that cannot hold the cubic leak (a linear one), misfit stays
    after C's law is put back: the next round has no component left to search (it used to try
    C again, whose terminals the law had replaced, and fail) and the run ends with C's law."""
    run = setup_run(tmp_path, cubic=0.3)
    run.write_text(run.read_text().replace("unknown: auto", "unknown: C\ntemplates:\n"
                                           "  - {name: polynomial, lhs: [i], rhs: [dv, v], family: storage}"))
    assert main(["run", str(run)]) == 0
    report = json.loads((tmp_path / "out/rc/report.json").read_text())
    assert [c["component"] for c in report["causes"]] == ["C"]
    assert "C.v" in report["cause"]["law"]["equation"]


def test_early_stop_weighs_parameters_not_only_rss(tmp_path):
    """A fit stops when another cannot be beaten: a smaller law is not stopped by a larger law's
    lower RSS (the criterion may prefer it), a larger law at the same component is stopped by a
    smaller one it cannot improve on, and a law far behind is stopped whatever its size (at
    another component, only 10x behind)."""
    from mcl.discovery.candidates import Context, Item, publish

    ctx = Context(None, {}, {}, None, None, 10, "bic", "simulation", str(tmp_path), n_obs=400)
    static, storage, other = Item("Rx", 0, {}), Item("Rx", 1, {}), Item("C", 1, {})
    publish(tmp_path, storage, 0.02252, k=6, dictionary=6)       # a 6-term law, lower RSS
    publish(tmp_path, other, 0.02253, k=6, dictionary=6)
    # 400 ln(0.02265/0.02252) = 2.3 behind in RSS, 3 parameters (18 in BIC) ahead: runs on
    assert not ctx.give_up(0.02265, 0.02270, static, k=3, dictionary=3)
    publish(tmp_path, static, 0.02279, k=2, dictionary=3)
    assert ctx.give_up(0.02275, 0.02276, storage, k=4, dictionary=6)       # can only prune back
    assert not ctx.give_up(0.02200, 0.02276, storage, k=4, dictionary=6)   # can improve on it
    assert ctx.give_up(0.0300, 0.0301, Item("Rx", 2, {}), k=2, dictionary=3)   # 400 ln(1.3) behind
    assert not ctx.give_up(0.0300, 0.0600, Item("Rx", 2, {}), k=2, dictionary=3)  # far from its optimum
    # at another component only 10x behind stops it: a local model's reach can be far off
    assert not ctx.give_up(0.0300, 0.0301, Item("R1", 0, {}), k=2, dictionary=3)
    assert ctx.give_up(0.300, 0.301, Item("R1", 0, {}), k=2, dictionary=3)


def test_near_its_optimum_a_law_stops_behind_a_parallel_component_s_law(tmp_path):
    """A spring and a damper between the same two flanges carry the same effect: near its own
    optimum, the damper's law stops when it cannot come within the decisive margin of the
    spring's; a component elsewhere (another hypothesis) runs on unless 10x behind."""
    from mcl.discovery.candidates import Context, Item, publish

    ctx = Context(None, {}, {}, None, None, 10, "bic", "simulation", str(tmp_path), n_obs=400,
                  kin={"S": {"S", "D"}, "D": {"D", "S"}, "R": {"R"}})
    publish(tmp_path, Item("S", 0, {}), 0.0200, k=3, dictionary=3)
    assert ctx.give_up(0.0260, 0.0270, Item("D", 1, {}), k=5, dictionary=6)
    assert not ctx.give_up(0.0260, 0.0270, Item("R", 0, {}), k=3, dictionary=3)
    assert ctx.give_up(0.2100, 0.2200, Item("R", 0, {}), k=3, dictionary=3)


def test_near_its_optimum_a_larger_law_stops_where_its_component_s_smaller_law_reached_the_noise(tmp_path):
    """Near its own optimum, a storage law that the Gauss-Newton model says could still gain a
    little more than one parameter's cost stops when the static law at the same component has
    reached the noise (its pruning could at best come back to it); far from its optimum, beside
    a smaller law above the noise, or at another component, it runs on."""
    from mcl.discovery.candidates import Context, Item, publish

    ctx = Context(None, {}, {}, None, None, 10, "bic", "simulation", str(tmp_path), n_obs=400, floor=0.020)
    static, storage, other = Item("Rx", 0, {}), Item("Rx", 1, {}), Item("C", 1, {})
    publish(tmp_path, static, 0.0300, k=2, dictionary=3)          # 1.5x the noise's RSS: not there
    assert not ctx.give_up(0.0290, 0.0295, storage, k=6, dictionary=6)
    publish(tmp_path, static, 0.0210, k=2, dictionary=3)          # at the noise
    assert ctx.give_up(0.0205, 0.0210, storage, k=6, dictionary=6)
    assert not ctx.give_up(0.0205, 0.0600, storage, k=6, dictionary=6)   # far from its optimum
    assert not ctx.give_up(0.0205, 0.0210, other, k=6, dictionary=6)


def test_the_first_fit_is_the_top_component_s_law_of_fewest_terms():
    from mcl.discovery.candidates import Item
    from mcl.discovery.search import simplest_first
    from mcl.templates import PolynomialTemplate

    terms = {0: ["v", "v^3"], 1: ["dv", "v*dv", "v", "v^3"]}
    todo = [Item("R2", 1, {}), Item("R3", 1, {}), Item("R2", 0, {}), Item("R1", 0, {})]
    templates = {it.key: PolynomialTemplate(lhs=["i"], rhs=terms[it.index]) for it in todo}
    order = simplest_first(todo, templates)
    assert [(it.component, it.index) for it in order] == [("R2", 0), ("R2", 1), ("R3", 1), ("R1", 0)]


def test_a_fit_reads_only_the_waves_before_its_own(tmp_path):
    """Fits run in waves of as many as there are workers; a fit of one wave is never stopped by
    another of the same wave (which of them finishes first is a race), only by earlier waves."""
    import dataclasses

    from mcl.discovery.candidates import Context, Item, publish

    ctx = Context(None, {}, {}, None, None, 10, "bic", "simulation", str(tmp_path), n_obs=400)
    lead, behind = Item("R1", 0, {}), Item("R1", 1, {})
    publish(tmp_path, lead, 0.0200, k=2, dictionary=3, wave="w1")
    assert not dataclasses.replace(ctx, wave="w1").give_up(0.0300, 0.0301, behind, k=2, dictionary=3)
    assert dataclasses.replace(ctx, wave="w2").give_up(0.0300, 0.0301, behind, k=2, dictionary=3)


def test_the_first_fit_runs_alone_however_few_the_fits():
    """The most promising fit is a wave of its own, so that every other fit reads how far it
    got, also when there are no more fits than workers (two fits on two workers ran side by
    side: the loser to its end)."""
    from mcl.discovery.search import waves

    assert waves(2, 2, reading=True) == [(0, 1), (1, 2)]
    assert waves(5, 2, reading=True) == [(0, 1), (1, 3), (3, 5)]
    assert waves(1, 2, reading=True) == [(0, 1)]
    assert waves(3, 2, reading=False) == [(0, 3)]      # no early stops: nothing to read


def test_a_failed_law_of_the_cause_s_own_component_leaves_the_cause_decided():
    """Only another component that could not be evaluated puts the cause in doubt; a second
    law of the named component that failed to fit is a question of which law, not which part."""
    from types import SimpleNamespace

    from mcl.discovery.verdict import weigh_unevaluated

    best = {"component": "nl", "score": -70000.0}
    spec = SimpleNamespace(criterion="bic")
    own = [{"component": "nl", "template": {"name": "polynomial"}, "failed": "FitError"}]
    evidence = {"strength": "decisive"}
    weigh_unevaluated(evidence, best, own, [], spec, 8192)
    assert evidence == {"strength": "decisive"}
    other = [{"component": "C", "template": {"name": "polynomial"}, "failed": "FitError"}]
    weigh_unevaluated(evidence, best, other, [], spec, 8192)
    assert evidence["strength"] == "undecided: C could not be evaluated" and evidence["unevaluated"] == ["C"]


def test_laws_of_one_component_the_data_do_not_choose_between_are_named_together():
    """A cause's component may follow two laws equally well (a tank's outflow as a cubic or as
    exp plus Torricelli): the verdict names the best and lists those within the criterion's
    tie as as good, with their score differences; a law further behind, or another
    component's, is not listed."""
    from types import SimpleNamespace

    from mcl.discovery.verdict import EQUAL, decide

    law = lambda comp, score, eq: {"component": comp, "score": score, "family": "shape", "equation": eq,
                                   "template": {"name": "polynomial"}}
    cands = [law("out1", -201.5, "i = c*va^3"), law("out1", -201.5 + 0.5 * EQUAL, "i = a*sqrt(va)"),
             law("out1", -201.5 + 2 * EQUAL, "i = b*sinh(va)"), law("out2", -201.0, "i = d*v^3")]
    spec = SimpleNamespace(criterion="bic")
    causes, why_not, _ = decide(cands, spec, np.ones(100), None, {}, None, 1e3)
    assert why_not is None and causes[0]["equation"] == "i = c*va^3"
    assert [(a["equation"], a["score_difference"]) for a in causes[0]["alternatives"]] == [("i = a*sqrt(va)", 0.5 * EQUAL)]


def test_screening_keeps_laws_predicted_as_a_tie_with_the_last_one_kept():
    """The screening's linearised prediction cannot part two laws predicted within a few percent
    (a drive's two bearings, one seen through a gear): the one just past the limit is fitted
    too, where one predicted far behind is not, and where many tie, the first of them only."""
    from mcl.discovery.search import promising

    predicted = [("motorBearing", 3130.8), ("bearing", 3152.9), ("motorBearing", 3270.7), ("bearing", 3307.8),
                 ("shaft", 36755.6)]
    screening = [{"component": c, "predicted_rss": rss, "n_params": 7} for c, rss in predicted]
    assert sorted(promising(screening, 3)) == [0, 1, 2, 3]
    apart = [{"component": c, "predicted_rss": rss, "n_params": 7} for c, rss in [("a", 100), ("b", 101), ("a", 112)]]
    assert sorted(promising(apart, 2)) == [0, 1]
    # many alike (a ladder's sections): the first past the limit only
    alike = [{"component": f"R{j}", "predicted_rss": 100 + 0.1 * j, "n_params": 3} for j in range(8)]
    assert sorted(promising(alike, 3)) == [0, 1, 2, 3]
