"""Refinement by full discretisation (paper 004) of a candidate inside `mcl run`."""
import json

import numpy as np
import pytest

from helpers import LIB
from mcl.cli import main
from test_discover import CIRCUIT, rc_data, setup_run


def test_refine_learns_and_prunes_the_hidden_law(tmp_path):
    from mcl.api import compile_model
    from mcl.data import read_csv
    from mcl.graph import build_graph
    from mcl.refine import refine
    from mcl.swap import swap_component
    from mcl.templates import PolynomialTemplate

    (tmp_path / "Circuit.mo").write_text(CIRCUIT)
    rc_data(tmp_path / "train.csv", 1, 0.3)
    graph = build_graph([LIB, tmp_path / "Circuit.mo"], "Circuit.RC")
    template = PolynomialTemplate(lhs=["i"], rhs=["v", "v^2", "v^3"])
    w0 = np.array([1.0, 0.5, 0.0, 0.0])                      # the nominal law i = v / 2
    tm = swap_component(graph, "Rx", template, tmp_path / "learn", w=w0)
    model = compile_model(tm.sources, tm.model_name)
    w, active, path = refine(model, read_csv(tmp_path / "train.csv"), tm.parameter_names, w0, "bic",
                             terms=template.terms)
    law = dict(zip([str(m) for m in template.terms], w * active))
    assert not active[2] and active[1] and active[3]             # v^2 pruned, v and v^3 kept
    assert abs(law["v"] - 0.5) < 0.03 and abs(law["v^3"] - 0.3) < 0.03
    assert path[0]["removed"] is None and any(p["accepted"] for p in path[1:])


def test_mcl_run_with_full_discretisation_refinement(tmp_path):
    run = setup_run(tmp_path, cubic=0.3)
    run.write_text(run.read_text() + "refinement: {method: full-discretisation}\nreport: {plots: false}\n")
    assert main(["run", str(run)]) == 0
    report = json.loads((tmp_path / "out/rc/report.json").read_text())
    cause = report["cause"]
    assert cause["component"] == "Rx" and "v^3" in cause["effect"]
    xs, fs = np.array(cause["law"]["curve"]).T
    truth = 0.5 * xs + 0.3 * xs**3
    assert np.max(np.abs(fs - truth)) <= 0.05 * np.max(np.abs(truth))
    assert report["gain"]["validation_rms_after"] <= 0.2 * report["gain"]["validation_rms_before"]


def test_unknown_refinement_method_is_named(tmp_path):
    from mcl.errors import ConfigError
    from mcl.runfile import load_runfile

    run = setup_run(tmp_path, cubic=0.3)
    run.write_text(run.read_text() + "refinement: {method: magic}\n")
    with pytest.raises(ConfigError, match="refinement.method: 'magic'"):
        load_runfile(run)
