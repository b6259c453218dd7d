"""What a model holds, as ``fmpy info`` tells it (``mcl info``): its variables with causality,
unit and description, its parameters with their values, its states with their start values.

Works on an FMU (from mcl or any tool), a saved model directory, or a compiled model.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Variable:
    name: str
    causality: str          # input, output, parameter, state, local (readable), ...
    value: str = ""         # a parameter's value, a state's start value
    unit: str = ""
    description: str = ""


@dataclass(frozen=True)
class ModelInfo:
    name: str
    kind: str               # "FMI 2.0 FMU (Model Exchange, Co-Simulation)", "in-process model"
    notes: tuple            # generation tool, default experiment, structure
    variables: tuple

    def table(self) -> str:
        """The model's description and one line per variable, grouped by causality."""
        lines = [f"model        {self.name}", f"kind         {self.kind}"]
        lines += [f"{k:12s} {v}" for k, v in self.notes]
        order = ["state", "input", "output", "parameter", "calculatedParameter", "local", "independent"]
        groups = sorted({v.causality for v in self.variables}, key=lambda c: (order.index(c) if c in order else 99, c))
        width = max([len(v.name) for v in self.variables] + [4])
        for group in groups:
            members = [v for v in self.variables if v.causality == group]
            title = {"state": "states", "input": "inputs", "output": "outputs", "parameter": "parameters",
                     "local": "other variables", "calculatedParameter": "calculated parameters"}.get(group, group)
            lines.append(f"\n{title} ({len(members)}):")
            for v in members:
                unit = f"[{v.unit}]" if v.unit else ""
                value = f"= {v.value}" if v.value != "" else ""
                lines.append(f"  {v.name:{width}s}  {value:14s} {unit:10s} {v.description}".rstrip())
        return "\n".join(lines)


def model_info(model) -> ModelInfo:
    """The :class:`ModelInfo` of an FMU path, a saved model directory or a compiled model."""
    if isinstance(model, (str, Path)):
        path = Path(model)
        if path.suffix.lower() == ".fmu":
            return fmu_info(path)
        from .model import CompiledModel

        return compiled_info(CompiledModel.load(path))
    if hasattr(model, "ode"):
        return compiled_info(model)
    return fmu_info(model.path)


def fmu_info(path) -> ModelInfo:
    """Read from the FMU's modelDescription.xml (checked before it is opened)."""
    from fmpy import read_model_description

    from .compile.fmu.archive import check_archive
    from .errors import DataError

    check_archive(path)
    try:
        md = read_model_description(str(path), validate=False)
    except Exception as exc:    # noqa: BLE001 - a broken FMU from elsewhere: one line
        raise DataError(f"not a readable FMU: {exc}", where=str(path)) from None
    states = {d.variable.derivative.name for d in md.derivatives if d.variable.derivative is not None}
    variables = []
    for v in md.modelVariables:
        unit = v.unit or (v.declaredType.unit if v.declaredType is not None else None) or ""
        causality = "state" if v.name in states else v.causality
        variables.append(Variable(v.name, causality, "" if v.start is None else str(v.start), unit,
                                  v.description or ""))
    kinds = [k for k, on in (("Model Exchange", md.modelExchange), ("Co-Simulation", md.coSimulation)) if on]
    notes = [("generated", " ".join(x for x in (md.generationTool, md.generationDateAndTime) if x) or "?")]
    if md.defaultExperiment is not None:
        e = md.defaultExperiment
        notes.append(("experiment", ", ".join(f"{k} {getattr(e, a)}" for k, a in
                                              (("start", "startTime"), ("stop", "stopTime"),
                                               ("tolerance", "tolerance"), ("step", "stepSize"))
                                              if getattr(e, a) is not None)))
    if md.description:
        notes.append(("description", md.description))
    return ModelInfo(md.modelName, f"FMI {md.fmiVersion} FMU ({', '.join(kinds) or 'no interface'})",
                     tuple(notes), tuple(variables))


def compiled_info(model) -> ModelInfo:
    """From a compiled (or saved) in-process model: names, units and descriptions the compiler
    recorded, parameter values, and the states' start values at t = 0 with the nominal inputs."""
    import numpy as np

    o = model.ode
    units, desc = model.info.get("units", {}), model.info.get("descriptions", {})
    x0 = {}
    try:
        values = np.asarray(o.init(o.u_start, o.p_values, 0.0)).ravel()
        x0 = {n: f"{float(v) + 0.0:.6g}" for n, v in zip(o.x_names, values)}     # + 0.0: no "-0"
    except Exception:    # noqa: BLE001 - start values are a courtesy; the listing stands without
        pass
    var = lambda n, c, value="": Variable(n, c, value, units.get(n, ""), desc.get(n, ""))
    listed = set(o.x_names) | set(o.u_names) | set(o.y_names) | set(o.p_names)
    variables = ([var(n, "state", x0.get(n, "")) for n in o.x_names] + [var(n, "input") for n in o.u_names]
                 + [var(n, "output") for n in o.y_names]
                 + [var(n, "parameter", f"{float(v):.6g}") for n, v in zip(o.p_names, o.p_values)]
                 + [var(n, "local") for n in o.probe_names if n not in listed])
    notes = [("compiled by", str(model.info.get("compiler", "?"))),
             ("structure", f"index {o.index}, {o.nonlinear_blocks} algebraic loop(s), "
                           f"{len(o.time_events)} time event(s)")]
    return ModelInfo(model.name, "in-process model (CasADi functions)", tuple(notes), tuple(variables))
