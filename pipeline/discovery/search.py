"""One search round: which laws at which components could explain what the model gets wrong.

:func:`search` lists the candidates (every candidate component with the law families of its
role, or the pinned templates), screens them all in one simulation (:mod:`.screen`: the
Gauss-Newton prediction of each law at each component, and, when no single law comes near the
noise, of each pair of laws at two components: two faults at once), fits the promising ones in
the executor's workers (:mod:`.candidates`) and, for the best law of one variable, looks for its
shape (a network distilled into sparse readable laws).
"""
from __future__ import annotations

import dataclasses
import itertools
import json
import re
from pathlib import Path

import numpy as np

from ..data import TimeSeries
from ..errors import ConfigError
from ..executor import TaskFailed
from ..progress import log
from ..sensitivity import fine_grid
from ..simulation import SimulationOptions
from ..stats import criterion as criterion_of, gram_inverse
from .candidates import NEURAL_INDEX, SHAPE_INDEX, Base, Context, Item, Pair, fit_task, free_parameters, publish, stopped
from .families import distillations, families, friction_laws, hysteresis_families, inverse_families, potential_families, role_of
from .inject import compiled, mode_of, rate_variables, with_injections
from .screen import law_signals, linear_response
from .verdict import EQUAL, READABLE, kept_terms, size_of

#: pairs of laws are screened when the best single law is predicted to leave more than this
#: times the noise's share of the RSS; a pair is fitted when it promises at most half the best
#: single law's RSS
PAIR_WHEN, PAIR_GAIN = 2.0, 0.5
#: a candidate's simulation may take this many times the nominal model's solver steps: a law
#: that makes the model crawl (stiff, near singular) fails fast and is recorded as such
WORK = 50
#: and its states may reach this many times the largest |state| of the nominal run
SPREAD = 1e3
#: a candidate's run may take this many times the nominal run's seconds (where that is more
#: than SimulationOptions' 60 s)
TIME_FACTOR = 20
#: family indices of the hysteresis laws, the laws in both potentials and the inverse law
#: (:func:`potential_items`)
HYSTERESIS_INDEX, POTENTIALS_INDEX, INVERSE_INDEX = 85, 90, 95
#: family index of the plainer laws distilled from a wordy best law (:func:`plainer`)
TIDY_INDEX = 110
#: and of the textbooks' friction laws distilled from a wordy law in a speed
FRICTION_INDEX = 120


def balanced(base: Base, train: TimeSeries, comp) -> bool:
    """Whether what flows into one connector of ``comp`` flows out of the other along the run
    (a one-port: resistor, spring, damper, capacitor); a mass or an inertia stores it."""
    from ..simulation import prepare_inputs

    if comp.signal or comp.sensor:     # a block's output is what its law gives: nothing stored
        return True
    ode, res = base.model.ode, base.result
    fa, fb = comp.flow()
    idx = [ode.probe_names.index(n) for n in (fa, fb)]
    u = prepare_inputs(base.model, train)
    N = len(res.time)
    U = np.array([np.interp(res.time, u.time, u.values[:, j]) for j in range(len(u.names))]).reshape(-1, N)
    p = base.model.parameter_vector()
    vals = np.array(ode.probe.map(N)(res.states.T, U, np.repeat(p[:, None], N, 1), res.time[None]))[idx]
    scale = float(np.max(np.abs(vals))) or 1.0
    return float(np.max(np.abs(vals[0] + vals[1]))) <= 1e-6 * scale


def blocked(template, rates: dict, component: str) -> str | None:
    """Why a law cannot sit at a component (it is in the rate of a variable the model's states
    do not set there: it would add a state), or None."""
    for var, d in (("v", "dv"), ("i", "di")):
        if d in template.uses and rates.get(var) is None:
            what = "across value" if var == "v" else "flow"
            return f"the {what} of {component} is not set by the model's states: a law in its rate would add a state"
    return None


# -- screening -----------------------------------------------------------------------------------
#: predicted RSS this close (relative) to the last one kept by the screening: a tie, fitted too
TIE = 0.05


def promising(screening: list[dict], limit: int, ratio: float = 10.0, score=None) -> list[int]:
    """Indices of the candidates worth a full fit: at most ``limit``, best predicted first, and
    only those whose predicted RSS after one Gauss-Newton step is within ``ratio`` of the best
    prediction (a candidate predicted 10x worse loses by n ln 10 in any criterion unless the
    linearisation is badly wrong). ``score(rss, k)``, the criterion of a law with ``k`` free
    terms, orders them: a small law predicted a little behind a large one in RSS may well be
    ahead in the criterion (default: by RSS alone). The first law past the limit predicted
    within :data:`TIE` of the last one kept is kept too, and laws that could not be screened
    are always fitted."""
    rank = score or (lambda rss, k: rss)
    ok = sorted((rank(s["predicted_rss"], s.get("n_params", 1) - 1), s["predicted_rss"], k)
                for k, s in enumerate(screening) if s.get("predicted_rss") is not None)
    unscreened = [k for k, s in enumerate(screening) if s.get("unscreened")]
    if not ok:
        return unscreened
    floor = max(min(pred for _, pred, _ in ok), 1e-300)
    kept = [(pred, k) for _, pred, k in ok[:limit] if pred <= ratio * floor]
    last = max((pred for pred, _ in kept), default=floor)
    # a prediction within TIE of one kept is a tie the linearised prediction cannot part (two
    # bearings of a drive, one reflected through a gear): the first of them is fitted too. Only
    # the first: where many tie, the prediction finds them alike (a ladder's sections, whose
    # resistors' storage laws tied five ways, each fit a minute of a 16-section ladder's 5)
    ties = [k for _, pred, k in ok[limit:limit + 1] if pred <= (1 + TIE) * last and pred <= ratio * floor]
    return [k for _, k in kept] + ties + unscreened


class Screening:
    """Every law at every component screened in one simulation: the linear response of the
    outputs to a deviation at each component (:func:`.screen.linear_response`), and from it the
    Gauss-Newton prediction of any law, or any pair of laws."""

    def __init__(self, items: list[Item], base: Base, train: TimeSeries, resid: np.ndarray):
        from ..services import registry, simulate
        from ..simulation import SimulationOptions

        reg = registry()
        comps = [base.structure.components[c] for c in dict.fromkeys(it.component for it in items)]
        templates = {it.key: reg.template(it.spec) for it in items}
        modes = {}
        for it in items:
            modes.setdefault(it.component, mode_of(templates[it.key]))
        sdae, j_names = with_injections(base.dae, comps, modes)
        model = compiled(sdae, base.model.name, outputs=train.names, info=base.model.info, structure=base.structure)
        fine, at_data = fine_grid(train.time, substeps(model, train))
        nominal = simulate(model, train, t_out=fine, options=SimulationOptions(rtol=1e-7, atol=1e-9))
        if not nominal.ok:
            raise ConfigError(f"the model does not simulate the training data: {nominal.reason}")
        sig = law_signals(model, nominal.states, fine, train, comps)
        phis = {}
        for it in items:
            tpl = templates[it.key]
            if tpl.explicit is None:      # an implicit law has no deviation terms to screen
                continue
            try:   # d D / d w_k: the law's right-hand terms (features are signed, lhs first)
                phis[it.key] = -tpl.features(sig[it.component].env())[:, 1:len(tpl.terms)].T
            except (NotImplementedError, KeyError, AttributeError):
                continue
        # one deviation parameter per component; every law at it shares that parameter's response
        j_of = {c.name: n for c, n in zip(comps, j_names)}
        resp = linear_response(model, [j_of[k[0]] for k in phis], train, nominal, at_data, phis) if phis else None
        measured = [o for o in model.output_names if o in train.names]
        o_idx = [model.output_names.index(o) for o in measured]
        self.r = resid.ravel()      # (weighted as the fits weigh it: train.weights)
        ok = np.isfinite(self.r)
        self.columns: dict = {}
        self.rss0 = float(np.sum(self.r[ok] ** 2))
        # (G, g, RSS) of the record, or of each growing window of a switched system's record
        self.windows = []
        if resp is not None:
            S = (resp.S[:, o_idx, :] * train.weight_of(measured)[None, :, None]).reshape(-1, len(resp.columns))
            for n in self.window_ends(train, nominal):
                rows = ok.copy()
                rows[n * len(measured):] = False
                Sw, rw = S[rows], self.r[rows]
                self.windows.append((Sw.T @ Sw, Sw.T @ rw, float(rw @ rw)))     # every prediction from these
            for j, (key, _) in enumerate(resp.columns):
                self.columns.setdefault(key, []).append(j)

    @staticmethod
    def window_ends(train: TimeSeries, nominal) -> list[int]:
        """The data points each prediction covers: the record; for a switched system also each
        of its refits' growing windows (:data:`.fitters.SWITCHED_LADDER`). Its switching times
        move with a law, and over a long record the phase of its sawtooth drifts past where a
        linear response holds: a thermostat's room, its wall's loss twice the nominal, was
        predicted to remove 0.8 % of the misfit over 6 h (the fit removes 99.6 %), 97 % over its
        first 11 minutes and 84 % over 22. The first windows alone favour no one (any law of a
        furnished room's parts took 97 % of its first 11 minutes): their geometric mean ranks."""
        from .fitters import SWITCHED_LADDER, horizons

        if not nominal.switched:
            return [len(train.time)]
        return [len(w.time) for w in horizons(train, **SWITCHED_LADDER)]

    def predicted(self, keys) -> float | None:
        """The RSS one Gauss-Newton step of the laws ``keys`` together is predicted to reach:
        over the record, or for a switched system the record's RSS times the geometric mean of
        the shares left in its windows (:meth:`window_ends`)."""
        if any(k not in self.columns for k in keys):
            return None
        j = [c for k in keys for c in self.columns[k]]
        shares = []
        for G, g, rss in self.windows:
            g = g[j]
            left = max(rss - g @ gram_inverse(G[np.ix_(j, j)]) @ g, 0.0)
            shares.append(max(left / rss, 1e-12) if rss > 0 else 1.0)
        return float(self.rss0 * np.exp(np.mean(np.log(shares))))

    def singles(self, items: list[Item]) -> list[dict]:
        out = []
        for it in items:
            pred = self.predicted([it.key])
            entry = {"component": it.component, "template": it.spec, "predicted_rss": pred}
            if pred is None:
                entry["unscreened"] = True
            else:
                entry.update(rss0=self.rss0, n_params=len(self.columns[it.key]) + 1)
            out.append(entry)
        return out

    def pairs(self, items: list[Item], limit: int) -> list[tuple[float, Item, Item]]:
        """The best ``limit`` pairs of laws at two different components, by predicted RSS."""
        ranked = [(self.predicted([a.key, b.key]), a, b) for a, b in itertools.combinations(items, 2)
                  if a.component != b.component and a.key in self.columns and b.key in self.columns]
        return sorted(ranked, key=lambda t: t[0])[:limit]


def substeps(model, train: TimeSeries) -> int:
    """Points per data interval for the linearised response (:mod:`mcl.sensitivity`): enough
    that the modes the data can show move little in one step, and faster ones are damped."""
    from ..services import simulate
    from ..sensitivity import SUBSTEPS, Linearisation, substeps_for

    res = simulate(model, train)
    if not res.ok:
        return SUBSTEPS
    lin = Linearisation(model, res.states, res.time, train, model.parameter_vector(), [])
    h = float(np.max(np.diff(train.time)))
    return substeps_for(lin.rate(), h)


# -- fitting batches -----------------------------------------------------------------------------
class Batch:
    """Fits candidates in the executor's workers (each builds its own candidate model from the
    compiled DAE), each saved as it finishes so that a rerun skips it."""

    def __init__(self, ctx: Context, part: Path, rundir, reg, executor: dict):
        self.ctx, self.part, self.rundir, self.reg, self.executor = ctx, part, rundir, reg, executor

    def __call__(self, items: list) -> list[dict]:
        part = self.part
        todo = [it for it in items if not _done(part / it.file)]
        log.info("      fitting %d candidate(s) (%d already done)", len(items), len(items) - len(todo))

        def checkpoint(wave, ctx):
            def save(k, r):
                it = wave[k]
                if isinstance(r, TaskFailed):
                    r = {"component": it.component, "template": it.spec, "failed": r.reason, "score": None}
                self.rundir.write_json(str((part / it.file).relative_to(self.rundir.partial)), r)
                if ctx.progress_dir and r.get("rss") is not None and not r.get("failed"):
                    publish(Path(ctx.progress_dir), it, r["rss"], *free_parameters(r), wave=ctx.wave)
            return save

        if todo:
            with self.reg.executor(self.executor) as ex:
                # waves of as many fits as workers, each reading only the finished waves before
                # it: the early stops, and so the answer, are the same however the workers race.
                # The first wave is the most promising fit alone: where it reaches the noise, the
                # others stop within a few simulations (a 16-section ladder: a losing fit beside
                # the right one ran 62 simulations)
                for start, end in waves(len(todo), int(getattr(ex, "workers", 1)), bool(self.ctx.progress_dir)):
                    wave = todo[start:end]
                    ctx = dataclasses.replace(self.ctx, wave=f"{part.name}:{wave[0].file}")
                    ex.map(fit_task, wave, context=ctx, timeout=3600, label="candidates",
                           on_result=checkpoint(wave, ctx))
        out = [json.loads((part / it.file).read_text()) for it in items]
        leading = [it for it, r in zip(items, out) if stopped(r) and _leads(r, out)]
        if leading and self.ctx.progress_dir:
            # a fit stopped where it stood (before pruning) by another's progress, which still
            # leads the batch: fitted to its end, so the answer does not depend on which worker
            # got ahead
            for it in leading:
                (part / it.file).unlink()
            self.patient()(leading)
            out = [json.loads((part / it.file).read_text()) for it in items]
        return out

    def patient(self) -> "Batch":
        """The same batch with no early stop (every fit to its end)."""
        return Batch(dataclasses.replace(self.ctx, progress_dir=""), self.part, self.rundir, self.reg, self.executor)


def _leads(result: dict, results: list[dict], margin: float = EQUAL) -> bool:
    """Whether ``result`` scores within ``margin`` (what does not separate two laws) of the best
    of ``results``."""
    scores = [r["score"] for r in results if r.get("score") is not None and not r.get("failed")]
    return result.get("score") is not None and bool(scores) and result["score"] <= min(scores) + margin


def _done(path: Path) -> bool:
    """A candidate already fitted (a failed one is tried again on resume)."""
    if not path.exists():
        return False
    try:
        return "failed" not in json.loads(path.read_text())
    except ValueError:
        return False


def _ranked(cands: list[dict]) -> list[dict]:
    return sorted((c for c in cands if c.get("score") is not None), key=lambda c: c["score"])


def at_noise(c: dict, sigma: float) -> bool:
    """Whether a fitted candidate's training RMS is within 1.2x the noise ``sigma``."""
    return c.get("train_rms") is not None and c["train_rms"] < 1.2 * sigma


def done_at_noise(c: dict, sigma: float) -> bool:
    """Whether a fitted candidate leaves nothing for other shapes to find: at the noise on the
    training data (:func:`at_noise`), and on the validation data, where given, within 2x it (a
    law in a pipe's pressure drop and its rate, standing in for the tank's capacity, reached the
    noise on 500 samples and 28x it on the validation record, where the root it stood for
    reaches the noise on both)."""
    v = c.get("validation_rms")
    return at_noise(c, sigma) and (v is None or not np.isfinite(v) or v < 2 * sigma)


def potential_items(ctx: Context, ranked: list[dict], top: int = 2) -> list[Item]:
    """The static laws a cubic in v cannot follow: the law the other way round, v = f(i)
    (:func:`families.inverse_families`), at the best component where it is a static physical
    one (not a block or a sensor, whose output follows its input) whose law in v bends back
    (:func:`softening`; not the second best: a tank's outlet behind the other's, whose inverse
    law cannot win but costs minutes to fit through the loop it makes), and laws in both
    connectors' own potentials where both vary (:func:`families.potential_families`:
    radiation where the model has a linear conductor) at the static components among the
    ``top`` best components; and a hysteresis (:func:`families.hysteresis_families`) where
    the best component's best law reads the rate beside v (:func:`directional`: its force
    depends on the direction of motion), at it where it is a static physical one, else at the
    static ones in parallel with it (a damper beside the spring takes that law as well)."""
    comps = list(dict.fromkeys(c["component"] for c in ranked if "parts" not in c))[:top]
    items = hysteresis_items(ctx, ranked, comps[0]) if comps and directional(ranked, comps[0]) else []
    for rank, comp in enumerate(comps):
        env = ctx.signals[comp].env() if comp in ctx.signals else None
        if env is None or role_of(env) != "static":
            continue
        part = ctx.base.structure.components[comp]
        law = next((c for c in ranked if c["component"] == comp and c.get("family") == "static"), None)
        if rank == 0 and not (part.signal or part.sensor) and law is not None and softening(law):
            items += [Item(comp, INVERSE_INDEX + k, f) for k, f in enumerate(inverse_families(env))]
        items += [Item(comp, POTENTIALS_INDEX + k, f) for k, f in enumerate(potential_families(env))]
    return items


def hysteresis_items(ctx: Context, ranked: list[dict], best: str) -> list[Item]:
    """The hysteresis laws at ``best`` where it is a static physical component, else at the
    static physical components in parallel with it."""
    structure = ctx.base.structure

    def static(comp: str) -> bool:
        part = structure.components[comp]
        return comp in ctx.signals and role_of(ctx.signals[comp].env()) == "static" and not (part.signal or part.sensor)

    targets = [best] if static(best) else [c for c in structure.parallel(best) if static(c)]
    return [Item(c, HYSTERESIS_INDEX + k, f) for c in targets
            for k, f in enumerate(hysteresis_families(ctx.signals[c].env()))]


def directional(ranked: list[dict], comp: str) -> bool:
    """Whether the best law fitted at ``comp`` is a storage law that keeps a term in the rate
    beside its terms in v: a force that depends on the direction of motion, as a hysteresis'
    does (the spring of a hysteretic oscillator is best fitted so: i = f(v) dv + g(v))."""
    law = next((c for c in ranked if c["component"] == comp), None)
    if law is None or law.get("family") != "storage":
        return False
    kept = kept_terms(law)
    return any("dv" in t for t in kept) and any(re.search(r"\bv\b", t) for t in kept)


def softening(law: dict) -> bool:
    """Whether a fitted static law i = f(v) bends back toward the v axis, its cubic term against
    its linear one: the shape of a root (a saturating core's flux in its magnetic potential, a
    pipe's flow in its turbulent pressure drop), which the law the other way round follows.
    A hardening spring's (a cubic that adds to the line) does not."""
    coef = dict(zip(law.get("terms") or [], np.asarray(law["w"]) * np.asarray(law["active"])))
    return float(coef.get("v", 0.0)) * float(coef.get("v^3", 0.0)) < 0


def shapes(fit: Batch, cands: list[dict], sigma: float) -> list[dict]:
    """What the polynomial laws in one difference variable could not reach, when the best of them
    leaves misfit above the noise: first, at the best static components, the law the other way
    round (a saturating core's potential in its flux) and laws in both connectors' own
    potentials (radiation between two bodies whose temperatures both vary, where the model has
    a linear conductor); then, unless such a law wins, non-polynomial shapes for the
    most promising component: a neural law in the variable of its best polynomial law (v, dv,
    or a connector's own potential), fitted to the data, then distilled into a sparse readable
    law over tanh, sinh, |x| x, sqrt(|x|), x/sqrt(1 + x^2), exp and polynomial terms
    (:func:`families.distillations`) and fitted and pruned like any candidate. Skipped when the
    polynomial law already fits to the noise, or when it is not a law of one variable. A best
    law that keeps many terms is then distilled itself (:func:`plainer`)."""
    from ..services import registry

    done = _ranked(cands)
    if not done:
        return []
    if done_at_noise(done[0], sigma):
        return plainer(fit, done[0])
    items = potential_items(fit.ctx, done)
    out = fit(items) if items else []
    done = _ranked(cands + out)
    if done_at_noise(done[0], sigma) or done[0].get("family") in ("potentials", "inverse", "hysteresis"):
        return out
    one = [c for c in done if one_variable(c)]
    if not one:
        return out
    best, var = one[0], one[0]["law_variable"]
    log.info("      shape of %s's law in %s: neural fit, then a sparse law distilled from it", best["component"], var)
    xs, curve = law_curve(best)
    if curve is None:      # (a law that overflows on its range)
        log.info("      no shape stage: %s's best law is not finite over its range", best["component"])
        return out
    spec = {"name": "neural", "hidden": 4, "x": var, "coupled": False, "family": "reference"}
    start = registry().template(spec).fit_curve(xs, curve)
    neural = fit([Item(best["component"], NEURAL_INDEX, {**spec, "start": start.tolist()})])
    out += neural
    n = neural[0]
    if n.get("score") is None or not n.get("law_range"):
        return out
    out += distilled(fit, best["component"], n, SHAPE_INDEX, keep=("1",) if "1" in kept_terms(best) else ())
    # (the best law but the network, its reference: a wordy law below the network was not
    # distilled, though the network is never named)
    top = next((c for c in _ranked(cands + out) if c.get("family") != "reference"), None)
    return out + (plainer(fit, top) if top is not None else [])


def distilled(fit: Batch, component: str, law: dict, index: int, keep: tuple = (), size: int = 3,
              plain: bool = False) -> list[dict]:
    """The sparse readable laws (:func:`families.distillations`) of ``law``'s curve over the
    range its variable visited, of up to ``size`` terms beside the basis terms ``keep``, fitted
    at ``component`` (items from ``index`` on); ``plain``: the polynomial ones too."""
    xs, curve = law_curve(law)
    if curve is None:
        return []
    laws = distillations(xs, curve, law["law_variable"], max_terms=size, keep=keep, plain=plain,
                         sensor=fit.ctx.base.structure.components[component].sensor)
    return fitted(fit, component, laws, index)


def fitted(fit: Batch, component: str, laws: list[dict], index: int) -> list[dict]:
    """Distilled ``laws`` (terms, scales, coefficients from a curve) fitted by simulation at
    ``component`` (items from ``index`` on)."""
    return fit([Item(component, index + k,
                     {"name": "polynomial", "lhs": ["i"], "rhs": d["terms"], "scales": d["scales"],
                      "start": [1.0, *map(float, d["c"])], "family": "shape"})
                for k, d in enumerate(laws)])


def law_curve(law: dict):
    """(x, f(x)): a fitted law's curve at 201 points over the range its variable visited
    ([-1, 1] where not told); f None where the law is not finite there."""
    from ..services import registry

    xs = np.linspace(*(law.get("law_range") or [-1.0, 1.0]), 201)
    w = np.asarray(law["w"]) * np.asarray(law.get("active", np.ones(len(law["w"]), bool)))
    curve = registry().template(law["template"]).curve(w, xs)
    return (xs, curve) if np.all(np.isfinite(xs)) and np.all(np.isfinite(curve)) else (xs, None)


def one_variable(law: dict) -> bool:
    """Whether a fitted law is a polynomial family's law of one variable (v, dv or a potential)."""
    return law.get("family") in ("static", "rate", "absolute") and law.get("law_variable") in ("v", "dv", "va", "vb")


def wordy(law: dict) -> bool:
    """Whether a fitted law of one variable keeps more than :data:`READABLE` terms beside a
    constant: a law a person cannot read at a glance."""
    return one_variable(law) and size_of(law) > READABLE


def plainer(fit: Batch, best: dict) -> list[dict]:
    """Plainer laws for a best law that is :func:`wordy`: its own curve distilled into laws of
    at most :data:`READABLE` terms beside a constant, the line and the constant it keeps kept,
    the shapes' scales fitted. The fixed scales of a family's Coulomb-like terms only
    approximate a step, so pruning keeps several of them where one tanh of the right scale is
    the law (dry friction tau = 0.1 w + 0.15 tanh(w/0.01) came as five terms, three of them tanh
    at the family's scales); the criterion decides between them."""
    if not wordy(best) or not best.get("law_range"):
        return []
    log.info("      %s's law has %d terms: plainer laws distilled from its curve", best["component"],
             len(kept_terms(best)))
    var = best["law_variable"]
    keep = tuple(t for t in ("1", "{x}") if t.format(x=var) in kept_terms(best))
    out = distilled(fit, best["component"], best, TIDY_INDEX, keep=keep, size=READABLE - ("{x}" in keep),
                    plain=True)
    if var == "dv" and any(t.startswith("tanh(") for t in kept_terms(best)):
        # a law in a speed that keeps Coulomb-like terms: the textbooks' friction laws too
        out += fitted(fit, best["component"], friction_laws(*law_curve(best), var, keep), FRICTION_INDEX)
    return out


# -- a round ------------------------------------------------------------------------------------
@dataclasses.dataclass
class Round:
    """What a search round found: the fitted candidates (singles and pairs), the screening,
    each component's nominal law variables and role, and the batch that fitted them."""

    candidates: list
    screening: list
    pairs: list
    signals: dict
    roles: dict
    fit: Batch | None


def waves(n: int, workers: int, reading: bool) -> list[tuple[int, int]]:
    """(start, end) of each wave of ``n`` fits: where fits read each other's progress, the first
    alone and then as many as there are ``workers``; otherwise all at once. (The first was not
    alone when the fits were no more than the workers: the loser ran beside the winner to its
    end, 59 simulations in the bundled example, where reading it stops after 8.)"""
    starts = [0, *range(1, n, max(1, workers))] if reading else [0]
    return list(zip(starts, [*starts[1:], n]))


def simplest_first(todo: list, templates: dict) -> list:
    """The fits in screening order, but the most promising component's law of fewest terms
    first: it is fitted alone (the first wave), so that the fits after it read how far it got
    and stop when they cannot win, or, near their optimum, when it has reached the noise and
    they could only prune back to it (a storage law ranked first
    for the right resistor of a ladder fell into a local minimum with five terms while the
    static law beside it fitted in 18 simulations)."""
    if not todo:
        return todo
    size = (lambda it: len(getattr(templates[it.key], "terms", ())) or np.inf)
    mine = [it for it in todo if it.component == todo[0].component]
    first = min(mine, key=size)      # the first of the smallest: screening order among equals
    return [first, *(it for it in todo if it is not first)]


def time_limit(base: Base) -> dict:
    """A candidate's time limit where :data:`TIME_FACTOR` times the nominal run's seconds is
    more than SimulationOptions' own (a large model's nominal run takes long), else none."""
    seconds = getattr(base.result, "seconds", 0.0) or 0.0
    return {"time_limit": seconds * TIME_FACTOR} if seconds * TIME_FACTOR > SimulationOptions.time_limit else {}


def limits(base: Base, steps: int) -> dict:
    """Simulation options that stop a candidate's run early: WORK times the nominal run's
    solver steps, and states SPREAD times beyond the largest of the nominal run's (a law that
    blows up: such runs took 7x the steps of the others before they ended)."""
    out = {"max_work": WORK * steps, **time_limit(base)} if steps else time_limit(base)
    states = getattr(base.result, "states", None)
    top = float(np.max(np.abs(states))) if states is not None and np.size(states) else 0.0
    if np.isfinite(top) and top > 0:
        out["state_bound"] = SPREAD * top
    return out


def search(spec, base: Base, train, validate, part: Path, rundir, reg, sigma: float, resid,
           chain: bool = False, beat: float | None = None) -> Round:
    """The candidate components with their law families (or the pinned templates), screened in
    one pass, the promising ones (and pairs of them, when no single law comes near the noise)
    fitted, then the shape stage. ``chain``: the measuring chain's components instead of the
    plant's; ``beat``: the score a law must be predicted to beat by more than EQUAL to be fitted
    (the plant's best: a sensor's or an input's law is fitted only where it could win)."""
    pool = base.structure.measuring_chain() if chain else base.structure.candidates()
    comps = [c for c in pool if c.name not in base.excluded]
    if spec.unknown != "auto":       # the pinned component, once (a later round has no other)
        comps = [c for c in [base.structure.components[spec.unknown]] if c.name not in base.excluded]
    stores = [c.name for c in comps if not balanced(base, train, c)]
    if stores:
        log.info("      not one-ports (their flows do not balance: masses, inertias): %s", ", ".join(stores))
        comps = [c for c in comps if c.name not in stores]
    if not comps:
        return Round([], [], [], {}, {}, None)
    signals = law_signals(base.model, base.result.states, base.result.time, train, comps)
    roles = {c.name: "static" if c.signal or c.sensor else role_of(signals[c.name].env()) for c in comps}
    items = [Item(c.name, k, t) for c in comps
             for k, t in enumerate(spec.templates or families(roles[c.name], signals[c.name].env(), c.signal,
                                                               c.sensor))]
    templates = {it.key: reg.template(it.spec) for it in items}
    modes = {}
    for it in items:
        modes.setdefault(it.component, mode_of(templates[it.key]))
    rates = rate_variables(base.dae, comps, modes)
    why_not = {it.key: blocked(templates[it.key], rates[it.component], it.component) for it in items}
    n_obs = int(np.isfinite(resid).sum())
    screening, pairs = _screened(part, rundir, items, why_not, base, train, resid, spec, n_obs * sigma**2)
    criterion = criterion_of(spec.criterion)
    keep = promising(screening, spec.screen, ratio=10.0 if spec.early_stop else np.inf,
                     score=lambda rss, k: criterion.score(rss, n_obs, k))
    if beat is not None:
        from .verdict import EQUAL

        keep = [k for k in keep if screening[k].get("predicted_rss") is not None
                and criterion.score(screening[k]["predicted_rss"], n_obs, screening[k].get("n_params", 1) - 1)
                < beat - EQUAL]
        pairs = []
    for k, s_ in enumerate(screening):
        if k not in keep and s_.get("predicted_rss") is not None:
            s_["not_fitted"] = "screening predicts it cannot compete"
    steps = getattr(base.result, "steps", 0) or 0
    ctx = Context(base, signals, rates, train, validate, spec.max_simulations, spec.criterion,
                  spec.refinement_method, str(part / "progress") if spec.early_stop else "", n_obs,
                  algorithm=getattr(spec, "algorithm", "levenberg-marquardt"),
                  limits=limits(base, steps), floor=n_obs * sigma**2)
    fit = Batch(ctx, part, rundir, reg, spec.executor)
    by_key = {it.key: it for it in items}
    todo = simplest_first([items[k] for k in keep], templates)
    todo += [Pair(by_key[tuple(p["first"])], by_key[tuple(p["second"])]) for p in pairs]
    cands = fit(todo)
    for c in cands:       # a law that cannot sit at its component is not applicable, not a failure
        if c.get("not_applicable"):
            s_ = next((s for s in screening if s["component"] == c["component"] and s["template"] == c["template"]), None)
            if s_ is not None:
                s_["not_applicable"] = c["not_applicable"]
    cands = [c for c in cands if not c.get("not_applicable")]
    simpler = simpler_families(cands, items, screening) if beat is None else []
    if simpler:
        cands += [c for c in fit(simpler) if not c.get("not_applicable")]
    if spec.templates is None:
        cands += [c for c in shapes(fit, [c for c in cands if "parts" not in c], sigma) if not c.get("not_applicable")]
    return Round(cands, screening, pairs, signals, roles, fit)


def simpler_families(cands: list[dict], items: list, screening: list[dict]) -> list:
    """The families of the best fitted component with fewer parameters than its best law that
    the screening left out: they are fitted too. The screening's prediction is linear about the
    nominal law and misjudges a law of another shape (a tank's square-root outflow, predicted
    behind a cubic with saturations, which then won with five terms where one was the law)."""
    done = [c for c in _ranked(cands) if "parts" not in c]
    if not done:
        return []
    best = done[0]
    size = next((s.get("n_params") for s in screening
                 if s["component"] == best["component"] and s["template"] == best["template"]), None)
    if size is None:
        return []
    out = []
    for it, s in zip(items, screening):
        if (it.component == best["component"] and s.get("not_fitted") and s.get("n_params", size) < size
                and not s.get("not_applicable")):
            s.pop("not_fitted")
            s["fitted_because"] = "a simpler family of the best component"
            out.append(it)
    return out


def _screened(part: Path, rundir, items, why_not, base, train, resid, spec, floor: float):
    """The screening of every item (and the pairs worth fitting), read back on a rerun."""
    screen_file, pair_file = part / "screening.json", part / "pairs.json"
    if screen_file.exists() and pair_file.exists():
        return json.loads(screen_file.read_text()), json.loads(pair_file.read_text())
    runnable = [it for it in items if not why_not[it.key]]
    log.info("[2/5] screening %d law(s) on %d component(s) in one simulation", len(items),
             len({it.component for it in items}))
    screen = Screening(runnable, base, train, resid) if runnable else None
    singles = iter(screen.singles(runnable) if screen else [])
    screening = [{"component": it.component, "template": it.spec, "predicted_rss": None,
                  "not_applicable": why_not[it.key]} if why_not[it.key] else next(singles) for it in items]
    pairs = []
    best = min((s["predicted_rss"] for s in screening if s.get("predicted_rss") is not None), default=None)
    if screen is not None and best is not None and best > PAIR_WHEN * floor and spec.unknown == "auto":
        for pred, a, b in screen.pairs(runnable, spec.screen):
            if pred < PAIR_GAIN * best:
                pairs.append({"first": list(a.key), "second": list(b.key), "predicted_rss": pred,
                              "components": [a.component, b.component]})
        if pairs:
            log.info("      no single law comes near the noise: %d pair(s) of laws screened in", len(pairs))
    rundir.write_json(str(screen_file.relative_to(rundir.partial)), screening)
    rundir.write_json(str(pair_file.relative_to(rundir.partial)), pairs)
    return screening, pairs
