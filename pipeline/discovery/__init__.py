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
from ..runfile import RunSpec
from .families import family_of

__all__ = ["Discovery"]


class Discovery:
    """Find the component of ``model`` that the data contradict and learn its law.

    Parameters mirror the run file: ``model`` (class name), ``sources`` (.mo files or package
    directories; may be empty for a class on the library path), ``unknown`` ("auto" or a
    component name), ``templates``, ``libraries``, ``max_simulations``, ``screen``, ``early_stop``,
    ``criterion`` ("bic"/"aic"), ``refinement`` ("simulation"/"full-discretisation"),
    ``executor`` (a kind or ``{kind: ..., options}``), ``second`` (another configuration),
    ``output`` (run directory; a temporary one by default), ``force``, ``verbose``.

    After :meth:`fit`: ``misfit_``, ``cause_`` (None when no cause convinces), ``law_``,
    ``gain_``, ``candidates_``, ``report_`` (all of report.json) and ``run_dir_``.
    """

    def __init__(self, model: str, sources=(), unknown: str = "auto", templates=None, libraries=(),
                 max_simulations: int = 60, screen: int = 3, criterion: str = "bic",
                 refinement: str = "simulation", executor="local", second: dict | None = None,
                 report: dict | None = None, output=None, force: bool = False, verbose: bool = True,
                 early_stop: bool = True):
        self.model, self.sources, self.unknown = model, sources, unknown
        self.early_stop = early_stop
        self.templates, self.libraries = templates, libraries
        self.max_simulations, self.screen, self.criterion = max_simulations, screen, criterion
        self.refinement, self.executor, self.second = refinement, executor, second
        self.report_options, self.output, self.force, self.verbose = report, output, force, verbose
        self._spec: RunSpec | None = None

    @classmethod
    def from_spec(cls, spec: RunSpec, force: bool = False, verbose: bool = True) -> "Discovery":
        self = cls(spec.model_name, spec.sources, spec.unknown, spec.templates, spec.libraries,
                   spec.max_simulations, spec.screen, spec.criterion, spec.refinement_method,
                   spec.executor, spec.second, spec.report, spec.output, force, verbose, spec.early_stop)
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
                       criterion=self.criterion,
                       refinement_method=self.refinement, executor=executor, second=self.second,
                       report=dict(self.report_options or {}), libraries=as_paths(self.libraries))

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
        from ..api import registry
        from ..runfile import CRITERIA

        reg = registry()
        if spec.criterion not in CRITERIA:
            raise ConfigError(f"criterion '{spec.criterion}': choose one of {', '.join(CRITERIA)}")
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
                         "output": self.output, "early_stop": self.early_stop})

    def __getattr__(self, name: str):
        # called only for attributes never set: the results (ending in _) before fit
        if name.endswith("_") and not name.startswith("_"):
            raise NotFittedError(f"{name} is not set: this Discovery is not fitted yet; call fit(train) first")
        raise AttributeError(f"'{type(self).__name__}' object has no attribute '{name}'")

    def _set_results(self, report: dict, run_dir: Path) -> None:
        self.report_, self.run_dir_ = report, Path(run_dir)
        self.misfit_, self.cause_, self.gain_ = report["misfit"], report["cause"], report["gain"]
        self.causes_ = report.get("causes") or ([report["cause"]] if report.get("cause") else [])
        self.law_ = (report["cause"] or {}).get("law")
        self.candidates_ = report["candidates"]

    def _fitted(self) -> None:
        if not hasattr(self, "report_"):
            raise NotFittedError("this Discovery is not fitted yet: call fit(train) first")

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
            lines.append(f"gain: training RMS {g['train_rms_before']:.4g} -> {g['train_rms_after']:.4g}{val}")
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
        comps = sorted({s["component"] for s in screening})
        lines = [f"tried: {len(screening)} law(s) on {len(comps)} component(s): " + "; ".join(
            f"{c} ({', '.join(family_of(s['template']) for s in screening if s['component'] == c)})" for c in comps)]
        ranked = [c for c in self.report_.get("candidates", []) if c.get("score") is not None]
        crit = (self.cause_ or {}).get("evidence", {}).get("criterion", "").upper() or "score"
        if ranked:
            lines.append("ranking: " + "; ".join(
                f"{c['component']} {c.get('family', '')} {crit} {c['score']:.1f}" for c in ranked[:4])
                + (f"; nominal {self.report_['nominal_score']:.1f}" if "nominal_score" in self.report_ else ""))
        return lines

    def __str__(self) -> str:
        return "\n".join(self.summary())

    def __repr__(self) -> str:
        state = "fitted" if hasattr(self, "report_") else "not fitted"
        return f"Discovery(model={self.model!r}, unknown={self.unknown!r}) [{state}]"

    def _repr_html_(self) -> str:
        items = "".join(f"<li>{html.escape(line)}</li>" for line in self.summary())
        return f"<div><b>Discovery of {html.escape(self.model)}</b><ul>{items}</ul></div>"
