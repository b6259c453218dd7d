"""One exception family for the whole tool; only the CLI turns it into a one-line message."""
from __future__ import annotations


class MclError(Exception):
    """Base of every error `mcl` raises for a user mistake or an unsupported input.

    ``where`` is the file (and line) the problem is in, shown before the message.
    """

    def __init__(self, message: str, where: str | None = None):
        super().__init__(message)
        self.message = message
        self.where = where

    def __str__(self) -> str:
        return f"{self.where}: {self.message}" if self.where else self.message


class ModelicaError(MclError):
    """A Modelica source that does not parse, names a missing class, or is unbalanced."""


class UnsupportedConstruct(ModelicaError):
    """A construct the compiler cannot translate faithfully (never compiled wrongly)."""


class CompileError(MclError):
    """The compiler failed on a model it accepted (C compiler, FMU packaging, ...)."""


class PluginError(MclError):
    """A plugin failed to load, registered a duplicate name, or nothing handles a request."""


class DataError(MclError):
    """A data file is missing, malformed, or does not match the model."""


class ConfigError(MclError):
    """A run file or command-line value is invalid."""


class FitError(MclError):
    """A fit that cannot proceed: no parameter value near its start simulates."""


class NotFittedError(MclError, AttributeError):
    """A result of an estimator (``law_``, ``cause_``, ...) read before ``fit``; also an
    AttributeError, so ``hasattr(d, "law_")`` is False before fit."""


def did_you_mean(word, choices) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``choices`` to a misspelt ``word``, or ""."""
    import difflib

    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""
