"""The run API: compile, load and simulate models, with the plugins doing the work."""
from __future__ import annotations

from pathlib import Path

from .data import TimeSeries
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
    sources = [Path(s) for s in ([sources] if isinstance(sources, (str, Path)) else sources)]
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
    specs = [spec] if isinstance(spec, (str, Path)) else list(spec)
    if len(specs) == 1 and model is None:
        return reg.load_model_file(specs[0])
    if model is None:
        from .errors import ConfigError

        raise ConfigError("Modelica sources need a model class name (--model Pkg.Model)")
    return compile_model(specs, model, compiler, reg=reg)


def simulate(model, inputs: TimeSeries, params: dict | None = None, t_out=None,
             options: SimulationOptions | dict | None = None, sensitivities=None,
             engine: str | None = None, reg: Registry | None = None) -> SimulationResult:
    """Simulate ``model`` with measured ``inputs``; a failure is a result with ``ok=False``."""
    reg = reg or registry()
    if not isinstance(options, SimulationOptions):
        options = SimulationOptions.from_dict(options)
    eng = reg.engine_for(model, engine)
    context = {"model": model, "engine": eng.name, "params": params or {}}
    with reg.stage("simulate", context) as stage:
        stage.result = eng.simulate(model, inputs, params, t_out, options, sensitivities)
    return stage.result


def discover(model: str, train, validate=None, **options):
    """Run a discovery and return the fitted :class:`mcl.Discovery` (options as its constructor's)."""
    from .discovery import Discovery

    return Discovery(model, **options).fit(train, validate)
