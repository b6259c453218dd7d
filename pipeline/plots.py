"""Plots a person would rather look at than read (matplotlib, no display needed)."""
from __future__ import annotations

from pathlib import Path

from .data import TimeSeries
from .simulation import SimulationResult


def plot_simulation(result: SimulationResult, inputs: TimeSeries, path, title: str = "") -> Path:
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
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time")
    status = "" if result.ok else f" — FAILED: {result.reason}"
    fig.suptitle((title or "simulation") + f" ({result.engine} engine){status}")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)
    return path
