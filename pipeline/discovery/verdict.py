"""The verdict of a search round: which law convinces, how strongly, and which components the
data cannot tell from it.

Candidates are ranked by the run's :class:`mcl.stats.Criterion` against each other and the model
without them; the best must also improve the validation data. Of laws that explain the data
equally well (within :data:`EQUAL`), the one at the component whose role fits the learned effect
is named: a force in the position is the spring's, in the speed the damper's; a current in the
voltage is the resistor's, not a capacitor's leak. Every component in parallel with a cause is
named as equivalent (a law in the across value or its rate gives the same flow whichever of two
parallel parts carries it), as is any other that scores within :data:`EQUAL`.
"""
from __future__ import annotations

import numpy as np

from ..errors import MclError
from ..stats import criterion as criterion_of
from .candidates import Item, stopped
from .families import families, spec_name

#: a lead below this (in the criterion) does not separate two laws: they explain the data alike
EQUAL = 2.0
#: a law of one variable with more terms than this (beside a constant) is distilled further
READABLE = 3


def components_of(c: dict) -> list[str]:
    return c.get("components") or [c["component"]]


def effect_kind(c: dict, env: dict | None = None) -> str | None:
    """Which role the learned law's additions to the nominal law point to: ``static`` (terms in
    the across value only), ``rate`` (its rate only), ``integral`` (the flow and its rate),
    ``storage`` (both), ``hysteresis`` (a hysteresis' state); None when nothing is added. With ``env`` (the component's law variables
    along the run), additions that carry less than a tenth of the added flow's energy there do
    not count: a damper's law that is mostly a cubic in the position, with a small term in the
    speed, points to the spring beside it."""
    from ..templates import Monomial

    nominal = set(c.get("nominal_form") or {})
    extra = [(t, w) for t, on, w in zip(c.get("terms", [])[1:], c.get("active", [])[1:], c.get("w", [])[1:])
             if on and w != 0 and t not in nominal]
    if not extra:
        return None
    if any(t == "z" for t, _ in extra) and c.get("family") == "hysteresis":
        return "hysteresis"
    scales = (c.get("template") or {}).get("scales", {}) if isinstance(c.get("template"), dict) else {}
    try:
        monos = [(Monomial.parse(t, scales), w) for t, w in extra]
    except MclError:
        return None
    if env is not None:
        with np.errstate(all="ignore"):
            energy = [float(np.nanmean((w * np.broadcast_to(m.value({**scales, **env}), np.shape(env["v"]))) ** 2))
                      for m, w in monos]
        total = sum(energy)
        if np.isfinite(total) and total > 0:
            monos = [mw for mw, e in zip(monos, energy) if e >= 0.1 * total]
    used = set().union(*(m.variables for m, _ in monos))
    if used <= {"v"}:
        return "static"
    if used <= {"dv"}:
        return "rate"
    if used <= {"i", "di"}:
        return "integral"
    return "storage"


def equivalents(best: dict, ranked: list[dict], structure) -> list[dict]:
    """The other components that explain the data as well as ``best``, each with the reason the
    data cannot separate them."""
    out, seen = [], {best["component"]}
    if best.get("mode", "parallel") == "parallel" and structure is not None:
        for p in structure.parallel(best["component"]):
            seen.add(p)
            out.append({"component": p, "class": structure.components[p].cls,
                        "reason": f"parallel to {best['component']}: the law found could be {p}'s as well; "
                                  "the data cannot separate them"})
    for c in ranked:
        if "parts" in c or c["component"] in seen or c["score"] - best["score"] > EQUAL:
            continue
        seen.add(c["component"])
        out.append({"component": c["component"], "class": c.get("class"), "equation": c.get("equation"),
                    "score_difference": c["score"] - best["score"],
                    "reason": f"explains the data as well ({c['score'] - best['score']:+.2g} in the criterion)"})
    return out


def alternatives(best: dict, scored: list[tuple[float, dict]], score: float) -> list[dict]:
    """The other laws of ``best``'s component that explain the data as well (``scored``: (score,
    law) pairs; ``score``: best's), each with its equation and score difference: the data do
    not choose between them (a tank's outflow as a cubic, or as exp plus Torricelli, 2.5 apart
    in the BIC, named one or the other by the last digit of a run)."""
    out = []
    for value, c in sorted(scored, key=lambda x: x[0]):
        if (c is best or "parts" in c or c.get("component") != best["component"] or value - score > EQUAL
                or (c.get("family"), c.get("equation")) == (best.get("family"), best.get("equation"))):
            continue
        out.append(other_law(c, value - score))
    return out


def other_law(c: dict, score_difference: float) -> dict:
    """A law named beside the cause's (an as good one, a plainer one): its equation, family,
    template, coefficients and score difference to the cause's."""
    w = (np.asarray(c["w"]) * np.asarray(c["active"])).tolist() if "w" in c and "active" in c else None
    return {"equation": c.get("equation") or spec_name(c["template"]), "family": c.get("family"),
            "template": c.get("template"), "w": w, "score_difference": float(score_difference)}


def decide(cands: list[dict], spec, resid, val0, roles: dict, structure, rss0: float, signals: dict | None = None):
    """(causes, why not, score of the model without them): the winning law, or both laws of a
    winning pair, each with its lead over the best candidate that shares none of its components
    (or the model without it), its equivalents, its role and the kind of its effect. The neural
    law of the shape stage is never a cause (it is the reference the readable laws are
    distilled from); one the user pinned may be."""
    n_obs = int(np.isfinite(resid).sum())
    nominal_score = criterion_of(spec.criterion).score(rss0, n_obs, 0)
    env = {k: v.env() for k, v in (signals or {}).items()}
    kind = lambda c: effect_kind(c, env.get(c["component"]))
    scored = sorted((c for c in cands if c.get("score") is not None and c.get("family") != "reference"),
                    key=lambda c: c["score"])
    ranked = [c for c in scored if c["score"] < nominal_score]
    if not ranked:
        return [], ("no candidate could be evaluated" if not scored
                    else "no candidate explains the training data better than the model without it"), nominal_score
    close = [c for c in ranked if c["score"] - ranked[0]["score"] <= EQUAL and "parts" not in c]
    fits = [c for c in close if kind(c) is not None and roles.get(c["component"]) == kind(c)]
    best = fits[0] if fits and "parts" not in ranked[0] else ranked[0]
    best = plainest(best, close)
    if val0 is not None and not helps(best.get("validation_rms"), val0):
        return [], (f"the best candidate, {best['component']} ({spec_name(best['template']) if 'parts' not in best else 'two laws'}), "
                    f"does not improve the validation data (RMS {val0:.4g} -> {_fmt(best.get('validation_rms'))})"), \
            nominal_score
    mine = set(components_of(best))
    laws = best["parts"] if "parts" in best else [best]
    for law in laws:
        mine |= {e["component"] for e in equivalents(law, [], structure)}
    others = [c["score"] for c in ranked if not set(components_of(c)) & mine]
    delta = min(others + [nominal_score]) - best["score"]
    shared = {k: best.get(k) for k in ("score", "rss", "train_rms", "validation_rms", "simulations")}
    causes = [{**law, **shared, "delta": delta, "equivalents": equivalents(law, ranked if len(laws) == 1 else [], structure),
               "effect_kind": kind(law), "role": roles.get(law["component"]), "pair": len(laws) > 1,
               "alternatives": alternatives(law, [(c["score"], c) for c in ranked], law["score"]) if len(laws) == 1 else []}
              for law in laws]
    return causes, None, nominal_score


def plainest(best: dict, close: list[dict]) -> dict:
    """Of the laws of ``best``'s component that explain the data as well (``close``: within
    :data:`EQUAL`), the one with the fewest parameters, the better score on a tie: the data do
    not choose, so the plainer law is named (a drain's sqrt(|dp|) tanh(dp/s), 0.7 behind a
    four-parameter law whose saturation term does not extrapolate: validation RMS 2.7e-3
    against 7.8e-3). A shape law in the same variable counts as the same kind of law: it is
    a family's law distilled (:func:`.search.plainer`)."""
    if "parts" in best:
        return best
    size = lambda c: int(np.sum(np.asarray(c["active"], bool))) if "active" in c else len(c.get("w") or ())  # noqa: E731
    kin = lambda c: c.get("family") == best.get("family") or (  # noqa: E731
        "shape" in (c.get("family"), best.get("family")) and c.get("law_variable") == best.get("law_variable"))
    same = [c for c in close if c is best or (c.get("component") == best["component"] and "parts" not in c and kin(c))]
    return min(same, key=lambda c: (size(c), c["score"]))


def kept_terms(law: dict) -> list[str]:
    """The terms a fitted law keeps (not its scale anchor)."""
    return [t for t, on in zip((law.get("terms") or [])[1:], (law.get("active") or [])[1:]) if on]


def size_of(law: dict) -> int:
    """How many terms a fitted law keeps beside a constant (:data:`READABLE` the most a person
    reads at a glance)."""
    return len([t for t in kept_terms(law) if t != "1"])


def readable(best: dict, cands: list[dict]) -> dict | None:
    """Where the law named keeps more than :data:`READABLE` terms beside a constant, the
    best-scoring law of its component that keeps at most that many, of its family or a shape law
    in the same variable (:func:`plainest`'s kin): the plainer law a person may prefer, reported
    with what it costs in fit (a positioning axis's seven-term friction, and a three-term shape
    law beside it at 1.3x its training RMS); else None."""
    if "parts" in best or size_of(best) <= READABLE:
        return None
    plain = [c for c in cands if c is not best and c.get("component") == best["component"] and "parts" not in c
             and c.get("score") is not None and not c.get("failed") and c.get("family") != "reference"
             and c.get("family") in (best.get("family"), "shape") and c.get("law_variable") == best.get("law_variable")
             and 0 < size_of(c) <= READABLE]
    if not plain:
        return None
    c = min(plain, key=lambda c: c["score"])
    return {**other_law(c, c["score"] - best["score"]), "train_rms": c.get("train_rms"),
            "validation_rms": c.get("validation_rms")}


def helps(after, before: float, margin: float = 0.02) -> bool:
    """Whether the validation error improves by more than ``margin`` (relative): a law that
    only fits the training data is not a cause."""
    return after is not None and np.isfinite(after) and after < (1 - margin) * before


def _fmt(x) -> str:
    return "failed" if x is None else f"{x:.4g}"


def role_items(best: dict, roles: dict, structure, cands: list[dict], signals) -> list[Item]:
    """When the best law's additions do not fit its component's role (a storage law on a damper
    whose new terms are in the position), the laws of that kind for the components in parallel
    with it whose role does fit, so that the verdict can name the part whose physics it is (a
    law of that kind fitted there already, to its end, is not fitted again)."""
    kind = effect_kind(best, signals[best["component"]].env() if best["component"] in signals else None)
    if best.get("pair") or kind is None or roles.get(best["component"]) == kind or structure is None:
        return []
    tried = {(c["component"], c.get("family")) for c in cands if not stopped(c)}
    items = []
    for other in structure.parallel(best["component"]):
        if roles.get(other) != kind or other not in signals:
            continue
        for k, spec_ in enumerate(families(kind, signals[other].env())):
            if spec_.get("family") == kind and (other, kind) not in tried:
                items.append(Item(other, 50 + k, spec_))
    return items


def failures(screening: list, cands: list) -> list[dict]:
    """Every candidate that could not be evaluated, with the stage and the reason."""
    out = [{"component": s["component"], "template": s["template"], "stage": "screening",
            "reason": s.get("reason", "failed")} for s in screening
           if s.get("predicted_rss") is None and not s.get("not_applicable") and not s.get("unscreened")]
    out += [{"component": c["component"], "template": c["template"], "stage": "fitting",
             "reason": c["failed"]} for c in cands if c.get("failed")]
    return out


def weigh_unevaluated(evidence: dict, best: dict, cands: list, screening: list, spec, n_obs: int) -> None:
    """A contender that failed in fitting can only be excluded by its screening prediction:
    its predicted score (one linearised step) must lose by the criterion's 'decisive' margin;
    otherwise the cause is at most 'undecided'. Another law of the cause's own component that
    failed does not contest which component it is (only which law: the report lists it)."""
    score_of = criterion_of(spec.criterion).score
    open_ = []
    for c in (c for c in cands if c.get("failed") and c["component"] != best["component"]):
        pred = next((s for s in screening if s["component"] == c["component"] and s["template"] == c["template"]), {})
        k = pred.get("n_params", 3)
        if pred.get("predicted_rss") is None or score_of(pred["predicted_rss"], n_obs, k - 1) - best["score"] <= 10:
            open_.append(c["component"])
    if open_:
        evidence["unevaluated"] = open_
        evidence["strength"] = f"undecided: {', '.join(open_)} could not be evaluated"
