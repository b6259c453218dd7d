"""mcl: learn the constitutive laws of Modelica components from measurements.

Public face: :data:`hookimpl` for plugins, the run API (:func:`compile_model`,
:func:`load_model`, :func:`simulate`) and the error family rooted at :class:`MclError`.
"""
from .errors import MclError
from .hookspecs import hookimpl

__all__ = ["hookimpl", "MclError", "compile_model", "load_model", "simulate"]


def __getattr__(name):  # the run API imports CasADi: load it on first use, not at import
    if name in ("compile_model", "load_model", "simulate"):
        from . import api

        return getattr(api, name)
    raise AttributeError(name)
