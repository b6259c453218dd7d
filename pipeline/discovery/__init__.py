"""Discovery: what a model gets wrong, which component, which law, what gain.

:class:`Discovery` is the public face, in the scikit-learn manner: options in the constructor,
``fit(train, validate)`` on data, results in attributes ending in ``_``. ``mcl run run.yaml``
builds the same object from the run file (:meth:`Discovery.from_runfile`), so both routes run
one implementation (:func:`mcl.discovery.run.run_discovery`).
"""
from __future__ import annotations

import html
import shutil
import tempfile
from pathlib import Path

from ..data import as_timeseries
from ..errors import ConfigError, NotFittedError
from ..progress import console
from ..runfile import MAX_SAMPLES, RunSpec
from .families import family_of
from .law import LearnedLaw

__all__ = ["Discovery"]


class Discovery:
    """Find the component of ``model`` that the data contradict and learn its law.

    Parameters mirror the run file: ``model`` (class name), ``sources`` (.mo files or package
    directories; may be empty for a class on the library path), ``unknown`` ("auto" or a
    component name), ``templates``, ``libraries``, ``max_simulations``, ``screen``, ``early_stop``,
    ``max_samples``, ``criterion`` ("bic"/"aic"), ``refinement`` ("simulation"/"full-discretisation"),
    ``executor`` (a kind or ``{kind: ..., options}``), ``second`` (another configuration),
    ``output`` (run directory; a temporary one by default), ``force``, ``verbose``.

    After :meth:`fit`: ``misfit_``, ``cause_`` (None when no cause convinces), ``law_``,
    ``gain_``, ``candidates_``, ``report_`` (all of report.json) and ``run_dir_``.
    """

    def __init__(self, model: str, sources=(), unknown: str = "auto", templates=None, libraries=(),
                 max_simulations: int = 60, screen: int = 3, criterion: str = "bic",
                 refinement: str = "simulation", executor="local", second: dict | None = None,
                 report: dict | None = None, output=None, force: bool = False, verbose: bool = True,
                 early_stop: bool = True, algorithm: str = "levenberg-marquardt", noise=None, free=None,
                 max_samples: int = MAX_SAMPLES):
        self.max_samples = max_samples
        self.model, self.sources, self.unknown = model, sources, unknown
        self.early_stop, self.algorithm, self.noise, self.free = early_stop, algorithm, noise, free
        self.templates, self.libraries = templates, libraries
        self.max_simulations, self.screen, self.criterion = max_simulations, screen, criterion
        self.refinement, self.executor, self.second = refinement, executor, second
        self.report_options, self.output, self.force, self.verbose = report, output, force, verbose
        self._spec: RunSpec | None = None

    @classmethod
    def from_spec(cls, spec: RunSpec, force: bool = False, verbose: bool = True) -> "Discovery":
        self = cls(spec.model_name, spec.sources, spec.unknown, spec.templates, spec.libraries,
                   spec.max_simulations, spec.screen, spec.criterion, spec.refinement_method,
                   spec.executor, spec.second, spec.report, spec.output, force, verbose, spec.early_stop,
                   spec.algorithm, spec.noise, spec.free, spec.max_samples)
        self._spec = spec
        return self

    @classmethod
    def from_runfile(cls, path, force: bool = False, verbose: bool = True) -> "Discovery":
        """The discovery a run file describes (checked completely first: schema, files, data)."""
        from ..runfile import load_runfile

        return cls.from_spec(load_runfile(path), force, verbose)

    def spec(self) -> RunSpec:
        """The run as a :class:`RunSpec` (what the run file would say)."""
        if self._spec is not None:
            return self._spec
        as_paths = (lambda xs: [Path(x) for x in ([xs] if isinstance(xs, (str, Path)) else xs or ())])
        executor = {"kind": self.executor} if isinstance(self.executor, str) else dict(self.executor)
        output = Path(self.output) if self.output else Path(tempfile.mkdtemp(prefix="mcl-run-")) / "run"
        return RunSpec(path=None, sources=as_paths(self.sources), model_name=self.model, train=None,
                       validate=None, unknown=self.unknown, output=output,
                       templates=([self.templates] if isinstance(self.templates, (str, dict)) else
                                  list(self.templates)) if self.templates else None,
                       max_simulations=self.max_simulations, screen=self.screen, early_stop=self.early_stop,
                       max_samples=self.max_samples, criterion=self.criterion,
                       refinement_method=self.refinement, executor=executor, second=self.second,
                       report=dict(self.report_options or {}), libraries=as_paths(self.libraries),
                       algorithm=self.algorithm, noise=self.noise, free=self.free)

    def fit(self, train, validate=None, time: str | None = None) -> "Discovery":
        """Run the discovery on ``train`` (and held-out ``validate``) data: a pandas DataFrame,
        a NumPy structured array, a mapping of columns, a :class:`mcl.data.TimeSeries` or a CSV.
        Time is the ``time`` column (or a DataFrame index named time); ``time="t"`` names
        another column, ``time="index"`` takes the index. Mistakes are refused as the run
        file's are, with the same messages."""
        from .run import run_discovery
        from ..runfile import check_series

        if self._spec is None:
            self._check_arguments()
        spec = self.spec()
        self._check(spec)
        train_ts = as_timeseries(train, "train", time=time)
        validate_ts = None if validate is None else as_timeseries(validate, "validate", time=time)
        if spec.path is None:       # a run file's data were checked against the model already
            check_series(spec, train_ts, validate_ts)
        fingerprint = spec.fingerprint() if spec.path else {
            "train": train_ts.fingerprint(), **({"validate": validate_ts.fingerprint()} if validate_ts else {})}
        with console(self.verbose):
            report = run_discovery(spec, train_ts, validate_ts, force=self.force, fingerprint=fingerprint)
        self._set_results(report, spec.output)
        return self

    def _check(self, spec: RunSpec) -> None:
        """The options an API user gives, checked like a run file's (kinds, templates)."""
        from ..services import registry

        reg = registry()
        reg.criterion(spec.criterion)
        reg.fitter(spec.refinement_method)
        reg.executor_class(spec.executor)
        for t in spec.templates or []:
            reg.template(t)

    def _check_arguments(self) -> None:
        from ..runfile import check_arguments

        check_arguments({"model": self.model, "sources": self.sources, "unknown": self.unknown,
                         "templates": self.templates, "libraries": self.libraries,
                         "max_simulations": self.max_simulations, "screen": self.screen,
                         "criterion": self.criterion, "refinement": self.refinement,
                         "executor": self.executor, "second": self.second, "report": self.report_options,
                         "output": self.output, "early_stop": self.early_stop, "algorithm": self.algorithm,
                         "noise": self.noise, "free": self.free, "max_samples": self.max_samples})

    def __getattr__(self, name: str):
        # called only for attributes never set: the results (ending in _) before fit
        if name.endswith("_") and not name.startswith("_"):
            raise NotFittedError(f"{name} is not set: this Discovery is not fitted yet; call fit(train) first")
        raise AttributeError(f"'{type(self).__name__}' object has no attribute '{name}'")

    def _set_results(self, report: dict, run_dir: Path) -> None:
        self.report_, self.run_dir_ = report, Path(run_dir)
        self.misfit_, self.cause_, self.gain_ = report["misfit"], report["cause"], report["gain"]
        self.causes_ = report.get("causes") or ([report["cause"]] if report.get("cause") else [])
        self.laws_ = [LearnedLaw(c) for c in self.causes_]
        self.law_ = self.laws_[0] if self.laws_ else None
        self.candidates_ = report["candidates"]
        self.model_ = report.get("_model")       # the extended model, compiled (None when read back)
        # with ``free:``, the values it is delivered with (read back, the delivered class has them;
        # where the calibrated class did not compile, the laws alone are delivered)
        from .modelica import calibrated_name

        delivered = (report.get("extended") or {}).get("model")
        self._delivered_params = ((report.get("_calibrated") or {}).get("params")
                                  if delivered == calibrated_name(self.model) else None)

    def _fitted(self) -> None:
        if not hasattr(self, "report_"):
            raise NotFittedError("this Discovery is not fitted yet: call fit(train) first")

    # -- the estimator's methods: parameters, prediction, score ----------------------------------
    def get_params(self, deep: bool = True) -> dict:
        """The constructor's options (scikit-learn's convention)."""
        import inspect

        return {k: getattr(self, "report_options" if k == "report" else k)
                for k in inspect.signature(type(self).__init__).parameters if k != "self"}

    def set_params(self, **params) -> "Discovery":
        """Change constructor options (a fitted result stays until the next fit)."""
        known = self.get_params()
        for k, v in params.items():
            if k not in known:
                from ..errors import did_you_mean

                raise ConfigError(f"Discovery has no option '{k}'{did_you_mean(k, known)}")
            setattr(self, "report_options" if k == "report" else k, v)
        self._spec = None
        return self

    def extended_model(self):
        """The model with the learned laws in place (the compiled one of this run, or the
        written Modelica compiled again)."""
        self._fitted()
        if self.model_ is None:
            from ..services import compile_model

            ext = self.report_.get("extended") or {}
            if not ext.get("model"):
                return None
            self.model_ = compile_model([self.run_dir_ / s for s in ext.get("sources", [])], ext["model"],
                                        libraries=self.spec().libraries)
        return self.model_

    def predict(self, inputs, time: str | None = None, model: str = "extended"):
        """The outputs of the extended model as delivered (with ``free:``, calibrated;
        ``model="nominal"``: the model as given) on new
        ``inputs`` (a DataFrame, structured array, mapping, TimeSeries or CSV, with a time
        column): a DataFrame indexed by time."""
        from ..services import compile_model, simulate

        self._fitted()
        data = as_timeseries(inputs, "inputs", time=time)
        m = self.extended_model() if model == "extended" else compile_model(
            self.spec().sources, self.model, libraries=self.spec().libraries)
        if m is None:          # nothing was learned: the model as given
            m = compile_model(self.spec().sources, self.model, libraries=self.spec().libraries)
        res = simulate(m, data, self._delivered_params if m is self.report_.get("_model") else None)
        if not res.ok:
            raise ConfigError(f"the {model} model does not simulate these inputs: {res.reason}")
        return res.to_frame()

    def score(self, data, time: str | None = None) -> float:
        """R^2 of the extended model's outputs on ``data`` (measured outputs against the
        simulation; 1 is perfect, scikit-learn's convention)."""
        import numpy as np

        self._fitted()
        ts = as_timeseries(data, "data", time=time)
        pred = self.predict(ts)
        outs = [c for c in pred.columns if c in ts.names]
        y = ts.select(outs).values
        f = pred[outs].to_numpy()
        ok = np.isfinite(y)
        ss_res = float(np.sum((y[ok] - f[ok]) ** 2))
        ss_tot = float(np.sum((y[ok] - np.nanmean(np.where(ok, y, np.nan), axis=0)[np.nonzero(ok)[1]]) ** 2))
        return 1.0 - ss_res / ss_tot if ss_tot > 0 else float("nan")

    def export(self, directory, name: str = "MCLLearned") -> Path:
        """The learned component as a Modelica library ``directory/name`` (and its FMU)."""
        from .export import export_library

        self._fitted()
        return export_library(self.run_dir_, directory, name)

    def report(self, directory) -> Path:
        """report.html and report.json copied into ``directory``; returns the HTML file."""
        self._fitted()
        out = Path(directory)
        out.mkdir(parents=True, exist_ok=True)
        for f in ("report.html", "report.json"):
            if (self.run_dir_ / f).is_file():
                shutil.copyfile(self.run_dir_ / f, out / f)
        return out / "report.html"

    def summary(self) -> list[str]:
        """The result in words, a line each."""
        if not hasattr(self, "report_"):
            return [f"Discovery of {self.model} (not fitted)"]
        m, cause, g = self.misfit_, self.cause_, self.gain_
        lines = [f"misfit: {'significant' if m['significant'] else 'not significant'} "
                 f"(training RMS {m['train_rms']:.4g}, noise {m['noise_estimate']:.4g})"]
        if cause:
            val = ("" if g["validation_rms_before"] is None else
                   f"; validation RMS {g['validation_rms_before']:.4g} -> {g['validation_rms_after']:.4g}")
            causes = self.report_.get("causes") or [cause]
            for k, c in enumerate(causes):
                label = "cause" if len(causes) == 1 else f"cause {k + 1}"
                lines.append(f"{label}: {c['effect']} [{c['evidence']['strength']}]")
            calibrated = g.get("train_rms_calibrated") is not None
            lines.append(f"gain: training RMS {g['train_rms_before']:.4g} -> {g['train_rms_after']:.4g}{val}"
                         + (" (the law alone)" if calibrated else ""))
            if calibrated:
                freed = ", ".join((self.report_.get("calibration") or {}).get("freed") or []) or "initial states"
                cal = ("" if g.get("validation_rms_calibrated") is None else
                       f"; validation RMS {g['validation_rms_calibrated']:.4g}")
                lines.append(f"gain with the calibration ({freed} refitted with the law): "
                             f"training RMS {g['train_rms_calibrated']:.4g}{cal}")
        else:
            lines.append("cause: none (the model explains the data to the noise level)"
                         if not m["significant"] else
                         f"cause: no convincing cause ({self.report_.get('no_cause', 'no candidate explains the data')})")
        lines += self._tried()
        failed = self.report_.get("failed") or []
        if failed:
            lines.append(f"warning: {len(failed)} candidate(s) could not be evaluated: " + "; ".join(
                f"{f['component']} ({f['stage']}: {f['reason']})"[:160] for f in failed))
        return lines

    def _tried(self) -> list[str]:
        """What was tried (components x law families) and the runners-up with their scores."""
        screening = self.report_.get("screening") or []
        if not screening:
            return []
        # the laws screened, and those fitted without a screening (the shape stage's)
        screened = {(s["component"], repr(s["template"])) for s in screening}
        neural = {"reference": "neural"}       # (the shape stage's tanh network)
        cands = self.report_.get("candidates", [])
        tried = [(s["component"], family_of(s["template"])) for s in screening] + [
            (c["component"], neural.get(c.get("family"), c.get("family") or family_of(c["template"])))
            for c in cands
            if "parts" not in c and "template" in c and (c["component"], repr(c["template"])) not in screened]
        comps = sorted({c for c, _ in tried})

        def families(comp):
            counts = {}
            for c, f in tried:
                if c == comp:
                    counts[f] = counts.get(f, 0) + 1
            return ", ".join(f if n == 1 else f"{f} x{n}" for f, n in counts.items())
        lines = [f"tried: {len(tried)} law(s) on {len(comps)} component(s): "
                 + "; ".join(f"{c} ({families(c)})" for c in comps)]
        ranked = [c for c in cands if c.get("score") is not None]
        crit = (self.cause_ or {}).get("evidence", {}).get("criterion", "").upper() or "score"
        if ranked:
            lines.append("ranking: " + "; ".join(
                f"{c['component']} {neural.get(c.get('family'), c.get('family', ''))} {crit} {c['score']:.1f}"
                for c in ranked[:4])
                + (f"; nominal {self.report_['nominal_score']:.1f}" if "nominal_score" in self.report_ else ""))
        return lines

    def __str__(self) -> str:
        return "\n".join(self.summary())

    def __repr__(self) -> str:
        state = "fitted" if hasattr(self, "report_") else "not fitted"
        return f"Discovery(model={self.model!r}, unknown={self.unknown!r}) [{state}]"

    def _repr_html_(self) -> str:
        """A table in notebooks: misfit, each cause with its law and evidence, the gain."""
        head = f"<b>Discovery of {html.escape(self.model)}</b>"
        if not hasattr(self, "report_"):
            return f"<div>{head} (not fitted)</div>"
        m, g = self.misfit_, self.gain_
        rows = [("misfit", m.get("significance") or ("significant" if m["significant"] else "not significant"))]
        for k, c in enumerate(self.causes_):
            rows.append((f"cause {k + 1}" if len(self.causes_) > 1 else "cause",
                         f"{c['component']} ({c.get('class', '')}): {c['law']['equation']} "
                         f"[{c['evidence']['strength']}]"))
            for e in c.get("equivalents", []):
                rows.append(("equivalent", f"{e['component']}: {e['reason']}"))
            for a in c.get("alternatives", []):
                rows.append(("as good a law", f"{a['equation']} ({a['score_difference']:+.2g})"))
        if not self.causes_:
            rows.append(("cause", self.report_.get("no_cause", "none")))
        rows.append(("training RMS", f"{g['train_rms_before']:.4g} → {g['train_rms_after']:.4g}"))
        if g.get("validation_rms_before") is not None:
            rows.append(("validation RMS", f"{g['validation_rms_before']:.4g} → {g['validation_rms_after']:.4g}"))
        body = "".join(f"<tr><th style='text-align:left'>{html.escape(a)}</th><td style='text-align:left'>"
                       f"{html.escape(str(b))}</td></tr>" for a, b in rows)
        return f"<div>{head}<table>{body}</table></div>"
