"""report.json and report.html: numbers for programs, plots for people."""
from __future__ import annotations

import base64
import html
import io
import json
import math
from pathlib import Path

import numpy as np

from .plots import axis_label


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()


def _write_atomic(path: Path, text: str) -> None:
    """A full disk leaves the old file (or none), never half of the new one."""
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(text)
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def _clean(obj):
    """JSON-safe: numpy scalars to Python, non-finite floats to null."""
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def write_report(directory: Path, report: dict, train, outputs, y_nominal, y_extended,
                 title: str | None = None, plots: bool = True) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    directory = Path(directory)
    _write_atomic(directory / "report.json", json.dumps(_clean(report), indent=1))
    if not plots:
        return
    figs = []
    y_meas = train.select(outputs).values
    fig, axes = plt.subplots(len(outputs), 2, figsize=(12, 3.2 * len(outputs)), squeeze=False)
    for k, o in enumerate(outputs):
        ax = axes[k, 0]
        ax.plot(train.time, y_meas[:, k], ".", ms=2, color="black", label="measured")
        ax.plot(train.time, y_nominal[:, k], color="tab:red", label="nominal model")
        if y_extended is not None:
            ax.plot(train.time, y_extended[:, k], color="tab:green", label="extended model")
        ax.set_ylabel(axis_label(o, report.get("units")))
        ax.legend(fontsize=8)
        ax = axes[k, 1]
        ax.plot(train.time, y_meas[:, k] - y_nominal[:, k], color="tab:red", lw=0.8, label="nominal residual")
        if y_extended is not None:
            ax.plot(train.time, y_meas[:, k] - y_extended[:, k], color="tab:green", lw=0.8,
                    label="extended residual")
        ax.axhline(0, color="gray", lw=0.5)
        ax.legend(fontsize=8)
    axes[-1, 0].set_xlabel("time")
    axes[-1, 1].set_xlabel("time")
    fig.suptitle("training data: where and how much the model is wrong")
    figs.append(("Measured, nominal and extended outputs; residuals", _png(fig)))
    cause = report.get("cause")
    if cause:
        xs, fs = np.array(cause["law"]["curve"]).T
        fig, ax = plt.subplots(figsize=(6, 4))
        if cause["law"].get("nominal"):
            vn, fn = np.array(cause["law"]["nominal"]).T
            ax.plot(vn, fn, ".", color="tab:red", ms=3, label="nominal model (along the training run)")
        ax.plot(xs, fs, color="tab:green", lw=2, label="learned law")
        law = cause["law"]
        x_name = {"across": law["across"], "der(across)": f"der({law['across']})", "flow": law["flow"]}
        y_name = law["across"] if law.get("variable") == "flow" else law["flow"]
        ax.set_xlabel(x_name.get(law.get("variable", "across"), law["across"]))
        ax.set_ylabel(y_name)
        ax.set_title(cause["law"]["equation"], fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend()
        figs.append((f"Learned law of {cause['component']} over the range the data visits", _png(fig)))
    visited = np.array((cause or {}).get("visited") or [], dtype=float)
    if visited.size:
        W, ok = visited[:, :-1], visited[:, -1] > 0.5
        W = W / np.where(W[:, :1] == 0, 1.0, W[:, :1])           # the law is unchanged by scaling w
        spread = np.argsort(-np.std(W[:, 1:], axis=0))[:2] + 1
        fig, ax = plt.subplots(figsize=(6, 4.5))
        names = cause.get("parameters") or [f"w{k + 1}" for k in range(W.shape[1])]
        ax.scatter(W[ok, spread[0]], W[ok, spread[-1]], c="tab:green", s=14, label="simulated")
        ax.scatter(W[~ok, spread[0]], W[~ok, spread[-1]], c="tab:red", marker="x", s=20, label="failed")
        ax.set_xlabel(f"{names[spread[0]]} / {names[0]}")
        ax.set_ylabel(f"{names[spread[-1]]} / {names[0]}")
        ax.legend()
        figs.append(("Feasibility map: parameter values visited while fitting", _png(fig)))
    cands = [c for c in report.get("candidates", []) if c.get("score") is not None and math.isfinite(c["score"])]
    if cands:
        fig, ax = plt.subplots(figsize=(7, 0.4 * len(cands) + 1.5))
        labels = [f"{c['component']} ({c['template'].get('name', '?') if isinstance(c['template'], dict) else c['template']})"
                  for c in cands]
        scores = [c["score"] - cands[0]["score"] for c in cands]
        colours = ["tab:green"] + ["tab:gray"] * (len(cands) - 1)   # the winner first, drawn at the top
        ax.barh(labels[::-1], scores[::-1], color=colours[::-1])
        ax.plot([0], [len(cands) - 1], "o", color="tab:green")      # the winner's bar has length 0
        ax.set_xlabel("BIC above the best candidate (lower is better)")
        figs.append(("Candidate ranking", _png(fig)))
    m = report["misfit"]
    g = report["gain"]
    rows = "".join(f"<tr><td>{html.escape(k)}</td><td>{html.escape(str(v))}</td></tr>" for k, v in (
        ("misfit significant", m["significant"]), ("training RMS (nominal)", f"{m['train_rms']:.4g}"),
        ("noise estimate", f"{m['noise_estimate']:.4g}"),
        ("cause", cause["effect"] if cause else "none found"),
        ("evidence", f"{cause['evidence']['strength']} (Δ{cause['evidence'].get('criterion', 'bic').upper()} "
                      f"{cause['evidence']['delta_to_next']:.3g})"
         if cause else "-"),
        ("training RMS after", g["train_rms_after"]), ("validation RMS before", g["validation_rms_before"]),
        ("validation RMS after", g["validation_rms_after"]),
        ("not evaluated", "; ".join(f"{f['component']} ({f['stage']}: {f['reason']})"
                                    for f in report.get("failed", [])) or "-")))
    imgs = "".join(f"<h2>{html.escape(t)}</h2><img src='data:image/png;base64,{b}'/>" for t, b in figs)
    heading = html.escape(title or report["model"])
    page = (f"<!doctype html><html><head><meta charset='utf-8'><title>mcl: {heading}</title>"
            "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}td{padding:4px 12px}"
            "img{max-width:100%}</style></head><body>"
            f"<h1>{heading}</h1><table>{rows}</table>{imgs}</body></html>")
    _write_atomic(directory / "report.html", page)
