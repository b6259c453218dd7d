"""What a compiler produces: a model both engines can run.

:class:`CompiledModel` is the in-process form (CasADi functions of the explicit ODE, exact
sensitivities); :class:`FmuModel` wraps an FMU file, from ``mcl compile`` or from another tool.
Both carry the names of inputs, outputs and free parameters, so the rest of the pipeline does not
care which it has.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

from .errors import DataError, MclError
from .compile.structure import Ode, build_ode, expanded, with_start_guesses

_FUNCTIONS = ("ode", "out", "alg_res", "drift", "init", "probe", "checks", "zero", "start", "init_start",
              "update", "init_discrete", "asserts",   # these three: a hybrid model's
              "loops", "given", "solved")              # a model with algebraic loops


@dataclass
class CompiledModel:
    """A model compiled to CasADi functions (see :class:`mcl.compile.structure.Ode`)."""

    name: str
    ode: Ode
    info: dict = field(default_factory=dict)
    #: the DAE as compiled, before alias elimination (candidate laws are put into it) and the
    #: component structure (:class:`mcl.compile.components.Structure`); None for a model loaded
    #: from a file saved without them
    dae: object = None
    structure: object = None

    @classmethod
    def from_dae(cls, dae, name: str, outputs=(), info: dict | None = None, structure=None) -> "CompiledModel":
        """``dae`` compiled (alias elimination, index reduction, causalisation), with ``outputs``
        (any variables of the model) appended to its outputs."""
        from .compile.dae import eliminate_aliases

        ode = build_ode(eliminate_aliases(dae), name)
        return cls(name, ode, dict(info or {}), dae, structure).with_outputs(outputs)

    @property
    def input_names(self) -> list[str]:
        return self.ode.u_names

    @property
    def output_names(self) -> list[str]:
        return self.ode.y_names

    @property
    def parameters(self) -> dict[str, float]:
        return dict(zip(self.ode.p_names, map(float, self.ode.p_values)))

    def _named_parameters(self) -> list[tuple[str, float]]:
        """(name, value) of the parameters a user sets: not the compiler's own ($homotopy)."""
        return [(n, v) for n, v in zip(self.ode.p_names, self.ode.p_values) if not n.startswith("$")]

    @property
    def initial_parameters(self) -> list[str]:
        """The free parameters that only the initial equations read (an initial position, a
        tank's start level): no equation of the run and no output depends on them."""
        o, n = self.ode, len(self.ode.p_names)
        cols = lambda f, k: {c for c in f.sparsity_jac(k, 0).get_col() if c < n}
        try:
            read = set().union(*(cols(getattr(o, f), 2) for f in ("ode", "out", "zero", "update", "asserts", "loops")
                                 if getattr(o, f, None) is not None))
            init = cols(o.init, 1)
        except RuntimeError:      # a function CasADi cannot give the sparsity of: claim none
            return []
        return [o.p_names[k] for k in sorted(init - read)]

    def __repr__(self) -> str:
        o = self.ode
        return (f"CompiledModel({self.name!r}: {len(o.x_names)} states, {len(o.u_names)} inputs, "
                f"{len(o.y_names)} outputs, {len(self._named_parameters())} free parameters)")

    def _repr_html_(self) -> str:
        """A table in notebooks: the model's inputs, outputs, states and parameters with units."""
        import html

        o, units = self.ode, self.info.get("units", {})
        rows = [("input", n, "") for n in o.u_names] + [("output", n, "") for n in o.y_names]
        rows += [("state", n, "") for n in o.x_names]
        rows += [("parameter", n, f"{v:g}") for n, v in self._named_parameters()]
        body = "".join(f"<tr><td>{k}</td><td>{html.escape(n)}</td><td>{html.escape(units.get(n, ''))}</td>"
                       f"<td>{v}</td></tr>" for k, n, v in rows[:200])
        more = f"<p>... and {len(rows) - 200} more</p>" if len(rows) > 200 else ""
        return (f"<div><b>{html.escape(self.name)}</b> (index {o.index}, {o.nonlinear_blocks} algebraic loop(s))"
                f"<table><tr><th>kind</th><th>name</th><th>unit</th><th>value</th></tr>{body}</table>{more}</div>")

    def parameter_vector(self, overrides: dict | None = None) -> np.ndarray:
        """Nominal parameter values with ``overrides`` (by name) applied."""
        p = self.ode.p_values.astype(float).copy()
        for k, v in (overrides or {}).items():
            if k not in self.ode.p_names:
                raise MclError(f"model {self.name} has no free parameter '{k}' (free parameters: "
                               f"{', '.join(n for n, _ in self._named_parameters())})")
            p[self.ode.p_names.index(k)] = float(v)
        return p

    @property
    def variable_names(self) -> list[str]:
        """Every variable a simulation can record (states, algebraic variables, parameters)."""
        return list(self.ode.probe_names)

    def with_outputs(self, names, only: bool = False) -> "CompiledModel":
        """The same model with the named variables (any of ``ode.probe_names``: ``M.v``,
        ``C2.T``) appended to its outputs, so data may measure any variable, declared output
        or not; ``only``: those variables its outputs instead. Names already outputs (kept
        where ``only``), or not variables of the model, are left out."""
        o = self.ode
        kept = [n for n in dict.fromkeys(names) if n in o.y_names] if only else list(o.y_names)
        extra = [n for n in dict.fromkeys(names) if n not in o.y_names and n not in o.u_names
                 and n in o.probe_names]
        if not extra and kept == o.y_names:
            return self
        return CompiledModel(self.name, _recording(o, kept, extra), self.info, self.dae, self.structure)

    def save(self, directory, force: bool = False) -> Path:
        """Write the functions (CasADi serialisation) and names to ``directory``: a new one, or
        with ``force`` one mcl saved before (never a folder of the user's: :mod:`mcl.outputs`)."""
        from .outputs import new_directory

        with new_directory(directory, force, what="a saved model") as d:
            self._write(d)
        return Path(directory)

    def _write(self, d: Path) -> Path:
        """The files of a saved model, into the new directory ``d``."""
        o = self.ode.warm or self.ode        # (with its loops' guesses an argument: see Ode.warm)
        # in one file: the functions they share (a loop's solve, called by ode, out and checks)
        # are written once and read back shared. Saved one by one, each read back with copies of
        # its own, and an FMU's C held every copy (HeatingSystem's 20 MB, 2 compiled fresh)
        present = [f for f in _FUNCTIONS if getattr(o, f) is not None]     # zero: only a model with state events
        packer = ca.FileSerializer(str(d / "functions.casadi"))
        try:
            packer.pack([getattr(o, f) for f in present])
        finally:
            del packer       # (its destructor closes the file)
        meta = dict(name=self.name, info=self.info, x_names=o.x_names, u_names=o.u_names,
                    p_names=o.p_names, y_names=o.y_names, p_values=o.p_values.tolist(),
                    u_start=o.u_start.tolist(), probe_names=o.probe_names, index=o.index,
                    nonlinear_blocks=o.nonlinear_blocks, time_events=list(o.time_events),
                    discrete=o.discrete, events=o.events,
                    guess0=None if o.guess0 is None else o.guess0.tolist(), functions=present)
        (d / "model.json").write_text(json.dumps(meta, indent=1))
        if self.dae is not None:
            from .compile.saved import save_dae

            save_dae(self.dae, d)
        if self.structure is not None:
            (d / "structure.json").write_text(json.dumps(self.structure.to_dict()))
        return d

    @classmethod
    def load(cls, directory) -> "CompiledModel":
        d = Path(directory)
        meta = json.loads((d / "model.json").read_text())
        if "functions" in meta:
            packed = ca.FileDeserializer(str(d / "functions.casadi")).unpack()
            if len(packed) != len(meta["functions"]):
                raise ValueError(f"{d}: {len(packed)} functions saved for {len(meta['functions'])} names")
            funcs = {f: _fresh(g) for f, g in zip(meta["functions"], packed)}
        else:        # (saved one by one, by earlier versions)
            funcs = {f: _fresh(ca.Function.load(str(d / f"{f}.casadi"))) for f in _FUNCTIONS
                     if (d / f"{f}.casadi").is_file()}
        if "checks" not in funcs:      # saved by mcl 0.1: compose it
            from .compile.structure import composed_checks

            funcs["checks"] = composed_checks(funcs["out"], funcs["alg_res"], funcs["drift"])
        ode = Ode(x_names=meta["x_names"], u_names=meta["u_names"], p_names=meta["p_names"],
                  y_names=meta["y_names"], p_values=np.array(meta["p_values"]),
                  u_start=np.array(meta["u_start"]), probe_names=meta["probe_names"],
                  index=meta["index"], nonlinear_blocks=meta["nonlinear_blocks"],
                  time_events=tuple(meta.get("time_events", ())), discrete=meta.get("discrete", 0),
                  events=meta.get("events"), **funcs,
                  guess0=None if meta.get("guess0") is None else np.array(meta["guess0"]))
        ode = with_start_guesses(ode)
        from .compile.components import Structure
        from .compile.saved import load_dae

        structure = (Structure.from_dict(json.loads((d / "structure.json").read_text()))
                     if (d / "structure.json").is_file() else None)
        return cls(meta["name"], ode, meta.get("info", {}), load_dae(d), structure)


def _fresh(f: ca.Function) -> ca.Function:
    """A loaded SX function rebuilt on new symbols: CasADi 3.8 cannot differentiate the one it
    deserialises ("the input expressions are not independent"), which the integrator must."""
    if not f.is_a("SXFunction"):
        return f
    args = f.sx_in()
    return ca.Function(f.name(), args, f.call(args), f.name_in(), f.name_out())


def _recording(o: Ode, kept: list[str], extra: list[str]) -> Ode:
    """``o`` with outputs ``kept`` (of its own) then ``extra`` (of its probe variables); its
    twin with the loops' guesses an argument (``warm``, which the engine runs) alike."""
    import dataclasses

    idx = [o.probe_names.index(n) for n in extra]
    own = [o.y_names.index(n) for n in kept]
    args = o.out.mx_in()
    pick = lambda v, rows: v[rows] if rows else ca.MX(0, 1)     # noqa: E731 - (v[[]] is 1x0: no vertcat)
    probe = pick(o.probe(*args), idx)
    y = ca.vertcat(pick(o.out(*args), own), probe)
    y_c, res, drift = o.checks(*args)
    io = (["x", "u", "p", "t"],)
    out = expanded(ca.Function("out", args, [y], *io, ["out"]))
    checks = expanded(ca.Function("checks", args, [ca.vertcat(pick(y_c, own), probe), res, drift],
                                  *io, ["y", "res", "drift"]))
    warm = _recording(o.warm, kept, extra) if o.warm is not None else None
    return dataclasses.replace(o, y_names=[*kept, *extra], out=out, checks=checks, warm=warm)


@dataclass
class FmuModel:
    """An FMI 2.0/3.0 Model Exchange or Co-Simulation FMU, read with FMPy."""

    path: Path
    name: str
    input_names: list[str]
    output_names: list[str]
    parameters: dict[str, float]
    fmi_version: str
    variable_names: list[str] = field(default_factory=list)    # every Real a run can record

    @classmethod
    def read(cls, path) -> "FmuModel":
        from fmpy import read_model_description

        path = Path(path)
        if not path.is_file():
            raise DataError("no such FMU", where=str(path))
        from .compile.fmu.archive import check_archive

        check_archive(path)
        try:
            md = read_model_description(str(path), validate=False)
        except Exception as exc:
            raise DataError(f"not a readable FMU: {exc}", where=str(path)) from None
        real = [v for v in md.modelVariables if v.type == "Real" or v.type.startswith("Float")]
        params = {v.name: float(v.start) for v in real
                  if v.causality == "parameter" and v.start is not None}
        return cls(path=path, name=md.modelName,
                   input_names=[v.name for v in real if v.causality == "input"],
                   output_names=[v.name for v in real if v.causality == "output"],
                   parameters=params, fmi_version=md.fmiVersion,
                   variable_names=[v.name for v in real if v.causality != "input"])

    def with_outputs(self, names, only: bool = False) -> "FmuModel":
        """The FMU recording the named variables too (``only``: those alone), as
        :meth:`CompiledModel.with_outputs`."""
        import dataclasses

        chosen = [n for n in dict.fromkeys(names) if n in self.variable_names]
        kept = [n for n in chosen if n in self.output_names] if only else list(self.output_names)
        return dataclasses.replace(self, output_names=[*kept, *(n for n in chosen if n not in kept)])

    def parameter_vector(self, overrides: dict | None = None) -> dict[str, float]:
        p = dict(self.parameters)
        for k, v in (overrides or {}).items():
            if k not in p:
                raise MclError(f"FMU {self.path.name} has no parameter '{k}'")
            p[k] = float(v)
        return p
