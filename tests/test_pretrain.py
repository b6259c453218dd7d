"""Multi-configuration pre-training (paper 000, Remark 3.1)."""
import numpy as np
import pytest

from helpers import LIB
from mcl.api import registry
from mcl.cli import main
from mcl.graph import build_graph
from mcl.pretrain import build_configurations, plot_feasibility, pretrain
from mcl.templates import PolynomialTemplate
from test_templates import OWN

PAPER = PolynomialTemplate(lhs=["i"], rhs=["v^2", "v^3"])


@pytest.fixture(scope="module")
def pin():
    return build_graph([LIB], "MCL.Examples.CauerFilter").components["Rnl"].connectors[0]


@pytest.fixture(scope="module")
def paper_result(pin, tmp_path_factory):
    return pretrain(PAPER, pin, [LIB], registry(), n_samples=160, seed=1,
                    directory=tmp_path_factory.mktemp("cfg"), progress=False)


def test_configurations_exercise_the_law_differently(pin, tmp_path):
    configs = build_configurations(PAPER, pin, [LIB], registry(), tmp_path)
    names = {c.name for c in configs}
    assert {"across_series", "through_parallel", "across", "through",
            "across_series_swapped", "through_parallel_swapped"} <= names
    by = {c.name: c for c in configs}
    # driven by a flow source alone, v solves w2 v^2 + w3 v^3 = w1 i: Newton's method has no step
    # at its double root v = 0 (i = 0 at the start), the loop's sign change is found instead
    assert all(by[n].informative for n in ("through", "across_series", "through_parallel"))
    # different structures: the series circuit has an algebraic loop, the parallel one a state
    assert by["across_series"].model.ode.nonlinear_blocks == 1
    assert len(by["through_parallel"].model.ode.x_names) >= 1


def test_paper_template_feasible_set_is_a_hyperplane_through_the_origin(paper_result, tmp_path, capsys):
    r = paper_result
    with capsys.disabled():
        print(f"\npre-training w1 i = w2 v^2 + w3 v^3: {r.labels.sum()}/{len(r.labels)} feasible, "
              f"held-out accuracy {r.accuracy:.1%}, hyperplane normal {np.round(r.model.coef_, 3)}")
    assert 0.1 < r.labels.mean() < 0.9          # both classes are there to separate
    assert r.accuracy >= 0.8
    assert r.model.intercept_ == 0.0            # through the origin, as in the paper
    beta = r.model.coef_ / np.linalg.norm(r.model.coef_)
    assert abs(beta[2]) > 0.8                   # the sign of w3 relative to w1 decides
    q = r.model.predict_proba(np.array([[0.5, 0, 0.5], [0.5, 0, -0.5], [-0.5, 0, -0.5]]))
    assert q[0] > 0.5 > q[1] and q[2] == q[0]   # w1 w3 > 0 feasible; w and -w are the same law
    png = plot_feasibility(r, tmp_path / "fig4.png")
    assert png.stat().st_size > 20_000


def test_domain_agnostic_pretraining(tmp_path):
    src = tmp_path / "Own.mo"
    src.write_text(OWN)
    port = build_graph([src], "Own.Circuit").components["leak"].connectors[0]
    assert port.cls == "Own.Port" and port.potential == ["F"] and port.flow == ["q"]
    r = pretrain(PolynomialTemplate(lhs=["i"], rhs=["v", "v^3"]), port, [src], registry(),
                 n_samples=40, seed=2, directory=tmp_path / "cfg", progress=False)
    assert "across_series" in r.configurations and len(r.labels) == 40


def test_pretrain_command(tmp_path, capsys):
    out = tmp_path / "pt"
    assert main(["pretrain", str(LIB), "-m", "MCL.Examples.CauerFilter", "-c", "Rnl", "--lhs", "i",
                 "--rhs", "v^2,v^3", "--samples", "40", "--executor", "serial", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "held-out accuracy" in text and "separating hyperplane" in text
    assert (out / "feasibility.png").exists() and (out / "samples.npz").exists()
