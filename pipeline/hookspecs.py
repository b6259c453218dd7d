"""Every hook of mcl, in one place: read this module to learn the architecture.

Built-in plugins (``plugins/``) and third-party plugins (entry-point group ``mcl``) implement
these with :data:`mcl.hookimpl`. Capability hooks return classes carrying a unique ``name``
(a duplicate name is an error); the YAML file and the command line pick a class by that name.
"""
from __future__ import annotations

from typing import Any

import pluggy

#: Marker name shared by hook specs and implementations.
PROJECT = "mcl"

hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


@hookspec
def mcl_compilers() -> list[type]:
    """Register compiler classes (subclasses of :class:`mcl.compile.Compiler`).

    Called once per plugin manager; all results are collected. When a user names no compiler,
    the first registered compiler that is available and accepts the sources wins (plugins
    registered later are asked first, so a third-party compiler can take over a file type).
    """


@hookspec
def mcl_engines() -> list[type]:
    """Register simulation engine classes (subclasses of :class:`mcl.simulation.Engine`).

    All results are collected; a model is simulated by the first engine that accepts it
    (plugins registered later are asked first), unless the user names one.
    """


@hookspec
def mcl_templates() -> list[type]:
    """Register component template classes (subclasses of :class:`mcl.templates.Template`).

    All results are collected; a run file or command picks one by ``name`` and passes its
    options to the constructor.
    """


@hookspec
def mcl_feasibility_models() -> list[type]:
    """Register feasibility model classes q(w; beta) (subclasses of
    :class:`mcl.feasibility.FeasibilityModel`). All results are collected; picked by name.
    """


@hookspec
def mcl_executors() -> list[type]:
    """Register batch executor classes (subclasses of :class:`mcl.executor.Executor`).

    All results are collected; picked by name (``local`` by default).
    """


@hookspec
def mcl_fitters() -> list[type]:
    """Return candidate fitter classes (subclasses of
    :class:`mcl.discovery.fitters.CandidateFitter`), chosen by ``refinement: {method: name}``."""


@hookspec
def mcl_criteria() -> list[type]:
    """Register information criteria (subclasses of :class:`mcl.stats.Criterion` with a
    ``name``), chosen by ``refinement: {criterion: name}`` and resolved once into the object that
    ranks candidates and prunes terms. All results are collected (bic, aic and aicc built in)."""


@hookspec
def mcl_prioritisers() -> list[type]:
    """Register prioritiser classes for backward elimination (subclasses of
    :class:`mcl.sparsify.Prioritiser`): which parameters may be removed next, in stages.
    All results are collected; picked by name (``degree`` by default).
    """


@hookspec
def mcl_option_schemas() -> dict[str, dict[str, dict]]:
    """The JSON Schemas of a plugin's own options, checked before any run starts.

    Return ``{section: {name: schema}}`` with section ``executor``, ``template`` (or any other
    section with kinds), e.g. ``{"executor": {"inline": {"type": "object", "properties":
    {"workers": {"type": "integer", "minimum": 1}}, "additionalProperties": False}}}``. The
    schema describes the options beside ``kind``/``name``; a kind without a schema is not checked.
    All results are merged; a later plugin's schema for the same name wins.
    """


@hookspec(firstresult=True)
def mcl_load_model(path: str) -> Any:
    """Read a ready-made model file (an FMU, a saved compiled model, ...), or return None.

    First non-None result wins. Called wherever a model is expected and a file is given instead
    of Modelica sources.
    """


@hookspec
def mcl_before_stage(stage: str, context: dict) -> None:
    """Called before a stage (``compile``, ``simulate``, ...) runs; ``context`` holds its inputs.

    Observers may log or record; they must not replace the stage. Return value ignored.
    """


@hookspec
def mcl_after_stage(stage: str, context: dict, result: Any) -> None:
    """Called after a stage finished, with its result. Return value ignored."""


@hookspec
def mcl_on_stage_error(stage: str, context: dict, error: BaseException) -> None:
    """Called when a stage raised; the error propagates afterwards. Return value ignored."""
