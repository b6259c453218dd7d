"""Run files (``mcl run run.yaml``): a JSON Schema checked in one pass, every problem with its line.

    model:
      name: Lib.Systems.Plant    # the class to learn in
      sources: [Lib.mo]          # .mo files or package directories, relative to this file
      libraries: [../libs]       # optional: more of the library path (besides MODELICAPATH)
    data:
      train: train.csv
      validate: validate.csv     # optional held-out data
    unknown: auto                # or the instance name of the suspect component
    output: out/plant            # the run directory

Optional sections: ``templates`` (list of template specs), ``fitting`` (``max_simulations`` per
fit, ``screen``: how many candidates, ranked by a linearised first step, are fitted fully;
``early_stop: false`` fits them all even where screening or a fit shows they cannot win;
``max_samples``: the search and its fits see the first this many training samples, 8192 by default,
while the misfit, the gain and the report use all of them;
``algorithm``: levenberg-marquardt, the default, or paper 000's algorithm1 or algorithm3),
``refinement`` (``criterion``: bic, aic, aicc or a plugin's; ``method``: simulation, the default, or
full-discretisation for paper 004's states-and-parameters least squares), ``executor``
(``kind`` and that kind's options), ``second`` (``model``/``data`` of another configuration where
the learned component is placed), ``report`` (``title`` of report.html, ``plots: false``).

The options of each executor and template kind are checked against the schema its plugin gives
(hook ``mcl_option_schemas``), so a third-party plugin's options are checked like a built-in's,
before anything is compiled.
"""
from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from .errors import ConfigError, MclError
from .errors import did_you_mean

#: no ``templates`` in a run file: discovery picks law families by each component's role
DEFAULT_TEMPLATES = None
#: a long record is searched on its first this many samples (each fit simulates it tens of
#: times; the laws of a system show in a few thousand samples, and the gain is measured on all)
MAX_SAMPLES = 8192
#: the joint refit (``free:``) fits up to this many times as many: the model delivered, one
#: fit, where a calibration on the head alone drifts off in the rest of the record
CALIBRATION_SPAN = 4
CRITERIA = ("bic", "aic", "aicc")   # the built-in criteria (plugins may add more)
FITTING_ALGORITHMS = ("levenberg-marquardt", "algorithm1", "algorithm3")   # mcl.fit.FITTERS
METHODS = ("simulation", "full-discretisation")   # the built-in fitters (plugins may add more)

_PATH = {"type": "string", "minLength": 1}
_PATHS = {"anyOf": [_PATH, {"type": "array", "items": _PATH}]}
_NAME = {"type": "string", "pattern": r"^[A-Za-z_][\w]*(\.[A-Za-z_][\w]*)*$"}
#: the measurement noise, when known: one level for every output or a level per output
_NOISE = {"anyOf": [{"type": "number", "exclusiveMinimum": 0},
                    {"type": "object", "minProperties": 1, "additionalProperties": {"type": "number", "exclusiveMinimum": 0}}]}
_MODEL = {"type": "object", "additionalProperties": False, "required": ["name"],
          "properties": {"name": _NAME, "sources": _PATHS, "libraries": _PATHS, "fmu": _PATH}}


def schema(option_schemas: dict, kinds: dict) -> dict:
    """The run file's JSON Schema; ``kinds`` = installed names per section (executor, template)."""
    return {
        "type": "object", "additionalProperties": False, "required": ["model", "data", "output"],
        "properties": {
            "model": _MODEL,
            "data": {"type": "object", "additionalProperties": False, "required": ["train"],
                     "properties": {"train": _PATH, "validate": _PATH, "noise": _NOISE}},
            "unknown": _NAME,
            "free": {"anyOf": [{"const": "auto"}, {"type": "array", "items": _NAME, "minItems": 1}]},
            "output": _PATH,
            "templates": {"type": "array", "minItems": 1, "items": _kind_schema(
                "name", kinds["template"], option_schemas.get("template", {}), allow_string=True)},
            "fitting": {"type": "object", "additionalProperties": False, "properties": {
                "max_simulations": {"type": "integer", "minimum": 5},
                "algorithm": {"enum": list(FITTING_ALGORITHMS)},
                "screen": {"type": "integer", "minimum": 1},
                "early_stop": {"type": "boolean"},
                "max_samples": {"type": "integer", "minimum": 100}}},
            "refinement": {"type": "object", "additionalProperties": False, "properties": {
                "criterion": {"enum": kinds.get("criterion", list(CRITERIA))}, "method": {"enum": kinds.get("fitter", list(METHODS))}}},
            "executor": _kind_schema("kind", kinds["executor"], option_schemas.get("executor", {})),
            "second": {"type": "object", "additionalProperties": False, "required": ["model", "data"],
                       "properties": {"model": _MODEL, "data": _PATH, "component": _NAME}},
            "report": {"type": "object", "additionalProperties": False, "properties": {
                "title": {"type": "string"}, "plots": {"type": "boolean"}}},
        },
    }


def _kind_schema(key: str, names, per_kind: dict, allow_string: bool = False) -> dict:
    """``{key: <one of names>, ...options}``, the options checked by that kind's own schema."""
    rules = []
    for name in names:
        own = per_kind.get(name)
        if own is None:
            continue
        props = {key: {}, **own.get("properties", {})}
        then = {**own, "properties": props}
        rules.append({"if": {"properties": {key: {"const": name}}, "required": [key]}, "then": then})
    obj = {"type": "object", "required": [key], "properties": {key: {"enum": list(names)}}, "allOf": rules}
    return {"anyOf": [{"enum": list(names)}, obj]} if allow_string else obj


@dataclass
class RunSpec:
    path: Path
    sources: list[Path]
    model_name: str
    train: Path
    validate: Path | None
    unknown: str
    output: Path
    templates: list | None = None      # None: law families chosen per component (discovery.families)
    max_simulations: int = 60
    screen: int = 3
    early_stop: bool = True     # drop candidates screening says cannot compete; stop hopeless fits
    max_samples: int = MAX_SAMPLES   # the search and the fits see at most this many training samples
    algorithm: str = "levenberg-marquardt"   # the optimiser of every fit (mcl.fit.FITTERS)
    noise: object = None        # the user's noise level(s): a number or {output: level}; None: estimated
    free: object = None         # nominal parameters refitted with the learned laws: names, "auto" or None
    criterion: str = "bic"
    refinement_method: str = "simulation"
    executor: dict = field(default_factory=lambda: {"kind": "local"})
    second: dict | None = None
    report: dict = field(default_factory=dict)
    libraries: list[Path] = field(default_factory=list)

    def fingerprint(self) -> dict:
        """SHA-256 of the run file and the data files (recorded in report.json)."""
        files = {"run_file": self.path, "train": self.train, "validate": self.validate}
        return {k: _sha256(p) for k, p in files.items() if p is not None}


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _lines(node, prefix="", out=None) -> dict[str, int]:
    """Dotted key (list items by index) -> line number (1-based) from a composed YAML node tree."""
    out = {} if out is None else out
    if isinstance(node, yaml.MappingNode):
        for k, v in node.value:
            key = f"{prefix}.{k.value}" if prefix else str(k.value)
            out[key] = k.start_mark.line + 1
            _lines(v, key, out)
    elif isinstance(node, yaml.SequenceNode):
        for n, v in enumerate(node.value):
            key = f"{prefix}.{n}" if prefix else str(n)
            out[key] = v.start_mark.line + 1
            _lines(v, key, out)
    return out


class _Problems:
    """Problems of one run file, each ``file:line: key: why``; without a file (the Python API),
    ``key: why`` with the key as the caller named it (``names``: run-file key -> argument)."""

    def __init__(self, path: Path | None, lines: dict, names: dict | None = None):
        self.path, self.lines, self.items, self.names = path, lines, [], names or {}

    def add(self, key: str, why: str) -> None:
        if self.path is None:
            shown = next((arg + key[len(k):] for k, arg in sorted(self.names.items(), key=lambda kv: -len(kv[0]))
                          if key == k or key.startswith(k + ".")), key)
            self.items.append((0, f"{shown or '(top level)'}: {why}"))
            return
        line = self.lines.get(key)
        parent = key
        while line is None and "." in parent:
            parent = parent.rsplit(".", 1)[0]
            line = self.lines.get(parent)
        self.items.append((line or 1, f"{self.path}:{line or 1}: {key or '(top level)'}: {why}"))

    def about(self, key: str) -> bool:
        """Whether a problem was reported for ``key`` or below it."""
        return any(f": {key}:" in f": {text}" or f": {key}." in f": {text}" for _, text in self.items)

    def raise_if_any(self) -> None:
        if self.items:
            ordered = sorted(dict.fromkeys(self.items), key=lambda item: item[0])
            raise ConfigError("\n".join(text for _, text in ordered))


def _describe(error, problems: _Problems) -> None:
    """One jsonschema error as run-file problems, with the key path and a hint."""
    key = ".".join(str(p) for p in error.absolute_path)
    v, inst = error.validator, error.instance
    if v in ("anyOf", "oneOf") and error.context:
        # a template given as a mapping or as a name: report the problems of the form it has
        branch = 1 if isinstance(inst, dict) else 0
        own = [e for e in error.context if e.relative_schema_path[0] == branch] or error.context
        for e in own:
            _describe(e, problems)
        return
    if v == "additionalProperties" and isinstance(inst, dict):
        known = list(error.schema.get("properties", {}))
        for extra in [k for k in inst if k not in known]:
            problems.add(f"{key}.{extra}" if key else str(extra),
                         f"unknown key{did_you_mean(extra, known)} (known: {', '.join(known) or 'none'})")
    elif v == "required":
        missing = [r for r in error.validator_value if r not in (inst or {})]
        for r in missing:
            problems.add(f"{key}.{r}" if key else r, "missing")
    elif v == "enum":
        problems.add(key, f"'{inst}' is not one of {', '.join(map(str, error.validator_value))}"
                          f"{did_you_mean(inst, error.validator_value)}")
    elif v == "type":
        want = error.validator_value
        problems.add(key, f"must be {' or '.join(want) if isinstance(want, list) else want}, "
                          f"not {type(inst).__name__} ({inst!r})"[:200])
    elif v in ("minimum", "maximum", "minItems", "minLength"):
        n = error.validator_value
        problems.add(key, {"minimum": f"{inst!r} is less than {n}", "maximum": f"{inst!r} is more than {n}",
                           "minItems": f"needs at least {n} item(s)", "minLength": "must not be empty"}[v])
    elif v == "pattern":
        problems.add(key, f"'{inst}' is not a valid name here")
    else:
        problems.add(key, error.message[:200])


def load_runfile(path, registry=None) -> RunSpec:
    """Parse and validate ``path``: the schema, the files it names, the templates' options and
    the data against the model; every problem together (file:line: key: why)."""
    spec, lines = parse_runfile(path, registry)
    check_data(spec, lines)
    return spec


class _Loader(yaml.SafeLoader):
    """YAML 1.2's numbers: ``1e5`` and ``1.0e5`` are floats (YAML 1.1's rules, PyYAML's, read
    them as text, and a template's start value 1.0e5 was refused as 'not a number')."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"), list("-+0123456789."))


def _read_yaml(path: Path):
    from .outputs import check_input

    check_input(path, "run file", error=ConfigError)
    try:
        text = path.read_text(encoding="utf-8")
        node = yaml.compose(text)
        raw = yaml.load(text, Loader=_Loader)
    except UnicodeDecodeError as exc:
        raise ConfigError(f"not UTF-8 text ({exc.reason} at byte {exc.start})", where=str(path)) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{path}:{mark.line + 1}" if mark else str(path)
        raise ConfigError(f"not valid YAML: {getattr(exc, 'problem', None) or exc}", where=where) from None
    except RecursionError:
        raise ConfigError("not valid YAML: nested too deeply", where=str(path)) from None
    except OSError as exc:
        raise ConfigError(f"cannot read: {exc.strerror}", where=str(path)) from None
    if _expanded_size(node) > MAX_VALUES:
        raise ConfigError(f"the run file expands to more than {MAX_VALUES} values (anchors and "
                          "aliases repeated inside each other?)", where=str(path))
    if not isinstance(raw, dict):
        raise ConfigError("the run file must be a mapping of sections (model, data, output, ...)",
                          where=str(path))
    twice = _duplicate_keys(node)
    if twice:
        raise ConfigError("\n".join(f"{path}:{line}: {key}: given twice (first on line {first}); "
                                    "keep one" for key, line, first in twice))
    return raw, _lines(node)


def _duplicate_keys(node, prefix: str = "", seen_nodes=None) -> list[tuple[str, int, int]]:
    """(dotted key, line, line of its first occurrence) of every key a mapping gives twice
    (YAML loaders keep the last one silently)."""
    seen_nodes = set() if seen_nodes is None else seen_nodes
    if node is None or id(node) in seen_nodes:      # an alias: its node was checked where anchored
        return []
    seen_nodes.add(id(node))
    out = []
    if isinstance(node, yaml.MappingNode):
        first: dict = {}
        for k, v in node.value:
            name = str(k.value)
            key = f"{prefix}.{name}" if prefix else name
            if name in first and name != "<<":
                out.append((key, k.start_mark.line + 1, first[name]))
            first.setdefault(name, k.start_mark.line + 1)
            out += _duplicate_keys(v, key, seen_nodes)
    elif isinstance(node, yaml.SequenceNode):
        for n, v in enumerate(node.value):
            out += _duplicate_keys(v, f"{prefix}.{n}" if prefix else str(n), seen_nodes)
    return out


MAX_VALUES = 100_000


def _expanded_size(node) -> int:
    """How many values the document holds once its aliases are expanded (counted, not built)."""
    sizes: dict[int, int] = {}

    def size(n) -> int:
        if id(n) in sizes:
            return sizes[id(n)]
        if isinstance(n, yaml.MappingNode):
            total = 1 + sum(size(k) + size(v) for k, v in n.value)
        elif isinstance(n, yaml.SequenceNode):
            total = 1 + sum(size(v) for v in n.value)
        else:
            total = 1
        sizes[id(n)] = min(total, MAX_VALUES + 1)
        return sizes[id(n)]

    return size(node) if node is not None else 0


def parse_runfile(path, registry=None) -> tuple[RunSpec, dict]:
    """The run file checked without touching the model or the data (no compile)."""
    import jsonschema

    from .services import registry as default_registry

    path = Path(path)
    raw, lines = _read_yaml(path)
    reg = registry or default_registry()
    problems = _Problems(path, lines)
    kinds = {"template": list(reg.templates), "executor": list(reg.executors), "fitter": list(reg.fitters),
             "criterion": list(reg.criteria)}
    validator = jsonschema.Draft202012Validator(schema(reg.option_schemas, kinds))
    for error in sorted(validator.iter_errors(raw), key=lambda e: list(map(str, e.absolute_path))):
        _describe(error, problems)
    files, sources, libraries = _check_files(raw, path.parent, problems, reg)
    problems.raise_if_any()
    model, base = raw["model"], path.parent
    output = _at(base, raw["output"])
    fitting, refinement = raw.get("fitting") or {}, raw.get("refinement") or {}
    spec = RunSpec(path=path, sources=sources, model_name=model["name"], train=files["train"],
                   validate=files.get("validate"), unknown=str(raw.get("unknown", "auto")),
                   output=output, templates=raw.get("templates", DEFAULT_TEMPLATES),
                   max_simulations=fitting.get("max_simulations", 60), screen=fitting.get("screen", 3),
                   early_stop=fitting.get("early_stop", True),
                   max_samples=fitting.get("max_samples", MAX_SAMPLES),
                   algorithm=fitting.get("algorithm", "levenberg-marquardt"),
                   criterion=refinement.get("criterion", "bic"),
                   refinement_method=refinement.get("method", "simulation"),
                   executor=dict(raw.get("executor") or {"kind": "local"}), second=raw.get("second"),
                   report=dict(raw.get("report") or {}), libraries=libraries,
                   noise=(raw.get("data") or {}).get("noise"), free=raw.get("free"))
    return spec, lines


def _at(base: Path, name) -> Path:
    """A path the run file names: ``~`` is the user's home, relative paths are from the file."""
    return base / Path(str(name)).expanduser()


def _strings(x) -> list[str]:
    return [x] if isinstance(x, str) else [s for s in (x if isinstance(x, list) else []) if isinstance(s, str)]


def _check_files(raw: dict, base: Path, problems: _Problems, reg, with_data: bool = True):
    """Files the run file names exist, templates build; checked where the shape allows, so
    these problems come together with the schema's."""
    section = (lambda k: raw.get(k) if isinstance(raw.get(k), dict) else {})
    model, data, second = section("model"), section("data"), section("second")
    sources = [_at(base, s) for s in _strings(model.get("sources"))]
    libraries = [_at(base, s) for s in _strings(model.get("libraries"))]
    if "fmu" in model:
        problems.add("model.fmu", "discovery needs the Modelica sources (the template is swapped "
                                  "into them): give model.sources and model.name")
    for name in _strings(model.get("sources")):
        why = _path_problem(_at(base, name), "source")
        if why:
            problems.add("model.sources", f"'{name}' {why}")
    for name in _strings(model.get("libraries")):
        p = _at(base, name)
        why = _path_problem(p, "library") or (None if p.is_dir() else
                                               "is not a directory: a library on the path is a directory "
                                               "(a library with package.mo, or a folder of libraries)")
        if why:
            problems.add("model.libraries", f"'{name}' {why}")
    files = {k: _at(base, v) for k, v in data.items() if k in ("train", "validate") and isinstance(v, str)} \
        if with_data else {}
    for key, p in files.items():
        why = _path_problem(p, "file") or (None if p.is_file() else "is not a file")
        if why:
            problems.add(f"data.{key}", f"'{data[key]}' {why}")
    if second:
        for name in _strings((second.get("model") or {}).get("sources") if isinstance(second.get("model"), dict) else None):
            why = _path_problem(_at(base, name), "source")
            if why:
                problems.add("second.model.sources", f"'{name}' {why}")
        if isinstance(second.get("data"), str):
            p = _at(base, second["data"])
            why = _path_problem(p, "file") or (None if p.is_file() else "is not a file")
            if why:
                problems.add("second.data", f"'{second['data']}' {why}")
            elif not second["data"].lower().endswith(".csv"):
                problems.add("second.data", f"'{second['data']}' is not a CSV file")
    templates = raw.get("templates") or []
    for k, tpl in enumerate(templates if isinstance(templates, list) else []):
        name = tpl if isinstance(tpl, str) else tpl.get("name") if isinstance(tpl, dict) else None
        if name in reg.templates and not problems.about(f"templates.{k}"):
            try:
                reg.template(tpl)
            except MclError as exc:
                problems.add(f"templates.{k}", exc.message)
    if isinstance(raw.get("output"), str):
        output = _at(base, raw["output"])
        if output.exists() and not output.is_dir():
            problems.add("output", f"'{raw['output']}' is a file, not a run directory")
    return files, sources, libraries


def _path_problem(p: Path, what: str) -> str | None:
    """Why the input ``p`` cannot be read (missing, a FIFO or a device), or None."""
    from .outputs import special_kind

    kind = special_kind(p)
    if kind:
        return f"is {kind}, not a {what}"
    if not p.exists():
        return "does not exist"
    return None


def check_data(spec: RunSpec, lines: dict) -> None:
    """The data files against the model: readable, columns present (one pass over both files)."""
    from .data import read_csv

    problems = _Problems(spec.path, lines)
    series = {}
    for key, p in (("train", spec.train), ("validate", spec.validate)):
        if p is None:
            continue
        try:
            series[key] = (read_csv(p), p.name)
        except MclError as exc:
            problems.add(f"data.{key}", str(exc))
    try:
        _check_against_model(spec, series, problems)
    except MclError as exc:
        raise ConfigError(f"{spec.path}:{lines.get('model.name', 1)}: model: {exc}") from None
    problems.raise_if_any()


def _check_against_model(spec: RunSpec, series: dict, problems: _Problems) -> None:
    """Each series (key -> (TimeSeries, label)) against the compiled model; the unknown
    component and the second configuration against the component graphs. A model that does not
    compile raises its own error."""
    from .services import compile_model

    model = compile_model(spec.sources, spec.model_name, libraries=spec.libraries)
    for key, (ts, label) in series.items():
        for why in model_column_problems(model, ts, spec.model_name, label):
            problems.add(f"data.{key}", why)
    if isinstance(spec.noise, dict) and series:
        measured = [c for c in next(iter(series.values()))[0].names if c not in model.input_names]
        for name in spec.noise:
            if name not in measured:
                problems.add(f"data.noise.{name}", f"not a measured output{did_you_mean(name, measured)} "
                                                   f"(measured: {', '.join(measured)})")
    if spec.unknown != "auto":
        _check_component(problems, "unknown", model, spec.unknown, spec.model_name)
    ode = getattr(model, "ode", None)
    if isinstance(spec.free, (list, tuple)) and ode is not None:
        # (before the search: found wrong only by the calibration, it ended a run of minutes)
        for why in unknown_free(spec.free, ode.p_names, spec.model_name):
            problems.add("free", why)
    if spec.second:
        sec, base = spec.second, spec.path.parent if spec.path else Path(".")
        try:
            second = compile_model([_at(base, s) for s in _strings(sec["model"].get("sources"))],
                                   sec["model"]["name"], libraries=spec.libraries)
            target = sec.get("component", spec.unknown)
            if target != "auto":
                _check_component(problems, "second.component", second, target, sec["model"]["name"])
        except MclError as exc:
            problems.add("second.model.name", str(exc))


def unknown_free(free, p_names, model_name: str) -> list[str]:
    """What is wrong with the names of ``free:`` (a list) for a model whose free parameters are
    ``p_names``: one message per name it does not have."""
    return [f"'{name}' is not a free parameter of {model_name}{did_you_mean(name, p_names)}"
            for name in free if name not in p_names]


def _check_component(problems, key: str, model, name: str, model_name: str) -> None:
    """``name`` is a component of the compiled ``model`` whose law discovery can question."""
    structure = getattr(model, "structure", None)
    if structure is None:
        return
    comps = structure.components
    if name not in comps:
        problems.add(key, f"no component '{name}' in {model_name}{did_you_mean(name, comps)}")
    # (a block or a sensor of the measuring chain may be named)
    elif name not in {c.name for c in structure.candidates()} and not (comps[name].signal or comps[name].sensor):
        c = comps[name]
        why = ("it has signal inputs or outputs (a source or a sensor)" if c.inputs else
               f"it has {len(c.connectors)} connector(s), not two of one kind with one potential and one flow each")
        problems.add(key, f"'{name}' ({c.cls or 'its class'}) cannot take a learned law: {why}")


#: run-file keys as the arguments of :class:`mcl.Discovery` name them
ARGUMENTS = {"model.name": "model", "model.sources": "sources", "model.libraries": "libraries",
             "fitting.max_simulations": "max_simulations", "fitting.screen": "screen",
             "fitting.early_stop": "early_stop", "fitting.max_samples": "max_samples", "fitting.algorithm": "algorithm", "refinement.criterion": "criterion",
             "refinement.method": "refinement", "data.train": "train", "data.validate": "validate",
             "data.noise": "noise"}


def check_arguments(args: dict, registry=None) -> None:
    """The arguments of :class:`mcl.Discovery` checked as the run file's keys are (the same
    schema, the same messages, named by argument); a ConfigError with every problem."""
    import jsonschema

    from .services import registry as default_registry

    reg = registry or default_registry()
    plain = lambda x: str(x) if isinstance(x, os.PathLike) else x
    paths = lambda x: [plain(v) for v in x] if isinstance(x, (list, tuple)) else plain(x)
    templates = args.get("templates")
    executor = args.get("executor", "local")
    raw = {"model": {"name": args.get("model")}, "data": {"train": "<memory>"},
           "unknown": args.get("unknown", "auto"),
           "output": str(args["output"]) if args.get("output") is not None else "<temporary>",
           "fitting": {"max_simulations": args.get("max_simulations", 60), "screen": args.get("screen", 3),
                       "early_stop": args.get("early_stop", True),
                       "max_samples": args.get("max_samples", MAX_SAMPLES),
                       "algorithm": args.get("algorithm", "levenberg-marquardt")},
           "refinement": {"criterion": args.get("criterion", "bic"), "method": args.get("refinement", "simulation")},
           "executor": {"kind": executor} if isinstance(executor, str) else executor}
    for key in ("sources", "libraries"):
        if args.get(key) not in (None, (), []):
            raw["model"][key] = paths(args[key])
    if templates is not None:
        raw["templates"] = [templates] if isinstance(templates, (str, dict)) else \
            list(templates) if isinstance(templates, (list, tuple)) else templates
    for key in ("second", "report", "free"):
        if args.get(key) is not None:
            raw[key] = args[key]
    if args.get("noise") is not None:
        raw["data"]["noise"] = args["noise"]
    problems = _Problems(None, {}, ARGUMENTS)
    kinds = {"template": list(reg.templates), "executor": list(reg.executors), "fitter": list(reg.fitters),
             "criterion": list(reg.criteria)}
    validator = jsonschema.Draft202012Validator(schema(reg.option_schemas, kinds))
    for error in sorted(validator.iter_errors(raw), key=lambda e: list(map(str, e.absolute_path))):
        _describe(error, problems)
    _check_files(raw, Path("."), problems, reg, with_data=False)
    problems.raise_if_any()


def check_series(spec: RunSpec, train, validate=None) -> None:
    """In-memory data (TimeSeries) against the model, as :func:`check_data` checks files."""
    problems = _Problems(None, {}, ARGUMENTS)
    series = {"train": (train, "train")}
    if validate is not None:
        series["validate"] = (validate, "validate")
    _check_against_model(spec, series, problems)
    problems.raise_if_any()


def model_column_problems(model, ts, model_name: str, label: str) -> list[str]:
    """What keeps the time series ``ts`` (called ``label``) from being data for ``model``: a
    column must be an input or a variable of the model (declared output or not)."""
    out = []
    missing = [u for u in model.input_names if u not in ts.names]
    if missing:
        out.append(f"{label} lacks the model input column(s) {', '.join(missing)}")
    known = set(model.input_names) | set(model.output_names) | set(getattr(getattr(model, "ode", None), "probe_names", ()))
    extra = [c for c in ts.names if c not in known]
    if extra:
        hint = did_you_mean(extra[0], sorted(known - set(model.input_names)))
        out.append(f"column(s) {', '.join(extra)} of {label} are not inputs or variables of {model_name}"
                   f"{hint} (inputs: {', '.join(model.input_names) or 'none'}; outputs: "
                   f"{', '.join(model.output_names)})")
    if not [c for c in ts.names if c in known and c not in model.input_names]:
        out.append(f"{label} measures none of the model's variables (outputs: {', '.join(model.output_names)})")
    return out
