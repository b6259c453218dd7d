"""Multi-configuration pre-training of the feasibility model q(w) (paper 000, Remark 3.1).

Instead of simulating the whole system for every sample of w, the template is put into small
circuits that compute its variables in different ways, each giving the template's equation a
different place in the Jacobian that must stay invertible:

- ``across_series``: a potential source drives the template through a known linear element;
- ``through_parallel``: a flow source feeds the template in parallel with a known storage element;
- ``across``: a potential source directly across the template (the law is solved for the flow);
- ``through``: a flow source directly through it (the law is solved for the across variable);
- each also with the template's connectors swapped (ground on the other side).

Helper elements are generated for the template's own connector class, so this works in any
domain of any library. A configuration in which the template's start point already fails says
nothing about w and is left out. A sample is labelled feasible when it simulates in every
remaining configuration.
"""
from __future__ import annotations

import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.stats import qmc

from .data import TimeSeries
from .errors import MclError
from .executor import TaskFailed
from .graph import Component, Connector
from .simulation import SimulationOptions
from .swap import write_package
from .templates import Template

PACKAGE = "MCLConfigurations"


def _helpers(c: Connector) -> list[str]:
    """Ground, sources and known elements for connector class ``c`` (potential x, flow f)."""
    x, f, C = c.potential[0], c.flow[0], c.cls
    two = f"  {C} a;\n  {C} b;\n"
    balance = f"  a.{f} + b.{f} = 0;\n"
    return [
        f"model Ground\n  {C} a;\nequation\n  a.{x} = 0;\nend Ground;",
        f"model AcrossSource\n{two}  input Real u;\nequation\n  a.{x} - b.{x} = u;\n{balance}end AcrossSource;",
        f"model FlowSource\n{two}  input Real u;\nequation\n  a.{f} = u;\n{balance}end FlowSource;",
        f"model Linear\n{two}  parameter Real k = 1;\nequation\n  a.{x} - b.{x} = k * a.{f};\n"
        f"{balance}end Linear;",
        f"model Storage\n{two}  parameter Real c = 1;\n  Real e(start = 0, fixed = true);\nequation\n"
        f"  e = a.{x} - b.{x};\n  c * der(e) = a.{f};\n{balance}end Storage;",
    ]


def _config(name: str, parts: list[str], connects: list[tuple[str, str]], output: str) -> str:
    decl = "\n".join(f"  {p};" for p in parts)
    eqs = "\n".join(f"  connect({a}, {b});" for a, b in connects)
    return (f"model {name}\n  input Real u;\n  output Real y;\n{decl}\nequation\n"
            f"  src.u = u;\n{eqs}\n  y = {output};\nend {name};")


def configuration_models(template_cls: str, swapped: bool) -> dict[str, str]:
    """The configuration models (Modelica text) around class ``template_cls``."""
    ta, tb = ("T.b", "T.a") if swapped else ("T.a", "T.b")
    tag = "_swapped" if swapped else ""
    g, T = "Ground g", f"{template_cls} T"
    return {
        f"across_series{tag}": _config(f"across_series{tag}", [g, "AcrossSource src", "Linear r", T],
                                       [("src.a", "r.a"), ("r.b", ta), (tb, "g.a"), ("src.b", "g.a")], "T.i"),
        f"through_parallel{tag}": _config(f"through_parallel{tag}", [g, "FlowSource src", "Storage s", T],
                                       [("src.b", ta), ("s.a", ta), (tb, "g.a"), ("s.b", "g.a"),
                                        ("src.a", "g.a")], "T.v"),
        f"across{tag}": _config(f"across{tag}", [g, "AcrossSource src", T],
                                [("src.a", ta), (tb, "g.a"), ("src.b", "g.a")], "T.i"),
        f"through{tag}": _config(f"through{tag}", [g, "FlowSource src", T],
                              [("src.b", ta), (tb, "g.a"), ("src.a", "g.a")], "T.v"),
    }


def excitation(amplitude: float = 1.0, duration: float = 10.0, n: int = 201) -> TimeSeries:
    """Input of every configuration: two sines, so the template sees both signs and a range."""
    t = np.linspace(0.0, duration, n)
    u = amplitude * (np.sin(2 * np.pi * t / duration) + 0.5 * np.sin(2 * np.pi * 3.1 * t / duration))
    return TimeSeries(t, u[:, None], ["u"])


@dataclass
class Configuration:
    name: str
    model: object          # CompiledModel
    informative: bool
    note: str = ""


def build_configurations(template: Template, connector: Connector, sources, registry,
                         directory=None, amplitude: float = 1.0) -> list[Configuration]:
    """Write, compile and check every configuration; the ones failing at the start are dropped."""
    from .services import compile_model, simulate

    directory = Path(directory or tempfile.mkdtemp(prefix="mcl-config-"))
    cls = "Template"
    comp = Component("T", cls, [Connector("a", connector.cls, connector.potential, connector.flow),
                                Connector("b", connector.cls, connector.potential, connector.flow)], "")
    models = {**configuration_models(cls, False), **configuration_models(cls, True)}
    path = write_package(directory, PACKAGE,
                         [*_helpers(connector), template.modelica_class(cls, comp), *models.values()])
    u = excitation(amplitude)
    out = []
    for name in models:
        try:
            model = compile_model([*sources, path], f"{PACKAGE}.{name}", reg=registry)
        except MclError as exc:
            out.append(Configuration(name, None, False, f"does not compile: {exc}"))
            continue
        start = {f"T.{p}": v for p, v in zip(template.parameter_names(), template.start())}
        res = simulate(model, u, start, reg=registry, options={"time_limit": 20})
        out.append(Configuration(name, model, res.ok, "" if res.ok else f"fails at the start: {res.reason}"))
    return out


def _label_task(context, item):
    """Executor task: simulate configuration k with parameters w; True when it succeeds."""
    from .engine_casadi import CasadiEngine

    models, u, names, options = context
    k, w = item
    res = CasadiEngine().simulate(models[k], u, dict(zip(names, w)), options=options)
    return bool(res.through(u.time).ok)


@dataclass
class PretrainResult:
    """Samples, labels and the trained q; ``accuracy`` is measured on held-out samples."""

    parameter_names: list[str]
    samples: np.ndarray
    labels: np.ndarray               # feasible in every informative configuration
    per_configuration: np.ndarray    # (N, C) bool
    configurations: list[str]
    notes: dict[str, str]
    model: object                    # FeasibilityModel
    train: np.ndarray                # indices used for training
    test: np.ndarray                 # held-out indices
    accuracy: float
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)

    def save(self, path) -> Path:
        path = Path(path)
        np.savez(path, samples=self.samples, labels=self.labels, per_configuration=self.per_configuration,
                 parameter_names=np.array(self.parameter_names), configurations=np.array(self.configurations),
                 train=self.train, test=self.test, accuracy=self.accuracy)
        return path


def sample_box(n_samples: int, dim: int, box, seed: int = 0) -> np.ndarray:
    """Latin hypercube samples in a box: ``box`` is a half-width or (low, high) arrays."""
    lo, hi = (np.full(dim, -float(box)), np.full(dim, float(box))) if np.isscalar(box) else \
        (np.asarray(box[0], float), np.asarray(box[1], float))
    return qmc.scale(qmc.LatinHypercube(d=dim, seed=seed).random(n_samples), lo, hi)


def pretrain(template: Template, connector: Connector, sources, registry, n_samples: int = 200,
             box=1.0, seed: int = 0, executor=None, feasibility="logistic", holdout: float = 0.25,
             amplitude: float = 1.0, time_limit: float = 10.0, directory=None,
             progress: bool = True) -> PretrainResult:
    """Remark 3.1: label samples of w in simple configurations and train q(w; beta) on them."""
    import time

    t0 = time.perf_counter()
    configs = build_configurations(template, connector, sources, registry, directory, amplitude)
    useful = [c for c in configs if c.informative]
    notes = {c.name: c.note for c in configs if c.note}
    if not useful:
        raise MclError("no configuration simulates at the template's start point: "
                       + "; ".join(f"{k}: {v}" for k, v in notes.items()))
    names = template.parameter_names()
    W = sample_box(n_samples, len(names), box, seed)
    u = excitation(amplitude)
    options = SimulationOptions(time_limit=time_limit)
    context = ([c.model for c in useful], u, [f"T.{p}" for p in names], options)
    items = [(k, w) for k in range(len(useful)) for w in W]
    own = executor is None
    executor = executor or registry.executor("local")
    try:
        flat = executor.map(_label_task, items, context=context, timeout=4 * time_limit + 30,
                            label="pre-training q(w)", progress=progress)
    finally:
        if own:
            executor.close()
    per = np.array([bool(r) and not isinstance(r, TaskFailed) for r in flat]).reshape(len(useful), -1).T
    labels = per.all(axis=1)
    rng = np.random.default_rng(seed)
    order = rng.permutation(n_samples)
    n_test = int(round(holdout * n_samples))
    test, train = np.sort(order[:n_test]), np.sort(order[n_test:])
    spec = {"name": feasibility} if isinstance(feasibility, str) else dict(feasibility)
    spec.setdefault("symmetric_axis", template.symmetric_axis)
    q = registry.feasibility_model(spec)
    q.fit(W[train], labels[train])
    accuracy = float(np.mean(q.predict(W[test]) == labels[test])) if n_test else float("nan")
    return PretrainResult(names, W, labels, per, [c.name for c in useful], notes, q, train, test,
                          accuracy, time.perf_counter() - t0)


def draw_feasibility(ax, W, y, names, axes=(0, 1, 2), coef=None, intercept: float = 0.0) -> None:
    """Feasible (green) and infeasible (red) points and the plane coef^T w + intercept = 0."""
    y = np.asarray(y, dtype=bool)
    axes = [a for a in axes if a < W.shape[1]]
    for mask, color, label in ((y, "tab:green", "feasible"), (~y, "tab:red", "infeasible")):
        ax.scatter(*[W[mask, a] for a in axes], c=color, s=12, alpha=0.7, label=f"{label} ({mask.sum()})")
    if coef is not None and len(axes) == 3 and abs(coef[axes[2]]) > 1e-12:
        g1, g2 = np.meshgrid(np.linspace(W[:, axes[0]].min(), W[:, axes[0]].max(), 12),
                             np.linspace(W[:, axes[1]].min(), W[:, axes[1]].max(), 12))
        g3 = -(coef[axes[0]] * g1 + coef[axes[1]] * g2 + intercept) / coef[axes[2]]
        zlo, zhi = W[:, axes[2]].min(), W[:, axes[2]].max()
        ax.plot_surface(g1, g2, np.where((g3 >= zlo) & (g3 <= zhi), g3, np.nan), alpha=0.25,
                        color="tab:blue")
    ax.set_xlabel(names[axes[0]])
    ax.set_ylabel(names[axes[1]])
    if len(axes) == 3:
        ax.set_zlabel(names[axes[2]])
    ax.legend(loc="upper left")


def plot_feasibility(result: PretrainResult, path, axes=(0, 1, 2), title: str = "") -> Path:
    """Pre-training samples and the learned boundary (paper 000, Fig. 4)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .plots import save_figure

    fig = plt.figure(figsize=(7.5, 6))
    ax = fig.add_subplot(111, projection="3d" if len(result.parameter_names) >= 3 else None)
    draw_feasibility(ax, result.samples, result.labels, result.parameter_names, axes,
                     getattr(result.model, "coef_", None), getattr(result.model, "intercept_", 0.0))
    ax.set_title(title or f"feasibility of w: held-out accuracy {result.accuracy:.1%}")
    return save_figure(fig, path)
