"""Fuzzing the three inputs a user hands mcl: run files, data files, Modelica sources.

For every generated case: the exit code is 0, 1 or 2, nothing is printed as a traceback or an
internal error, nothing outside the output location is written, and nothing is deleted.
`MCL_FUZZ_EXAMPLES=N` runs N cases per input kind instead of the quick default.
"""
import os
import string
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from helpers import LIB, RC_MODEL
from mcl.cli import main

N = int(os.environ.get("MCL_FUZZ_EXAMPLES", "0"))
FUZZ = settings(max_examples=N or 60, deadline=None, derandomize=not N,
                suppress_health_check=list(HealthCheck))

CIRCUIT = "package Circuit\n" + RC_MODEL + "end Circuit;\n"
BASE = {"model": {"sources": ["Circuit.mo", str(LIB)], "name": "Circuit.RC"},
        "data": {"train": "train.csv"}, "unknown": "auto", "output": "out/run",
        "fitting": {"max_simulations": 5, "screen": 1}, "report": {"plots": False}}


def snapshot(root: Path) -> dict:
    return {p: (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*")
            if p.is_file() and "out" not in p.relative_to(root).parts}


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
                            "-o", str(workdir / "run.csv")])


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
                            "-o", str(workdir / "run_model")])
