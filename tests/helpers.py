"""Helpers shared by the tests: the project library, a compile cache, signals, error measures."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from mcl.api import compile_model
from mcl.data import TimeSeries

ROOT = Path(__file__).resolve().parents[1]
LIB = ROOT / "modelica" / "MCL"
DATA = Path(__file__).resolve().parent / "data"
FAULTS = ROOT / "examples" / "faults" / "Faults.mo"      # systems with hidden faults (and their truths)

_compiled: dict = {}


def msl_path() -> Path | None:
    """The Modelica Standard Library: an entry of MODELICAPATH holding it, else ../shared/msl."""
    import os

    for entry in [*os.environ.get("MODELICAPATH", "").split(os.pathsep), str(ROOT.parent / "shared" / "msl")]:
        if entry and (Path(entry) / "Modelica" / "package.mo").is_file():
            return Path(entry)
    return None


def needs_msl():
    """The skip mark of a test that needs the MSL, saying where it was looked for."""
    import pytest

    return pytest.mark.skipif(msl_path() is None, reason="the Modelica Standard Library is not on "
                              "MODELICAPATH nor at ../shared/msl")


def compiled(name: str, sources=None):
    """Compile once per test session (compiling is deterministic and the models are immutable)."""
    key = (name, tuple(map(str, sources or [LIB])))
    if key not in _compiled:
        _compiled[key] = compile_model(sources or [LIB], name)
    return _compiled[key]


def discovered(directory: Path, source: str, name: str, text: str) -> dict:
    """``mcl run`` on the model ``text`` (written to ``directory/source``, built on the MSL) with
    the train.csv and validate.csv there: the report."""
    import json

    from mcl.cli import main

    (directory / source).write_text(text)
    (directory / "run.yaml").write_text(
        f"model: {{sources: [{source}], name: {name}, libraries: [{msl_path()}]}}\n"
        "data: {train: train.csv, validate: validate.csv}\noutput: out\n")
    assert main(["--quiet", "run", str(directory / "run.yaml")]) == 0
    return json.loads((directory / "out" / "report.json").read_text())


def write_uy(path: Path, t, u, y) -> None:
    """A data file of columns time, u and y (10 significant digits)."""
    path.write_text("time,u,y\n" + "\n".join(f"{a:.10g},{b:.10g},{c:.10g}" for a, b, c in zip(t, u, y)) + "\n")


def multisine(t, parts=((2.0, 0.5, 0.0), (0.5, 2.1, 0.3))):
    """Sum of sines a*sin(w t + phi): a smooth input known in closed form."""
    return sum(a * np.sin(w * t + phi) for a, w, phi in parts)


def random_parts(rng, low: float, high: float, w) -> list:
    """(a, w, phi) parts for :func:`multisine`: at the frequencies ``w``, amplitudes uniform in
    [low, high] and phases uniform, drawn from ``rng`` in that order."""
    return list(zip(rng.uniform(low, high, len(w)), w, rng.uniform(0, 2 * np.pi, len(w))))


def series(t, **columns) -> TimeSeries:
    values = np.column_stack(list(columns.values())) if columns else np.zeros((len(t), 0))
    return TimeSeries(t, values, list(columns))


def unforced_run(model, t_end: float, n: int):
    """(the grid, the run of ``model`` with no inputs over n points from 0 to ``t_end``),
    asserted to succeed."""
    from mcl import simulate

    t = np.linspace(0.0, t_end, n)
    res = simulate(model, TimeSeries(t, np.zeros((n, 0)), []), t_out=t)
    assert res.ok, res.reason
    return t, res


def probed(model, res) -> dict:
    """Every named variable of ``model`` along the run ``res`` (name -> values at its points),
    read from the states it kept."""
    o = model.ode
    at = np.array([np.array(o.probe(x, o.u_start, o.p_values, t)).ravel() for x, t in zip(res.states, res.time)])
    return dict(zip(o.probe_names, at.T))


def rel_err(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


#: A source, a series resistor, a capacitor and the load resistor Rx some tests hide a law in.
RC_MODEL = """
model RC "source, series resistor, capacitor in parallel with a load resistor"
  input Real u;
  output Real y;
  MCL.Electrical.VoltageSource V;
  MCL.Electrical.Ground G;
  MCL.Electrical.Resistor R1(R = 1);
  MCL.Electrical.Capacitor C(C = 0.5);
  MCL.Electrical.Resistor Rx(R = 2);
equation
  V.u = u;
  connect(V.p, R1.p);
  connect(R1.n, C.p);
  connect(C.p, Rx.p);
  connect(C.n, G.p);
  connect(Rx.n, G.p);
  connect(V.n, G.p);
  y = C.v;
end RC;
"""
