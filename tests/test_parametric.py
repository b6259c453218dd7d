"""What the parameters alone determine is computed once per run, not in every solver call.

An MSL Chebyshev filter's coefficients are functions of its cut-off frequency and ripple; the
flat model writes them into the right-hand side. Split out (:mod:`mcl.compile.parametric`),
the states' part is a small fraction of the whole; the run, its sensitivities (through the
coefficients, by the chain rule) and the linearised sensitivities are those of the whole
function.
"""
import numpy as np
import pytest

from helpers import msl_path, needs_msl

MSL = msl_path()
pytestmark = [needs_msl()]

FILTERED = """
model Filtered "a Chebyshev low-pass then a gain"
  import Modelica.Blocks;
  Blocks.Interfaces.RealInput u;
  Blocks.Continuous.Filter lowPass(analogFilter=Blocks.Types.AnalogFilter.ChebyshevI,
    filterType=Blocks.Types.FilterType.LowPass, order=3, f_cut=5, A_ripple=0.5,
    init=Blocks.Types.Init.InitialState);
  Blocks.Math.Gain k(k=2);
  Blocks.Interfaces.RealOutput y;
equation
  connect(u, lowPass.u);
  connect(lowPass.y, k.u);
  connect(k.y, y);
end Filtered;
"""


@pytest.fixture(scope="module")
def filtered(tmp_path_factory):
    from mcl import compile_model
    from mcl.data import TimeSeries

    d = tmp_path_factory.mktemp("filtered")
    (d / "Filtered.mo").write_text(FILTERED)
    model = compile_model([d / "Filtered.mo"], "Filtered", libraries=[MSL])
    t = np.linspace(0, 0.5, 251)
    u = np.sin(2 * np.pi * 3 * t) + 0.5 * np.sin(2 * np.pi * 11 * t + 1)
    return model, TimeSeries(t, u[:, None], ["u"])


def test_the_filters_coefficients_are_split_out(filtered):
    from mcl.compile import parametric

    model, _ = filtered
    split = parametric.split(model.ode)
    assert split is not None and split.nq > 0
    whole = model.ode.ode.n_instructions() + model.ode.out.n_instructions()
    assert split.ode.n_instructions() + split.out.n_instructions() < 0.1 * whole


def test_runs_and_sensitivities_are_those_of_the_whole_function(filtered, monkeypatch):
    from mcl import simulate
    from mcl.compile import parametric
    from mcl.simulation import SimulationOptions

    model, data = filtered
    tight = SimulationOptions(rtol=1e-10, atol=1e-12)
    names = ["lowPass.f_cut", "k.k"]
    split_run = simulate(model, data, options=tight, sensitivities=names)
    # the sensitivities by finite differences, through the coefficients (and in the gain)
    for j, (name, value) in enumerate((("lowPass.f_cut", 5.0), ("k.k", 2.0))):
        up = simulate(model, data, {name: value * 1.0002}, options=tight).output("y")
        down = simulate(model, data, {name: value * 0.9998}, options=tight).output("y")
        fd = (up - down) / (0.0004 * value)
        assert np.max(np.abs(split_run.sensitivities[:, 0, j] - fd)) < 1e-4 * np.max(np.abs(fd)), name
    # the run of the whole function (no sensitivities: through the whole graph they take minutes)
    monkeypatch.setattr(parametric, "split", lambda ode: None)
    whole_run = simulate(model, data, options=tight)
    assert whole_run.ok and np.max(np.abs(split_run.output("y") - whole_run.output("y"))) < 1e-6


def test_the_linearised_sensitivities_read_the_coefficients_derivative(filtered, monkeypatch):
    from mcl import simulate
    from mcl.compile import parametric
    from mcl.sensitivity import Linearisation

    model, data = filtered
    res = simulate(model, data)
    p = model.parameter_vector()
    A = Linearisation(model, res.states, res.time, data, p, ["lowPass.f_cut"])._at(slice(0, 50))
    monkeypatch.setattr(parametric, "split", lambda ode: None)
    monkeypatch.setattr("mcl.sensitivity._FUNCTIONS", type(__import__("collections").OrderedDict())())
    B = Linearisation(model, res.states, res.time, data, p, ["lowPass.f_cut"])._at(slice(0, 50))
    for a, b in zip(A, B):
        assert np.allclose(a, b, rtol=1e-9, atol=1e-12)


def test_the_fmu_computes_the_coefficients_when_a_parameter_is_set(filtered, tmp_path):
    """The FMU's functions read the coefficients after the parameters; they are computed from
    the parameters once, when one is set (here a cut-off frequency, between two runs)."""
    from mcl import simulate
    from mcl.compile.fmu.export import build_fmu
    from mcl.model import FmuModel

    model, data = filtered
    path = build_fmu(model, tmp_path / "filtered.fmu")
    source = __import__("zipfile").ZipFile(path).read("sources/fmi2_model.c").decode()
    assert "#define NQ 0" not in source          # the coefficients are computed apart
    fmu = FmuModel.read(path)
    opts = {"rtol": 1e-9, "atol": 1e-11}
    for params in ({}, {"lowPass.f_cut": 8.0}, {}):
        a, b = simulate(model, data, params, options=opts), simulate(fmu, data, params, options=opts)
        assert a.ok and b.ok, (a.reason, b.reason)
        assert np.max(np.abs(a.output("y") - b.output("y"))) < 1e-5 * np.max(np.abs(a.output("y")))
    slow, fast = (simulate(fmu, data, p, options=opts).output("y") for p in ({}, {"lowPass.f_cut": 8.0}))
    assert np.max(np.abs(slow - fast)) > 0.05 * np.max(np.abs(slow))     # the change took effect
