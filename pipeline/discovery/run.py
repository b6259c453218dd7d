"""The main job (``mcl run``): what the model gets wrong, which components, which laws, what gain.

The user's model is compiled once, exactly as written; everything below works on that compiled
model (its DAE and component structure, :mod:`.inject`), never on rewritten Modelica.

1. Misfit: the nominal model simulated on the training inputs; the residual (where measured)
   against the noise estimated from the data, so a correct model comes out not significant;
   where it exceeds the noise.
2. Search (:mod:`.search`): every candidate component (or the named one) with the law families
   of its role (:mod:`.families`) or the pinned templates, screened together in one simulation
   (:mod:`.screen`); the promising laws, and pairs of laws when no single one comes near the
   noise, fitted and pruned in the compiled DAE (:mod:`.candidates`, :mod:`.fitters`), stopped
   when they cannot win; then the shape stage (a network distilled into sparse laws).
3. Verdict (:mod:`.verdict`): ranked by the run's :class:`mcl.stats.Criterion`; a cause must
   also improve the validation data; of laws that explain the data equally well on parallel
   components, the one whose role fits the learned effect is named, the others listed.
4. Several faults (:class:`Causes`): the causes are put into the model and steps 1-3 repeat on
   the extended model until the misfit is at the noise level or no further cause convinces.
5. Extend and report (:mod:`.extend`, :mod:`.report`): the laws in the components' words, the
   extended model written as Modelica, compiled and exported as an FMU, gains on training and
   validation data (and another configuration); report.json and report.html.

The run directory is built in ``<output>.partial`` (each candidate's result saved as it finishes,
so an interrupted run resumes) and renamed to ``<output>`` at the end.
"""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from ..compile.isolation import cpu_seconds
from ..data import TimeSeries
from ..errors import ConfigError, DataError
from ..executor import TaskFailed
from ..progress import log
from ..runfile import CALIBRATION_SPAN
from ..stats import misfit_significance, noise_levels, rms
from .candidates import Base
from .families import spec_name
from .fitters import WHOLE_RUN, rms_both
from .inject import NominalForm, compiled, mode_of, rate_variables, with_law
from .search import at_noise, search, time_limit
from .verdict import EQUAL, decide, failures, readable, role_items, weigh_unevaluated

#: outputs whose noise levels differ by more than this factor are weighted by them in the fits
WEIGHED_WHEN = 3.0
#: with ``free:``, this many of the winning component's laws are compared after calibration
CALIBRATED_LAWS = 3
#: at most this many causes are searched for
MAX_CAUSES = 3
#: 0 degC in K: a temperature measured this far below the model's throughout was logged in degC
ZERO_CELSIUS = 273.15


def _outputs_of(model, result, outputs) -> np.ndarray | None:
    return result.outputs[:, [model.output_names.index(o) for o in outputs]] if result.ok else None


def with_causes(base: Base, bests: list[dict], train: TimeSeries) -> Base:
    """The base model with each of ``bests``' laws put in at its fitted values (pruned terms
    at 0), its components (and those in parallel with them) excluded from further search."""
    from ..services import registry, simulate

    if not bests:
        return base
    dae = base.dae
    for best in bests:
        template = registry().template(best["template"])
        comp = base.structure.components[best["component"]]
        nominal = (NominalForm(best["nominal_form"], 0.0 if best.get("nominal_exact", True) else 1.0)
                   if best.get("nominal_form") is not None else None)
        rates = rate_variables(dae, [comp], {comp.name: mode_of(template)})[comp.name]
        dae, best["_names"] = with_law(dae, comp, template, np.asarray(best["w"]) * np.asarray(best["active"]),
                                       nominal, rates, active=best["active"])
    model = compiled(dae, base.model.name, outputs=train.names, info=base.model.info, structure=base.structure)
    # (a candidate's time, not a whole run's: a law that makes the model crawl is not a cause)
    took = time_limit(base)
    result = simulate(model, train, options=took)
    if not result.ok:     # a stiff learned law: the tolerance its fit simulated it at
        from .fitters import FIT_OPTIONS

        result = simulate(model, train, options={**FIT_OPTIONS, **took})
    if not result.ok:
        raise ConfigError(f"the model with the learned laws of {', '.join(b['component'] for b in bests)} does not "
                          f"simulate the training data: {result.reason}")
    # a component in parallel with a cause is not searched again: its law would only repeat
    # terms of the cause's (the data cannot separate them), and the two would be collinear
    named = {b["component"] for b in bests}
    named |= {p for b in bests if b.get("mode", "parallel") == "parallel" for p in base.structure.parallel(b["component"])}
    return dataclasses.replace(base, model=model, result=result, excluded=base.excluded | named, validation=None)


class Causes:
    """Several faults: causes found round after round on the model extended by those found
    before (each round a search and a verdict; a round may name two at once, a pair of laws
    fitted together), until the misfit is at the noise level or no further law convinces."""

    def __init__(self, spec, train, validate, outputs, part: Path, rundir, reg, noise: dict):
        self.spec, self.train, self.validate, self.outputs = spec, train, validate, outputs
        self.part, self.rundir, self.reg, self.noise = part, rundir, reg, noise
        self.sigma = overall(noise)
        self.n_params = 0             # parameters the causes found so far added
        self.y = train.select(outputs).values
        self.rounds: list[dict] = []

    def misfit(self, base: Base) -> tuple[np.ndarray, float | None, float | None]:
        """The training residual of ``base`` and its validation RMS, in the data's units and
        weighted as the fits weigh it (its run kept on ``base``)."""
        from ..services import simulate

        resid = self.y - _outputs_of(base.model, base.result, self.outputs)
        val = weighted = None
        if self.validate is not None:
            if base.validation is None:
                base.validation = simulate(base.model, self.validate, options=WHOLE_RUN)
            val, weighted = rms_both(self.validate, base.model, base.validation, self.outputs)
        return resid, val, weighted

    def round(self, base: Base, val_base) -> list[dict]:
        """One search and its verdict on ``base``: the winning law(s), each with what it was
        found on; empty when nothing convinces. In the search for the first cause, where no law
        of the plant brings the misfit to the noise, the measuring chain (sensors, the blocks at
        the model's inputs and outputs) is searched in a round of its own; its laws are fitted
        only where the screening predicts they beat the plant's best by more than :data:`EQUAL`,
        and one is the cause only where it does: a sensor's law could otherwise stand in for the
        plant's (and a plant's law for a sensor's: a bearing's offset torque of 7e5 N m spun a
        pulley one way to mimic a counter blind to the direction). Later rounds leave the chain:
        a static map at the output then only trims what the plant's laws left (the Silverbox's
        run took twice as long for it)."""
        bests = self._round(base, val_base)
        chain = [c.name for c in base.structure.measuring_chain() if c.name not in base.excluded]
        first = self._plant_rounds() == 1
        if not (chain and first) or self.spec.unknown != "auto" or (bests and at_noise(bests[0], self.sigma)):
            return bests
        log.info("      the measuring chain is searched (%s)", ", ".join(chain))
        plant, verdict = self.rounds[-1], self._verdict
        measured = self._round(base, val_base, chain=True,
                               beat=bests[0]["score"] if bests else plant.get("nominal_score"))
        if measured and (not bests or measured[0]["score"] < bests[0]["score"] - EQUAL):
            return measured
        if measured:
            log.info("      the measuring chain's best law (%s) does not score better than the plant's by %g",
                     measured[0]["component"], EQUAL)
        # (the plant's round is the round's: its candidates are what the next steps read)
        self.rounds.remove(plant)
        self.rounds.append(plant)
        self._verdict = verdict
        return bests

    def _plant_rounds(self) -> int:
        """Rounds searched so far on the plant (a round of the measuring chain shares its number)."""
        return sum(not r["chain"] for r in self.rounds)

    def _round(self, base: Base, val_base, chain: bool = False, beat: float | None = None) -> list[dict]:
        number = self._plant_rounds() + (0 if chain else 1)
        label = f"round{number}" + ("chain" if chain else "")
        rpart = self.part / label
        (rpart / "candidates").mkdir(parents=True, exist_ok=True)
        resid = (self.y - _outputs_of(base.model, base.result, self.outputs)) * self.train.weight_of(self.outputs)
        rss = float(np.nansum(resid**2))
        found = search(self.spec, base, self.train, self.validate, rpart, self.rundir, self.reg, self.sigma, resid,
                       chain, beat)
        cands = found.candidates

        def verdict() -> list[dict]:
            bests, why, nominal_score = decide(cands, self.spec, resid, val_base, found.roles, base.structure, rss,
                                               found.signals)
            if not cands and not found.screening and base.excluded:
                why = ("no component is left to search (the causes found and the components in parallel "
                       "with them are not searched again)")
            elif not cands and found.screening and beat is not None:
                why = f"no law of the measuring chain is predicted to beat the plant's by more than {EQUAL:g}"
            entry.update(nominal_score=nominal_score, no_cause=why)
            if not bests:
                log.info("      round %d%s: %s", number, " (measuring chain)" if chain else "", why)
            return [{**b, "_signals": found.signals, "_base": base, "_round": label} for b in bests]

        entry = {"label": label, "round": number, "chain": chain, "screening": found.screening,
                 "pairs": found.pairs, "candidates": cands, "roles": found.roles}
        self.rounds.append(entry)
        self._verdict = verdict
        bests = verdict()
        items = role_items(bests[0], found.roles, base.structure, cands, found.signals) if bests else []
        if items:
            cands += [c for c in found.fit.patient()(items) if not c.get("not_applicable")]
            bests = verdict()
        return bests

    def without(self, bests: list[dict], why: str) -> list[dict]:
        """The round's verdict again with the laws of ``bests`` (which do not simulate once put
        in the model) marked failed: the next best law, or none."""
        for cand in self.rounds[-1]["candidates"]:
            if any(cand.get("component") == b["component"] and cand.get("template") == b["template"] for b in bests):
                cand.update(failed=why, score=None)
        return self._verdict()

    def after(self, base: Base) -> dict:
        resid, val, weighted = self.misfit(base)
        left = significance(resid, self.noise, self.outputs, self.train.time, self.n_params)
        return {"train_rms": rms(resid), "validation_rms": val, "_validation_fit": weighted, "significance": left.reason,
                "misfit_left": "significant" if left.significant else "at the noise level"}

    def calibrated_choice(self, nominal: Base, found: list[dict], bests: list[dict], val0) -> list[dict]:
        """With ``free:``, the winning component's best laws (up to :data:`CALIBRATED_LAWS`)
        compared once each is refitted with the freed parameters: a law's shape must not win by
        standing in for a miscalibrated offset or gain (a hardening spring written as exp(s/s1)
        beside a force offset, where the calibrated cubic explains the data better)."""
        from ..stats import criterion as criterion_of
        from .verdict import alternatives, effect_kind, helps

        if not self.spec.free or len(bests) != 1 or bests[0].get("pair"):
            return bests
        best = bests[0]
        ranked = sorted((c for c in self.rounds[-1]["candidates"]
                         if c.get("component") == best["component"] and c.get("score") is not None
                         and c.get("family") != "reference" and "parts" not in c and not c.get("failed")
                         and (val0 is None or helps(c.get("validation_rms"), val0))),
                        key=lambda c: c["score"])
        # one law once: of the fits of one law from several starts (a hysteresis'), the best
        # (a worse local optimum, calibrated, may climb to the other's and be named with the
        # values it had before)
        law_of = lambda c: (c.get("family"), spec_name(c["template"]), tuple(c.get("terms") or ()))  # noqa: E731
        laws = [c for k, c in enumerate(ranked) if law_of(c) not in {law_of(o) for o in ranked[:k]}][:CALIBRATED_LAWS]
        if len(laws) < 2:
            return bests
        n_obs = int(np.isfinite(self.y).sum())
        score = criterion_of(self.spec.criterion).score
        # each law's calibration in a worker of its own: they are independent, and each is
        # dozens of simulations of the record searched
        context = Calibration(nominal, found, laws, self.train, self.spec.free, self.outputs,
                              internal(self.spec, nominal.model) if self.spec.free == "auto" else [])
        with self.reg.executor(self.spec.executor) as ex:
            done = ex.map(_calibrated, list(range(len(laws))), context=context, timeout=3600,
                          label="calibrations")
        for law, cal in zip(laws, done):
            if isinstance(cal, TaskFailed):      # (the law is left out of the choice, not the run)
                log.warning("      the calibration of %s's law %s failed: %s", law["component"],
                            law.get("equation") or spec_name(law["template"]), cal.reason)
        scored = [(score(cal["train_rms"] ** 2 * n_obs, n_obs, self.n_params + cal["k"]), law)
                  for law, cal in zip(laws, done) if cal and cal.get("train_rms") is not None]
        if not scored:
            return bests
        value, chosen = min(scored, key=lambda x: x[0])
        # (the final calibration, on more of the record, starts where the chosen law's ended)
        start = next(cal["params"] for law, cal in zip(laws, done) if law is chosen)
        for v, law in sorted(scored, key=lambda x: x[0]):
            log.debug("      calibrated %s %+.3g: %s", law["component"], v - value,
                      law.get("equation") or spec_name(law["template"]))
        log.info("      the calibration (free: %s) chooses %s's law: %s (as found; calibrated values in the report)",
                 self.spec.free if isinstance(self.spec.free, str) else ", ".join(self.spec.free), best["component"],
                 chosen.get("equation") or spec_name(chosen["template"]))
        same = lambda a, b: (a.get("family"), a.get("equation")) == (b.get("family"), b.get("equation"))
        # the laws the calibrated data do not choose between, named with the one chosen
        others = alternatives(chosen, scored, value)
        if same(chosen, best):
            return [{**best, "alternatives": others, "calibrated_score": value, "_calibrated_start": start}]
        env = best["_signals"][best["component"]].env() if best["component"] in best["_signals"] else None
        decided = {k: best[k] for k in ("equivalents", "role", "pair", "_signals", "_base", "_round") if k in best}
        return [{**chosen, **decided, "delta": best["delta"] + best["score"] - chosen["score"],
                 "effect_kind": effect_kind(chosen, env), "calibrated_score": value, "alternatives": others,
                 "_calibrated_start": start}]

    def find(self, nominal: Base, val0) -> tuple[list[dict], Base]:
        found, base, val = [], nominal, val0
        while len(found) < MAX_CAUSES:
            bests = self.round(base, val)
            if bests:
                bests = self.calibrated_choice(nominal, found, bests, val)
            extended = None
            while bests and extended is None:
                try:
                    extended = with_causes(nominal, found + bests, self.train)
                except ConfigError as exc:
                    # a law that simulated while it was fitted but not once put in the model (near
                    # a singular point) is not a cause: the next best law of the round is weighed
                    log.warning("      round %d: %s", self.rounds[-1]["round"], exc)
                    bests = self.without(bests, f"does not simulate once put in the model: {exc}")
            if not bests:
                break
            for b in bests:     # (the plainer law beside a wordy one, and what it costs)
                b["plainer"] = readable(b, self.rounds[-1]["candidates"])
            base = extended
            found += bests
            self.n_params += sum(int(np.sum(b["active"])) - 1 for b in bests)
            after = self.after(base)
            for b in bests:
                b["_after"] = after
            val = after["_validation_fit"]
            if after["misfit_left"] == "at the noise level":
                break
        return found, base


@dataclasses.dataclass
class Calibration:
    """What the calibrations of a round's best laws share (inherited by forked workers)."""
    nominal: Base
    found: list
    laws: list
    train: TimeSeries
    free: object
    outputs: list
    internal: list


def _calibrated(ctx: Calibration, k: int) -> dict | None:
    """The executor's task: law ``k`` put in the model and calibrated with the parameters freed
    (its training RMS, and ``k``: the parameters it was fitted with); None when it cannot be put
    in the model."""
    from ..progress import quiet
    from .calibrate import calibrate

    trial = dict(ctx.laws[k])
    try:
        ext = with_causes(ctx.nominal, ctx.found + [trial], ctx.train)
    except ConfigError:
        return None
    names = refitted(trial["_names"], trial["active"])
    held = [n for n in trial["_names"] if n not in names] + ctx.internal
    held += replaced([c["component"] for c in ctx.found + [trial]], ext.model,
                     held + names + [n for c in ctx.found for n in c.get("_names", ())])
    with quiet():
        cal = calibrate(ext.model, ctx.train, None, ext.model.parameters, names, ctx.free, ctx.outputs, held)
    fitted = names + list(cal.get("freed", ()))
    return {"train_rms": cal.get("_fit_rms"), "k": len(fitted),
            "params": {n: cal["params"][n] for n in fitted} if "params" in cal else {}}


def run_discovery(spec, train: TimeSeries, validate: TimeSeries | None = None, force: bool = False,
                  fingerprint: dict | None = None) -> dict:
    """Execute a validated :class:`mcl.runfile.RunSpec` on ``train`` (and ``validate``) data;
    returns the report dict. :class:`mcl.Discovery` is the public face of this function."""
    from ..services import compile_model, registry, simulate
    from .extend import describe, extend
    from .rundir import RunDirectory

    rundir = RunDirectory(spec.output, force=force)
    part = rundir.partial
    t_start, cpu_start = time.perf_counter(), cpu_seconds()
    reg = registry()
    # the criterion resolved once, by name, through the registry (a plugin's as a built-in's)
    spec = dataclasses.replace(spec, criterion=reg.criterion(spec.criterion))
    nominal = compile_model(spec.sources, spec.model_name, libraries=spec.libraries).with_outputs(train.names)
    if nominal.dae is None or nominal.structure is None:
        raise ConfigError(f"the compiler '{nominal.info.get('compiler')}' keeps no DAE of {spec.model_name}: "
                          "discovery needs the default compiler (casadi, on rumoca)")
    if spec.unknown != "auto":      # a component that can take a law (a run file was checked for it)
        from ..runfile import _Problems, _check_component

        problems = _Problems(None, {})
        _check_component(problems, "unknown", nominal, spec.unknown, spec.model_name)
        problems.raise_if_any()
    outputs = [o for o in nominal.output_names if o in train.names]
    _say_unmeasured(nominal.output_names, outputs, validate)
    _say_constant(nominal.input_names, train)
    log.info("[1/5] nominal model %s: simulating the training data", spec.model_name)
    sim0 = simulate(nominal, train, options=WHOLE_RUN)
    if not sim0.ok:
        raise ConfigError(f"the nominal model does not simulate the training data: {sim0.reason}")
    y_meas = train.select(outputs).values
    y0 = _outputs_of(nominal, sim0, outputs)
    resid = y_meas - y0
    _celsius_for_kelvin(resid, outputs, nominal.info.get("units", {}), train.source)
    noise = noise_levels(y_meas, train.time, outputs, spec.noise)
    sigma = overall(noise)
    weights = output_weights(noise, y_meas, outputs, [rms(resid[:, k]) for k in range(len(outputs))])
    train = train.weighted(weights)
    validate = validate.weighted(weights) if validate is not None else None
    train_rms0 = rms(resid)
    verdict = significance(resid, noise, outputs, train.time)
    significant = verdict.significant
    report = {"model": spec.model_name, "outputs": outputs,
              "misfit": {"significant": significant, "train_rms": train_rms0, "noise_estimate": sigma,
                         "significance": verdict.reason, "level_p": verdict.level_p,
                         "whiteness_p": verdict.whiteness_p,
                         "noise": {o: {"sigma": n.sigma, "method": n.method, "reliable": n.reliable}
                                   for o, n in noise.items()},
                         "per_output_rms": {o: rms(resid[:, k]) for k, o in enumerate(outputs)},
                         "weights": weights},
              "cause": None, "causes": [], "candidates": [], "gain": None,
              "units": {n: u for n, u in nominal.info.get("units", {}).items() if n in outputs},
              "components": len(nominal.structure.components), "software": software_versions(),
              "settings": settings(spec),
              "inputs": fingerprint or {}}
    log.info("      %s", verdict.reason)
    from .report import misfit_in_time

    # (each output against its own noise: weighted)
    report["misfit"]["where"] = misfit_in_time(train.time, resid * train.weight_of(outputs), sigma) if significant else []
    val0, val0_fit, val_y = None, None, None
    if validate is not None:
        sv = simulate(nominal, validate, options=WHOLE_RUN)
        val0, val0_fit = rms_both(validate, nominal, sv, outputs)
        val_y = [_outputs_of(nominal, sv, outputs), None]
    searched, base0 = train, Base(nominal, sim0)
    if significant and len(train.time) > spec.max_samples:
        searched = train.head(spec.max_samples)
        log.info("      the search fits the first %d of %d training samples (fitting.max_samples); the gain is "
                 "measured on all", spec.max_samples, len(train.time))
        _say_head(searched, train)
        base0 = Base(nominal, simulate(nominal, searched, options=WHOLE_RUN))
    causes = Causes(spec, searched, validate, outputs, part, rundir, reg, noise)
    found, base = causes.find(base0, val0_fit) if significant else ([], base0)
    rounds = causes.rounds
    report["failed"] = [f for r in rounds for f in failures(r["screening"], r["candidates"])]
    for f in report["failed"]:
        log.warning("      %s with %s could not be evaluated (%s): %s", f["component"], spec_name(f["template"]),
                    f["stage"], f["reason"])
    val_base = val0
    for best in found:
        cause = describe(best, best["_base"], spec, train, best["_signals"])
        r = next(r for r in rounds if r["label"] == best["_round"])
        weigh_unevaluated(cause["evidence"], best, r["candidates"], r["screening"], spec, int(np.isfinite(causes.y).sum()))
        cause["after"], cause["round"] = best["_after"], best["_round"]
        val_base = best["_after"]["validation_rms"]
        report["causes"].append(cause)
    if found:
        _how_sure(report, found, base, spec, searched, validate, outputs, train)
    _summarise_rounds(report, rounds)
    extended_y = None
    if report["causes"]:
        report["cause"] = report["causes"][0]
        report["_model"] = base.model         # the extended model, for Discovery.predict (not written)
        extended_y, ext_val, files = extend(report["causes"], base, spec, part, train, validate, outputs,
                                            report.get("_calibrated"))
        report["extended"] = files
        if val_y is not None:
            val_y[1] = ext_val
        report["gain"] = {"train_rms_before": train_rms0, "train_rms_after": rms(y_meas - extended_y) if extended_y is not None else None,
                          "validation_rms_before": val0, "validation_rms_after": val_base}
        cal = report.get("calibration") or {}
        if cal.get("train_rms") is not None:      # the law alone (above) and with the calibration
            report["gain"].update(train_rms_calibrated=cal["train_rms"], validation_rms_calibrated=cal.get("validation_rms"))
        report["gain_per_output"] = _per_output(outputs, noise, y_meas, y0, extended_y, validate, val_y,
                                                (report.get("calibration") or {}).get("per_output"))
    if report["gain"] is None:
        report["gain"] = {"train_rms_before": train_rms0, "train_rms_after": train_rms0,
                          "validation_rms_before": val0, "validation_rms_after": val0}
    report["seconds"] = time.perf_counter() - t_start
    report["cpu_seconds"] = cpu_seconds() - cpu_start
    log.info("[5/5] report")
    from .report import write_report

    write_report(part, report, train, outputs, y0, extended_y, validate=validate, validation=val_y, **spec.report)
    rundir.finish()
    log.info("wrote %s/report.html and report.json", spec.output)
    return report


def _celsius_for_kelvin(resid: np.ndarray, outputs: list[str], units: dict, source: str) -> None:
    """A DataError where a temperature the model gives in K is measured about 273.15 K below it
    all along: logged in degC. (Taken for a misfit, the offset was blamed on conductances that
    became capacitances of 1e13 J/K.)"""
    for k, name in enumerate(outputs):
        r = resid[:, k][np.isfinite(resid[:, k])]
        if units.get(name) != "K" or not r.size:
            continue
        offset = float(np.median(r))
        if abs(offset + ZERO_CELSIUS) < 0.1 * ZERO_CELSIUS and np.percentile(np.abs(r - offset), 90) < 0.1 * ZERO_CELSIUS:
            raise DataError(f"column {name} is {-offset:.0f} K below the model's {name} (in K) throughout: "
                            "degC? give temperatures in K", where=source)


def _say_unmeasured(declared: list[str], measured: list[str], validate: TimeSeries | None) -> None:
    """Say which of the model's outputs the training data do not measure (they are not
    compared), and warn where the validation data measure one of them: it is not used."""
    missing = [o for o in declared if o not in measured]
    if not missing:
        return
    log.info("      compared: %s; not measured in the training data: %s", ", ".join(measured), ", ".join(missing))
    unused = [o for o in missing if validate is not None and o in validate.names]
    if unused:
        log.warning("the validation data's column%s %s %s not used: the training data do not measure %s",
                    "s" if len(unused) > 1 else "", ", ".join(unused), "are" if len(unused) > 1 else "is",
                    "them" if len(unused) > 1 else "it")


def _per_output(outputs, noise, y_meas, y0, y_ext, validate, val_y, calibrated=None) -> dict:
    """Each output's RMS before and after the laws (and with the calibration, ``calibrated``:
    calibrate's per_output), on the training and validation data, beside its noise: the pooled
    RMS mixes units where the outputs have different ones (a pressure in Pa beside a flow in m3/s
    hid a flow and two temperatures left at 9-15x their noise). Said in the log where there are
    several outputs."""
    v_meas = validate.select(outputs).values if validate is not None and val_y is not None else None
    out = {}
    for k, o in enumerate(outputs):
        row = {"noise": noise[o].sigma, "train_before": rms(y_meas[:, k] - y0[:, k])}
        if y_ext is not None:
            row["train_after"] = rms(y_meas[:, k] - y_ext[:, k])
        for key, y in zip(("validation_before", "validation_after"), val_y or ()):
            if v_meas is not None and y is not None:
                row[key] = rms(v_meas[:, k] - y[:, k])
        row.update({f"{key}_calibrated": v for key, v in ((calibrated or {}).get(o) or {}).items()})
        out[o] = row
    if len(outputs) > 1:
        from .report import judged_on

        which = judged_on(out)
        cal = all(f"{which}_calibrated" in r for r in out.values())
        log.info("      per output, %s RMS before -> after the laws%s (noise): %s", which,
                 " -> with the calibration" * cal, "; ".join(
                     f"{o} {r[which + '_before']:.3g} -> {r.get(which + '_after', float('nan')):.3g}"
                     + (f" -> {r[which + '_calibrated']:.3g}" if cal else "") + f" ({r['noise']:.3g})"
                     for o, r in out.items()))
    return out


def _say_constant(inputs: list[str], train: TimeSeries) -> None:
    """Warn of inputs the training data hold constant: they show the system at one operating
    point (a constant drive named a sensor's law for a shunt's that never moved)."""
    for name in inputs:
        if name in train.names:
            u = train.select([name]).values[:, 0]
            u = u[np.isfinite(u)]
            if u.size > 1 and np.ptp(u) <= 1e-12 * max(float(np.max(np.abs(u))), 1e-300):
                log.warning("the input %s is constant in the training data (%g): they show the system at one "
                            "operating point, and a law learned from them may not hold at another", name, u[0])


#: the share of the training record's time below which the search's head is said to be short
SHORT_HEAD = 0.05


def _say_head(head: TimeSeries, whole: TimeSeries) -> None:
    """Warn where the search's head spans little of the record's time: a record sampled far
    faster than the system moves (a million samples at 10 kHz: the head saw 0.8 s, before the
    fault ever showed)."""
    span = float(whole.time[-1] - whole.time[0])
    seen = float(head.time[-1] - head.time[0])
    if span > 0 and seen < SHORT_HEAD * span:
        every = int(np.ceil(len(whole.time) / len(head.time)))
        log.warning("the search sees the first %.3g s of the training record's %.3g s; if the data are sampled "
                    "far faster than the system moves, resample them (every %dth sample, say) or raise "
                    "fitting.max_samples", seen, span, every)


def refitted(names: list[str], active) -> list[str]:
    """A law's parameters that are fitted: the active ones but its first (the scale it is held at)."""
    return [n for k, (n, on) in enumerate(zip(names, active)) if on and k > 0]


def _how_sure(report: dict, found: list[dict], base: Base, spec, train, validate, outputs, whole) -> None:
    """Each cause's parameters with standard errors and its curve's band (the laws together, in
    the extended model, on the samples searched, ``train``); with ``free:``, the laws refitted
    with the nominal parameters on the training record ``whole`` (up to CALIBRATION_SPAN times
    the samples searched: the model delivered; a calibration fitted to the head of a long
    record drifts off in the rest, its initial state bent to the head's errors)."""
    from .calibrate import calibrate, uncertainty

    params = base.model.parameters
    laws = [{"names": b["_names"], "active": b["active"], "held": [k == 0 for k in range(len(b["_names"]))],
             "template": b["template"], "w": b["w"], "curve_x": [x for x, _ in c["law"]["curve"]]}
            for b, c in zip(found, report["causes"])]
    uncertainty(base.model, train, params, laws)
    for law, cause in zip(laws, report["causes"]):
        cause["law"]["parameters"] = law.get("parameters", [])
        if law.get("band"):
            cause["law"]["band"] = law["band"]
    if spec.free:
        names = [n for law in laws for n in refitted(law["names"], law["active"])]
        held = [n for law in laws for n in law["names"] if n not in names]
        held += replaced([b["component"] for b in found], base.model, held + names)
        hidden = internal(spec, base.model)
        # each round's calibration of its cause, merged (the tanks' two outlets), then the last
        # cause's alone (it started from the causes before it as found), then the laws as found:
        # the first not far behind the best of them is taken (calibrate._first_good)
        last = found[-1].get("_calibrated_start", {})
        starts = [{k: v for b in found for k, v in b.get("_calibrated_start", {}).items()}, last]
        cal = calibrate(base.model, whole.head(CALIBRATION_SPAN * spec.max_samples), validate, params, names,
                        spec.free, outputs, held + (hidden if spec.free == "auto" else []), judged_on=whole,
                        own_start=spec.max_samples, starts=starts)
        report["calibration"] = {k: v for k, v in cal.items() if k not in ("params", "run")}
        if "params" in cal:          # the model delivered (:func:`modelica.calibrated_class`)
            report["_calibrated"] = {"params": cal["params"], "run": cal["run"], "free": spec.free,
                                     "w": [[cal["params"][n] for n in law["names"]] for law in laws],
                                     "values": {n: cal["params"][n] for n in cal["freed"] if n not in hidden},
                                     "unwritable": [n for n in cal["freed"] if n in hidden]}


def replaced(components, model, laws) -> list[str]:
    """The nominal parameters of the components a law replaced (R1.R beside R1's law): the
    learned class that takes the component's place has none of them, so a calibration does not
    move them (the model delivered could not carry the values); ``laws``: the laws' own names."""
    prefixes = tuple(f"{c}." for c in components)
    return [n for n in getattr(getattr(model, "ode", None), "p_names", ()) if n.startswith(prefixes) and n not in laws]


def internal(spec, model) -> list[str]:
    """The parameters no modifier can set (protected or final in their classes,
    :func:`modelica.internal_parameters`): ``free: auto`` leaves them (a list the user gives
    stands), and the calibrated model is not written with them."""
    from .modelica import internal_parameters

    if getattr(model, "ode", None) is None:
        return []
    return internal_parameters(spec.model_name, model.ode.p_names, spec.libraries, spec.sources)


def overall(noise: dict) -> float:
    """One noise level for all outputs (root mean square of each output's)."""
    return float(np.sqrt(np.mean([n.sigma ** 2 for n in noise.values()])))


#: an output the nominal model misses by more than this many times its noise is weighed as if
#: its noise were this share of that misfit (see :func:`output_weights`)
MISFIT_SHARE = 0.01


def output_weights(noise: dict, y_meas: np.ndarray, outputs: list[str], misfit=None) -> dict | None:
    """Each output's weight in the fits where the outputs' noise levels differ by more than
    :data:`WEIGHED_WHEN` (other units: a pressure in Pa beside a temperature in K): the overall
    noise over the output's own, so that every output's noise weighs as the overall noise does
    (the noise floor and the criteria read it) and a law is fitted to all outputs, not to the
    one with the largest numbers (a fault only a current in A showed, beside a voltage in V,
    was not found: tests/test_mixed_units.py). None where they are alike. A
    noise level is taken as at least 1e-4 of its output's spread (a noiseless output would
    outweigh all others). Where the nominal model's RMS ``misfit`` per output is given and
    misses an output by more than 1 / :data:`MISFIT_SHARE` times its noise (and 1e-6 of its
    spread), the floor is :data:`MISFIT_SHARE` of that misfit where that is lower. (A fine
    encoder beside a noisy force, EMPS in its loop: the position's noise 1.7e-8 m, 1e-4 of its
    spread 8e-6 m, the nominal's misfit 1.6e-5 m, counted 2 noise units against the force's 233,
    and the laws fitted to the force tripled the position's error.)"""
    if len(outputs) < 2:
        return None
    sigma = overall(noise)
    own = []
    for k, o in enumerate(outputs):
        spread = np.nanstd(y_meas[:, k]) if np.isfinite(y_meas[:, k]).any() else 0.0
        floor, least = 1e-4 * spread, max(noise[o].sigma, 1e-6 * spread)
        if misfit is not None and np.isfinite(misfit[k]) and misfit[k] * MISFIT_SHARE > least:
            floor = min(floor, MISFIT_SHARE * misfit[k])
        s = max(noise[o].sigma, floor)
        own.append(s if s > 0 else sigma)
    w = sigma / np.array(own)
    if not np.all(np.isfinite(w)) or w.max() <= WEIGHED_WHEN * w.min():
        return None
    log.info("      the outputs' noise levels differ (%s): each is fitted in units of its noise",
             ", ".join(f"{o} {noise[o].sigma:.3g}" + (f" (taken as {s:.3g})" if s != noise[o].sigma else "")
                       for o, s in zip(outputs, own)))
    return {o: float(v) for o, v in zip(outputs, w)}


def significance(resid, noise: dict, outputs, t, n_params: int = 0):
    """Whether a residual is a misfit or the noise (:func:`mcl.stats.misfit_significance`): too
    large for the noise, or not white."""
    return misfit_significance(resid, [noise[o] for o in outputs], t, n_params=n_params)


def _summarise_rounds(report: dict, rounds: list[dict]) -> None:
    """report.json's candidates, screening and verdict: every round's, in order (the first round
    is the search for the first cause)."""
    report["rounds"] = [{"round": r["round"], "label": r["label"], "no_cause": r["no_cause"], "roles": r["roles"],
                         "pairs": r["pairs"]} for r in rounds]
    report["candidates"] = []
    report["screening"] = []
    for r in rounds:
        ranked = sorted((c for c in r["candidates"] if c.get("score") is not None), key=lambda c: c["score"])
        report["candidates"] += [{**c, "round": r["round"]} for c in ranked]
        report["candidates"] += [{**c, "round": r["round"]} for c in r["candidates"] if c.get("score") is None]
        report["screening"] += [{**s, "round": r["round"]} for s in r["screening"]]
    if rounds:
        # (the search for the first cause on the plant: the chain's round, searched after it,
        # stands before it in the list)
        first = next((r for r in rounds if not r["chain"]), rounds[0])
        report["nominal_score"] = first["nominal_score"]
        report["roles"] = {k: v for r in reversed(rounds) for k, v in r["roles"].items()}   # (the first's first)
        if not report["causes"]:
            report["no_cause"] = first["no_cause"]


def settings(spec) -> dict:
    """The run's settings, as the report shows them."""
    from ..stats import criterion as criterion_of

    return {"model": spec.model_name, "sources": ", ".join(map(str, spec.sources)) or "(library path)",
            "libraries": ", ".join(map(str, spec.libraries)) or "-", "unknown": spec.unknown,
            "laws": "pinned templates" if spec.templates else "law families chosen by each component's role",
            "criterion": criterion_of(spec.criterion).name, "fitting": spec.refinement_method,
            "algorithm": spec.algorithm, "simulations per fit": spec.max_simulations,
            "screened in for fitting": spec.screen, "early stop": spec.early_stop,
            "executor": spec.executor.get("kind", "local"),
            "noise": "estimated from the data" if spec.noise is None else spec.noise,
            "calibration": spec.free or "-", "samples searched": spec.max_samples}


def software_versions() -> dict:
    """Versions of mcl and of what computes its numbers (recorded in report.json)."""
    from ..compile.library import distribution_versions

    return distribution_versions("mcl", "casadi", "fmpy", "numpy", "scipy", "rumoca")
