"""FMUs engineers use elsewhere: FMPy with its default settings runs them as Co-Simulation (the
embedded stiff solver, inputs continuous between communication points) to mcl's own accuracy;
start values of states are settable; the DefaultExperiment says what to simulate."""
import zipfile

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave
from scipy.integrate import solve_ivp

from helpers import RC_MODEL, ROOT, compiled, multisine, series
from mcl import compile_model
from mcl.api import simulate
from mcl.compile.fmu.experiment import for_model
from mcl.compile.fmu.export import build_fmu, derivative_unit, validate_fmu
from mcl.data import read_csv
from mcl.errors import ConfigError

CAUER_DATA = ROOT / "examples" / "cauer"


def rms(a) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


def signal(t, **columns):
    """An input table for FMPy: a structured array with time first."""
    table = np.zeros(len(t), dtype=[("time", float)] + [(n, float) for n in columns])
    table["time"] = t
    for n, v in columns.items():
        table[n] = v
    return table


@pytest.fixture(scope="module")
def validation():
    return read_csv(CAUER_DATA / "validate.csv")


@pytest.fixture(scope="module")
def cauer_fmu(tmp_path_factory, cauer, validation):
    """The Cauer filter with the true law (the model discovery extends the nominal one into),
    its DefaultExperiment from the data, as discovery builds it."""
    return build_fmu(cauer, tmp_path_factory.mktemp("cs") / "cauer.fmu", experiment=validation)


def test_fmpy_defaults_reproduce_mcls_validation_error(cauer, cauer_fmu, validation):
    """FMPy's defaults (Co-Simulation, chosen when both are present) at the data's interval give
    the validation error mcl's in-process engine gives, within 10 %; Model Exchange, whose
    importer holds the input over each interval, is the inaccurate route."""
    d = validation
    u, y = d.values[:, d.names.index("u")], d.values[:, d.names.index("y")]
    own = simulate(cauer, series(d.time, u=u))
    assert own.ok, own.reason
    err_mcl = rms(own.output("y") - y)
    dt = float(np.median(np.diff(d.time)))
    res = simulate_fmu(str(cauer_fmu), input=signal(d.time, u=u), output_interval=dt)
    assert len(res) == len(d.time) and res["time"][-1] == pytest.approx(d.time[-1])
    err_cs = rms(np.interp(d.time, res["time"], res["y"]) - y)
    assert abs(err_cs / err_mcl - 1) < 0.1, (err_cs, err_mcl)
    me = simulate_fmu(str(cauer_fmu), input=signal(d.time, u=u), output_interval=dt, fmi_type="ModelExchange")
    err_me = rms(np.interp(d.time, me["time"], me["y"]) - y)
    assert err_me > 1.5 * err_cs      # why Co-Simulation is what FMPy should (and does) pick


def test_both_interfaces_a_default_experiment_and_fmpy_validation(cauer_fmu, validation):
    assert validate_fmu(cauer_fmu) == []
    md = read_model_description(str(cauer_fmu))
    assert md.modelExchange is not None and md.coSimulation is not None
    assert md.coSimulation.canInterpolateInputs and md.coSimulation.canHandleVariableCommunicationStepSize
    ex = md.defaultExperiment
    assert (float(ex.startTime), float(ex.stopTime)) == (validation.time[0], validation.time[-1])
    assert float(ex.stepSize) == pytest.approx(0.05) and float(ex.tolerance) == 1e-6


def test_cosimulation_agrees_with_the_in_process_engine(cauer, cauer_fmu):
    """With the input's slope given at each communication point (mcl's FMU engine does), the
    embedded solver sees the same input as the in-process engine: agreement to the tolerance."""
    t = np.linspace(0, 30, 601)
    u = series(t, u=multisine(t))
    opts = {"rtol": 1e-8, "atol": 1e-10}
    from mcl.model import FmuModel

    a, b = simulate(cauer, u, options=opts), simulate(FmuModel.read(cauer_fmu), u, options=opts)
    assert a.ok and b.ok, (a.reason, b.reason)
    assert np.max(np.abs(a.outputs - b.outputs)) / np.max(np.abs(a.outputs)) < 1e-5


def test_state_start_values_are_settable(tmp_path):
    """C.v(start) from FMPy's start_values: the RC circuit decays from it, v0 exp(-t/tau)."""
    (tmp_path / "RC.mo").write_text(RC_MODEL)
    fmu = build_fmu(compile_model([tmp_path / "RC.mo"], "RC"), tmp_path / "rc.fmu")
    md = {v.name: v for v in read_model_description(str(fmu)).modelVariables}
    assert md["C.v"].initial == "exact" and md["C.v"].causality == "local"
    tau = 0.5 * (1 * 2 / 3)                                 # C (R1 || Rx)
    zero = signal(np.array([0.0, 2.0]), u=np.zeros(2))
    for kind in ("CoSimulation", "ModelExchange"):
        res = simulate_fmu(str(fmu), start_values={"C.v": 2.0}, input=zero, stop_time=2.0,
                           output_interval=0.1, fmi_type=kind, output=["y"])
        assert np.max(np.abs(res["y"] - 2.0 * np.exp(-res["time"] / tau))) < 1e-5, kind


def test_a_state_fixed_by_constraints_is_not_settable(cauer_fmu):
    """In the Cauer filter's capacitor loops C3.v follows from C1.v and C2.v: setting C1.v moves
    C3.v; C3.v itself is calculated, and FMPy refuses to set it."""
    md = {v.name: v for v in read_model_description(str(cauer_fmu)).modelVariables}
    assert md["C1.v"].initial == "exact" and md["C3.v"].initial == "calculated"
    res = simulate_fmu(str(cauer_fmu), start_values={"C1.v": 1.0}, stop_time=1.0, output_interval=0.5,
                       output=["C1.v", "C2.v", "C3.v"])
    assert (res["C1.v"][0], res["C2.v"][0], res["C3.v"][0]) == pytest.approx((1.0, 0.0, 1.0))
    with pytest.raises(Exception, match="C3.v"):
        simulate_fmu(str(cauer_fmu), start_values={"C3.v": 1.0}, stop_time=1.0)


SMALL = """
model Kink "x falls at rate 1 while positive, at rate 3 once negative; y integrates x"
  Real x(start = 0.5, fixed = true);
  Real y(start = 0, fixed = true);
  output Real out;
equation
  der(x) = if x > 0 then -1 else -3;
  der(y) = x;
  out = y;
end Kink;
model Switched "a time event: the input drives x until t = 0.5, then x decays"
  Real x(start = 1, fixed = true);
  input Real u;
  output Real y;
equation
  der(x) = if time > 0.5 then -x else u;
  y = x;
end Switched;
model Robertson "stiff chemical kinetics (rates 0.04, 1e4, 3e7)"
  Real y1(start = 1, fixed = true);
  Real y2(start = 0, fixed = true);
  Real y3(start = 0, fixed = true);
  output Real out;
equation
  der(y1) = -0.04*y1 + 1e4*y2*y3;
  der(y2) = 0.04*y1 - 1e4*y2*y3 - 3e7*y2^2;
  der(y3) = 3e7*y2^2;
  out = y2;
  annotation(experiment(StartTime = 0, StopTime = 40, Interval = 0.2, Tolerance = 1e-8));
end Robertson;
"""


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    d = tmp_path_factory.mktemp("small")
    (d / "Small.mo").write_text(SMALL)
    return {n: build_fmu(compile_model([d / "Small.mo"], n), d / f"{n}.fmu") for n in ("Kink", "Switched", "Robertson")}


def test_cosimulation_locates_state_events_inside_a_step(small):
    res = simulate_fmu(str(small["Kink"]), stop_time=1.05, output_interval=0.15, output=["out"])
    t = res["time"]                                          # the kink at t = 0.5, inside a step
    y = np.where(t < 0.5, 0.5 * t - t**2 / 2, 0.125 - 1.5 * (t - 0.5) ** 2)
    assert np.max(np.abs(res["out"] - y)) < 1e-8


def test_cosimulation_stops_at_time_events(small):
    res = simulate_fmu(str(small["Switched"]), stop_time=2.0, output_interval=0.3, output=["y"],
                       input=signal(np.array([0.0, 2.0]), u=np.full(2, 2.0)))
    t = res["time"]
    assert np.max(np.abs(res["y"] - np.where(t <= 0.5, 1 + 2 * t, 2 * np.exp(-(t - 0.5))))) < 1e-6


def test_the_embedded_solver_handles_stiff_models(small):
    """Robertson's kinetics (eigenvalues from -0.04 to about -1e4) over the annotation's 40 s,
    against SciPy's Radau at tight tolerances."""
    md = read_model_description(str(small["Robertson"]))
    assert (float(md.defaultExperiment.stopTime), float(md.defaultExperiment.stepSize)) == (40.0, 0.2)
    res = simulate_fmu(str(small["Robertson"]), output=["out"])      # all from the DefaultExperiment
    ref = solve_ivp(lambda t, y: [-0.04 * y[0] + 1e4 * y[1] * y[2], 0.04 * y[0] - 1e4 * y[1] * y[2] - 3e7 * y[1] ** 2,
                                  3e7 * y[1] ** 2], (0, 40), [1, 0, 0], method="Radau", rtol=1e-11, atol=1e-14,
                    t_eval=res["time"])
    assert res["time"][-1] == pytest.approx(40.0)
    assert np.max(np.abs(res["out"] - ref.y[1])) < 1e-4 * np.max(ref.y[1])


def test_fmu_state_can_be_saved_and_restored(small):
    """A master may roll back: fmi2Get/SetFMUstate and their serialised form."""
    import shutil

    from fmpy import extract

    md = read_model_description(str(small["Switched"]))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzipped = extract(str(small["Switched"]))
    try:
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier)
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.setReal([vr["u"]], [1.0])
        fmu.exitInitializationMode()
        fmu.doStep(0.0, 0.2)
        saved = fmu.deserializeFMUState(fmu.serializeFMUState(fmu.getFMUState()))
        fmu.doStep(0.2, 0.6)
        first = fmu.getReal([vr["y"]])[0]
        fmu.setFMUState(saved)
        fmu.doStep(0.2, 0.6)
        assert fmu.getReal([vr["y"]])[0] == first == pytest.approx(1.5 * np.exp(-0.3))
        fmu.terminate()
        fmu.freeInstance()
    finally:
        shutil.rmtree(unzipped, ignore_errors=True)


def test_units_and_descriptions_on_every_state_derivative_and_given_names(tmp_path, cauer):
    fmu = build_fmu(cauer, tmp_path / "c.fmu", experiment={"start": 0, "stop": 5, "step": 0.01},
                    units={"Rnl.w3": "A/V3"}, descriptions={"Rnl.w3": "coefficient of v^3 in the law of Rnl"})
    md = {v.name: v for v in read_model_description(str(fmu)).modelVariables}
    assert md["Rnl.w3"].unit == "A/V3" and md["Rnl.w3"].description.startswith("coefficient")
    assert md["der(C1.v)"].unit == "V/s" and md["der(L1.i)"].unit == "A/s"
    assert md["der(C1.v)"].description.startswith("time derivative of C1.v")
    assert all(md[n].unit for n in cauer.ode.x_names) and validate_fmu(fmu) == []
    with pytest.raises(ConfigError, match="Rnl.w9"):
        build_fmu(cauer, tmp_path / "d.fmu", units={"Rnl.w9": "1"})


@pytest.mark.parametrize("unit,der", [("V", "V/s"), ("m/s", "m/s2"), ("rad/s2", "rad/s3"),
                                      ("N.m/rad", "N.m/(rad.s)"), ("1", "1/s"), (None, None)])
def test_derivative_units(unit, der):
    assert derivative_unit(unit) == der


def test_default_experiment_without_data(small, tmp_path):
    """From the class's annotation when it has one, else a few slowest time constants."""
    ex = {n: read_model_description(str(small[n])).defaultExperiment for n in ("Robertson", "Switched")}
    assert float(ex["Robertson"].tolerance) == 1e-8
    assert float(ex["Switched"].stopTime) > 0 and float(ex["Switched"].stepSize) > 0
    guess = for_model(compiled("MCL.Examples.CauerFilter"))      # MCL's source has no annotation
    assert guess.source == "estimate" and 5 <= guess.stop <= 500 and 0 < guess.step <= guess.stop / 100
    with zipfile.ZipFile(small["Switched"]) as z:
        assert "<DefaultExperiment" in z.read("modelDescription.xml").decode()


def test_a_link_in_the_documentation_does_not_hide_the_experiment(tmp_path):
    """``modelica://`` in a string on the annotation's line is not a comment: the stop time
    after it is read (it was cut off as one, and the stop time estimated)."""
    (tmp_path / "Doc.mo").write_text(
        'model Doc\n  Real x(start=1, fixed=true);\nequation\n  der(x) = -x;\n'
        '  annotation(Documentation(info="<a href=\\"modelica://Doc\\">Doc</a>"), experiment(StopTime=7, Interval=0.01));\n'
        'end Doc;\n')
    ex = for_model(compile_model([tmp_path / "Doc.mo"], "Doc"))
    assert (ex.source, ex.stop, ex.step) == ("annotation", 7.0, 0.01)
