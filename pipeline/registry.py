"""Plugin manager factory and a typed facade over the hooks.

Built-in plugins are registered exactly like third-party ones; external plugins come from the
entry-point group ``mcl``. Environment variables make runs reproducible:

- ``MCL_DISABLE_EXTERNAL_PLUGINS=1`` loads no external plugin;
- ``MCL_PLUGINS=a,b`` loads only the external plugins named ``a`` and ``b``.
"""
from __future__ import annotations

import importlib
import os
from dataclasses import dataclass
from importlib import metadata

import pluggy

from . import hookspecs
from .errors import ConfigError, PluginError, did_you_mean  # noqa: F401  (re-exported)

ENTRY_POINT_GROUP = "mcl"
DEFAULT_PLUGINS = (
    "mcl.plugins.casadi_compiler",
    "mcl.plugins.openmodelica",
    "mcl.plugins.engines",
    "mcl.plugins.model_files",
    "mcl.plugins.templates",
    "mcl.plugins.feasibility",
    "mcl.plugins.executors",
    "mcl.plugins.prioritisers",
    "mcl.plugins.fitters",
    "mcl.plugins.criteria",
)
ENV_DISABLE = "MCL_DISABLE_EXTERNAL_PLUGINS"
ENV_ALLOW = "MCL_PLUGINS"


@dataclass
class PluginInfo:
    name: str
    origin: str      # "built-in" or "distribution==version"
    module: str


def _external_allowed(name: str) -> bool:
    if os.environ.get(ENV_DISABLE, "").strip().lower() in ("1", "true", "yes"):
        return False
    allow = os.environ.get(ENV_ALLOW)
    if allow is None:
        return True
    return name in {n.strip() for n in allow.split(",") if n.strip()}


def plugin_manager(external: bool = True, extra=()) -> tuple[pluggy.PluginManager, list[PluginInfo]]:
    """A fresh manager with the built-in plugins, (unless blocked) the external ones, and
    ``extra`` plugin objects (for programs that embed mcl, and for tests)."""
    pm = pluggy.PluginManager(hookspecs.PROJECT)
    pm.add_hookspecs(hookspecs)
    infos = []
    for modname in DEFAULT_PLUGINS:
        mod = importlib.import_module(modname)
        pm.register(mod, name=modname)
        infos.append(PluginInfo(modname, "built-in", modname))
    if external:
        for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
            if not _external_allowed(ep.name) or pm.has_plugin(ep.name):
                continue
            dist = f"{ep.dist.name}=={ep.dist.version}" if ep.dist else "unknown distribution"
            try:
                obj = ep.load()
                pm.register(obj, name=ep.name)
            except Exception as exc:
                raise PluginError(f"plugin '{ep.name}' from {dist} failed to load: {exc}") from None
            infos.append(PluginInfo(ep.name, dist, ep.value))
    for obj in extra:
        name = getattr(obj, "__name__", type(obj).__name__)
        pm.register(obj, name=name)
        infos.append(PluginInfo(name, "registered in process", getattr(obj, "__module__", "")))
    try:
        pm.check_pending()
    except pluggy.PluginValidationError as exc:
        raise PluginError(f"a plugin implements an unknown hook: {exc}") from None
    return pm, infos



def _named(results, kind: str) -> dict[str, type]:
    out: dict[str, type] = {}
    for group in results:
        for cls in group or []:
            name = getattr(cls, "name", "")
            if not name:
                raise PluginError(f"{kind} class {cls.__qualname__} has no name")
            if name in out and out[name] is not cls:
                raise PluginError(f"two {kind}s are named '{name}' ({out[name].__module__}, {cls.__module__})")
            out[name] = cls
    return out


class Registry:
    """What the installed plugins provide, by name; the one object the core asks."""

    def __init__(self, external: bool = True, extra=()):
        self.pm, self.plugins = plugin_manager(external, extra)
        self.compilers = _named(self.pm.hook.mcl_compilers(), "compiler")
        self.engines = _named(self.pm.hook.mcl_engines(), "engine")
        self.templates = _named(self.pm.hook.mcl_templates(), "template")
        self.feasibility_models = _named(self.pm.hook.mcl_feasibility_models(), "feasibility model")
        self.executors = _named(self.pm.hook.mcl_executors(), "executor")
        self.prioritisers = _named(self.pm.hook.mcl_prioritisers(), "prioritiser")
        self.fitters = _named(self.pm.hook.mcl_fitters(), "fitter")
        self.criteria = _named(self.pm.hook.mcl_criteria(), "criterion")
        self.option_schemas: dict[str, dict[str, dict]] = {}
        for contribution in reversed(self.pm.hook.mcl_option_schemas()):  # later plugins win
            for section, kinds in (contribution or {}).items():
                self.option_schemas.setdefault(section, {}).update(kinds)

    @property
    def hook(self):
        return self.pm.hook

    def compiler(self, sources, name: str | None = None):
        from .compile import choose

        return choose(self.compilers, sources, name)

    def engine_for(self, model, name: str | None = None):
        if name:
            if name not in self.engines:
                raise PluginError(f"no engine named '{name}' (installed: {', '.join(self.engines)})")
            engine = self.engines[name]()
            if not engine.accepts(model):
                raise PluginError(f"engine '{name}' cannot run a {type(model).__name__}")
            return engine
        for engine_cls in self.engines.values():
            engine = engine_cls()
            if engine.accepts(model):
                return engine
        raise PluginError(f"no engine runs a {type(model).__name__}")

    def template(self, spec):
        """A template instance from a name or ``{name: ..., options...}``."""
        from .templates import make_template

        return make_template(self.templates, spec)

    def fitter(self, name: str):
        """A candidate fitter by name (``refinement: {method: name}``)."""
        if name not in self.fitters:
            raise ConfigError(f"no candidate fitter named '{name}'{did_you_mean(name, self.fitters)} "
                              f"(installed: {', '.join(self.fitters)})")
        return self.fitters[name]()

    def criterion(self, which):
        """An information criterion by name (``refinement: {criterion: name}``), resolved once:
        what comes back is the object every stage scores with (a Criterion passes through)."""
        from .stats import Criterion

        if isinstance(which, Criterion):
            return which
        if which not in self.criteria:
            raise ConfigError(f"no criterion named '{which}'{did_you_mean(which, self.criteria)} "
                              f"(installed: {', '.join(self.criteria)})")
        return self.criteria[which]()

    def feasibility_model(self, spec="logistic"):
        spec = {"name": spec} if isinstance(spec, str) else dict(spec)
        name = spec.pop("name", "logistic")
        if name not in self.feasibility_models:
            raise PluginError(f"no feasibility model named '{name}' "
                              f"(installed: {', '.join(self.feasibility_models)})")
        return self.feasibility_models[name](**spec)

    def check_options(self, section: str, kind: str, options: dict) -> None:
        """``options`` of plugin ``kind`` against the schema its plugin gave (if any)."""
        import jsonschema

        schema = self.option_schemas.get(section, {}).get(kind)
        if schema is None:
            return
        errors = sorted(jsonschema.Draft202012Validator(schema).iter_errors(options), key=str)
        if errors:
            e = errors[0]
            key = ".".join(map(str, e.absolute_path)) or "options"
            raise ConfigError(f"{section} '{kind}': {key}: {e.message}")

    def executor_class(self, spec=None) -> tuple[type, dict]:
        """The executor class a spec names and its checked options (nothing started yet)."""
        spec = {"kind": spec} if isinstance(spec, str) or spec is None else dict(spec)
        kind = spec.pop("kind", None) or "local"
        if kind not in self.executors:
            raise ConfigError(f"no executor named '{kind}'{did_you_mean(kind, self.executors)} "
                              f"(installed: {', '.join(self.executors)})")
        self.check_options("executor", kind, spec)
        return self.executors[kind], spec

    def executor(self, spec=None):
        cls, options = self.executor_class(spec)
        return cls(**options)

    def load_model_file(self, path):
        model = self.hook.mcl_load_model(path=str(path))
        if model is None:
            raise PluginError(f"no plugin reads model files like '{path}'")
        return model

    def stage(self, stage: str, context: dict):
        """Context manager running the lifecycle hooks around a stage."""
        return _Stage(self, stage, context)


class _Stage:
    def __init__(self, registry, stage, context):
        self.r, self.stage, self.context, self.result = registry, stage, context, None

    def __enter__(self):
        self.r.hook.mcl_before_stage(stage=self.stage, context=self.context)
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc is not None:
            self.r.hook.mcl_on_stage_error(stage=self.stage, context=self.context, error=exc)
        else:
            self.r.hook.mcl_after_stage(stage=self.stage, context=self.context, result=self.result)
        return False
