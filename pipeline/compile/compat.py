"""Compatibility shim between pymoca 0.12 and casadi 3.8 (see ../shared/DESIGN.md, section 1).

pymoca maps Modelica operators to ``MX`` methods by name; casadi 3.8 dropped or never had some
of them. Patching them in one place keeps the rest of the code free of workarounds.
"""
from __future__ import annotations

import re

import casadi as ca

_PATCHED = False


def patch_casadi_for_pymoca() -> None:
    """Add the ``MX`` methods pymoca's generator looks up by name (idempotent)."""
    global _PATCHED
    if _PATCHED:
        return
    # pymoca maps "/" to __div__, a Python 2 name.
    ca.MX.__div__ = ca.MX.__truediv__
    ca.MX.__rdiv__ = ca.MX.__rtruediv__
    # noEvent(expr) and smooth(order, expr) only carry event semantics: the value is expr.
    ca.MX.noEvent = lambda self: self
    ca.MX.smooth = lambda self, expr: expr
    # Modelica built-ins that casadi names differently.
    ca.MX.log10 = lambda self: ca.log10(self)
    ca.MX.sign = lambda self: ca.sign(self)
    _patch_function_names()
    _PATCHED = True


def _patch_function_names() -> None:
    """casadi rejects dotted function names (``Pkg.f``): build them under ``Pkg_f``."""
    from pymoca.backends.casadi.generator import Generator

    original = Generator.get_function

    def get_function(self, function_name):
        if function_name in self.functions or function_name not in self.root.classes:
            return original(self, function_name)
        tree = self.root.classes[function_name]
        saved = tree.name
        tree.name = re.sub(r"\W", "_", saved)
        try:
            return original(self, function_name)
        finally:
            tree.name = saved

    Generator.get_function = get_function
