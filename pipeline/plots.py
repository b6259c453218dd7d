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


def plot_simulation(result: SimulationResult, inputs: TimeSeries, path, title: str = "",
                    units: dict | None = None) -> Path:
    """Inputs on top, every output below, on one time axis; written atomically as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(inputs.names) + len(result.output_names)
    fig, axes = plt.subplots(max(n, 1), 1, sharex=True, figsize=(9, 1.8 + 1.6 * n), squeeze=False)
    rows = [(inputs.time, inputs.column(k), k, "tab:gray") for k in inputs.names]
    rows += [(result.time, result.output(k), k, "tab:blue") for k in result.output_names]
    for ax, (t, v, label, color) in zip(axes[:, 0], rows):
        ax.plot(t, v, color=color, lw=1.2)
        ax.set_ylabel(axis_label(label, units))
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    status = "" if result.ok else f" — FAILED: {result.reason}"
    fig.suptitle((title or "simulation") + f" ({result.engine} engine){status}")
    fig.tight_layout()
    path = Path(path)
    save_figure(fig, path.with_name(f".{path.name}.tmp.png"), bbox_inches=None).replace(path)
    return path
