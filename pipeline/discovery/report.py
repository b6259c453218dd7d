"""report.json and report.html: numbers for programs, plots for people.

report.html tells the story a reviewer signs off: what the model gets wrong (where, how much,
against what noise, estimated how), which components are to blame and why, the laws they follow
(curves in the equations' own words, signs and units, with the nominal law beside them and a
confidence band), the gain on training and held-out data, what was tried, the files written, the
settings and the software. Solver messages are put in plain words, the raw text a click away.
"""
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
    """JSON-safe: numpy scalars to Python, non-finite floats to null, objects to their names."""
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items() if not str(k).startswith("_")}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if hasattr(obj, "name") and not isinstance(obj, (str, int, bool)) and obj is not None:
        return str(obj.name)
    return obj


def misfit_in_time(time, residual, sigma: float, factor: float = 3.0, max_spans: int = 5) -> list[list[float]]:
    """Where the misfit is: the time spans in which |residual| (any output, NaN = not measured)
    exceeds ``factor`` times the noise: the longest ``max_spans``, in time order."""
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
    return sorted(sorted(spans, key=lambda s: s[0] - s[1])[:max_spans])


def short_number(x, digits: int = 3) -> str:
    """``x`` in ``digits`` significant figures; "-" where there is none."""
    return "-" if x is None else f"{x:.{digits}g}"


def _factor(before, after) -> str:
    if before is None or after is None or after <= 0:
        return "-"
    return f"{before / after:.3g}x smaller" if after < before else f"{after / before:.3g}x larger"


def plain(reason: str) -> str:
    """A solver's or compiler's message in plain words (the raw text stays beside it)."""
    text = str(reason or "")
    for key, words in (("TOO_MUCH_WORK", "the solver needed too many steps (the law makes the model crawl)"),
                       ("CONV_FAILURE", "the solver could not converge (the law makes the model too stiff or singular)"),
                       ("ERR_FAILURE", "the solver could not meet its accuracy (a near-discontinuity)"),
                       ("RHSFUNC_FAIL", "the model could not be evaluated (an algebraic loop did not converge)"),
                       ("work budget", "it needed far more solver work than the nominal model (stopped)"),
                       ("time limit", "it took longer than the time allowed (stopped)"),
                       ("non-finite", "the simulation diverged (values became infinite)"),
                       ("no start point", "no parameter values near the start simulate"),
                       ("crashed", "the worker computing it crashed"),
                       ("timed out", "it took longer than the time allowed (stopped)")):
        if key in text:
            return words
    return text.split(":")[0] if len(text) > 80 else text


def _details(short: str, raw: str) -> str:
    if short == raw:
        return html.escape(short)
    return f"{html.escape(short)} <details><summary>detail</summary><code>{html.escape(raw)}</code></details>"


# -- figures -------------------------------------------------------------------------------------
def _inputs_figure(plt, data, units):
    names = list(data.names)
    fig, axes = plt.subplots(len(names), 1, figsize=(12, 1.6 + 1.2 * len(names)), squeeze=False, sharex=True)
    for ax, n in zip(axes[:, 0], names):
        ok = np.isfinite(data.column(n))
        ax.plot(data.time[ok], data.column(n)[ok], color="tab:gray", lw=1)
        ax.set_ylabel(axis_label(n, units))
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    return fig


def output_noise(report: dict, outputs) -> dict:
    """Each output's noise in its own units as the fits weigh it (the overall noise over the
    output's weight, where the outputs are weighted): an encoder's band of 1.6e-7 m beside a
    force's of 0.09 N, where the overall 0.06 drawn on both hid the position's residual."""
    weights = report["misfit"].get("weights") or {}
    return {o: report["misfit"]["noise_estimate"] / weights.get(o, 1.0) for o in outputs}


def _outputs_figure(plt, time, y_meas, y_nominal, y_extended, outputs, units, noise, title):
    """Measured (where measured), nominal and extended outputs; residuals with the noise band
    (``noise``: each output's, in its units) and the spans where the nominal model is wrong shaded."""
    fig, axes = plt.subplots(len(outputs), 2, figsize=(12, 3.2 * len(outputs)), squeeze=False)
    for k, o in enumerate(outputs):
        sigma = noise[o]
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


def _label(name, unit) -> str:
    return f"{name} [{unit}]" if unit else name


def _law_figure(plt, cause):
    """The learned law against the variable it is in, in the equation's words, sign and units,
    with its 95% band and the nominal law along the training run."""
    law = cause["law"]
    xs, fs = np.array(law["curve"]).T
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    if law.get("nominal"):
        vn, fn = np.array(law["nominal"]).T
        if law.get("nominal_is_function"):
            ax.plot(vn, fn, "--", color="tab:red", lw=1.5, label="nominal law")
        else:
            ax.plot(vn, fn, ".", color="tab:red", ms=3, label="nominal model along the training run")
    if law.get("band"):
        band = 1.96 * np.asarray(law["band"], float)
        ax.fill_between(xs, fs - band, fs + band, color="tab:green", alpha=0.2, label="95% band")
    if law.get("falling"):        # a hysteresis: the loop, its rising branch where the curve is
        xf, ff = np.array(law["falling"]).T
        ax.plot(xf, ff, color="tab:green", lw=2, ls=":", label="learned law, across value falling")
        ax.plot(xs, fs, color="tab:green", lw=2, label="learned law, across value rising")
    else:
        ax.plot(xs, fs, color="tab:green", lw=2, label="learned law")
    ax.set_xlabel(_label(law.get("x", law["across"]), law.get("x_unit")))
    ax.set_ylabel(_label(law.get("y", law["flow"]), law.get("y_unit")))
    ax.set_title(law["equation"], fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def _search_figure(plt, cause):
    """Where the fit searched: the two coefficients that moved most, each point green where the
    model simulated and red where it failed (the region the law must stay in)."""
    visited = np.array(cause.get("visited") or [], dtype=float)
    if not visited.size or visited.shape[1] < 3:
        return None
    W, ok = visited[:, :-1], visited[:, -1] > 0.5
    spread = np.argsort(-np.std(W[:, 1:], axis=0))[:2] + 1
    terms, names = cause.get("terms") or [], cause.get("parameters") or []
    # a coefficient is named by its term; a shape's scale (after the terms) by its own name
    label = lambda k: (f"coefficient of {terms[k]}" if k < len(terms) else
                       f"scale {names[k]}" if k < len(names) else f"parameter {k + 1}")
    fig, ax = plt.subplots(figsize=(6, 4.5))
    ax.scatter(W[ok, spread[0]], W[ok, spread[-1]], c="tab:green", s=14, label="simulated")
    ax.scatter(W[~ok, spread[0]], W[~ok, spread[-1]], c="tab:red", marker="x", s=20, label="failed to simulate")
    ax.set_xlabel(label(spread[0]))
    ax.set_ylabel(label(spread[-1]))
    ax.legend(fontsize=8)
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


# -- tables --------------------------------------------------------------------------------------
def _table(header, rows) -> str:
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def judged_on(each: dict) -> str:
    """The record each output's gain is shown on: the validation data where every output has a
    validation RMS after the laws, else the training data."""
    return "validation" if all("validation_after" in r for r in each.values()) else "train"


def _summary_rows(report) -> str:
    m, g = report["misfit"], report["gain"]
    causes = report.get("causes") or ([report["cause"]] if report.get("cause") else [])
    noise = "; ".join(f"{o}: {short_number(n['sigma'])} ({n['method']})" for o, n in (m.get("noise") or {}).items())
    rows = [("misfit", m.get("significance") or ("significant" if m["significant"] else "not significant")),
            ("noise", noise or short_number(m["noise_estimate"])),
            *([("fitted", "each output in units of its noise (their levels differ); candidates' RMS so weighted")]
              if m.get("weights") else []),
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
        for a in cause.get("alternatives", []):
            rows.append(("as good a law", f"{a['equation']}  (Δ{ev.get('criterion', 'bic').upper()} "
                                          f"{a['score_difference']:+.2g}: the data do not choose between them)"))
        if cause.get("plainer"):
            p = cause["plainer"]
            rows.append(("plainer law", f"{p['equation']}  (training RMS {short_number(p.get('train_rms'))} against "
                                        f"{short_number(cause.get('train_rms'))}; validation {short_number(p.get('validation_rms'))} "
                                        f"against {short_number(cause.get('validation_rms'))}; the law above was chosen)"))
        if cause.get("after"):
            rows.append(("misfit left", f"training RMS {short_number(cause['after']['train_rms'])}: {cause['after']['misfit_left']}"))
    failed = report.get("failed", [])
    rows.append(("not evaluated", "; ".join(f"{f['component']} ({f['stage']}: {plain(f['reason'])})" for f in failed) or "-"))
    body = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(str(v))}</td></tr>" for k, v in rows)
    calibrated = g.get("train_rms_calibrated") is not None
    gain_rows = []
    for name, b, a, c in (("training RMS", g["train_rms_before"], g["train_rms_after"], g.get("train_rms_calibrated")),
                          ("validation RMS", g["validation_rms_before"], g["validation_rms_after"],
                           g.get("validation_rms_calibrated"))):
        row = [name, short_number(b), short_number(a), _factor(b, a)] + ([short_number(c), _factor(b, c)] if calibrated else [])
        gain_rows.append(row)
    header = ["", "nominal model", "with the learned laws", "improvement"] + (
        ["laws + calibration", "improvement"] if calibrated else [])
    own = (report.get("calibration") or {}).get("validation_initial_state")
    note = (f"<p>The calibrated model's validation run starts from its own initial state "
            f"({html.escape(', '.join(own))}), fitted on the head of that record.</p>") if own else ""
    each = report.get("gain_per_output") or {}
    if len(each) > 1:      # (the pooled RMS mixes the outputs' units)
        which = judged_on(each)
        cal = all(f"{which}_calibrated" in r for r in each.values())
        note += "<h3>Each output</h3>" + _table(
            ["output", "noise", f"{which} RMS, nominal", "with the learned laws", "improvement"]
            + ["laws + calibration", "improvement"] * cal,
            [[html.escape(o), short_number(r["noise"]), short_number(r[f"{which}_before"]), short_number(r.get(f"{which}_after")),
              _factor(r[f"{which}_before"], r.get(f"{which}_after"))]
             + ([short_number(r[f"{which}_calibrated"]), _factor(r[f"{which}_before"], r[f"{which}_calibrated"])] if cal else [])
             for o, r in each.items()])
    return f"<table>{body}</table><h2>Before and after</h2>{_table(header, gain_rows)}{note}"


def _uncertainty_rows(report) -> str:
    out = []
    for cause in report.get("causes") or []:
        params = cause["law"].get("parameters") or []
        if not params:
            continue
        rows = [[html.escape(p["name"]), short_number(p["value"], 4), short_number(p["std_error"], 2),
                 f"[{short_number(p['ci95'][0], 4)}, {short_number(p['ci95'][1], 4)}]", short_number(p.get("bootstrap_std_error"), 2)]
                for p in params]
        out.append(f"<h3>{html.escape(cause['component'])}</h3>" + _table(
            ["parameter", "value", "standard error", "95% interval", "block bootstrap s.e."], rows))
    cal = report.get("calibration")
    if cal and not cal.get("error"):
        rows = [[html.escape(n), short_number(v["before"], 4), short_number(v["after"], 4), short_number(v["std_error"], 2)]
                for n, v in cal.get("values", {}).items()]
        out.append("<h3>Calibration (nominal parameters refitted with the laws)</h3>" + _table(
            ["parameter", "before", "after", "standard error"], rows))
        if cal.get("loose"):
            out.append(f"<p>Fitted, but trading off with the laws (standard error above half the value: "
                       f"one of many equally good sets): {html.escape(', '.join(cal['loose']))}</p>")
        if cal.get("sign_changed"):
            out.append(f"<p>Driven through zero by the fit, so held at the model's values (standing in "
                       f"for the law, not for the system): {html.escape(', '.join(cal['sign_changed']))}</p>")
        if cal.get("not_determined"):
            out.append(f"<p>Not determined by the data (left at their values): "
                       f"{html.escape(', '.join(cal['not_determined']))}</p>")
    return ("<h2>How sure the laws are</h2>" + "".join(out)) if out else ""


def _tried_rows(report) -> str:
    rows = []
    for s in report.get("screening", []):
        raw = s.get("not_applicable") or s.get("reason") or ""
        status = (s.get("not_applicable") and f"not applicable: {raw}" or s.get("reason") and
                  _details(f"failed: {plain(raw)}", raw) or s.get("not_fitted") or "fitted")
        fam = family_of(s["template"])
        rows.append([html.escape(f"{s.get('round', 1)}"), html.escape(s["component"]), html.escape(str(fam)),
                     short_number(s.get("predicted_rss")), status if "<details>" in str(status) else html.escape(str(status))])
    if not rows:
        return ""
    return "<h2>What was tried</h2>" + _table(["round", "component", "law family",
                                               "predicted RSS after one step", "status"], rows)


def _files_and_settings(report) -> str:
    ext = report.get("extended") or {}
    links = [(label, ext.get(key)) for label, key in (("extended model (Modelica)", "modelica"), ("FMU", "fmu"))]
    items = "".join(f"<li>{html.escape(label)}: <a href='{html.escape(path)}'>{html.escape(path)}</a></li>"
                    for label, path in links if path)
    items += "<li>numbers: <a href='report.json'>report.json</a></li>"
    notes = "".join(f"<li>{html.escape(n)}</li>" for n in ext.get("notes", []))
    settings = [[html.escape(k), html.escape(str(v))] for k, v in (report.get("settings") or {}).items()]
    software = [[html.escape(k), html.escape(v)] for k, v in (report.get("software") or {}).items()]
    cost = f"{short_number(report.get('cpu_seconds'))} CPU seconds ({short_number(report.get('seconds'))} s on the clock)"
    return (f"<h2>Files</h2><ul>{items}{notes}</ul><h2>Settings</h2>{_table(['setting', 'value'], settings)}"
            f"<p>{html.escape(cost)}</p><h2>Software</h2>{_table(['package', 'version'], software)}")


def write_report(directory: Path, report: dict, train, outputs, y_nominal, y_extended,
                 title: str | None = None, plots: bool = True, validate=None, validation=None) -> None:
    """report.json, and report.html: the story (misfit, where, causes, laws, before/after on the
    training and validation data, how sure, what was tried, files, settings). ``validation`` is
    (nominal, extended) outputs on the ``validate`` data."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    directory = Path(directory)
    _write_atomic(directory / "report.json", json.dumps(_clean(report), indent=1))
    if not plots:
        return
    units, noise = report.get("units"), output_noise(report, outputs)
    figs = [("Training data: where and how much the model is wrong (shaded: beyond 3 x noise)",
             _png(_outputs_figure(plt, train.time, train.select(outputs).values, y_nominal, y_extended, outputs,
                                  units, noise, "training data")))]
    inputs = [n for n in train.names if n not in outputs]
    if inputs:
        figs.append(("The inputs that drove the system (training data)", _png(_inputs_figure(plt, train.select(inputs),
                                                                                           units))))
    if validate is not None and validation is not None and validation[0] is not None:
        figs.append(("Validation data (not used for fitting)",
                     _png(_outputs_figure(plt, validate.time, validate.select(outputs).values, validation[0],
                                          validation[1], outputs, units, noise, "validation data"))))
    for cause in report.get("causes") or ([report["cause"]] if report.get("cause") else []):
        figs.append((f"Learned law of {cause['component']} over the range the data visit", _png(_law_figure(plt, cause))))
        fig = _search_figure(plt, cause)
        if fig is not None:
            figs.append((f"Where the fit of {cause['component']}'s law searched", _png(fig)))
    cands = [c for c in report.get("candidates", []) if c.get("score") is not None and math.isfinite(c["score"])
             and c.get("round", 1) == 1]
    if cands:
        figs.append(("Candidates of the first search, ranked", _png(_ranking_figure(plt, report, cands))))
    imgs = "".join(f"<h2>{html.escape(t)}</h2><img src='data:image/png;base64,{b}'/>" for t, b in figs)
    heading = html.escape(title or report["model"])
    page = (f"<!doctype html><html><head><meta charset='utf-8'><title>mcl: {heading}</title>"
            "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}td,th{padding:4px 12px;"
            "text-align:left;vertical-align:top}img{max-width:100%}details{display:inline}</style></head><body>"
            f"<h1>{heading}</h1>{_summary_rows(report)}{_uncertainty_rows(report)}{imgs}{_tried_rows(report)}"
            f"{_files_and_settings(report)}</body></html>")
    _write_atomic(directory / "report.html", page)
