"""mcl: learn the constitutive laws of Modelica components from measurements.

The public face:

- :func:`compile_model`, :func:`load_model`, :func:`simulate` — Modelica to a model, a model to
  a :class:`SimulationResult`;
- :class:`Discovery` (and :func:`discover`) — what a model gets wrong, which component, which
  law, what gain; :func:`export_library` for a finished run directory;
- :class:`TimeSeries`, :func:`read_csv` — data; :data:`hookimpl` for plugins; the error family
  rooted at :class:`MclError`.

Built-in plugins live in :mod:`mcl.plugins`, the MCL Modelica library in :mod:`mcl.modelica`.
"""
from .errors import MclError

#: public name -> module defining it, imported on first use (so `mcl --help` imports no numpy)
_LAZY = {"compile_model": "api", "load_model": "api", "simulate": "api", "discover": "api",
         "Discovery": "discovery", "export_library": "discovery.export", "TimeSeries": "data",
         "read_csv": "data", "SimulationOptions": "simulation", "SimulationResult": "simulation",
         "hookimpl": "hookspecs"}

_SUBPACKAGES = ("modelica", "plugins", "compile", "discovery", "api", "data", "stats", "fit", "templates")

__all__ = ["compile_model", "load_model", "simulate", "discover", "Discovery", "export_library",
           "TimeSeries", "read_csv", "SimulationOptions", "SimulationResult", "MclError", "hookimpl",
           "__version__"]


def __getattr__(name: str):
    import importlib

    if name in _LAZY:
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    elif name == "__version__":
        from .compile.library import mcl_version

        value = mcl_version()
    elif name in _SUBPACKAGES:       # mcl.modelica, mcl.plugins, ...: imported when first named
        value = importlib.import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
