"""The run API, the public face of the services (:mod:`mcl.services`): compile, load and simulate
models, and run a discovery."""
from __future__ import annotations

from . import services
from .services import compile_model, load_model, registry
from .simulation import RUN_TIME_LIMIT, SimulationOptions

__all__ = ["compile_model", "load_model", "registry", "simulate", "discover"]


def simulate(model, inputs, params: dict | None = None, t_out=None, options=None, sensitivities=None,
             engine: str | None = None, reg=None):
    """:func:`mcl.services.simulate`, a run the user asked for: unless ``options`` say otherwise,
    it may take :data:`~mcl.simulation.RUN_TIME_LIMIT` seconds (a fit's many runs keep
    SimulationOptions' own limit, 60 s)."""
    if not isinstance(options, SimulationOptions) and (options is None or "time_limit" not in options):
        options = {"time_limit": RUN_TIME_LIMIT, **(options or {})}
    return services.simulate(model, inputs, params, t_out, options, sensitivities, engine, reg)


def discover(model: str, train, validate=None, **options):
    """Run a discovery and return the fitted :class:`mcl.Discovery` (options as its constructor's)."""
    from .discovery import Discovery

    return Discovery(model, **options).fit(train, validate)
