"""State events: a relation on the states switches the equations; the crossing is located and
the solver restarted there. Exact solutions derived by hand."""
from pathlib import Path

import numpy as np

from mcl import compile_model
from mcl.data import TimeSeries
from mcl.engine_casadi import CasadiEngine

KINK = """
model Kink "x falls at rate 1 while positive, at rate 3 once negative; y integrates x"
  Real x(start = 0.5, fixed = true);
  Real y(start = 0, fixed = true);
  output Real out;
equation
  der(x) = if x > 0 then -1 else -3;
  der(y) = if noEvent(x > 10) then 0 else x;   // noEvent: no event indicator
  out = y;
end Kink;
"""


def test_a_state_event_is_located_and_the_solution_is_exact(tmp_path):
    (tmp_path / "Kink.mo").write_text(KINK)
    model = compile_model([tmp_path / "Kink.mo"], "Kink")
    assert model.ode.zero is not None and model.ode.zero.size1_out(0) == 1   # x > 0 only
    t = np.linspace(0, 1.05, 8)                       # the crossing, t = 0.5, between two points
    engine = CasadiEngine()
    res = engine.simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok, res.reason
    plan = next(iter(engine._plans.values()))
    assert plan.hybrid.count == 1
    x = np.where(t < 0.5, 0.5 - t, -3 * (t - 0.5))
    y = np.where(t < 0.5, 0.5 * t - t**2 / 2, 0.125 - 1.5 * (t - 0.5) ** 2)
    assert np.max(np.abs(res.states[:, 0] - x)) < 1e-6
    assert np.max(np.abs(res.output("out") - y)) < 1e-5


def test_a_model_without_relations_on_states_has_no_event_function(tmp_path):
    (tmp_path / "Plain.mo").write_text("model Plain\n  Real x(start = 1, fixed = true);\n  input Real u;\n"
                                       "equation\n  der(x) = if time > 0.5 then -x else u;\nend Plain;\n")
    model = compile_model([tmp_path / "Plain.mo"], "Plain")
    assert model.ode.zero is None and model.ode.time_events == (0.5,)


def test_the_fmu_carries_the_event_indicators(tmp_path):
    """FMPy's solver locates the zeros of the FMU's event indicators (the same relations)."""
    from fmpy import read_model_description

    from mcl import simulate
    from mcl.compile.fmu.export import build_fmu
    from mcl.model import FmuModel

    (tmp_path / "Kink.mo").write_text(KINK)
    fmu = build_fmu(compile_model([tmp_path / "Kink.mo"], "Kink"), tmp_path / "kink.fmu")
    assert read_model_description(str(fmu)).numberOfEventIndicators == 1
    t = np.linspace(0, 1.05, 8)
    res = simulate(FmuModel.read(fmu), TimeSeries(t, np.zeros((len(t), 0)), []))
    assert res.ok, res.reason
    y = np.where(t < 0.5, 0.5 * t - t**2 / 2, 0.125 - 1.5 * (t - 0.5) ** 2)
    assert np.max(np.abs(res.output("out") - y)) < 1e-4
