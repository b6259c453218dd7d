"""A learned law as a Python object: read like report.json's dict, evaluated like a function."""
from __future__ import annotations

import numpy as np


class LearnedLaw(dict):
    """A cause's law (report.json's ``law`` entry, so ``law["equation"]`` works) that can be
    evaluated: ``law(x)`` is what the law gives at values ``x`` of the variable it is in (the
    flow for a law in the across value or its rate, the across value for a law in the flow), in
    the equation's own words and sign (``law.x``, ``law.y``) and units (``law.x_unit``)."""

    def __init__(self, cause: dict):
        super().__init__(cause["law"])
        self.component = cause["component"]
        self._template_spec, self._w = cause["template"], np.asarray(cause["w"], float)

    def __getattr__(self, name):
        try:
            return self[name]
        except KeyError:
            raise AttributeError(name) from None

    def __call__(self, x):
        """The law at ``x`` (a number or an array), in the equation's words and sign."""
        from ..services import registry

        s = float(self.get("sign", 1.0))
        xs = np.atleast_1d(np.asarray(x, float))
        out = s * np.asarray(registry().template(self._template_spec).curve(self._w, s * xs), float)
        return out if np.ndim(x) else float(out[0])

    def __repr__(self) -> str:
        return f"LearnedLaw({self.get('equation')!r})"

    def _repr_html_(self) -> str:
        import html

        return f"<code>{html.escape(str(self.get('equation')))}</code> <i>where {html.escape(str(self.get('where', '')))}</i>"
