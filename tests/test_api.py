"""The public Python API: the `mcl` namespace, Discovery on in-memory data, quiet runs."""
import json
import logging

import numpy as np
import pytest

import mcl
from mcl import Discovery, compile_model, discover, simulate
from mcl.data import as_timeseries, read_csv
from mcl.discovery.candidates import stopped
from mcl.errors import ConfigError, DataError, NotFittedError

from test_discover import setup_run


def test_public_names_are_the_functions():
    import mcl.simulation  # importing the module must not shadow the function

    assert callable(simulate) and simulate.__module__ == "mcl.api"   # the services' with a run's time limit
    assert mcl.simulate is simulate and mcl.compile_model is compile_model and callable(discover)
    assert mcl.Discovery is Discovery
    from mcl.plugins import executors, templates  # noqa: F401  built-ins inside the namespace

    assert (mcl.modelica.MCL_LIBRARY / "package.mo").is_file()
    assert mcl.__version__ == mcl.compile.library.mcl_version()


def test_a_simulation_the_user_asks_for_may_take_ten_minutes_a_fit_s_one(monkeypatch):
    """mcl.simulate (and mcl simulate) give one run RUN_TIME_LIMIT (a 10 s machine model with a
    load dump takes 220 CPU-s); options that set a limit, or a SimulationOptions, keep theirs;
    the fits' runs (the services' simulate) keep SimulationOptions' own 60 s."""
    from mcl import services
    from mcl.simulation import RUN_TIME_LIMIT, SimulationOptions

    seen = []
    monkeypatch.setattr(services, "simulate", lambda model, inputs, params, t_out, options, *rest: seen.append(options))
    for options in (None, {"rtol": 1e-8}, {"time_limit": 5.0}, SimulationOptions(time_limit=7.0)):
        simulate(None, None, options=options)
    limit = lambda o: o.time_limit if isinstance(o, SimulationOptions) else o["time_limit"]
    assert [limit(o) for o in seen] == [RUN_TIME_LIMIT, RUN_TIME_LIMIT, 5.0, 7.0] and seen[1]["rtol"] == 1e-8
    assert SimulationOptions().time_limit == 60.0 and RUN_TIME_LIMIT == 600.0


def test_mcl_library_carries_the_distribution_version():
    text = (mcl.modelica.MCL_LIBRARY / "package.mo").read_text()
    assert f'version="{mcl.__version__}"' in text


def test_mcl_classes_compile_without_sources():
    model = compile_model([], "MCL.Examples.CauerFilter")
    assert model.output_names and len(model.ode.x_names) >= 3


def test_data_frames_structured_arrays_and_back():
    pd = pytest.importorskip("pandas")
    t = np.linspace(0, 1, 5)
    frame = pd.DataFrame({"time": t, "u": np.sin(t), "y": np.cos(t)})
    ts = as_timeseries(frame)
    assert ts.names == ["u", "y"] and np.allclose(ts.column("y"), np.cos(t))
    rec = np.zeros(5, dtype=[("time", float), ("u", float)])
    rec["time"], rec["u"] = t, 2 * t
    assert np.allclose(as_timeseries(rec).column("u"), 2 * t)
    assert np.allclose(as_timeseries(ts.to_frame()).values, ts.values)   # the index is time
    with pytest.raises(DataError, match="no 'time' column"):
        as_timeseries({"u": t})
    # NaN is pandas' missing value: not measured there; infinity is refused
    part = as_timeseries(pd.DataFrame({"time": t, "u": [0, 1, np.nan, 3, 4]}))
    assert part.measured().sum() == 4 and np.allclose(part.filled().column("u"), [0, 1, 2, 3, 4])
    with pytest.raises(DataError, match="infinite"):
        as_timeseries(pd.DataFrame({"time": t, "u": [0, 1, np.inf, 3, 4]}))


def test_simulation_result_to_frame():
    model = compile_model([], "MCL.Examples.CauerFilter")
    t = np.linspace(0, 2, 21)
    inputs = {"time": t, **{u: np.sin(t) for u in model.input_names}}
    frame = simulate(model, as_timeseries(inputs)).to_frame()
    assert list(frame.columns) == model.output_names and frame.index.name == "time" and len(frame) == 21


def test_a_model_that_reads_no_inputs_is_simulated_on_the_times_asked(tmp_path):
    """simulate(model, None, t_out=...): a free decay, x' = -x from 1, is exp(-t) at the times
    asked; a model that reads inputs, or no times, is a one-line error."""
    (tmp_path / "Decay.mo").write_text("model Decay\n  Real x(start = 1, fixed = true);\n"
                                       "  output Real y = x;\nequation\n  der(x) = -x;\nend Decay;\n")
    model = compile_model([tmp_path / "Decay.mo"], "Decay")
    t = np.linspace(0, 2, 11)
    run = simulate(model, None, t_out=t)
    assert run.ok and np.allclose(run.outputs[:, 0], np.exp(-t), rtol=1e-4)
    with pytest.raises(DataError, match="give t_out"):
        simulate(model, None)
    with pytest.raises(DataError, match="the model reads u: give them"):
        simulate(compile_model([], "MCL.Examples.CauerFilter"), None, t_out=t)


@pytest.mark.slow
def test_api_on_a_data_frame_equals_the_run_file(tmp_path, capsys):
    run = setup_run(tmp_path, cubic=0.3)
    assert mcl.cli.main(["--quiet", "run", str(run)]) == 0
    printed = capsys.readouterr()
    assert printed.err == "" and printed.out.startswith("misfit: significant")
    yaml_report = json.loads((tmp_path / "out/rc/report.json").read_text())

    train = read_csv(tmp_path / "train.csv").to_frame().reset_index()
    validate = read_csv(tmp_path / "validate.csv").to_frame()
    d = Discovery("Circuit.RC", sources=[tmp_path / "Circuit.mo"], verbose=False)
    assert d.fit(train, validate) is d
    assert d.cause_["component"] == "Rx" and d.law_["equation"] == yaml_report["cause"]["law"]["equation"]
    assert d.gain_ == pytest.approx(yaml_report["gain"], rel=1e-5)    # (the integrator's rounding, below)
    assert d.misfit_["train_rms"] == pytest.approx(yaml_report["misfit"]["train_rms"])
    assert d.misfit_["noise_estimate"] == pytest.approx(yaml_report["misfit"]["noise_estimate"])
    # the same fits; a freshly compiled and a cached model may round differently in the
    # integrator (~1e-6), far below what the criterion can tell apart (~2); a losing fit stopped
    # early stops where the other workers' progress found it, which timing decides
    def finished(cands):
        return {(c["component"], c["family"]): c["score"] for c in cands if not stopped(c)}

    api, yaml_ = finished(d.candidates_), finished(yaml_report["candidates"])
    both = sorted(set(api) & set(yaml_))
    assert d.candidates_[0]["score"] == pytest.approx(yaml_report["candidates"][0]["score"], abs=0.05)
    assert [api[k] for k in both] == pytest.approx([yaml_[k] for k in both], abs=0.05)
    assert d.report_["inputs"]["train"] != yaml_report["inputs"]["train"]   # array hash vs file hash
    assert "cause: Rx follows" in str(d) and "<th style='text-align:left'>cause</th>" in d._repr_html_()
    assert d.run_dir_.name == "run" and (d.run_dir_ / "report.json").is_file()

    lib = d.export(tmp_path / "lib", name="Parts")
    text = (lib / "package.mo").read_text()
    assert f'uses(MCL(version="{mcl.__version__}"))' in text and "Rx_polynomial" in text
    assert d.report(tmp_path / "rep").is_file()
    soft = yaml_report["software"]
    assert {"mcl", "casadi", "fmpy", "numpy", "scipy"} <= set(soft)
    assert set(yaml_report["inputs"]) == {"run_file", "train", "validate"}


def test_api_options_are_checked_like_a_run_file(tmp_path):
    with pytest.raises(ConfigError, match="did you mean 'dask'"):
        Discovery("MCL.Examples.CauerFilter", executor="dsak").fit({"time": [0, 1], "u": [0, 0]})
    with pytest.raises(ConfigError, match="workers"):
        Discovery("MCL.Examples.CauerFilter", executor={"kind": "local", "workers": 0}).fit(
            {"time": [0, 1], "u": [0, 0]})
    with pytest.raises(NotFittedError, match="not fitted"):
        Discovery("MCL.Examples.CauerFilter").export(tmp_path)


def test_library_code_prints_nothing(capsys, caplog):
    """Everything said goes through logging (logger 'mcl') and the progress bars on stderr."""
    from mcl.progress import Progress, quiet
    from mcl.sparsify import PruneStep, log_step

    with caplog.at_level(logging.INFO, logger="mcl"):
        log_step(PruneStep(removed=None, estimate=None, cost=1.0, criterion=1.0, accepted=True, active=["a"]))
        with quiet():
            bar = Progress("batch", 2)
            bar.update()
            bar.update()
    out = capsys.readouterr()
    assert out.out == "" and out.err == ""
    assert "1 terms, cost 1" in caplog.text and "batch: 2/2" not in caplog.text


def test_messages_come_back_after_a_quiet_block(caplog):
    """quiet() restores the logger's level so that logging sees it (its cache of levels too): a
    run's messages after a quiet calibration are not lost."""
    from mcl.progress import log, quiet

    with caplog.at_level(logging.INFO, logger="mcl"):
        log.info("before")
        with quiet():
            log.info("hidden")
        log.info("after")
    assert "before" in caplog.text and "after" in caplog.text and "hidden" not in caplog.text
