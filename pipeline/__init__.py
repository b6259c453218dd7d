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
from .api import compile_model, discover, load_model, simulate
from .data import TimeSeries, read_csv
from .discovery import Discovery
from .discovery.export import export_library
from .errors import MclError
from .hookspecs import hookimpl
from .compile.library import mcl_version
from .simulation import SimulationOptions, SimulationResult

__version__ = mcl_version()
__all__ = ["compile_model", "load_model", "simulate", "discover", "Discovery", "export_library",
           "TimeSeries", "read_csv", "SimulationOptions", "SimulationResult", "MclError", "hookimpl",
           "__version__"]
