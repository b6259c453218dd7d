"""The compile stage: which compiler handles a model, and the base class compilers implement."""
from __future__ import annotations

from pathlib import Path

from ..errors import PluginError


class Compiler:
    """Base of compiler plugins.

    ``name`` picks it (``--compiler NAME``, YAML ``compiler:``); ``automatic`` says whether it may
    be chosen without being named. :meth:`compile` returns a
    :class:`~mcl.model.CompiledModel` (in-process engine and FMU export) or an
    :class:`~mcl.model.FmuModel` (FMU engine only).
    """

    name = ""
    description = ""
    automatic = True

    def available(self) -> tuple[bool, str]:
        """(True, "") when usable here, else (False, why not)."""
        return True, ""

    def accepts(self, sources: list[Path]) -> bool:
        """Whether this compiler reads these source files (none: the class is on the library path)."""
        return all(Path(s).suffix == ".mo" or Path(s).is_dir() for s in sources)

    def compile(self, sources: list[Path], model: str, options: dict | None = None):
        raise NotImplementedError  # pragma: no cover - interface


def choose(compilers: dict[str, type], sources, name: str | None = None) -> Compiler:
    """The named compiler, or the first automatic one that is available and accepts ``sources``."""
    sources = [Path(s) for s in sources]
    if name:
        if name not in compilers:
            raise PluginError(f"no compiler named '{name}' (installed: {', '.join(compilers)})")
        comp = compilers[name]()
        ok, why = comp.available()
        if not ok:
            raise PluginError(f"compiler '{name}' is not available: {why}")
        return comp
    reasons = []
    for cname, cls in compilers.items():
        comp = cls()
        ok, why = comp.available()
        if comp.automatic and ok and comp.accepts(sources):
            return comp
        reasons.append(f"{cname}: {why or 'does not accept these sources'}")
    raise PluginError("no compiler accepts these sources (" + "; ".join(reasons) + ")")
