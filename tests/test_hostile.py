"""Regression tests for hostile input: never lose a user's files, never a confident wrong answer,
never a traceback for bad input, bounded resources."""
import json
import os
import signal
import subprocess
import sys
import time
import zipfile

import pytest

import mcl.api
from helpers import LIB
from mcl import hookimpl
from mcl.cli import main
from mcl.errors import DataError
from mcl.executor import LocalExecutor
from mcl.compile.fmu.archive import check_archive
from mcl.registry import Registry

from test_discover import setup_run


def test_an_existing_directory_not_made_by_mcl_is_never_touched(tmp_path, capsys):
    run = setup_run(tmp_path, cubic=0.0)
    run.write_text(run.read_text().replace("output: out/rc", "output: ."))
    (tmp_path / "notes.txt").write_text("mine")
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(["run", str(run)]) == 2
    assert "was not made by mcl" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    assert main(["run", str(run), "--force"]) == 2           # --force does not change that
    assert (tmp_path / "notes.txt").read_text() == "mine"


def test_output_naming_a_file_is_a_run_file_error(tmp_path, capsys):
    run = setup_run(tmp_path, cubic=0.0)
    run.write_text(run.read_text().replace("output: out/rc", "output: train.csv"))
    assert main(["run", str(run)]) == 2
    assert "run.yaml:8: output: 'train.csv' is a file" in capsys.readouterr().err


def test_compile_output_that_is_a_directory(tmp_path, capsys):
    (tmp_path / "x.fmu").mkdir()
    assert main(["compile", str(LIB), "--model", "MCL.Examples.MassSpringDamper", "-o",
                 str(tmp_path / "x.fmu")]) == 2
    assert "existing directory" in capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir()] == ["x.fmu"]          # no .tmp left behind


@pytest.mark.parametrize("value", ["nan", "inf", "-1e999", "abc"])
def test_non_finite_parameters_are_refused(tmp_path, capsys, value):
    assert main(["simulate", str(LIB), "-m", "MCL.Examples.MassSpringDamper", "-i", "x.csv",
                 "-p", f"mass.m={value}", "-o", str(tmp_path / "r.csv")]) == 2
    assert "finite number" in capsys.readouterr().err


@pytest.mark.parametrize("content", [
    "time,u\n0,1\n1,2\n".encode("utf-16"), "time,u\n0,é\n".encode("latin-1"), b"\x00\x01\x02\xff" * 10,
    b"time,u\n", b"time,u\n0," + b"1" * 200000 + b"\n1,2\n"])
def test_unreadable_data_files_are_one_line(tmp_path, capsys, content):
    (tmp_path / "in.csv").write_bytes(content)
    assert main(["simulate", str(LIB), "-m", "MCL.Examples.MassSpringDamper", "-i",
                 str(tmp_path / "in.csv"), "-o", str(tmp_path / "r.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "in.csv" in err


def test_read_only_output_is_a_machine_failure(tmp_path, capsys):
    if os.geteuid() == 0:
        pytest.skip("root writes into read-only directories")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    assert main(["compile", str(LIB), "--model", "MCL.Examples.MassSpringDamper", "-o", str(ro / "m.fmu")]) == 1


def test_unsupported_delay_is_a_clear_error_not_a_crash(tmp_path, capsys):
    (tmp_path / "D.mo").write_text("model D\n  output Real y;\nequation\n  y = delay(time, 1.0);\nend D;\n")
    assert main(["compile", str(tmp_path / "D.mo"), "--model", "D", "-o", str(tmp_path / "d.fmu")]) == 2
    assert "D.mo:4: unsupported Modelica construct: delay()" in capsys.readouterr().err


def test_a_long_sum_compiles(tmp_path):
    terms = " + ".join(f"{k}*x" for k in range(1, 250))
    (tmp_path / "S.mo").write_text(f"model S\n  input Real u;\n  output Real y;\n  Real x(start=0);\n"
                                   f"equation\n  der(x) = -x + u;\n  y = {terms};\nend S;\n")
    assert main(["compile", str(tmp_path / "S.mo"), "--model", "S", "-o", str(tmp_path / "s")]) == 0


def test_zip_bombs_and_escaping_entries_are_refused_before_extraction(tmp_path):
    bomb = tmp_path / "bomb.fmu"
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("modelDescription.xml", "<x/>")
        z.writestr("binaries/zeros.bin", b"\0" * (64 << 20))
    with pytest.raises(DataError, match="zip bomb"):
        check_archive(bomb)
    climb = tmp_path / "climb.fmu"
    with zipfile.ZipFile(climb, "w") as z:
        z.writestr("../../evil.txt", "x")
    with pytest.raises(DataError, match="outside the archive"):
        check_archive(climb)


def test_fmu_simulations_leave_no_extracted_copies(tmp_path, monkeypatch):
    import tempfile

    monkeypatch.setenv("TMPDIR", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    tempfile.tempdir = None
    try:
        assert main(["compile", str(LIB), "--model", "MCL.Examples.MassSpringDamper", "-o",
                     str(tmp_path / "m.fmu")]) == 0
        inputs = tmp_path / "in.csv"
        inputs.write_text("time,u\n0,1\n1,1\n2,0\n")
        assert main(["simulate", str(tmp_path / "m.fmu"), "-i", str(inputs), "-o", str(tmp_path / "r.csv")]) == 0
        assert list((tmp_path / "tmp").iterdir()) == []
    finally:
        tempfile.tempdir = None


def test_export_validates_names_and_reads_only_inside_the_run(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "report.json").write_text(json.dumps({"cause": {"modelica": "../../../etc/passwd",
                                                           "fmu": "x.fmu", "learned_class": "X"}}))
    assert main(["export", str(run), "-o", str(tmp_path / "lib")]) == 2
    assert "outside the run directory" in capsys.readouterr().err
    assert main(["export", str(run), "-o", str(tmp_path / "lib"), "--name", "../../x"]) == 2
    assert "not a Modelica identifier" in capsys.readouterr().err
    (run / "report.json").write_text("{not json")
    assert main(["export", str(run), "-o", str(tmp_path / "lib")]) == 2
    assert not (tmp_path / "lib").exists()


def test_workers_must_be_positive():
    with pytest.raises(Exception, match="workers"):
        LocalExecutor(workers=-3)


def _sleeper(_ctx, _item):
    time.sleep(60)


def test_workers_die_with_their_parent(tmp_path):
    """A killed `mcl run` leaves no worker processes behind."""
    script = tmp_path / "parent.py"
    script.write_text(
        "import os, sys\nfrom mcl.executor import LocalExecutor\n"
        "from tests_sleeper import _sleeper\n"
        "print(os.getpid(), flush=True)\n"
        "LocalExecutor(workers=2).map(_sleeper, [1, 2], progress=False, timeout=120)\n")
    (tmp_path / "tests_sleeper.py").write_text("import time\ndef _sleeper(c, i):\n    time.sleep(60)\n")
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True, cwd=tmp_path)
    parent = int(proc.stdout.readline())
    time.sleep(1.5)
    children = subprocess.run(["pgrep", "-P", str(parent)], capture_output=True, text=True).stdout.split()
    assert len(children) == 2
    os.kill(parent, signal.SIGKILL)
    proc.wait()
    time.sleep(0.5)
    alive = [c for c in children if os.path.exists(f"/proc/{c}") and
             "Z" not in open(f"/proc/{c}/stat").read().split()[2]]
    assert alive == []


class KillOne(LocalExecutor):
    """A worker killed from outside while fitting one candidate (SIGKILL, as an OOM killer would)."""

    name = "kill-one"
    victim = "C"

    def map(self, fn, items, context=None, **kw):
        def task(ctx, item):
            if fn.__name__ == "_candidate_task" and item[0] == self.victim:
                os.kill(os.getpid(), signal.SIGKILL)
            return fn(ctx, item)

        return super().map(task, items, context=context, **kw)


class KillPlugin:
    @hookimpl
    def mcl_executors(self):
        return [KillOne]


@pytest.mark.slow
def test_a_killed_candidate_is_failed_shown_and_retried(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(mcl.api, "_registry", Registry(extra=[KillPlugin()]))
    run = setup_run(tmp_path, cubic=0.3)
    run.write_text(run.read_text() + "executor: {kind: kill-one}\n")
    assert main(["run", str(run)]) == 0
    out = capsys.readouterr()
    report = json.loads((tmp_path / "out/rc/report.json").read_text())
    failed = [f for f in report["failed"] if f["stage"] == "fitting"]
    # C (in parallel with Rx, its storage law can hold the same cubic leak) is among the fitted
    assert [f["component"] for f in failed] == ["C"] and "crashed" in failed[0]["reason"]
    assert "C with polynomial could not be evaluated" in out.err
    assert "warning: 1 candidate(s) could not be evaluated" in out.out
    cause = report["cause"]
    assert cause["component"] == "Rx"
    # C is weighed by its screening prediction: undecided unless the prediction excludes it
    assert cause["evidence"]["strength"].startswith("undecided: C") or "C" not in cause["evidence"].get("unevaluated", [])
    # resumed with a healthy executor: R1 is fitted this time
    (tmp_path / "out/rc/report.json").unlink()
    (tmp_path / "out/rc").rename(tmp_path / "out/rc.partial")
    run.write_text(run.read_text().replace("executor: {kind: kill-one}\n", ""))
    assert main(["run", str(run)]) == 0
    report = json.loads((tmp_path / "out/rc/report.json").read_text())
    assert not [f for f in report["failed"] if f["stage"] == "fitting"]
    assert report["cause"]["component"] == "Rx" and not report["cause"]["evidence"]["strength"].startswith("undecided")


def test_a_second_run_on_the_same_output_is_told_so(tmp_path):
    from mcl.discovery.rundir import RunDirectory
    from mcl.errors import ConfigError

    first = RunDirectory(tmp_path / "out")
    with pytest.raises(ConfigError, match="another mcl run"):
        RunDirectory(tmp_path / "out")
    first.finish()
    assert (tmp_path / "out" / ".mcl-run").is_file()


def test_a_second_configuration_that_does_not_exist_is_found_up_front(tmp_path, capsys):
    run = setup_run(tmp_path, cubic=0.0)
    run.write_text(run.read_text() + f"second:\n  model: {{sources: [Circuit.mo, {LIB}], name: Circuit.Nope}}\n"
                                     "  data: train.csv\n")
    assert main(["run", str(run)]) == 2
    err = capsys.readouterr().err
    assert "run.yaml:10: second.model.name:" in err and "Circuit.Nope" in err
    assert not (tmp_path / "out").exists()
