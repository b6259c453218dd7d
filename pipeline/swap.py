"""Put a template instance in place of a component, as Modelica that the compile stage accepts."""
from __future__ import annotations

import re
import textwrap
from dataclasses import dataclass
from pathlib import Path

from .errors import ModelicaError
from .graph import SystemGraph
from .templates import Template


@dataclass
class TemplateModel:
    """A system model in which ``component`` is an instance of ``template``."""

    path: Path
    model_name: str
    sources: list[Path]
    component: str
    template: Template
    parameter_names: list[str]   # qualified: 'Rnl.w1', ...


def write_package(directory, package: str, classes: list[str]) -> Path:
    """``directory/package.mo`` holding ``classes`` (Modelica text), written atomically."""
    from .compile.library import uses_annotation

    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    body = "\n".join(textwrap.indent(c.rstrip() + "\n", "  ") for c in classes)
    uses = uses_annotation(body)
    path = directory / f"{package}.mo"
    tmp = path.with_suffix(".mo.tmp")
    tmp.write_text(f"within ;\npackage {package}\n{body}" + (f"  {uses};\n" if uses else "") + f"end {package};\n")
    tmp.replace(path)
    return path


def class_name_for(component: str, template: Template) -> str:
    return re.sub(r"\W", "_", f"{component}_{template.name}")


def swap_component(graph: SystemGraph, component: str, template: Template, directory,
                   w=None, package: str = "MCLLearn", note: str = "") -> TemplateModel:
    """Replace ``component`` of ``graph`` by ``template`` (parameters ``w``, default its start)."""
    comps = graph.components
    if component not in comps:
        raise ModelicaError(f"{graph.name} has no component '{component}'")
    comp = comps[component]
    if not comp.two_connector:
        raise ModelicaError(f"'{component}' ({comp.cls}) is not a two-connector component with one "
                            "potential and one flow variable per connector")
    cls = class_name_for(component, template)
    system = graph.replaced(component, f"{package}.{cls}")
    short = graph.name.split(".")[-1]
    path = write_package(directory, package, [template.modelica_class(cls, comp, w, note),
                                              system.to_modelica(short)])
    return TemplateModel(path, f"{package}.{short}", [*graph.sources, path], component, template,
                         [f"{component}.{p}" for p in template.parameter_names()])
