"""report.json and report.html: numbers for programs, plots for people."""
from __future__ import annotations

import base64
import html
import io
import json
import math
from pathlib import Path

import numpy as np

from ..plots import axis_label
from .families import family_of


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


def misfit_in_time(time, residual, sigma: float, factor: float = 3.0, max_spans: int = 5) -> list[list[float]]:
    """Where the misfit is: the time spans in which |residual| (any output, NaN = not measured)
    exceeds ``factor`` times the noise, longest first (at most ``max_spans``)."""
    r = np.asarray(residual, float).reshape(len(time), -1)
    with np.errstate(invalid="ignore"):
        bad = np.nanmax(np.where(np.isfinite(r), np.abs(r), 0.0), axis=1) > factor * max(sigma, 1e-300)
    spans, k = [], 0
    while k < len(bad):
        if bad[k]:
            j = k
            while j + 1 < len(bad) and bad[j + 1]:
                j += 1
            spans.append([float(time[k]), float(time[j])])
            k = j + 1
        else:
            k += 1
    return sorted(spans, key=lambda s: s[0] - s[1])[:max_spans]


def _g(x, digits: int = 3) -> str:
    return "-" if x is None else f"{x:.{digits}g}"


def _factor(before, after) -> str:
    if before is None or after is None or after <= 0:
        return "-"
    return f"{before / after:.3g}x smaller" if after < before else f"{after / before:.3g}x larger"


def _outputs_figure(plt, time, y_meas, y_nominal, y_extended, outputs, units, sigma, title):
    """Measured (where measured), nominal and extended outputs; residuals with the noise band and
    the spans where the nominal model is wrong shaded."""
    fig, axes = plt.subplots(len(outputs), 2, figsize=(12, 3.2 * len(outputs)), squeeze=False)
    for k, o in enumerate(outputs):
        ok = np.isfinite(y_meas[:, k])
        ax = axes[k, 0]
        ax.plot(time[ok], y_meas[ok, k], ".", ms=2, color="black", label="measured")
        ax.plot(time, y_nominal[:, k], color="tab:red", label="nominal model")
        if y_extended is not None:
            ax.plot(time, y_extended[:, k], color="tab:green", label="extended model")
        ax.set_ylabel(axis_label(o, units))
        ax.legend(fontsize=8)
        ax = axes[k, 1]
        r0 = y_meas[:, k] - y_nominal[:, k]
        ax.plot(time[ok], r0[ok], color="tab:red", lw=0.8, label="nominal residual")
        if y_extended is not None:
            ax.plot(time[ok], (y_meas[:, k] - y_extended[:, k])[ok], color="tab:green", lw=0.8,
                    label="extended residual")
        ax.axhspan(-3 * sigma, 3 * sigma, color="tab:blue", alpha=0.12, label="3 x noise")
        for t0, t1 in misfit_in_time(time[ok], r0[ok], sigma, max_spans=50):
            ax.axvspan(t0, t1, color="tab:red", alpha=0.08)
        ax.set_ylabel(f"residual of {axis_label(o, units)}")
        ax.legend(fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    axes[-1, 1].set_xlabel("time [s]")
    fig.suptitle(title)
    return fig


def _law_figure(plt, cause):
    law = cause["law"]
    xs, fs = np.array(law["curve"]).T
    fig, ax = plt.subplots(figsize=(6, 4))
    if law.get("nominal"):
        vn, fn = np.array(law["nominal"]).T
        ax.plot(vn, fn, ".", color="tab:red", ms=3, label="nominal model (along the training run)")
    ax.plot(xs, fs, color="tab:green", lw=2, label="learned law")
    x_name = {"across": law["across"], "der(across)": f"der({law['across']})", "flow": law["flow"]}
    ax.set_xlabel(x_name.get(law.get("variable", "across"), law["across"]))
    ax.set_ylabel(law["across"] if law.get("variable") == "flow" else law["flow"])
    ax.set_title(law["equation"], fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend()
    return fig


def _feasibility_figure(plt, cause):
    visited = np.array(cause.get("visited") or [], dtype=float)
    if not visited.size or visited.shape[1] < 3:
        return None
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
    return fig


def _ranking_figure(plt, report, cands):
    crit = ((report.get("cause") or {}).get("evidence", {}).get("criterion") or "bic").upper()
    fig, ax = plt.subplots(figsize=(7, 0.4 * len(cands) + 1.5))
    labels = [f"{c['component']} ({c.get('family') or family_of(c['template'])})" for c in cands]
    scores = [c["score"] - cands[0]["score"] for c in cands]
    colours = ["tab:green"] + ["tab:gray"] * (len(cands) - 1)   # the winner first, drawn at the top
    ax.barh(labels[::-1], scores[::-1], color=colours[::-1])
    ax.plot([0], [len(cands) - 1], "o", color="tab:green")      # the winner's bar has length 0
    if report.get("nominal_score") is not None:
        ax.axvline(report["nominal_score"] - cands[0]["score"], color="tab:red", ls="--", label="nominal model")
        ax.legend(fontsize=8)
    ax.set_xlabel(f"{crit} above the best candidate (lower is better)")
    return fig


def _summary_rows(report) -> str:
    m, g = report["misfit"], report["gain"]
    causes = report.get("causes") or ([report["cause"]] if report.get("cause") else [])
    rows = [("misfit", f"{'significant' if m['significant'] else 'not significant'}: training RMS "
                       f"{_g(m['train_rms'])} vs noise {_g(m['noise_estimate'])}"),
            ("where", ", ".join(f"{a:.3g}-{b:.3g} s" for a, b in sorted(m.get("where", []))) or "-")]
    if not causes:
        rows.append(("cause", f"no convincing cause ({report.get('no_cause', 'none found')})"))
    for k, cause in enumerate(causes):
        label = "cause" if len(causes) == 1 else f"cause {k + 1}"
        ev = cause["evidence"]
        rows.append((label, cause["effect"]))
        rows.append(("evidence", f"{ev['strength']} (Δ{ev.get('criterion', 'bic').upper()} {ev['delta_to_next']:.3g} "
                                 "to the next component or the model without it)"))
        rows.append(("law", f"{cause['law']['equation']}  where {cause['law'].get('where', '')}"))
        for e in cause.get("equivalents", []):
            rows.append(("equivalent", f"{e['component']} ({e.get('class') or ''}): {e['reason']}"))
        if cause.get("after"):
            rows.append(("misfit left", f"training RMS {_g(cause['after']['train_rms'])}: {cause['after']['misfit_left']}"))
    rows.append(("not evaluated", "; ".join(f"{f['component']} ({f['stage']}: {f['reason']})"
                                            for f in report.get("failed", [])) or "-"))
    body = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(str(v))}</td></tr>" for k, v in rows)
    gain = "".join(f"<tr><th>{k}</th><td>{_g(b)}</td><td>{_g(a)}</td><td>{_factor(b, a)}</td></tr>" for k, b, a in (
        ("training RMS", g["train_rms_before"], g["train_rms_after"]),
        ("validation RMS", g["validation_rms_before"], g["validation_rms_after"])))
    return (f"<table>{body}</table><h2>Before and after</h2><table><tr><th></th><th>nominal model</th>"
            f"<th>extended model</th><th>improvement</th></tr>{gain}</table>")


def _tried_rows(report) -> str:
    rows = []
    for s in report.get("screening", []):
        status = (s.get("not_applicable") and "not applicable" or s.get("reason") and f"failed: {s['reason']}"
                  or s.get("not_fitted") or "fitted")
        fam = family_of(s["template"])
        rows.append(f"<tr><td>{html.escape(s['component'])}</td><td>{html.escape(str(fam))}</td>"
                    f"<td>{_g(s.get('predicted_rss'))}</td><td>{html.escape(str(status))[:140]}</td></tr>")
    if not rows:
        return ""
    return ("<h2>What was tried</h2><table><tr><th>component</th><th>law family</th>"
            "<th>predicted RSS after one step</th><th>status</th></tr>" + "".join(rows) + "</table>")


def write_report(directory: Path, report: dict, train, outputs, y_nominal, y_extended,
                 title: str | None = None, plots: bool = True, validate=None, validation=None) -> None:
    """report.json, and report.html: the story (misfit, where, cause, law, before/after on the
    training and validation data, what was tried). ``validation`` is (nominal, extended)
    outputs on the ``validate`` data."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    directory = Path(directory)
    _write_atomic(directory / "report.json", json.dumps(_clean(report), indent=1))
    if not plots:
        return
    units, sigma = report.get("units"), report["misfit"]["noise_estimate"]
    figs = [("Training data: where and how much the model is wrong (shaded: beyond 3 x noise)",
             _png(_outputs_figure(plt, train.time, train.select(outputs).values, y_nominal, y_extended, outputs,
                                  units, sigma, "training data")))]
    if validate is not None and validation is not None and validation[0] is not None:
        figs.append(("Validation data (not used for fitting)",
                     _png(_outputs_figure(plt, validate.time, validate.select(outputs).values, validation[0],
                                          validation[1], outputs, units, sigma, "validation data"))))
    for cause in report.get("causes") or ([report["cause"]] if report.get("cause") else []):
        figs.append((f"Learned law of {cause['component']} over the range the data visits", _png(_law_figure(plt, cause))))
        fig = _feasibility_figure(plt, cause)
        if fig is not None:
            figs.append((f"Feasibility map of {cause['component']}: parameter values visited while fitting", _png(fig)))
    cands = [c for c in report.get("candidates", []) if c.get("score") is not None and math.isfinite(c["score"])
             and c.get("round", 1) == 1]
    if cands:
        figs.append(("Candidate ranking", _png(_ranking_figure(plt, report, cands))))
    imgs = "".join(f"<h2>{html.escape(t)}</h2><img src='data:image/png;base64,{b}'/>" for t, b in figs)
    heading = html.escape(title or report["model"])
    page = (f"<!doctype html><html><head><meta charset='utf-8'><title>mcl: {heading}</title>"
            "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}td,th{padding:4px 12px;"
            "text-align:left;vertical-align:top}img{max-width:100%}</style></head><body>"
            f"<h1>{heading}</h1>{_summary_rows(report)}{imgs}{_tried_rows(report)}</body></html>")
    _write_atomic(directory / "report.html", page)
