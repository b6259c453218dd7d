"""Fuzzing what a user hands mcl: run files, data files, Modelica sources, and output paths.

For every generated case: the exit code is 0, 1 or 2, nothing is printed as a traceback or an
internal error, nothing outside the output location is written, and nothing is deleted. Output
paths (an existing file, a folder, a symlink, a FIFO, a folder with an ownership-looking file,
an output mcl wrote and the user changed...) are tried on every command that writes: no byte of
a user's file changes, and every refusal is one line with exit code 2.
`MCL_FUZZ_EXAMPLES=N` runs N cases per kind instead of the quick default.
"""
import hashlib
import itertools
import json
import os
import stat
import string
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from helpers import LIB, RC_MODEL
from mcl.cli import main
from mcl.outputs import RECORD

N = int(os.environ.get("MCL_FUZZ_EXAMPLES", "0"))
FUZZ = settings(max_examples=N or 60, deadline=None, derandomize=not N,
                suppress_health_check=list(HealthCheck))

CIRCUIT = "package Circuit\n" + RC_MODEL + "end Circuit;\n"
BASE = {"model": {"sources": ["Circuit.mo", str(LIB)], "name": "Circuit.RC"},
        "data": {"train": "train.csv"}, "unknown": "auto", "output": "out/run",
        "fitting": {"max_simulations": 5, "screen": 1}, "report": {"plots": False}}


def snapshot(root: Path) -> dict:
    return {p: (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*")
            if p.is_file() and "out" not in p.relative_to(root).parts and not p.name.startswith(RECORD)
            and not p.relative_to(root).parts[0].startswith("paths")}


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    d = tmp_path_factory.mktemp("fuzz")
    (d / "Circuit.mo").write_text(CIRCUIT)
    t = np.linspace(0, 2, 41)
    y = 0.3 * (1 - np.exp(-t))          # a null case: short, so a valid run file runs quickly
    (d / "train.csv").write_text("time,u,y\n" + "".join(f"{a},{0.3},{b}\n" for a, b in zip(t, y)))
    (d / "notes.txt").write_text("the user's own file: must survive every case\n")
    assert main(["--quiet", "compile", str(d / "Circuit.mo"), str(LIB), "--model", "Circuit.RC",
                 "-o", str(d / "model")]) == 0
    return d


def check(workdir, capsys, argv):
    before = snapshot(workdir)
    code = main(argv)
    err = capsys.readouterr().err
    assert code in (0, 1, 2), err
    assert "Traceback" not in err and "internal error" not in err, err
    after = snapshot(workdir)
    assert set(before) <= set(after), f"deleted: {set(before) - set(after)}"
    assert set(after) == set(before) | {p for p in after if p.relative_to(workdir).parts[0].startswith(("run", "case"))}, \
        f"written outside the output: {set(after) - set(before)}"
    return code


values = st.recursive(st.none() | st.booleans() | st.integers(-10**6, 10**6) | st.floats(allow_nan=True)
                      | st.text(string.printable, max_size=12),
                      lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3),
                      max_leaves=6)
paths = st.sampled_from([("model",), ("model", "sources"), ("model", "name"), ("data",), ("data", "train"),
                         ("unknown",), ("templates",), ("fitting",), ("fitting", "screen"), ("refinement",),
                         ("executor",), ("executor", "kind"), ("executor", "workers"), ("second",),
                         ("report",), ("report", "title"), ("extra",)])


@FUZZ
@given(edits=st.lists(st.tuples(paths, values, st.booleans()), min_size=1, max_size=3),
       garbage=st.one_of(st.none(), st.text(max_size=40)))
def test_fuzzed_run_files(workdir, capsys, edits, garbage):
    doc = yaml.safe_load(yaml.safe_dump(BASE))
    for path, value, delete in edits:
        node = doc
        for key in path[:-1]:
            node = node.setdefault(key, {}) if isinstance(node, dict) else {}
        if isinstance(node, dict):
            if delete:
                node.pop(path[-1], None)
            else:
                node[path[-1]] = value
    text = yaml.safe_dump(doc) if garbage is None else yaml.safe_dump(doc) + garbage
    (workdir / "case.yaml").write_text(text)
    check(workdir, capsys, ["--quiet", "run", str(workdir / "case.yaml"), "--force"])


cells = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr), st.just(""),
                  st.text(string.printable, max_size=6), st.integers().map(str))


@FUZZ
@given(header=st.lists(st.sampled_from(["time", "u", "y", "x", "", "time "]), max_size=4),
       rows=st.lists(st.lists(cells, max_size=4), max_size=6),
       raw=st.one_of(st.none(), st.binary(max_size=60)),
       encoding=st.sampled_from(["utf-8", "utf-16", "latin-1"]))
def test_fuzzed_data_files(workdir, capsys, header, rows, raw, encoding):
    f = workdir / "case.csv"
    if raw is not None:
        f.write_bytes(raw)
    else:
        text = "\n".join(",".join(r) for r in [header, *rows])
        f.write_bytes(text.encode(encoding, errors="replace"))
    check(workdir, capsys, ["--quiet", "simulate", str(workdir / "model"), "--input", str(f),
                            "-o", str(workdir / "run.csv"), "--force"])


TOKENS = ["when", "delay(x, 1)", "der(", ")", ";", "end", "connect(", "1e999", "/ 0", "Real", "input",
          "parameter", "equation", "algorithm", "if", "then", "else", "=", "x", "u", "y", "model", "\n",
          "pre(x)", "sample(0, 1)", "'", '"', "{", "}", "[", "]", "..."]
SMALL = """model M
  input Real u;
  output Real y;
  parameter Real k = 2;
  Real x(start = 0);
equation
  der(x) = -k * x + u;
  y = x;
end M;
"""


@FUZZ
@given(cuts=st.lists(st.tuples(st.integers(0, len(SMALL)), st.integers(0, 6), st.sampled_from(TOKENS)),
                     min_size=1, max_size=3))
def test_fuzzed_modelica_sources(workdir, capsys, cuts):
    text = SMALL
    for at, drop, token in cuts:
        text = text[:at] + token + text[at + drop:]
    (workdir / "case.mo").write_text(text)
    check(workdir, capsys, ["--quiet", "compile", str(workdir / "case.mo"), "--model", "M",
                            "-o", str(workdir / "run_model"), "--force"])


# ---- output paths -------------------------------------------------------------------------------

#: what is at the output path before the command runs (made by the "user", or by mcl first)
KINDS = ["new", "file", "dir", "dir+report.json", "dir+.mcl-run", "dir+bad record", "dir+partial record",
         "link->file", "link->dir", "dangling link", "fifo", "link->fifo", "mcl", "mcl+edited",
         "mcl+user file"]
#: command -> output name in the case folder
COMMANDS = {"simulate -o": "out.csv", "simulate --plot": "out.png", "compile FMU": "out.fmu",
            "compile dir": "out", "export": "libs/MyParts", "graph --draw": "out.svg", "run": "out"}
DIRECTORIES = ("compile dir", "export", "run")        # commands whose output is a directory
_cases = itertools.count()


def argv_for(command: str, target: Path, d: Path, force: bool) -> list[str]:
    """The command line writing ``target`` (the saved model, data, a finished run: in ``d``)."""
    sources = [str(d / "Circuit.mo"), str(LIB)]
    model = ["-m", "Circuit.RC"]
    args = {"simulate -o": ["simulate", str(d / "model"), "-i", str(d / "input.csv"), "-o", str(target)],
            "simulate --plot": ["simulate", str(d / "model"), "-i", str(d / "input.csv"),
                                "-o", str(target.with_name(f"r{next(_cases)}.csv")), "--plot", str(target)],
            "compile FMU": ["compile", *sources, *model, "-o", str(target), "--no-validate"],
            "compile dir": ["compile", *sources, *model, "-o", str(target)],
            "export": ["export", str(d / "finished"), "-o", str(target.parent), "--name", target.name],
            "graph --draw": ["graph", *sources, *model, "--draw", str(target)],
            "run": ["run", str(target.parent / "run.yaml")]}[command]
    if command == "run":
        doc = {**BASE, "model": {"sources": sources, "name": "Circuit.RC"}, "data": {"train": str(d / "train.csv")},
               "output": target.name}
        (target.parent / "run.yaml").write_text(yaml.safe_dump(doc))
    return ["--quiet", *args, *(["--force"] if force else [])]


def state(paths) -> dict:
    """What each protected path is: a link's target, a file's bytes, a folder's names, a FIFO."""
    out = {}
    for p in paths:
        try:
            mode = os.lstat(p).st_mode
        except FileNotFoundError:
            out[p] = "missing"
            continue
        if stat.S_ISLNK(mode):
            out[p] = ("link", os.readlink(p))
        elif stat.S_ISREG(mode):
            out[p] = ("file", hashlib.sha256(p.read_bytes()).hexdigest())
        elif stat.S_ISDIR(mode):
            out[p] = ("dir", sorted(os.listdir(p)))
        else:
            out[p] = ("special", stat.S_IFMT(mode))
    return out


def arrange(kind: str, command: str, target: Path, d: Path, capsys) -> list[Path]:
    """Put ``kind`` at ``target``; returns the paths that are the user's (never to change)."""
    case = target.parent
    case.mkdir(parents=True, exist_ok=True)
    mine = []
    if kind == "file":
        target.write_bytes(b"the user's own file\n")
        mine = [target]
    elif kind.startswith("dir"):
        target.mkdir()
        (target / "thesis.tex").write_text("the user's thesis\n")
        mine = [target, target / "thesis.tex"]
        extra = {"dir+report.json": ("report.json", "{}"), "dir+.mcl-run": (".mcl-run", "made by mcl\n"),
                 "dir+bad record": (RECORD, "{not json"),
                 "dir+partial record": (RECORD, json.dumps({"record": "written by mcl", "files": {}}))}.get(kind)
        if extra:
            (target / extra[0]).write_text(extra[1])
            mine.append(target / extra[0])
    elif kind in ("link->file", "link->dir", "link->fifo", "dangling link"):
        real = case / "elsewhere"
        if kind == "link->file":
            real.write_bytes(b"the user's file the link names\n")
        elif kind == "link->dir":
            real.mkdir()
            (real / "notes.txt").write_text("the user's notes\n")
            mine.append(real / "notes.txt")
        elif kind == "link->fifo":
            os.mkfifo(real)
        target.symlink_to(real)
        mine += [target] + ([real] if kind != "dangling link" else [])
    elif kind == "fifo":
        os.mkfifo(target)
        mine = [target]
    elif kind.startswith("mcl"):
        first = main(argv_for(command, target, d, force=False))
        capsys.readouterr()
        assert first == 0, f"{command} could not make {target}"
        if kind == "mcl+edited":
            edited = target if target.is_file() else sorted(p for p in target.rglob("*")
                                                             if p.is_file() and p.name != RECORD)[0]
            with open(edited, "ab") as fh:
                fh.write(b"\nthe user's edit\n")
            mine = [edited]
        elif kind == "mcl+user file":
            folder = target if target.is_dir() else target.parent
            (folder / "notes.txt").write_text("the user's notes\n")
            mine = [folder / "notes.txt"] + ([target] if target.is_dir() else [])
    return mine


def try_output(workdir, capsys, command: str, kind: str, force: bool) -> int:
    """Run ``command`` onto an output prepared as ``kind``: a user's path never changes, every
    refusal is one line with exit code 2, a new path or (with --force) mcl's own is written."""
    case = workdir / "paths" / f"case{next(_cases)}"
    target = case / COMMANDS[command]
    mine = arrange(kind, command, target, workdir, capsys)
    if kind == "mcl" and not force:        # mcl's own output is replaced only with --force
        mine.append(target)
    protected = set(mine) | {p for m in mine if m.is_dir() and not m.is_symlink() for p in m.rglob("*")}
    before, outside = state(protected), snapshot(workdir)
    code = main(argv_for(command, target, workdir, force))
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err, err
    assert state(protected) == before, f"{command} onto {kind} (force={force}) changed a user's path: {err}"
    assert snapshot(workdir) == outside, f"{command} wrote outside its case folder"
    if code == 2:
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("mcl: error:"), err
    else:      # written: a new path, or with --force mcl's own (a user's file beside it is kept)
        mcls = kind == "mcl" or (kind == "mcl+user file" and command not in DIRECTORIES)
        assert code == 0 and (kind == "new" or (force and mcls)), \
            f"{command} onto {kind} (force={force}) exited {code}: {err}"
    return code


@pytest.fixture(scope="module")
def finished_run(workdir):
    """A finished run directory as export reads it (report.json naming the learned class)."""
    run = workdir / "finished"
    if not run.exists():
        run.mkdir()
        (run / "ext.mo").write_text("package Ext\n  model Rx_learned\n    Real v;\n  equation\n    v = 1;\n"
                                    "  end Rx_learned;\nend Ext;\n")
        (run / "report.json").write_text(json.dumps({"cause": {"modelica": "ext.mo", "fmu": "x.fmu",
                                                               "learned_class": "Rx_learned"}}))
        (workdir / "input.csv").write_text("time,u\n0,0\n0.5,1\n1,1\n1.5,0\n2,0\n")
    return run


@settings(max_examples=N or 20, deadline=None, derandomize=not N, suppress_health_check=list(HealthCheck))
@given(command=st.sampled_from(sorted(COMMANDS)), kind=st.sampled_from(KINDS), force=st.booleans())
def test_fuzzed_output_paths(workdir, finished_run, capsys, command, kind, force):
    try_output(workdir, capsys, command, kind, force)
