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
import mcl.services
from helpers import LIB, msl_path, needs_msl
from mcl import compile_model, hookimpl
from mcl.cli import main
from mcl.data import TimeSeries
from mcl.engine_casadi import CasadiEngine
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


PANIC = """model P "A count of the thresholds passed: a sum over a comprehension, in a when"
  parameter Integer n = 3;
  Real y(start=0, fixed=true);
  Boolean x[n] = {time > 0.1*i for i in 1:n};
equation
  when sample(0, 0.1) then
    y = sum(if x[i] then 2^(i - 1) else 0 for i in 1:n);
  end when;
end P;
"""


def test_a_model_that_crashes_the_front_end_is_a_clear_error_and_the_next_compiles(tmp_path, capsys):
    """rumoca 0.10.2 panics (a Rust panic: pyo3's PanicException, not an Exception) on this
    model; that is the user's one-line error, and the session it left is not used again."""
    (tmp_path / "P.mo").write_text(PANIC)
    assert main(["compile", str(tmp_path / "P.mo"), "--model", "P", "-o", str(tmp_path / "p.fmu")]) == 2
    err = capsys.readouterr().err
    assert "P.mo" in err and "front end (rumoca) stopped on an internal error" in err
    assert "Traceback" not in err
    (tmp_path / "D.mo").write_text("model D\n  Real x(start=1, fixed=true);\nequation\n  der(x) = -x;\nend D;\n")
    assert main(["compile", str(tmp_path / "D.mo"), "--model", "D", "-o", str(tmp_path / "d.fmu")]) == 0


def test_a_parameter_the_compiler_needs_but_only_started_takes_its_start_or_is_named(tmp_path, capsys):
    """A sample() interval read from a parameter that has only a start value: as other tools
    do, the start value is taken, with a warning (rumoca alone stops: "unsupported runtime
    operator"); a start that is not a literal cannot be taken, and the error names the
    parameter, its line and how to set it."""
    tick = ("model Tick\n  output Integer n(start=0, fixed=true);\n  parameter Real T(start=0.5);\nequation\n"
            "  when sample(0, T) then\n    n = pre(n) + 1;\n  end when;\nend Tick;\n")
    (tmp_path / "Tick.mo").write_text(tick)
    model = compile_model([tmp_path / "Tick.mo"], "Tick")
    t = np.array([0.2, 0.7, 1.2, 1.9])
    res = CasadiEngine().simulate(model, TimeSeries(t, np.zeros((len(t), 0)), []), options=None)
    assert res.ok and list(np.diff(res.output("n"))) == [1, 1, 1]      # one tick each 0.5 s
    (tmp_path / "Tock.mo").write_text(tick.replace("Tick", "Tock").replace("T(start=0.5)", "T(start=2*T0)")
                                      .replace("  output Integer n", "  parameter Real T0 = 0.25;\n  output Integer n"))
    assert main(["compile", str(tmp_path / "Tock.mo"), "--model", "Tock", "-o", str(tmp_path / "t.fmu")]) == 2
    err = capsys.readouterr().err
    assert "Tock.mo:4: parameter T of Tock has no value, only a start value" in err and "T=..." in err


UNROLL = """model Unroll "a function whose loops unroll (as a medium's property functions do)"
  function f
    input Real x;
    output Real y;
  algorithm
    y := x;
    for i in 1:20 loop
      y := y + sin(y * x) / i;
    end for;
  end f;
  Real s(start = 0.1, fixed = true);
equation
  der(s) = -f(s);
end Unroll;
"""


def test_a_function_that_outgrows_the_compile_memory_is_a_clear_error(tmp_path, capsys, monkeypatch):
    """Water IF97's rho_ph took 19 GB before the machine killed it: past its memory allowance
    (here each read of it 1 GB more than the last), a compile stops with the function's name."""
    import itertools
    from mcl.compile import rumoca_frontend

    (tmp_path / "Unroll.mo").write_text(UNROLL)
    assert main(["compile", str(tmp_path / "Unroll.mo"), "--model", "Unroll", "-o", str(tmp_path / "a")]) == 0
    grows = itertools.count()
    monkeypatch.setattr(rumoca_frontend, "_resident_bytes", lambda: next(grows) * 10**9)
    monkeypatch.setenv("MCL_COMPILE_MEMORY_GB", "0.5")
    assert main(["compile", str(tmp_path / "Unroll.mo"), "--model", "Unroll", "-o", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert "Unroll.mo:" in err and "function" in err and "f unrolls" in err and "0.5 GB" in err
    assert len(err.strip().splitlines()) == 1


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
            if fn.__name__ == "fit_task" and item.component == self.victim:
                os.kill(os.getpid(), signal.SIGKILL)
            return fn(ctx, item)

        return super().map(task, items, context=context, **kw)


class KillPlugin:
    @hookimpl
    def mcl_executors(self):
        return [KillOne]


@pytest.mark.slow
def test_a_killed_candidate_is_failed_shown_and_retried(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(mcl.services, "_registry", Registry(extra=[KillPlugin()]))
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
    assert (tmp_path / "out" / ".mcl-outputs").is_file()


def test_a_second_configuration_that_does_not_exist_is_found_up_front(tmp_path, capsys):
    run = setup_run(tmp_path, cubic=0.0)
    run.write_text(run.read_text() + f"second:\n  model: {{sources: [Circuit.mo, {LIB}], name: Circuit.Nope}}\n"
                                     "  data: train.csv\n")
    assert main(["run", str(run)]) == 2
    err = capsys.readouterr().err
    assert "run.yaml:10: second.model.name:" in err and "Circuit.Nope" in err
    assert not (tmp_path / "out").exists()


# ---- issue 18, second round: every finding of the hostile-input probe ----------------------------

import contextlib  # noqa: E402
import hashlib  # noqa: E402
import stat  # noqa: E402

import numpy as np  # noqa: E402

from mcl.errors import ConfigError, MclError, ModelicaError, NotFittedError  # noqa: E402
from test_discover import CIRCUIT  # noqa: E402
from test_fuzz import try_output  # noqa: E402

SIM = ["simulate", "{d}/Circuit.mo", "-L", str(LIB), "-m", "Circuit.RC", "-i", "{d}/input.csv"]


@pytest.fixture
def user(tmp_path):
    """A user's folder: their model, their input data, their notes."""
    (tmp_path / "Circuit.mo").write_text(CIRCUIT)
    (tmp_path / "input.csv").write_text("time,u\n0,0\n0.5,1\n1,1\n1.5,0\n2,0\n")
    (tmp_path / "notes.txt").write_text("mine\n")
    (tmp_path / "Faults.mo").write_text("package Faults\nend Faults;\n")
    return tmp_path


def digest(root):
    """Every path under ``root`` with what it is (bytes, link target, folder, special)."""
    out = {}
    for p in sorted(root.rglob("*")):
        mode = os.lstat(p).st_mode
        out[str(p)] = (os.readlink(p) if stat.S_ISLNK(mode) else hashlib.sha256(p.read_bytes()).hexdigest()
                       if stat.S_ISREG(mode) else "dir" if stat.S_ISDIR(mode) else stat.S_IFMT(mode))
    return out


def refused(capsys, argv, message, d):
    """``argv`` exits 2 with one line holding ``message``."""
    try:
        code = main([a.format(d=d) for a in argv])
    except SystemExit as exc:         # argparse's own refusals
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and message in err, err
    return err


@contextlib.contextmanager
def deadline(seconds):
    """Fail instead of hanging (a FIFO read by mistake blocks forever)."""
    def expire(*_):
        raise TimeoutError(f"no answer within {seconds} s")

    old = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


@pytest.mark.parametrize("extra", ["report.json", ".mcl-run", ".mcl-outputs"])
def test_force_never_deletes_a_folder_that_merely_looks_like_a_run(tmp_path, capsys, extra):
    run = setup_run(tmp_path, cubic=0.0)
    run.write_text(run.read_text().replace("output: out/rc", "output: results"))
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / extra).write_text("{}")
    (tmp_path / "results" / "thesis.tex").write_text("my thesis")
    before = digest(tmp_path)
    err = refused(capsys, ["run", str(run), "--force"], "was not made by mcl", tmp_path)
    assert "run.yaml:8: output:" in err                    # said before anything is compiled
    assert digest(tmp_path) == before


@pytest.mark.parametrize("args,message", [
    (["-o", "{d}/Faults.mo"], "was not made by mcl"),           # the user's Modelica source
    (["-o", "{d}/Circuit.mo"], "is an input of this command"),
    (["-o", "{d}/input.csv"], "is an input of this command"),   # the data it reads
    (["-o", "{d}/notes.txt", "--force"], "was not made by mcl"),
    (["-o", "{d}/r.csv", "--plot", "{d}/Circuit.mo"], "ending in .png"),
    (["-o", "{d}/r.csv", "--plot", "{d}/notes.png"], "was not made by mcl"),
    (["-o", "{d}/r.csv", "--plot", "{d}/r.csv"], "ending in .png"),
    (["-o", "{d}/fifo"], "FIFO"),
    (["-o", "{d}/dangling"], "which does not exist"),
    (["-o", "{d}/notes.txt/r.csv"], "is a file, not a folder"),
])
def test_simulate_never_writes_over_a_users_file(user, capsys, args, message):
    os.mkfifo(user / "fifo")
    (user / "dangling").symlink_to(user / "nowhere")
    (user / "notes.png").write_bytes(b"\x89PNG mine")
    before = digest(user)
    refused(capsys, SIM + args, message, user)
    assert digest(user) == before


@pytest.mark.skipif(os.geteuid() != 0, reason="making a device node needs root")
def test_a_device_node_is_never_replaced(user, capsys):
    os.mknod(user / "full", 0o600 | stat.S_IFCHR, os.makedev(1, 7))     # like /dev/full
    refused(capsys, SIM + ["-o", "{d}/full", "--force"], "is a device", user)
    assert stat.S_ISCHR(os.lstat(user / "full").st_mode)


def test_a_result_mcl_wrote_is_replaced_only_with_force_and_only_unchanged(user, capsys):
    argv = [a.format(d=user) for a in SIM + ["-o", "{d}/r.csv"]]
    assert main(argv) == 0
    assert (user / ".mcl-outputs").is_file()
    refused(capsys, SIM + ["-o", "{d}/r.csv"], "use --force", user)
    assert main(argv + ["--force"]) == 0
    with open(user / "r.csv", "a") as fh:                    # the user edits the result: it is theirs now
        fh.write("# checked by hand\n")
    edited = (user / "r.csv").read_bytes()
    refused(capsys, SIM + ["-o", "{d}/r.csv", "--force"], "changed since mcl wrote it", user)
    assert (user / "r.csv").read_bytes() == edited


def test_compile_never_writes_over_a_users_fmu_or_folder(user, capsys):
    (user / "m.fmu").write_bytes(b"an FMU exported by Dymola")
    (user / "mine").mkdir()
    (user / "mine" / "model.json").write_text("{}")          # looks like a saved model
    before = digest(user)
    base = ["compile", "{d}/Circuit.mo", "-L", str(LIB), "-m", "Circuit.RC", "--force", "-o"]
    refused(capsys, base + ["{d}/m.fmu"], "was not made by mcl", user)
    refused(capsys, base + ["{d}/mine"], "was not made by mcl", user)
    refused(capsys, base + ["{d}/Circuit.mo"], "is an input of this command", user)
    refused(capsys, base + ["{d}/Faults.mo"], "is a file, not a saved model", user)
    assert digest(user) == before
    saved = [a.format(d=user) for a in base[:-2] + ["-o", "{d}/saved"]]
    assert main(saved) == 0 and main(saved + ["--force"]) == 0     # mcl's own: replaced with --force


def _finished_run(d):
    run = d / "run"
    run.mkdir()
    (run / "ext.mo").write_text("package Ext\n  model Rx_learned\n    Real v;\n  equation\n    v = 1;\n"
                                "  end Rx_learned;\nend Ext;\n")
    (run / "report.json").write_text(json.dumps({"cause": {"modelica": "ext.mo", "fmu": "x.fmu",
                                                           "learned_class": "Rx_learned"}}))
    return run


def test_export_never_replaces_a_users_library_and_names_are_checked(tmp_path, capsys):
    run = _finished_run(tmp_path)
    (tmp_path / "mylibs" / "MyParts").mkdir(parents=True)
    (tmp_path / "mylibs" / "MyParts" / "package.mo").write_text("package MyParts\nend MyParts;\n")
    before = digest(tmp_path)
    refused(capsys, ["export", str(run), "-o", "{d}/mylibs", "--name", "MyParts", "--force"],
            "was not made by mcl", tmp_path)
    for name, why in (("model", "Modelica keyword"), ("MCL", "MCL library"), ("Modelica", "Modelica library")):
        refused(capsys, ["export", str(run), "-o", "{d}/lib", "--name", name], why, tmp_path)
    assert digest(tmp_path) == before
    assert main(["export", str(run), "-o", str(tmp_path / "mylibs"), "--name", "Learned"]) == 0
    assert "model Rx_learned" in (tmp_path / "mylibs" / "Learned" / "package.mo").read_text()
    refused(capsys, ["export", str(run), "-o", "{d}/mylibs", "--name", "Learned"], "use --force", tmp_path)
    assert main(["export", str(run), "-o", str(tmp_path / "mylibs"), "--name", "Learned", "--force"]) == 0


def test_a_symlinked_run_output_is_followed_never_half_replaced(tmp_path, capsys):
    run = setup_run(tmp_path, cubic=0.0)
    run.write_text(run.read_text().replace("output: out/rc", "output: real"))
    assert main(["--quiet", "run", str(run)]) == 0
    (tmp_path / "link").symlink_to("real")
    run.write_text(run.read_text().replace("output: real", "output: link"))
    refused(capsys, ["run", str(run)], "use --force", tmp_path)
    assert main(["--quiet", "run", str(run), "--force"]) == 0
    assert (tmp_path / "link").is_symlink() and (tmp_path / "real" / "report.json").is_file()
    assert sorted(p.name for p in tmp_path.iterdir() if "real" in p.name or "link" in p.name) == ["link", "real"]
    (tmp_path / "real" / "thesis.tex").write_text("mine")   # the user's file inside the run: kept
    refused(capsys, ["run", str(run), "--force"], "thesis.tex, which mcl did not write", tmp_path)
    assert (tmp_path / "real" / "thesis.tex").read_text() == "mine"


def test_fifos_and_devices_are_never_read(user, capsys):
    for name in ("data.csv", "run.yaml", "m.fmu", "S.mo"):
        os.mkfifo(user / name)
    with deadline(60):
        refused(capsys, SIM[:-1] + ["{d}/data.csv", "-o", "{d}/r.csv"], "FIFO", user)
        refused(capsys, ["run", "{d}/run.yaml"], "FIFO", user)
        refused(capsys, ["simulate", "{d}/m.fmu", "-i", "{d}/input.csv", "-o", "{d}/r.csv"], "FIFO", user)
        refused(capsys, ["compile", "{d}/S.mo", "-m", "S", "-o", "{d}/s.fmu"], "FIFO", user)
        refused(capsys, ["info", "{d}/m.fmu"], "FIFO", user)
        with pytest.raises(ModelicaError, match="FIFO"):
            mcl.api.compile_model([user / "S.mo"], "S")
        (user / "P").mkdir()
        (user / "P" / "package.mo").write_text("package P\nend P;\n")
        os.mkfifo(user / "P" / "M.mo")                        # inside a package directory
        refused(capsys, ["compile", "{d}/P", "-m", "P.M", "-o", "{d}/p.fmu"], "P/M.mo: is a FIFO", user)
        (user / "t.yaml").write_text(f"model: {{sources: [Circuit.mo, {LIB}], name: Circuit.RC}}\n"
                                     "data: {train: data.csv}\noutput: out\n")
        refused(capsys, ["run", "{d}/t.yaml"], "t.yaml:2: data.train: 'data.csv' is a FIFO", user)


@pytest.mark.parametrize("option,message", [
    (["--rtol", "-1"], "--rtol = -1: must be a finite number greater than 0 and less than 1"),
    (["--rtol", "0"], "--rtol = 0:"), (["--rtol", "1e10"], "--rtol = 1e+10"), (["--rtol", "nan"], "--rtol = nan"),
    (["--atol", "-1"], "--atol = -1:"), (["--time-limit", "-5"], "--time-limit = -5:"),
    (["--time-limit", "nan"], "--time-limit = nan"), (["--time-limit", "inf"], "--time-limit = inf"),
    (["--rtol", "abc"], "invalid float value"), (["-L", "/nonexistent"], "--library /nonexistent: no such"),
    (["-L", "{d}/input.csv"], "is not a directory"),
])
def test_numeric_and_path_options_are_checked(user, capsys, option, message):
    err = refused(capsys, SIM + ["-o", "{d}/r.csv", *option], message, user)
    assert not (user / "r.csv").exists(), err


def test_simulation_options_are_checked_in_the_api_too():
    from mcl.simulation import SimulationOptions

    for bad in ({"rtol": 0}, {"rtol": 2.0}, {"atol": -1}, {"time_limit": float("nan")}, {"max_steps": 0.5}):
        with pytest.raises(ConfigError, match="must be a"):
            SimulationOptions.from_dict(bad)
    with pytest.raises(ConfigError, match="rtol = -1"):
        SimulationOptions(rtol=-1)


def test_pretrain_numbers_are_checked(user, capsys):
    base = ["pretrain", "{d}/Circuit.mo", str(LIB), "-m", "Circuit.RC", "-c", "Rx", "-o", "{d}/p"]
    refused(capsys, base + ["--samples", "0"], "--samples 0: must be a whole number greater than 0", user)
    refused(capsys, base + ["--box", "nan"], "--box nan", user)
    refused(capsys, base + ["--amplitude", "-1"], "--amplitude -1.0", user)


def test_run_file_keys_given_twice_and_paths(tmp_path, capsys, monkeypatch):
    run = setup_run(tmp_path, cubic=0.0)
    text = run.read_text()
    run.write_text(text + "output: other\n")
    refused(capsys, ["run", str(run)], "run.yaml:9: output: given twice (first on line 8)", tmp_path)
    run.write_text(text.replace("  name: Circuit.RC\n", "  name: Circuit.RC\n  libraries: [train.csv]\n"))
    refused(capsys, ["run", str(run)], "run.yaml:4: model.libraries: 'train.csv' is not a directory", tmp_path)
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    run.write_text(text.replace("output: out/rc", "output: ~/x"))
    assert main(["--quiet", "run", str(run)]) == 0
    assert (home / "x" / "report.json").is_file() and not (tmp_path / "~").exists()


def test_a_free_parameter_the_model_lacks_is_refused_before_the_search(tmp_path, capsys):
    run = setup_run(tmp_path, cubic=0.0)
    run.write_text(run.read_text() + "free: [R1.R, R1.RR]\n")
    refused(capsys, ["run", str(run)], "run.yaml:9: free: 'R1.RR' is not a free parameter of Circuit.RC "
                                       "(did you mean 'R1.R'?)", tmp_path)
    assert not (tmp_path / "out").exists() and not list(tmp_path.glob("out/*.partial"))


@pytest.mark.parametrize("cell", ["1_000", "١٢", "0x10", "1e", "--1"])
def test_csv_numbers_are_plain_decimal_numbers(tmp_path, cell):
    (tmp_path / "d.csv").write_text(f"time,u\n0,{cell}\n1,2\n")
    with pytest.raises(DataError, match=f"'{cell}' is not a number"):
        mcl.data.read_csv(tmp_path / "d.csv")


def test_template_scales_and_sizes_are_checked_with_the_run_file(tmp_path, capsys):
    run = setup_run(tmp_path, cubic=0.0)
    text = run.read_text().replace("unknown: auto", "unknown: Rx")
    run.write_text(text + "templates:\n  - {name: polynomial, rhs: [v, tanh(v/s1)], scales: {s1: 0}}\n")
    refused(capsys, ["run", str(run)], "run.yaml:10: templates.0: template scale s1 = 0", tmp_path)
    terms = ", ".join(f"'v^{k}'" for k in range(1, 300))
    run.write_text(text + f"templates:\n  - {{name: polynomial, rhs: [{terms}]}}\n")
    refused(capsys, ["run", str(run)], "template has 299 parameters; at most 40", tmp_path)
    assert not (tmp_path / "out").exists()
    from mcl.templates import NeuralTemplate, PolynomialTemplate

    for bad in ({"scales": {"s1": float("nan")}, "rhs": ["tanh(v/s1)"]}, {"degree": 10**9},
                {"start": [1, float("inf"), 1, 1]}):
        with pytest.raises(ConfigError):
            PolynomialTemplate(**bad)
    with pytest.raises(ConfigError, match="hidden"):
        NeuralTemplate(hidden=10**6)


def test_the_api_takes_frames_arrays_and_series_and_checks_like_the_cli(user):
    pd = pytest.importorskip("pandas")
    model = mcl.api.compile_model([user / "Circuit.mo", LIB], "Circuit.RC")
    t = np.linspace(0, 2, 21)
    frame = pd.DataFrame({"time": t, "u": np.sin(t)})
    rec = np.zeros(21, dtype=[("time", float), ("u", float)])
    rec["time"], rec["u"] = t, np.sin(t)
    results = [mcl.api.simulate(model, x).outputs for x in (frame, rec, mcl.data.as_timeseries(frame))]
    assert np.allclose(results[0], results[1]) and np.allclose(results[0], results[2])
    with pytest.raises(DataError, match="inputs: the model reads u: give them as a pandas DataFrame"):
        mcl.api.simulate(model, None)
    with pytest.raises(DataError, match="missing column.* u; the data have: x"):
        mcl.api.simulate(model, pd.DataFrame({"time": t, "x": t}))
    with pytest.raises(ConfigError, match="params: R1.R = nan"):
        mcl.api.simulate(model, frame, {"R1.R": float("nan")})
    with pytest.raises(ConfigError, match="rtol"):
        mcl.api.simulate(model, frame, options={"rtol": 0})
    with pytest.raises(ConfigError, match="no such library directory"):
        mcl.api.compile_model([user / "Circuit.mo"], "Circuit.RC", libraries=["/nonexistent"])
    with pytest.raises(ModelicaError, match="without package.mo"):
        mcl.api.compile_model([user], "Circuit.RC")


def test_discovery_checks_its_arguments_and_data_like_a_run_file(user):
    pd = pytest.importorskip("pandas")
    src = [user / "Circuit.mo", LIB]
    fit = {"time": [0, 1, 2], "u": [0, 1, 0], "y": [0, 0.1, 0.2]}
    for kwargs, message in (({"model": None}, "model: must be string, not NoneType"),
                            ({"unknown": 42}, "unknown: must be string, not int"),
                            ({"screen": 0}, "screen: 0 is less than 1"),
                            ({"max_simulations": 2}, "max_simulations: 2 is less than 5"),
                            ({"executor": "dsak"}, "did you mean 'dask'"),
                            ({"templates": "polynomal"}, "did you mean 'polynomial'"),
                            ({"sources": [user / "nope.mo"]}, "sources: '.*nope.mo' does not exist")):
        with pytest.raises(ConfigError, match=message):
            mcl.Discovery(**{"model": "Circuit.RC", "sources": src, **kwargs}).fit(fit)
    d = mcl.Discovery("Circuit.RC", sources=src, templates="polynomial")
    assert d.spec().templates == ["polynomial"]                 # a string is one template
    with pytest.raises(NotFittedError, match="law_ is not set"):
        d.law_
    assert isinstance(NotFittedError("x"), MclError) and not hasattr(d, "cause_")
    no_time = pd.DataFrame({"u": [0, 1, 0], "y": [0, 0.1, 0.2]})
    with pytest.raises(DataError, match="train: no 'time' column.*time="):
        d.fit(no_time)
    assert mcl.data.as_timeseries(no_time, time="index").time.tolist() == [0, 1, 2]
    with pytest.raises(ConfigError, match="column.* z of train are not inputs or variables of Circuit.RC"):
        d.fit(pd.DataFrame({"time": [0, 1, 2], "u": [0, 1, 0], "z": [0, 0.1, 0.2]}))


@pytest.mark.parametrize("command,kind,force", [
    ("run", "dir+report.json", True), ("run", "link->dir", True), ("compile FMU", "file", True),
    ("compile dir", "dir+.mcl-run", True), ("export", "mcl+user file", True), ("simulate -o", "fifo", True),
    ("simulate --plot", "mcl+edited", True), ("graph --draw", "link->file", True),
    ("compile FMU", "mcl", True), ("run", "mcl", False), ("simulate -o", "dangling link", False),
])
def test_output_paths_of_every_command(command, kind, force, tmp_path, capsys):
    """The fuzz suite's output-path cases that the first probe found, always run."""
    d = tmp_path
    (d / "Circuit.mo").write_text(CIRCUIT)
    setup_run(d, cubic=0.0)
    (d / "input.csv").write_text("time,u\n0,0\n0.5,1\n1,1\n1.5,0\n2,0\n")
    assert main(["--quiet", "compile", str(d / "Circuit.mo"), str(LIB), "-m", "Circuit.RC", "-o", str(d / "model")]) == 0
    _finished_run(d).rename(d / "finished")
    code = try_output(d, capsys, command, kind, force)
    assert code == (0 if kind == "mcl" and force else 2)


def test_argument_errors_are_one_line(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "m.fmu", "-i", "input.csv"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1
    assert err.startswith("mcl simulate: error: the following arguments are required: -o/--output")


def test_truths_says_how_to_use_it(tmp_path):
    script = [sys.executable, str(LIB.parents[1] / "examples" / "faults" / "truths.py")]
    for args, code, text in (([], 2, "usage: python examples/faults/truths.py CASE OUT_DIR"),
                             (["slider-frction", str(tmp_path)], 2, "did you mean 'slider-friction'"),
                             (["--help"], 0, "cases: slider-cubic")):
        proc = subprocess.run(script + args, capture_output=True, text=True, timeout=60)
        assert proc.returncode == code and text in proc.stdout + proc.stderr and "Traceback" not in proc.stderr
    (tmp_path / "train.csv").write_text("mine")
    proc = subprocess.run(script + ["shunt-sinh", str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and (tmp_path / "train.csv").read_text() == "mine"


def test_temperatures_logged_in_celsius_for_a_model_in_kelvin_are_one_clear_error():
    """Taken for a misfit, a thermocouple's 273 K offset was blamed on three conductances (one a
    capacitance of 1e13 J/K); a temperature the model gives in K, measured 273 K below it
    throughout, is a data error naming the file and the column. A real misfit is not."""
    import numpy as np

    from mcl.discovery.run import _celsius_for_kelvin

    rng = np.random.default_rng(0)
    sim = 293.15 + 15 * np.sin(np.linspace(0, 6, 400))
    celsius = sim - 273.15 + 2 * np.cos(np.linspace(0, 3, 400)) + 0.1 * rng.standard_normal(400)
    with pytest.raises(DataError, match=r"train\.csv: column T2 is 27\d K below the model's T2.*degC"):
        _celsius_for_kelvin(np.column_stack([celsius - sim]), ["T2"], {"T2": "K"}, "train.csv")
    _celsius_for_kelvin(np.column_stack([celsius - sim]), ["T2"], {"T2": "degC"}, "train.csv")
    _celsius_for_kelvin(np.column_stack([sim + 5 - sim]), ["T2"], {"T2": "K"}, "train.csv")


def test_a_model_output_the_training_data_do_not_measure_is_named(caplog):
    """An output with no column in the training data is not compared: the run says so, and
    warns where the validation data measure it (before, both went unsaid)."""
    import logging

    from mcl.discovery.run import _say_unmeasured

    validate = TimeSeries([0.0, 1.0], [[1.0, 2.0], [1.0, 2.0]], ["i", "w"])
    with caplog.at_level(logging.INFO, logger="mcl"):
        _say_unmeasured(["i", "w"], ["i"], validate)
    assert "not measured in the training data: w" in caplog.text
    assert any(r.levelno == logging.WARNING and "column w is not used" in r.getMessage() for r in caplog.records)


def test_an_input_held_constant_and_a_head_that_sees_little_of_the_record_are_warned_of(caplog):
    """A constant input shows the system at one operating point; a search on the first samples of
    a record sampled far faster than the system moves sees a sliver of it. Both are said."""
    import logging

    from mcl.discovery.run import _say_constant, _say_head

    t = np.linspace(0.0, 100.0, 200_001)
    train = TimeSeries(t, np.column_stack([np.full(t.size, 1.5), np.sin(t)]), ["u", "w"])
    with caplog.at_level(logging.INFO, logger="mcl"):
        _say_constant(["u", "w"], train)
        _say_head(train.head(8192), train)
        _say_head(train.head(50_000), train)      # (a quarter: no warning)
    warned = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warned) == 2, warned
    assert "input u is constant" in warned[0] and "w" not in warned[0].split("(")[0]
    assert "first 4.1 s of the training record's 100 s" in warned[1] and "every 25th" in warned[1]


@needs_msl()
def test_a_misspelt_class_is_named_at_its_declaration(tmp_path):
    """rumoca names the first connect that reaches into the instance of a class it cannot find;
    the error names the declaration and the class as written."""
    from mcl import compile_model
    from mcl.errors import ModelicaError

    (tmp_path / "Net.mo").write_text("""model Net
  import Modelica.Electrical.Analog.Basic;
  Basic.Ground gnd;
  Basic.Resistr R1(R = 10);
  Basic.Capacitor C1(C = 1e-3);
equation
  connect(R1.p, C1.p);
  connect(R1.n, gnd.p);
  connect(C1.n, gnd.p);
end Net;
""")
    with pytest.raises(ModelicaError) as err:
        compile_model([tmp_path / "Net.mo"], "Net", libraries=[msl_path()])
    assert f"{tmp_path / 'Net.mo'}:4" in str(err.value) and "class Basic.Resistr of R1 is not found" in str(err.value)
    assert "not on the library path" not in str(err.value)


def test_a_model_on_the_msl_with_no_library_path_says_so(tmp_path, monkeypatch):
    """A newcomer's first run without MODELICAPATH: the error names the declaration and says the
    library the model imports is not on the path (not only that a class is not found)."""
    from mcl import compile_model
    from mcl.errors import ModelicaError

    monkeypatch.setenv("MODELICAPATH", "")
    (tmp_path / "Net.mo").write_text("""model Net
  import Modelica.Electrical.Analog.Basic;
  Basic.Ground gnd;
  Basic.Resistor R1(R = 10);
equation
  connect(R1.p, gnd.p);
  connect(R1.n, gnd.p);
end Net;
""")
    with pytest.raises(ModelicaError) as err:
        compile_model([tmp_path / "Net.mo"], "Net")
    text = str(err.value)
    assert f"{tmp_path / 'Net.mo'}:" in text and "library Modelica is not on the library path" in text, text
    assert "MODELICAPATH" in text


def test_each_outputs_rms_is_given_beside_its_noise(caplog):
    """The pooled RMS mixes units where the outputs have different ones (Pa beside m3/s): each
    output's RMS before and after the laws is given beside its noise, in the log and the report."""
    import logging
    from types import SimpleNamespace

    from mcl.discovery.report import _summary_rows
    from mcl.discovery.run import _per_output

    t = np.linspace(0.0, 1.0, 101)
    p, q = 1e5 + 1e3 * np.sin(6 * t), 1e-4 * np.cos(6 * t)
    y = np.column_stack([p, q])
    nominal, learned = y + [[300.0, 5e-5]], y + [[3.0, 4e-5]]     # the pressure fixed, the flow not
    validate = TimeSeries(t, y, ["p", "q"])
    noise = {"p": SimpleNamespace(sigma=2.0), "q": SimpleNamespace(sigma=1e-6)}
    with caplog.at_level(logging.INFO, logger="mcl"):
        each = _per_output(["p", "q"], noise, y, nominal, learned, validate, [nominal, learned])
    assert each["p"]["validation_before"] == pytest.approx(300.0) and each["p"]["validation_after"] == pytest.approx(3.0)
    assert each["q"]["train_after"] == pytest.approx(4e-5) and each["q"]["noise"] == 1e-6
    assert "p 300 -> 3 (2); q 5e-05 -> 4e-05 (1e-06)" in caplog.text
    report = {"misfit": {"significant": True, "noise_estimate": 1.0}, "causes": [],
              "gain": {"train_rms_before": 212.0, "train_rms_after": 2.1, "validation_rms_before": 212.0,
                       "validation_rms_after": 2.1}, "gain_per_output": each}
    page = _summary_rows(report)
    assert "Each output" in page and "1.25x smaller" in page      # the flow: 5e-5 -> 4e-5
    # the calibration's own per output, where it ran (the flow then fixed too)
    calibrated = {"p": {"train": 2.5, "validation": 2.5}, "q": {"train": 1e-6, "validation": 1e-6}}
    with caplog.at_level(logging.INFO, logger="mcl"):
        each = _per_output(["p", "q"], noise, y, nominal, learned, validate, [nominal, learned], calibrated)
    assert each["q"]["validation_calibrated"] == 1e-6 and each["p"]["train_calibrated"] == 2.5
    assert "p 300 -> 3 -> 2.5 (2); q 5e-05 -> 4e-05 -> 1e-06 (1e-06)" in caplog.text
    page = _summary_rows({**report, "gain_per_output": each})
    assert "laws + calibration" in page and "50x smaller" in page   # the flow: 5e-5 -> 1e-6
