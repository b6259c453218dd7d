"""Plots a person would rather look at than read (matplotlib, no display needed)."""
from __future__ import annotations

from pathlib import Path

from .data import TimeSeries
from .simulation import SimulationResult


def axis_label(name: str, units: dict | None) -> str:
    """``name [unit]`` where the model declares a unit."""
    unit = (units or {}).get(name)
    return f"{name} [{unit}]" if unit else name


def save_figure(fig, path, **options) -> Path:
    """``fig`` written to ``path`` (its folder made; PNG, SVG or PDF by extension), then closed."""
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, **{"dpi": 110, "bbox_inches": "tight", **options})
    plt.close(fig)
    return path


#: a simulation plot's panels at most, and its lines per panel where outputs share panels
MAX_PANELS, PER_PANEL = 10, 6


def plot_simulation(result: SimulationResult, inputs: TimeSeries, path, title: str = "",
                    units: dict | None = None) -> Path:
    """Inputs on top, the outputs below (one panel each; where there are many, those that
    change, sharing a panel per unit), on one time axis; written atomically as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [[(inputs.time, inputs.column(k), k)] for k in inputs.names]
    panels += [[(result.time, result.output(k), k) for k in group] for group in _output_panels(result, units)]
    shown = panels[:MAX_PANELS]
    n = len(shown)
    fig, axes = plt.subplots(max(n, 1), 1, sharex=True, figsize=(9, 1.8 + 1.6 * n), squeeze=False)
    for k, (ax, lines) in enumerate(zip(axes[:, 0], shown)):
        color = "tab:gray" if k < len(inputs.names) else None
        for t, v, label in lines:
            ax.plot(t, v, color=color if len(lines) == 1 else None, lw=1.2, label=label)
        if len(lines) == 1:
            ax.set_ylabel(axis_label(lines[0][2], units))
        else:
            unit = (units or {}).get(lines[0][2])
            ax.set_ylabel(f"[{unit}]" if unit else "")
            ax.legend(fontsize=7, loc="best", ncol=2)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    status = "" if result.ok else f" — FAILED: {result.reason}"
    more = f"; {len(panels) - n} more panels not drawn (--variables chooses)" if len(panels) > n else ""
    fig.suptitle((title or "simulation") + f" ({result.engine} engine){status}{more}")
    fig.tight_layout()
    path = Path(path)
    save_figure(fig, path.with_name(f".{path.name}.tmp.png"), bbox_inches=None).replace(path)
    return path


def _output_panels(result: SimulationResult, units: dict | None) -> list[list[str]]:
    """The outputs' panels: one each where they fit, else those that change (all if none does),
    grouped by unit, at most :data:`PER_PANEL` to a panel."""
    import numpy as np

    names = list(result.output_names)
    if len(names) <= MAX_PANELS:
        return [[k] for k in names]
    def changes(k):
        v = result.output(k)
        return bool(np.isfinite(v).any()) and np.nanmax(v) - np.nanmin(v) > 1e-9 * max(1.0, np.nanmax(np.abs(v)))
    names = [k for k in names if changes(k)] or names
    groups: dict[str, list[str]] = {}
    for k in names:
        groups.setdefault((units or {}).get(k, ""), []).append(k)
    return [g[i:i + PER_PANEL] for g in groups.values() for i in range(0, len(g), PER_PANEL)]
