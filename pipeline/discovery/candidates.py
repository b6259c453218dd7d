"""Candidates: a law (or two, at two components) put into the compiled model and fitted.

A candidate is an :class:`Item` (one component, one law family) or a :class:`Pair` (two laws at
two components, fitted together: two faults at once). :func:`build` puts its laws into the base
model's DAE (:mod:`.inject`); :func:`fit_task`, the executor's task, fits and prunes them and
returns the result as a dict (a pair's dict holds one part per law), written to the run
directory as it finishes. Finished fits publish the RSS they reached, so that a later fit that
cannot win stops (:meth:`Context.give_up`), whichever worker it runs in. Fits run in waves of as
many as there are workers, and a fit reads only the waves before its own (all finished): which
fits stop, and so the answer, does not depend on which worker got ahead.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..data import TimeSeries
from ..errors import MclError
from ..stats import criterion as criterion_of, rms
from .fitters import residual
from .inject import NominalForm, compiled, mode_of, nominal_of, own_nominal, with_law
from .screen import law_signals
from .words import said

#: family indices of the shape stage (after any family list)
NEURAL_INDEX, SHAPE_INDEX = 100, 101


class Item(NamedTuple):
    """One candidate: a component with one law (family index ``index`` of its list, or of the
    shape stage) given by a template spec."""

    component: str
    index: int
    spec: object

    @property
    def key(self) -> tuple[str, int]:
        return (self.component, self.index)

    @property
    def file(self) -> str:
        return f"candidates/{self.component}_{self.index}.json"

    @property
    def parts(self) -> list["Item"]:
        return [self]


class Pair(NamedTuple):
    """Two laws at two components, fitted together (two faults the data show at once)."""

    first: Item
    second: Item

    @property
    def component(self) -> str:
        return f"{self.first.component}+{self.second.component}"

    @property
    def index(self) -> str:
        return f"{self.first.index}+{self.second.index}"

    @property
    def spec(self) -> list:
        return [self.first.spec, self.second.spec]

    @property
    def key(self) -> tuple[str, str]:
        return (self.component, self.index)

    @property
    def file(self) -> str:
        return f"candidates/{self.component}_{self.index}.json"

    @property
    def parts(self) -> list[Item]:
        return [self.first, self.second]


@dataclass
class Base:
    """The model a search round works on: the compiled model with the causes found so far."""

    model: object              # CompiledModel (outputs include the measured variables)
    result: object             # its simulation of the training data
    excluded: set = field(default_factory=set)   # components already named as causes
    validation: object = None  # its simulation of the validation data, once run (kept: 88 000 samples cost 10 s)

    @property
    def dae(self):
        return self.model.dae

    @property
    def structure(self):
        return self.model.structure


@dataclass
class Context:
    """What every executor task of a round shares (inherited by forked workers)."""

    base: Base
    signals: dict               # component -> nominal law variables at the data points
    rates: dict                 # component -> its across value and flow as functions of the states
    train: TimeSeries
    validate: TimeSeries | None
    budget: int                 # simulations per fit
    criterion: str
    method: str                 # simulation | full-discretisation
    progress_dir: str           # finished fits publish their RSS here ('' = no early stop)
    n_obs: int = 0
    algorithm: str = "levenberg-marquardt"   # the optimiser (mcl.fit.FITTERS)
    limits: dict | None = None  # simulation options bounding a candidate's runs by the nominal's (steps, |x|)
    floor: float = 0.0          # the RSS of the noise alone (n_obs sigma^2)
    wave: str = ""              # the wave this context's fits run in (they do not read each other)
    kin: dict = field(default_factory=dict, repr=False, compare=False)   # component -> it and its parallel ones

    def settled(self, item) -> bool:
        """Another fit of this round has reached the noise (its RMS within 1.2x of it): a law
        can then at best tie with it."""
        if not self.progress_dir or self.floor <= 0:
            return False
        return any(o.rss <= 1.44 * self.floor for o in reached(Path(self.progress_dir), item, self.wave))

    def give_up(self, reachable: float, current: float, item, k: int | None = None,
                dictionary: int | None = None) -> bool:
        """A fit stops when it cannot win or tie. Given the RSS the other fits have reached (with
        their free parameters and the number of terms they choose from) and what its trusted
        Gauss-Newton model can still reach with its ``k`` free parameters of ``dictionary``
        terms: it stops when that is 10x the best (n ln 10 behind in any criterion); or, near its
        own optimum (its RSS within 1.5x of what it can reach), when it cannot come within the
        decisive margin of another fit at its own component or one in parallel with it (the
        same effect), counting no more parameters than that fit has now (which pruning only
        lowers: a larger law's lower RSS does not stop a smaller one the criterion may prefer);
        or when it cannot improve by what one more parameter costs (ln n / n of the
        RSS) on a law at its own component with no more parameters chosen from no more terms:
        it could only prune back to that law, which the criterion then prefers. Laws at other
        components that can tie run to their end: the verdict compares them."""
        if not self.progress_dir:
            return False
        others = reached(Path(self.progress_dir), item, self.wave)
        if not others:
            return False
        n = max(self.n_obs, 2)
        complexity = criterion_of(self.criterion).complexity
        mine = set(item.component.split("+"))
        if reachable > 10.0 * min(o.rss for o in others):
            return True
        if current > 1.5 * reachable:
            return False
        kin = set().union(*(self._kin(c) for c in mine))
        for o in others:
            theirs = set(o.component.split("+"))
            if not theirs <= kin:
                # a component that is not this one nor in parallel with it (another hypothesis,
                # not the same effect) stops this fit only by the 10x above: a Gauss-Newton model
                # or a pace far from this law's optimum can be off by far more than the decisive
                # margin (a saturating amplifier's law, crawling at 2x a sensor's RSS and
                # reckoned unable to pass it, fell 100x below it ten simulations later)
                continue
            k_me = k if k is not None else o.k
            fewer = None in (k_me, o.k) or o.k <= k_me
            lead = n * np.log(max(reachable, 1e-300) / max(o.rss, 1e-300))
            if not fewer:
                lead -= complexity(n, o.k) - complexity(n, k_me)
            smaller = fewer and None not in (dictionary, o.dictionary) and o.dictionary <= dictionary
            if lead > 10.0 or (smaller and theirs == mine and reachable > o.rss * (1.0 - np.log(n) / n)):
                return True
        return self._tied_at_noise(others, mine, dictionary)

    def _kin(self, component: str) -> set:
        """``component`` and the components in parallel with it (the same effect's carriers)."""
        if component not in self.kin:     # (asked at every step of every fit: the structure once)
            parallel = self.base.structure.parallel(component) if self.base is not None else ()
            self.kin[component] = {component, *parallel}
        return self.kin[component]

    def _tied_at_noise(self, others: list, mine: set, dictionary: int | None) -> bool:
        """A law at this component chosen from no more terms has reached the noise: this fit,
        near its own optimum, stops before its pruning, which could at best come back to that
        law (checked after the rules above, so only near the optimum: far from it, a larger law
        that the data prefer is not stopped by a smaller one at 1.2x the noise's RMS)."""
        if self.floor <= 0 or dictionary is None:
            return False
        return any(set(o.component.split("+")) == mine and o.dictionary is not None
                   and o.dictionary <= dictionary and o.rss <= 1.44 * self.floor for o in others)


@dataclass
class GiveUp:
    """The early stop of one fit (:meth:`Context.give_up`), called as ``give_up(reachable,
    current, k, dictionary)``; ``settled()`` tells whether another fit has reached the noise."""

    ctx: Context
    item: object

    def __call__(self, reachable: float, current: float, *size) -> bool:
        return self.ctx.give_up(reachable, current, self.item, *size)

    def settled(self) -> bool:
        return self.ctx.settled(self.item)


@dataclass
class Law:
    """One law of a built candidate: its template, start, parameter names and nominal form."""

    item: Item
    template: object
    w0: np.ndarray
    names: list[str]
    nominal: NominalForm | None


def start_of(ctx: Context, item: Item):
    """(template, w0, nominal form) of ``item``'s law: started at its fit to the nominal law
    along the base model's run (or at the spec's own ``start``); the nominal form in the law's
    variables, affine where the law reads the connectors' own potentials or has a constant term
    (:func:`.inject.nominal_of`: so that the first simulation is the nominal model)."""
    from ..services import registry

    template = registry().template(item.spec)
    env = ctx.signals[item.component].env()
    explicit = isinstance(item.spec, dict) and "start" in item.spec
    w0 = np.asarray(template.start() if explicit else template.start_from(env), float)
    nominal = None
    if template.explicit is not None:
        constant = any(str(m) == "1" for m in getattr(template, "terms", []))
        nominal = nominal_of(env, template.uses | ({"1"} if constant else set()), mode_of(template) == "series")
    return template, w0, nominal


def build(ctx: Context, item) -> tuple[list[Law], object]:
    """The candidate model: the base model's DAE with each law of ``item`` at its component."""
    dae, laws = ctx.base.dae, []
    for part in item.parts:
        template, w0, nominal = start_of(ctx, part)
        comp = ctx.base.structure.components[part.component]
        dae, names = with_law(dae, comp, template, w0, nominal, ctx.rates.get(part.component))
        laws.append(Law(part, template, w0, names, nominal))
    base = ctx.base.model
    return laws, compiled(dae, base.name, outputs=ctx.train.names, info=base.info, structure=base.structure)


def fit_task(ctx: Context, item) -> dict:
    """Executor task: one candidate built, fitted and pruned; its result as a dict."""
    from ..services import registry, simulate
    from .fitters import FitOutcome, fit_and_prune

    try:
        laws, model = build(ctx, item)
    except MclError as exc:
        return {"component": item.component, "template": item.spec, "score": None,
                "not_applicable": f"the law cannot be put there: {exc.message}"}
    names = [n for law in laws for n in law.names]
    w0 = np.concatenate([law.w0 for law in laws])
    shape = isinstance(item, Item) and item.index >= NEURAL_INDEX
    give_up = None if shape or not ctx.progress_dir else GiveUp(ctx, item)
    if isinstance(item, Pair):        # two laws: each keeps its scale, every term may be pruned
        held, prunable, follows = [], [], {}
        for law in laws:
            n_terms, at = len(getattr(law.template, "terms", law.names)), len(held)
            follows.update({at + k: tuple(at + j for j in others)
                            for k, others in getattr(law.template, "follows", {}).items()})
            held += [k == 0 for k in range(len(law.names))]
            prunable += [0 < k < n_terms for k in range(len(law.names))]
        fit = FitOutcome(*fit_and_prune(model, ctx.train, names, w0, 2 * ctx.budget, ctx.criterion, give_up=give_up,
                                        held=held, prunable=prunable, algorithm=ctx.algorithm,
                                        limits=ctx.limits, follows=follows))
    else:
        # the shape stage (a network, then distilled laws with fitted scales) always simulates:
        # it refines the best law and is not stopped for being behind it; a network has many
        # parameters and one chance, so it gets three fits' budget
        template = laws[0].template
        fitter = registry().fitter("simulation" if shape else ctx.method)
        fit = fitter.fit(model, ctx.train, names, w0, template, ctx.criterion,
                         ctx.budget * (3 if item.index == NEURAL_INDEX else 1), give_up=give_up,
                         prune=bool(getattr(template, "terms", None)),
                         algorithm=ctx.algorithm, limits=ctx.limits)
    res = fit.result if fit.result is not None else simulate(model, ctx.train, dict(zip(names, fit.w)))
    out = {"component": item.component, "template": item.spec, "rss": fit.rss, "score": fit.score,
           "simulations": fit.simulations, "pruning": fit.path, "visited": fit.visited if len(laws) == 1 else [],
           "train_rms": rms(residual(ctx.train, model, res)) if res.ok else None}
    if ctx.validate is not None:
        rv = simulate(model, ctx.validate, dict(zip(names, fit.w)))
        out["validation_rms"] = rms(residual(ctx.validate, model, rv)) if rv.ok else None
    parts, k = [], 0
    for law in laws:
        n = len(law.names)
        parts.append(_law_result(ctx, law, model, res, fit.w[k:k + n], fit.active[k:k + n]))
        k += n
    if len(parts) == 1:
        return {**parts[0], **out}
    return {**out, "components": [p["component"] for p in parts], "parts": parts,
            "family": "+".join(p["family"] for p in parts), "equation": "; ".join(p["equation"] for p in parts)}


def _law_result(ctx: Context, law: Law, model, res, w, active) -> dict:
    """One fitted law: its terms and values, and the range of its variable along the fitted run."""
    template, comp = law.template, ctx.base.structure.components[law.item.component]
    out = {"component": comp.name, "class": comp.cls, "template": law.item.spec,
           "family": getattr(template, "family", "") or template.name, "law_variable": template.law_variable,
           "mode": mode_of(template), "parameter_names": law.names,
           "nominal_form": law.nominal.coefficients if law.nominal else None,
           "nominal_exact": bool(law.nominal.exact or own_nominal(comp, template)) if law.nominal else None,
           "w0": law.w0.tolist(), "w": np.asarray(w).tolist(), "active": np.asarray(active).tolist(),
           "equation": said(template, np.asarray(w) * np.asarray(active), comp),
           "terms": [str(m) for m in getattr(template, "terms", [])]}
    if res.ok:
        env = law_signals(model, res.states, res.time, ctx.train, [comp])[comp.name].env()
        out["v_range"] = [float(np.min(env["v"])), float(np.max(env["v"]))]
        x = env[template.law_variable]
        out["law_range"] = [float(np.min(x)), float(np.max(x))]
    return out


def stopped(result: dict) -> bool:
    """Whether a fit was stopped early (another fit could not be beaten)."""
    return any(str(step.get("message", "")).startswith("stopped") for step in result.get("pruning") or [])


def free_parameters(result: dict) -> tuple[int | None, int | None]:
    """A finished fit's free parameters (its laws' active terms but each law's scale) and the
    number of terms they were chosen from."""
    laws = result.get("parts") or [result]
    if not all("active" in law for law in laws):
        return None, None
    return (int(sum(max(int(np.sum(law["active"])) - 1, 0) for law in laws)),
            int(sum(len(law["active"]) - 1 for law in laws)))


class Reached(NamedTuple):
    """What a fit of the round has reached: its least RSS, with its free parameters chosen among
    ``dictionary`` terms (None: not told)."""

    component: str
    rss: float
    k: int | None = None
    dictionary: int | None = None
    wave: str = ""


def publish(directory: Path, item, rss: float, k: int | None = None, dictionary: int | None = None,
            wave: str = "") -> None:
    """A finished fit's RSS (with its free parameters, chosen among ``dictionary`` terms), where
    the fits of later waves (in any worker) read it."""
    if rss is None or not np.isfinite(rss):
        return
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{item.component}_{item.index}.json"
    tmp = path.with_suffix(f".{id(path)}.tmp")
    tmp.write_text(json.dumps(Reached(item.component, float(rss), k, dictionary, wave)._asdict()))
    tmp.replace(path)


def reached(directory: Path, exclude=None, wave: str = "") -> list[Reached]:
    """What every fit of this round (but ``exclude``, and those of ``wave``) has reached."""
    out = []
    own = f"{exclude.component}_{exclude.index}.json" if exclude is not None else None
    for f in directory.glob("*.json") if directory.is_dir() else []:
        if f.name == own:
            continue
        try:
            d = json.loads(f.read_text())
            if wave and d.get("wave") == wave:
                continue
            k, dictionary = (None if d.get(key) is None else int(d[key]) for key in ("k", "dictionary"))
            out.append(Reached(str(d.get("component", "")), float(d["rss"]), k, dictionary))
        except (OSError, ValueError, KeyError, TypeError):
            continue
    return out
