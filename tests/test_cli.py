"""The `mcl` command: compile, simulate, plugins; user mistakes are one line, never a traceback."""
import subprocess
import sys

import numpy as np
import pytest

from helpers import LIB, multisine
from mcl.cli import main
from mcl.data import read_csv
from mcl.compile.fmu.export import validate_fmu


@pytest.fixture
def input_csv(tmp_path):
    t = np.linspace(0, 20, 201)
    f = tmp_path / "input.csv"
    np.savetxt(f, np.column_stack([t, multisine(t)]), delimiter=",", header="time,u", comments="")
    return f


def test_compile_then_simulate_both_engines(tmp_path, input_csv, capsys):
    fmu = tmp_path / "cauer.fmu"
    assert main(["compile", str(LIB), "--model", "MCL.Examples.CauerFilter", "-o", str(fmu)]) == 0
    assert "index 2" in capsys.readouterr().out
    assert validate_fmu(fmu) == []
    out_fmu, out_src = tmp_path / "a.csv", tmp_path / "b.csv"
    assert main(["simulate", str(fmu), "-i", str(input_csv), "-o", str(out_fmu), "-p", "Rnl.w3=0.02"]) == 0
    assert main(["simulate", str(LIB), "--model", "MCL.Examples.CauerFilter", "-i", str(input_csv),
                 "-o", str(out_src), "--param", "Rnl.w3=0.02"]) == 0
    a, b = read_csv(out_fmu), read_csv(out_src)
    assert a.names == b.names == ["y"]
    assert np.max(np.abs(a.values - b.values)) < 1e-4 * np.max(np.abs(b.values))


def test_saved_model_directory_runs_in_process(tmp_path, input_csv):
    saved = tmp_path / "cauer"
    assert main(["compile", str(LIB), "-m", "MCL.Examples.CauerFilter", "-o", str(saved)]) == 0
    assert main(["simulate", str(saved), "-i", str(input_csv), "-o", str(tmp_path / "r.csv")]) == 0
    assert len(read_csv(tmp_path / "r.csv").time) == 201


def test_failed_simulation_exits_1_with_the_reason_and_what_it_reached(tmp_path, input_csv, capsys):
    """A run that fails writes the points it reached (the user's to look at) and says so."""
    code = main(["simulate", str(LIB), "-m", "MCL.Examples.CauerFilter", "-i", str(input_csv),
                 "-o", str(tmp_path / "r.csv"), "-p", "Rnl.w1=-0.1"])
    assert code == 1
    err = capsys.readouterr().err
    assert "simulation failed" in err
    r = read_csv(tmp_path / "r.csv")
    assert 1 < len(r.time) < 201 and np.isfinite(r.values).all()
    assert f"the {len(r.time)} samples up to t = {r.time[-1]:g}" in err


def test_modelica_sources_without_a_class_name_are_told_which_to_give(tmp_path, capsys):
    src = tmp_path / "AB.mo"
    src.write_text("model A\n  Real x;\nequation\n  x = time;\nend A;\nmodel B\n  Real y;\nequation\n  y = time;\nend B;\n")
    assert main(["simulate", str(src), "--stop-time", "1", "-o", str(tmp_path / "r.csv")]) == 2
    err = capsys.readouterr().err
    assert "need --model NAME" in err and "A, B" in err and "Traceback" not in err


BLOW = """model Blow "a level that runs away, past the domain of its outflow law at t = ln 2"
  Real h(start = 1, fixed = true);
  Real q = sqrt(2 - h) "defined below 2 only";
equation
  der(h) = h;
end Blow;
"""


def test_a_run_past_a_laws_domain_fails_keeping_the_points_before(tmp_path, capsys):
    src = tmp_path / "Blow.mo"
    src.write_text(BLOW)
    assert main(["simulate", str(src), "-m", "Blow", "--stop-time", "2", "--interval", "0.01",
                 "-o", str(tmp_path / "b.csv")]) == 1
    assert "non-finite output at t = 0.7" in capsys.readouterr().err
    r = read_csv(tmp_path / "b.csv")
    q, h = r.select(["q"]).values[:, 0], r.select(["h"]).values[:, 0]
    before = r.time < np.log(2)
    assert np.allclose(h, np.exp(r.time), rtol=1e-4)
    assert np.allclose(q[before], np.sqrt(2 - np.exp(r.time[before])), atol=1e-4)
    assert np.isnan(q[r.time > 0.7]).all()


DRAIN = """model Drain "two tanks, the first draining into the second"
  parameter Real tau1 = 2, tau2 = 5;
  Real h1(start = 1, fixed = true), h2(start = 0, fixed = true);
  Real q12 = h1/tau1 "flow from the first tank to the second";
equation
  der(h1) = -q12;
  der(h2) = q12 - h2/tau2;
  annotation(experiment(StopTime = 20, Interval = 0.5));
end Drain;
"""


def test_a_model_without_inputs_runs_its_experiment_recording_every_variable(tmp_path, capsys):
    """No input CSV: the grid is the class's experiment annotation (in process) or the FMU's
    DefaultExperiment; a model without outputs records every variable; --variables picks."""
    src = tmp_path / "Drain.mo"
    src.write_text(DRAIN)
    every = tmp_path / "every.csv"
    assert main(["simulate", str(src), "-m", "Drain", "-o", str(every)]) == 0
    assert "experiment" in capsys.readouterr().out
    r = read_csv(every)
    assert len(r.time) == 41 and r.time[-1] == 20.0
    assert {"h1", "h2", "q12"} <= set(r.names)
    assert np.allclose(r.select(["h1"]).values[:, 0], np.exp(-r.time / 2), rtol=1e-5)
    fmu = tmp_path / "drain.fmu"
    assert main(["compile", str(src), "-m", "Drain", "-o", str(fmu)]) == 0
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert main(["simulate", str(fmu), "-o", str(a), "-V", "h*"]) == 0
    assert main(["simulate", str(src), "-m", "Drain", "-o", str(b), "-V", "h*", "--stop-time", "20",
                 "--interval", "0.5"]) == 0
    for grid, says in ((["--interval", "50"], "at most the 20 s simulated"),
                       (["--stop-time", "1e9", "--interval", "1e-6"], "too many to record")):
        assert main(["simulate", str(src), "-m", "Drain", "-o", str(tmp_path / "c.csv"), *grid]) == 2
        assert says in capsys.readouterr().err
    ra, rb = read_csv(a), read_csv(b)
    assert ra.names == rb.names == ["h1", "h2"]
    assert np.allclose(ra.time, rb.time) and np.allclose(ra.values, rb.values, atol=1e-5)


def test_a_runs_warnings_and_its_terminate_are_said(tmp_path):
    """What the model says during a run (an assert of level warning, a terminate()) reaches the
    console, though the solvers' own output is silenced while it runs."""
    (tmp_path / "Fill.mo").write_text("""model Fill
  Real level(start = 0, fixed = true);
equation
  der(level) = 1;
  assert(level < 0.51, "the tank is above half", AssertionLevel.warning);
  when level > 0.81 then
    terminate("the tank is full");
  end when;
end Fill;
""")
    proc = subprocess.run([sys.executable, "-m", "mcl", "simulate", "Fill.mo", "-m", "Fill", "-o", "r.csv",
                           "--stop-time", "2", "--interval", "0.02"],
                          capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "warning at t = 0.52: the tank is above half" in proc.stderr
    assert "terminated the run at t = 0.81: the tank is full" in proc.stderr       # (at the event)
    assert read_csv(tmp_path / "r.csv").time[-1] == pytest.approx(0.8)      # the last point before it


def test_plugins_lists_compilers_and_engines(capsys):
    assert main(["plugins"]) == 0
    out = capsys.readouterr().out
    assert "casadi" in out and "openmodelica" in out and "fmu" in out and "built-in" in out


@pytest.mark.parametrize("args,message", [
    (["simulate", "{lib}", "-m", "MCL.Examples.CauerFilter", "-i", "{missing}", "-o", "x.csv"],
     "no such data file"),
    (["simulate", "{lib}", "-m", "MCL.Examples.CauerFilter", "-i", "{input}", "-o", "x.csv",
      "-p", "w1"], "expected NAME=NUMBER"),
    (["simulate", "{lib}", "-m", "MCL.Examples.CauerFilter", "-i", "{input}", "-o", "x.csv",
      "-p", "nope=1"], "no free parameter 'nope'"),
    (["compile", "{bad}", "-m", "B.M", "-o", "x.fmu"], "syntax error"),
    (["simulate", "{lib}", "-m", "MCL.Examples.CauerFilter", "-o", "x.csv"], "give their values with --input"),
    (["simulate", "{lib}", "-m", "MCL.Examples.CauerFilter", "-i", "{input}", "-o", "x.csv", "--stop-time", "2"],
     "--stop-time and --interval are for a model without inputs"),
    (["simulate", "{lib}", "-m", "MCL.Examples.CauerFilter", "-i", "{input}", "-o", "x.csv", "-V", "C9*"],
     "--variables C9*: no variable of MCL.Examples.CauerFilter matches"),
    (["compile", "{lib}", "-m", "MCL.Examples.CauerFilter", "-o", "x.fmu", "--compiler", "openmodelica"],
     "not available"),
])
def test_user_mistakes_are_one_line(tmp_path, input_csv, args, message):
    bad = tmp_path / "B.mo"
    bad.write_text("package B\n  model M\n    Real x\n  end M;\nend B;\n")
    fmt = dict(lib=LIB, missing=tmp_path / "none.csv", input=input_csv, bad=bad)
    proc = subprocess.run([sys.executable, "-m", "mcl", *[a.format(**fmt) for a in args]],
                          capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("mcl: error:") and message in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr


def test_help_on_every_subcommand_with_examples():
    from mcl.cli import build_parser

    commands = build_parser()._subparsers._group_actions[0].choices
    assert {"compile", "simulate", "info", "graph", "pretrain", "run", "export", "plugins"} <= set(commands)
    for cmd in commands:
        proc = subprocess.run([sys.executable, "-m", "mcl", cmd, "--help"],
                              capture_output=True, text=True, timeout=60)
        assert proc.returncode == 0 and "usage: mcl" in proc.stdout
        assert f"examples:\n  mcl {cmd}" in proc.stdout or "examples:\n  MCL_" in proc.stdout, proc.stdout


HEAVY = ("numpy", "casadi", "scipy", "pandas", "matplotlib", "rumoca")


@pytest.mark.parametrize("flag", ["--help", "--version"])
def test_help_and_version_import_nothing_heavy(flag):
    """`mcl --help` and `--version` answer at once: no numerical library is imported for them
    (their time is measured by `python -X importtime`, not asserted here)."""
    code = (f"import sys\nfrom mcl.cli import main\ntry:\n    main([{flag!r}])\nexcept SystemExit:\n    pass\n"
            f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout.strip().splitlines()[-1] == "[]", proc.stdout + proc.stderr
    assert ("mcl " if flag == "--version" else "usage: mcl") in proc.stdout


def test_info_lists_variables_units_parameters_and_states(tmp_path, capsys):
    fmu, saved = tmp_path / "msd.fmu", tmp_path / "msd"
    lib = ["compile", str(LIB), "-m", "MCL.Examples.MassSpringDamper"]
    assert main([*lib, "-o", str(fmu), "--no-validate"]) == 0 and main([*lib, "-o", str(saved)]) == 0
    capsys.readouterr()
    tables = []
    for args in ([str(fmu)], [str(saved)], [str(LIB), "-m", "MCL.Examples.MassSpringDamper"]):
        assert main(["info", *args]) == 0
        tables.append(capsys.readouterr().out)
    for out in tables:
        assert "model        MCL.Examples.MassSpringDamper" in out
        lines = out.splitlines()
        row = lambda name: next(line.split() for line in lines if line.split()[:1] == [name])
        assert row("u")[-3:] == ["[N]", "applied", "force"] and row("y")[1] == "[m]"
        assert float(row("mass.m")[2]) == 1 and float(row("spring.c")[2]) == 4 and row("spring.c")[3] == "[N/m]"
        states = lines[lines.index(next(x for x in lines if x.startswith("states ("))) + 1:]
        assert {"mass.s", "mass.v"} <= {s.split()[0] for s in states[:2]}
    assert "FMI 2.0 FMU (Model Exchange" in tables[0] and "generated    mcl" in tables[0]
    assert "in-process model" in tables[1] and "index 2, 0 algebraic loop(s)" in tables[1]
    assert main(["info", str(tmp_path / "none.fmu")]) == 2
    assert "no such model" in capsys.readouterr().err
