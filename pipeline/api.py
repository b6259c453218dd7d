"""The run API, the public face of the services (:mod:`mcl.services`): compile, load and simulate
models, and run a discovery."""
from __future__ import annotations

from .services import compile_model, load_model, registry, simulate

__all__ = ["compile_model", "load_model", "registry", "simulate", "discover"]


def discover(model: str, train, validate=None, **options):
    """Run a discovery and return the fitted :class:`mcl.Discovery` (options as its constructor's)."""
    from .discovery import Discovery

    return Discovery(model, **options).fit(train, validate)
