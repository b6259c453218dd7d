"""The services every stage uses: the plugin registry, compile, load and simulate models (the
plugins do the work). The lowest layer above the plugins: it imports no stage, so any stage can
import it; :mod:`mcl.api` is the public face that re-exports it.

Each function checks what the command line checks, with the same one-line messages (MclError):
sources and library directories that exist, a class name, inputs with a time column and the
model's input columns, finite parameter values and solver options in range.
"""
from __future__ import annotations

import math
import os
import re
from pathlib import Path

from .data import TimeSeries, as_timeseries
from .errors import ConfigError, DataError, ModelicaError
from .outputs import check_input, special_kind
from .registry import Registry
from .simulation import SimulationOptions, SimulationResult

_registry: Registry | None = None


def registry() -> Registry:
    """The process-wide registry (built on first use, never at import time)."""
    global _registry
    if _registry is None:
        _registry = Registry()
    return _registry


def compile_model(sources, model: str, compiler: str | None = None, options: dict | None = None,
                  reg: Registry | None = None, libraries=()):
    """Compile class ``model`` of Modelica ``sources`` (files or package directories; may be
    empty when the class is in a library on the path: ``libraries``, ``MODELICAPATH``, MCL)."""
    reg = reg or registry()
    sources = check_sources(sources)
    check_class_name(model)
    libraries = check_libraries(libraries)
    options = {**(options or {}), "libraries": [str(p) for p in libraries]}
    comp = reg.compiler(sources, compiler)
    context = {"sources": sources, "model": model, "compiler": comp.name}
    with reg.stage("compile", context) as stage:
        stage.result = comp.compile(sources, model, options)
    return stage.result


def load_model(spec, model: str | None = None, compiler: str | None = None,
               reg: Registry | None = None):
    """A model from an FMU / saved model file, or from Modelica sources plus a class name."""
    reg = reg or registry()
    specs = _paths(spec, "model")
    if len(specs) == 1 and model is None:
        check_input(specs[0], "model file (an FMU or a saved model directory)", directory_ok=True)
        return reg.load_model_file(specs[0])
    if model is None:
        raise ConfigError("Modelica sources need a model class name (--model Pkg.Model)")
    return compile_model(specs, model, compiler, reg=reg)


def simulate(model, inputs, params: dict | None = None, t_out=None,
             options: SimulationOptions | dict | None = None, sensitivities=None,
             engine: str | None = None, reg: Registry | None = None) -> SimulationResult:
    """Simulate ``model`` with measured ``inputs`` (a TimeSeries, a pandas DataFrame with a
    ``time`` column or index, a NumPy structured array, a mapping of columns or a CSV path); a
    failure is a result with ``ok=False``, a mistake an MclError."""
    reg = reg or registry()
    if not hasattr(model, "input_names") or not hasattr(model, "output_names"):
        raise ConfigError(f"model: give a model from compile_model or load_model, not {type(model).__name__}")
    if inputs is None and t_out is not None and not model.input_names:    # (a model that reads no inputs)
        import numpy as np

        grid = _time_grid(t_out)
        inputs = TimeSeries(grid, np.empty((len(grid), 0)), [])
    elif inputs is None:
        raise DataError(f"inputs: the model reads {', '.join(model.input_names)}: give them as a pandas DataFrame, "
                        "a NumPy structured array, a mapping of columns, a TimeSeries or a CSV path"
                        if model.input_names else "inputs: the model reads none; give t_out, the times to simulate and record")
    if not isinstance(inputs, TimeSeries):
        inputs = as_timeseries(inputs, "inputs")
    inputs.select(model.input_names)          # a DataError naming the missing columns
    params = check_params(params)
    if t_out is not None:
        t_out = _time_grid(t_out)
    if not isinstance(options, SimulationOptions):
        options = SimulationOptions.from_dict(options)
    eng = reg.engine_for(model, engine)
    context = {"model": model, "engine": eng.name, "params": params}
    with reg.stage("simulate", context) as stage:
        stage.result = eng.simulate(model, inputs, params, t_out, options, sensitivities)
    return stage.result


_CLASS = re.compile(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*")


def _paths(value, what: str) -> list[Path]:
    """One path or a list of paths (str or os.PathLike), or a ConfigError."""
    if isinstance(value, (str, os.PathLike)):
        value = [value]
    try:
        items = list(value)
    except TypeError:
        raise ConfigError(f"{what}: give a path or a list of paths, not {type(value).__name__}") from None
    bad = [x for x in items if not isinstance(x, (str, os.PathLike)) or not str(x)]
    if bad:
        raise ConfigError(f"{what}: {bad[0]!r} is not a path")
    return [Path(x).expanduser() for x in items]


def check_sources(sources) -> list[Path]:
    """Modelica sources: .mo files or package directories (with package.mo) that exist; a FIFO
    or a device is refused (reading one never ends)."""
    out = _paths(sources, "sources")
    for p in out:
        check_input(p, "Modelica source (.mo file or package directory)", directory_ok=True, error=ModelicaError)
        if p.is_dir() and not (p / "package.mo").is_file():
            raise ModelicaError("is a directory without package.mo, not a Modelica package: give the "
                                ".mo files, or the package's own directory", where=str(p))
        if p.is_dir():
            _regular_package(p)
    return out


def _regular_package(directory: Path) -> None:
    """Every file of a package directory the front end reads (.mo, package.order) is a regular
    file: a FIFO among them would block the compile forever."""
    for root, _, names in os.walk(directory):
        for name in names:
            if name.endswith(".mo") or name == "package.order":
                kind = special_kind(Path(root) / name)
                if kind:
                    raise ModelicaError(f"is {kind}, not a Modelica file: mcl reads only regular files",
                                        where=str(Path(root) / name))


def check_class_name(model) -> str:
    if not isinstance(model, str) or not _CLASS.fullmatch(model):
        raise ConfigError(f"model: {model!r} is not a Modelica class name (e.g. Pkg.Model)")
    return model


def check_libraries(libraries) -> list[Path]:
    """Library path entries: existing directories (a library, or a folder of libraries)."""
    out = _paths(libraries or [], "libraries")
    for p in out:
        if not p.exists():
            raise ConfigError("no such library directory", where=str(p))
        if not p.is_dir():
            raise ConfigError("is not a directory: a library on the path is a directory (a library "
                              "with package.mo, or a folder of libraries)", where=str(p))
    return out


def check_params(params) -> dict[str, float]:
    """Parameter values by name, each a finite number (the model checks the names)."""
    if params is None:
        return {}
    if not isinstance(params, dict):
        raise ConfigError(f"params: give a mapping of parameter names to numbers, not {type(params).__name__}")
    out = {}
    for name, value in params.items():
        try:
            v = float(value)
        except (TypeError, ValueError):
            v = None
        if isinstance(value, (bool, str)) or v is None or not math.isfinite(v):
            raise ConfigError(f"params: {name} = {value!r} is not a finite number")
        out[str(name)] = v
    return out


def _time_grid(t_out):
    import numpy as np

    try:
        t = np.asarray(t_out, dtype=float).ravel()
    except (TypeError, ValueError):
        raise ConfigError("t_out: give an increasing array of finite times") from None
    if len(t) < 1 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise ConfigError("t_out: give an increasing array of finite times")
    return t
