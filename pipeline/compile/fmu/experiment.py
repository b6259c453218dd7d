"""The DefaultExperiment of an FMU: from the data, from the model's annotation, or estimated.

An importer with no settings (``fmpy.simulate_fmu(path)``) runs the DefaultExperiment, so it
says what the model is for: discovery writes the data's span and sampling interval; ``mcl
compile`` reads the class's ``annotation(experiment(...))`` (rumoca's IR does not carry
annotations, so the class's source text is read); without either, the model's own time scales
(eigenvalues of its Jacobian at the initial state) give a span of a few slowest time constants.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..sources import COMMENT_OR_STRING

DEFAULT_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Experiment:
    start: float = 0.0
    stop: float = 1.0
    step: float | None = None        # the communication / output interval
    tolerance: float = DEFAULT_TOLERANCE
    source: str = "default"          # data, annotation or estimate: said in the report

    @classmethod
    def of(cls, value) -> "Experiment | None":
        """An Experiment from an Experiment, data (anything with ``time``: a TimeSeries), a dict
        (start, stop, step, tolerance) or None."""
        if value is None or isinstance(value, Experiment):
            return value
        if hasattr(value, "time"):
            return cls.from_data(value.time)
        return cls(**{"source": "given", **dict(value)})

    @classmethod
    def from_data(cls, time, tolerance: float = DEFAULT_TOLERANCE) -> "Experiment":
        """The span of a time grid and its typical (median) sampling interval."""
        t = np.asarray(time, dtype=float)
        # 12 digits: 0.05 stays 0.05, not 0.04999999999, so importers that halve the number of
        # points (FMPy keeps at most 1000) land on whole multiples of the data's interval
        step = float(f"{np.median(np.diff(t)):.12g}") if len(t) > 1 else None
        return cls(float(t[0]), float(t[-1]), step, tolerance, "data")

    def xml(self) -> str:
        step = f' stepSize="{self.step!r}"' if self.step else ""
        return (f'  <DefaultExperiment startTime="{self.start!r}" stopTime="{self.stop!r}"'
                f' tolerance="{self.tolerance!r}"{step}/>\n')


def for_model(model, libraries=()) -> Experiment:
    """The class's experiment annotation when its source is found (the model's sources, then
    ``libraries`` and the library path), else an estimate."""
    return from_annotation(model, libraries) or estimated(model)


def of_fmu(path) -> Experiment | None:
    """The DefaultExperiment of the FMU at ``path`` (any tool's), None where it sets no stop time."""
    from fmpy import read_model_description

    e = read_model_description(str(path), validate=False).defaultExperiment
    if e is None or e.stopTime is None:
        return None
    start = float(e.startTime or 0.0)
    return Experiment(start, float(e.stopTime), float(e.stepSize) if e.stepSize else None,
                      float(e.tolerance or DEFAULT_TOLERANCE), "annotation")


# -- the annotation ---------------------------------------------------------------------------

_KEYWORDS = r"(?:model|block|class|package)"
_NAMES = {"StartTime": "start", "StopTime": "stop", "Interval": "step", "Tolerance": "tolerance"}


def from_annotation(model, libraries=()) -> Experiment | None:
    text = class_text(model.name, model.info.get("sources", ()), libraries)
    if text is None:
        return None
    found = list(re.finditer(r"\bexperiment\s*\(([^()]*)\)", text))
    if not found:
        return None
    values = {}
    for key, val in re.findall(r"(\w+)\s*=\s*([-+]?[0-9.]+(?:[eE][-+]?[0-9]+)?)", found[-1].group(1)):
        if key in _NAMES:
            values[_NAMES[key]] = float(val)
    if "stop" not in values:
        return None
    values.setdefault("tolerance", DEFAULT_TOLERANCE)
    return Experiment(**values, source="annotation")


def class_text(name: str, sources=(), libraries=()) -> str | None:
    """Source text of class ``name`` (dotted) in ``sources`` or on the library path (``libraries``
    first); None if not found. Comments removed."""
    from ..library import available, library_path

    parts = name.split(".")
    roots = [Path(s) for s in sources]
    for root in roots:
        found = _in_root(root, parts, top_level=root.is_file())
        if found is not None:
            return found
    lib = available(library_path(libraries)).get(parts[0])
    return _in_root(lib, parts, top_level=False) if lib is not None else None


def _in_root(root: Path, parts: list[str], top_level: bool) -> str | None:
    if root.is_file():
        return _walk(_read(root), parts)
    if not root.is_dir():
        return None
    path, rest = root, list(parts)
    if (root / "package.mo").is_file() and root.name.split(" ")[0] == parts[0]:
        rest = rest[1:]
    elif not top_level and (root / f"{parts[0]}").is_dir():
        path, rest = root / parts[0], rest[1:]
    while rest and (path / rest[0] / "package.mo").is_file():
        path, rest = path / rest[0], rest[1:]
    if not rest:
        return _read(path / "package.mo") if (path / "package.mo").is_file() else None
    if (path / f"{rest[0]}.mo").is_file():
        return _walk(_read(path / f"{rest[0]}.mo"), rest)
    if (path / "package.mo").is_file():
        return _walk(_block(_read(path / "package.mo"), path.name.split(" ")[0]) or "", rest)
    return None


def _read(path: Path) -> str:
    """The file without its comments (its strings kept: a "//" in one is not a comment)."""
    text = path.read_text(encoding="utf-8", errors="replace")
    return COMMENT_OR_STRING.sub(lambda m: m[0] if m[0].startswith('"') else " ", text)


def _walk(text: str, parts: list[str]) -> str | None:
    for part in parts:
        text = _block(text, part)
        if text is None:
            return None
    return text


def _block(text: str, name: str) -> str | None:
    head = re.search(rf"(?:^|[\s;])(?:(?:partial|encapsulated|final|expandable)\s+)*{_KEYWORDS}\s+"
                     rf"{re.escape(name)}\b", text)
    if not head:
        return None
    end = re.search(rf"\bend\s+{re.escape(name)}\s*;", text[head.end():])
    return text[head.end(): head.end() + end.start()] if end else None


# -- the estimate -----------------------------------------------------------------------------

def estimated(model) -> Experiment:
    """A span of five slowest time constants (or periods) of the model at its initial state,
    rounded to 1, 2 or 5 times a power of ten, sampled 500 times; 0..1 s when nothing is known."""
    o = model.ode
    try:
        import casadi as ca

        x0 = np.array(o.init(o.u_start, o.p_values, 0.0)).ravel()
        X, U, P, T = o.ode.mx_in()
        jac = ca.Function("J", [X, U, P, T], [ca.jacobian(o.ode(X, U, P, T), X)])
        lam = np.linalg.eigvals(np.array(jac(x0, o.u_start, o.p_values, 0.0), dtype=float))
    except Exception:  # noqa: BLE001 - an estimate only: the default span is fine
        lam = np.zeros(0)
    mag = np.abs(lam[np.isfinite(lam)]) if lam.size else lam
    mag = mag[mag > 1e-9 * mag.max()] if mag.size and mag.max() > 0 else np.zeros(0)
    if not mag.size:
        return Experiment(0.0, 1.0, 0.002, DEFAULT_TOLERANCE, "estimate")
    slowest = 1.0 / mag.min()
    periods = [2 * math.pi / abs(z.imag) for z in lam if abs(z.imag) > 1e-9 * mag.max()]
    stop = _round125(5 * max([slowest, *periods]))
    stop = min(max(stop, 1e-3), 1e5)
    return Experiment(0.0, stop, _round125(stop / 500), DEFAULT_TOLERANCE, "estimate")


def _round125(x: float) -> float:
    e = math.floor(math.log10(x))
    m = x / 10 ** e
    return float(f"{min((1, 2, 5, 10), key=lambda k: abs(math.log(m / k))) * 10 ** e:.12g}")
