"""Run files (``mcl run run.yaml``): parsed, validated in one pass, every problem with its line.

    model:
      sources: [Lib.mo]          # .mo files or package directories, relative to this file
      name: Lib.Systems.Plant    # or `fmu: plant.fmu`
    data:
      train: train.csv
      validate: validate.csv     # optional held-out data
    unknown: auto                # or the instance name of the suspect component
    output: out/plant            # the run directory

Optional sections: ``templates`` (list of template specs), ``fitting`` (``max_simulations`` per
fit, ``screen``: how many candidates, ranked by a linearised first step, are fitted fully),
``refinement`` (``criterion``: bic or aic; ``method``: simulation, the default, or
full-discretisation for paper 004's states-and-parameters least squares), ``executor`` (``kind``, ``workers``),
``second`` (``model``/``data`` of another configuration where the learned component is placed),
``report`` (``title`` of report.html, ``plots: false`` for report.json only).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import yaml

from .errors import ConfigError, MclError

SCHEMA = {
    "model": {"sources", "name", "fmu"},
    "data": {"train", "validate"},
    "unknown": None,
    "output": None,
    "templates": None,
    "fitting": {"max_simulations", "screen"},
    "refinement": {"criterion", "method"},
    "executor": {"kind", "workers", "address"},
    "second": {"model", "data", "component"},
    "report": {"title", "plots"},
}
DEFAULT_TEMPLATES = [{"name": "polynomial", "lhs": ["i"], "rhs": ["v", "v^2", "v^3"]}]


@dataclass
class RunSpec:
    path: Path
    sources: list[Path]
    model_name: str
    train: Path
    validate: Path | None
    unknown: str
    output: Path
    templates: list = field(default_factory=lambda: list(DEFAULT_TEMPLATES))
    max_simulations: int = 60
    screen: int = 3
    criterion: str = "bic"
    refinement_method: str = "simulation"
    executor: dict = field(default_factory=lambda: {"kind": "local"})
    second: dict | None = None
    report: dict = field(default_factory=dict)


def _lines(node, prefix="", out=None) -> dict[str, int]:
    """Dotted key -> line number (1-based) from a composed YAML node tree."""
    out = {} if out is None else out
    if isinstance(node, yaml.MappingNode):
        for k, v in node.value:
            key = f"{prefix}.{k.value}" if prefix else str(k.value)
            out[key] = k.start_mark.line + 1
            _lines(v, key, out)
    return out


def load_runfile(path) -> RunSpec:
    """Parse and validate ``path``; all problems are reported together (file:line: key: why)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError("no such run file", where=str(path))
    text = path.read_text()
    try:
        node = yaml.compose(text)
        raw = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{path}:{mark.line + 1}" if mark else str(path)
        raise ConfigError(f"not valid YAML: {getattr(exc, 'problem', exc)}", where=where) from None
    if not isinstance(raw, dict):
        raise ConfigError("the run file must be a mapping of sections", where=str(path))
    lines = _lines(node)
    problems: list[str] = []

    def problem(key, why):
        problems.append(f"{path}:{lines.get(key, 1)}: {key}: {why}")

    for key, value in raw.items():
        if key not in SCHEMA:
            problem(key, f"unknown section (known: {', '.join(SCHEMA)})")
        elif SCHEMA[key] and isinstance(value, dict):
            for sub in value:
                if sub not in SCHEMA[key]:
                    problem(f"{key}.{sub}", f"unknown key (known: {', '.join(sorted(SCHEMA[key]))})")
    base = path.parent
    model = raw.get("model") or {}
    data = raw.get("data") or {}
    if not isinstance(model, dict) or not model:
        problem("model", "missing: give model.sources and model.name (or model.fmu)")
        model = {}
    if "fmu" in model:
        problem("model.fmu", "discovery needs the Modelica sources (the template is swapped into "
                             "them): give model.sources and model.name")
    sources = model.get("sources", [])
    sources = [sources] if isinstance(sources, str) else list(sources or [])
    src_paths = [base / s for s in sources]
    if model and not sources:
        problem("model.sources", "missing")
    for s, p in zip(sources, src_paths):
        if not p.exists():
            problem("model.sources", f"'{s}' does not exist")
    if model and not model.get("name"):
        problem("model.name", "missing (the class to learn in, e.g. Lib.Systems.Plant)")
    if not isinstance(data, dict) or "train" not in data:
        problem("data.train", "missing (a CSV with time, the model's inputs and measured outputs)")
        data = data if isinstance(data, dict) else {}
    files = {}
    for key in ("train", "validate"):
        if key in data:
            p = base / str(data[key])
            files[key] = p
            if not p.is_file():
                problem(f"data.{key}", f"'{data[key]}' does not exist")
    if "output" not in raw:
        problem("output", "missing (the run directory)")
    criterion = (raw.get("refinement") or {}).get("criterion", "bic")
    if criterion not in ("bic", "aic"):
        problem("refinement.criterion", f"'{criterion}': choose bic or aic")
    method = (raw.get("refinement") or {}).get("method", "simulation")
    if method not in ("simulation", "full-discretisation"):
        problem("refinement.method", f"'{method}': choose simulation or full-discretisation")
    fitting = raw.get("fitting") or {}
    budget = fitting.get("max_simulations", 60)
    if not isinstance(budget, int) or budget < 5:
        problem("fitting.max_simulations", "a whole number of at least 5")
    screen = fitting.get("screen", 3)
    if not isinstance(screen, int) or screen < 1:
        problem("fitting.screen", "how many screened candidates to fit fully: a whole number >= 1")
    second = raw.get("second")
    if second is not None:
        if not isinstance(second, dict) or not isinstance(second.get("model"), dict) or "data" not in second:
            problem("second", "give second.model (sources, name) and second.data (a CSV)")
        else:
            for s in second["model"].get("sources", []):
                if not (base / s).exists():
                    problem("second.model", f"'{s}' does not exist")
            if not (base / str(second["data"])).is_file():
                problem("second.data", f"'{second['data']}' does not exist")
    report = raw.get("report") or {}
    if not isinstance(report, dict) or not isinstance(report.get("plots", True), bool):
        problem("report", "report.title (text) and report.plots (true or false)")
    templates = raw.get("templates", DEFAULT_TEMPLATES)
    if not isinstance(templates, list) or not templates:
        problem("templates", "a non-empty list of templates (name and options)")
    if problems:
        raise ConfigError("\n".join(problems))
    spec = RunSpec(path=path, sources=src_paths, model_name=str(model["name"]), train=files["train"],
                   validate=files.get("validate"), unknown=str(raw.get("unknown", "auto")),
                   output=base / str(raw["output"]), templates=templates, max_simulations=budget, screen=screen,
                   criterion=criterion, refinement_method=method, executor=dict(raw.get("executor") or {"kind": "local"}),
                   second=raw.get("second"), report=report if isinstance(report, dict) else {})
    _check_data(spec, lines)
    return spec


def _check_data(spec: RunSpec, lines: dict) -> None:
    """The data files against the model: readable, columns present (one pass over both files)."""
    from .api import compile_model
    from .data import read_csv

    problems = []
    try:
        model = compile_model(spec.sources, spec.model_name)
    except MclError as exc:
        raise ConfigError(f"{spec.path}:{lines.get('model.name', 1)}: model: {exc}") from None
    for key, p in (("train", spec.train), ("validate", spec.validate)):
        if p is None:
            continue
        try:
            ts = read_csv(p)
        except MclError as exc:
            problems.append(f"{spec.path}:{lines.get('data.' + key, 1)}: data.{key}: {exc}")
            continue
        missing = [u for u in model.input_names if u not in ts.names]
        if missing:
            problems.append(f"{spec.path}:{lines.get('data.' + key, 1)}: data.{key}: {p.name} lacks the "
                            f"model input column(s) {', '.join(missing)}")
        extra = [c for c in ts.names if c not in model.input_names and c not in model.output_names]
        if extra:
            problems.append(f"{spec.path}:{lines.get('data.' + key, 1)}: data.{key}: column(s) "
                            f"{', '.join(extra)} of {p.name} are not inputs or outputs of {spec.model_name} "
                            f"(inputs: {', '.join(model.input_names) or 'none'}; outputs: "
                            f"{', '.join(model.output_names)})")
        if not [o for o in model.output_names if o in ts.names]:
            problems.append(f"{spec.path}:{lines.get('data.' + key, 1)}: data.{key}: {p.name} has none of "
                            f"the model outputs ({', '.join(model.output_names)})")
    if spec.unknown != "auto":
        from .graph import build_graph

        comps = build_graph(spec.sources, spec.model_name).components
        if spec.unknown not in comps:
            problems.append(f"{spec.path}:{lines.get('unknown', 1)}: unknown: no component "
                            f"'{spec.unknown}' in {spec.model_name}")
    if problems:
        raise ConfigError("\n".join(problems))
