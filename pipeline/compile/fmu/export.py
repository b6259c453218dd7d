"""Compiled model -> FMI 2.0 FMU (Model Exchange and Co-Simulation) that ``fmpy validate`` accepts.

CasADi generates C for the model's functions, and for Co-Simulation the Jacobian of the ODE
with its time derivative along the inputs; a hand-written FMI 2 wrapper (``fmi2_model.c``) calls
them with work arrays sized from ``*_work`` (fixed sizes segfault: ../shared/DESIGN.md, section
5) and integrates Co-Simulation steps with an embedded stiff solver (RODAS4) that takes the
inputs as continuous signals. Importers that can do both get Co-Simulation by default (FMPy
does), which is the accurate choice at coarse communication intervals: Model Exchange importers
hold the inputs between their communication points. The FMU carries its sources, so other
platforms can rebuild it.

Hybrid models (when, pre, edge, change, sample, reinit, discrete variables, assert) keep their
events: the wrapper iterates the model's discrete update at clock ticks (announced to Model
Exchange importers as the next event time), time events and state events (the event
indicators), as mcl's own engine does. The discrete variables are exported as local variables
of variability "discrete"; Boolean and Integer ones are Real-valued there (0/1 and whole numbers),
as the compiled model holds them. Outputs that change only at events are "discrete" too.
"""
from __future__ import annotations

import hashlib
import os
import re
import shutil
import subprocess
import tempfile
import time
import uuid
import zipfile
from pathlib import Path
from xml.sax.saxutils import quoteattr

import casadi as ca
import numpy as np

from .. import cache as compile_cache
from .. import parametric, structure
from ...errors import CompileError, ConfigError, ModelicaError
from ...model import CompiledModel
from .experiment import Experiment, for_model

_HERE = Path(__file__).parent
FUNCTIONS = ("ode", "out", "alg_res", "init", "start", "probe", "zero", "step", "update", "asserts", "derived")
#: the argument of each function that holds the parameters (the others: (x, u, p, t, ...))
P_ARG = {"init": 1, "start": 0}


def model_identifier(name: str) -> str:
    ident = re.sub(r"\W", "_", name)
    return ident if re.match(r"[A-Za-z_]", ident) else f"m_{ident}"


def _fmi_headers() -> Path:
    import fmpy

    return Path(fmpy.__file__).parent / "c-code"


def _renamed(f: ca.Function, name: str) -> ca.Function:
    """``f`` under another C symbol name (one FMU's symbols never clash with another's)."""
    sym = f.sx_in() if f.is_a("SXFunction") else f.mx_in()
    return ca.Function(name, sym, f.call(sym), f.name_in(), f.name_out())


def _fmt(values) -> str:
    return ", ".join(repr(float(v)) for v in values) or "0.0"


def _probe_variables(model: CompiledModel):
    """(index in probe output, name) of named variables not already exposed otherwise."""
    o = model.ode
    taken = set(o.p_names) | set(o.u_names) | set(o.y_names) | set(o.x_names)
    return [(i, n) for i, n in enumerate(o.probe_names) if n not in taken]


def start_functions(model: CompiledModel) -> tuple[ca.Function, ca.Function]:
    """(p -> the states' start values s, (u, p, t, s) -> x0). A model saved before start values
    were an argument of its initialiser gets an initialiser that ignores them (none settable)."""
    o = model.ode
    if o.start is not None and o.init_start is not None:
        return o.start, o.init_start
    U, P, T = o.init.mx_in()
    S = ca.MX.sym("s", len(o.x_names))
    return (ca.Function("start", [P], [ca.MX.zeros(len(o.x_names))], ["p"], ["s"]),
            ca.Function("init_start", [U, P, T, S], [o.init(U, P, T)], ["u", "p", "t", "s"], ["x0"]))


def settable_starts(model: CompiledModel) -> tuple[list[bool], np.ndarray]:
    """Which states start at their start value (a pinned initial condition, not a guess or a
    value fixed by constraints), and the nominal start values: x0_i = s_i exactly, so the row
    of dx0/ds is the unit vector."""
    o = model.ode
    start, init_start = start_functions(model)
    s0 = np.array(start(o.p_values), dtype=float).ravel()
    if not len(o.x_names):
        return [], s0
    # row i of dx0/ds is e_i where (dx0/ds v)_i = v_i for two generic directions v: two
    # directional derivatives, not the whole Jacobian (an engine's 1 410 states: 43 CPU-s, not
    # more than 6 minutes)
    n = len(o.x_names)
    U, P, T, S = init_start.mx_in()
    V = ca.MX.sym("v", n, 2)
    v = np.column_stack([1 + (np.arange(n) * 0.6180339887) % 1, 2 - (np.arange(n) * 0.4142135623) % 1])
    try:        # (CasADi cannot differentiate a loop's Newton solve read back from the compile
        # cache: its 'Duplicate'; then no start is said to be settable)
        jv = ca.Function("dx0ds_v", [U, P, T, S, V], [ca.jtimes(init_start(U, P, T, S), S, V)])
        d = np.array(jv(o.u_start, o.p_values, 0.0, s0, v), dtype=float)
    except RuntimeError:
        return [False] * n, s0
    return [bool(np.all(np.abs(d[i] - v[i]) < 1e-9 * n)) for i in range(n)], s0


def n_discrete(model: CompiledModel) -> int:
    """Discrete values at the end of the model's state vector (0 for a continuous model)."""
    return int(getattr(model.ode, "discrete", 0) or 0)


def _step_function(o, nd: int = 0) -> ca.Function:
    """(x, u, p, t, du) -> (f, df/dx dense, df/dt + df/du du) of the continuous states (the
    first nx - nd entries of x): what a Rosenbrock step needs."""
    _, U, P, T = o.ode.mx_in()
    nc = len(o.x_names) - nd
    XC, D = ca.MX.sym("xc", nc), ca.MX.sym("d", nd)
    X = ca.vertcat(XC, D) if nd else XC
    DU = ca.MX.sym("du", U.numel())
    ode = o.ode
    dirs = jacobian_directions(ode)
    if dirs < 64:       # (CasADi's default: a wrapper's option sets it for the calls through it)
        args = ode.mx_in()
        ode = ca.Function("ode_dirs", args, ode.call(args), {"max_num_dir": dirs})
    f = ode(X, U, P, T)[:nc] if nd else ode(X, U, P, T)
    ft = ca.jacobian(f, T) + (ca.mtimes(ca.jacobian(f, U), DU) if U.numel() else 0)
    return ca.Function("step", [X, U, P, T, DU], [f, ca.densify(ca.jacobian(f, XC)), ca.densify(ft)],
                       ["x", "u", "p", "t", "du"], ["f", "J", "ft"])


#: about the C code per SX instruction and forward direction of the Jacobian, and the most the
#: Jacobian's derivative functions may take: PlanarFourbar's right-hand side (5 349
#: instructions, 203 states, 109 directions) written out for 64 directions at once and for the 45
#: left was 25 MB of C, past C_LIMIT
C_PER_DIRECTION = 45
JACOBIAN_C_BUDGET = 6_000_000


def jacobian_directions(ode: ca.Function) -> int:
    """How many forward directions each derivative call of ``ode`` in the FMU's Jacobian takes:
    CasADi's 64 unless its code (twice that many copies at most: a full call and the rest)
    would pass :data:`JACOBIAN_C_BUDGET`; then fewer, more calls of smaller code (each call
    evaluates the function itself again: at 8, a Jacobian does about an eighth more work; not
    measured)."""
    from ..structure import expanded_size

    per = expanded_size(ode) * C_PER_DIRECTION
    dirs = 64
    while dirs > 1 and 2 * dirs * per > JACOBIAN_C_BUDGET:
        dirs //= 2
    return dirs


def _c_string(text: str) -> str:
    """A C string literal of ``text`` (UTF-8; anything but printable ASCII as octal escapes)."""
    out = []
    for b in text.encode("utf-8"):
        ch = chr(b)
        out.append(ch if 32 <= b < 127 and ch not in '"\\?' else f"\\{b:03o}")
    return '"' + "".join(out) + '"'


_ASSERT_LEVELS = {"warning": 0, "error": 1, "terminate": 2}     # ASSERT_ERROR in the C template


def _events(o) -> dict:
    """The template values of a hybrid model's clocks and asserts."""
    info = getattr(o, "events", None) or {}
    clocks = [(float(a), float(b)) for a, b in info.get("clocks", [])]
    asserts = info.get("asserts", []) if getattr(o, "asserts", None) is not None else []
    return dict(NCLOCK=len(clocks), CLOCK_START=_fmt(c[0] for c in clocks), CLOCK_PERIOD=_fmt(c[1] for c in clocks),
                NA=len(asserts), ASSERT_ERROR=", ".join(str(_ASSERT_LEVELS[a[0]]) for a in asserts) or "0",
                ASSERT_MSG=", ".join(_c_string(str(a[1])) for a in asserts) or '""')


def generate_sources(model: CompiledModel, build: Path, ident: str, guid: str,
                     residual_tol: float = 1e-6, tolerance: float = 1e-6, settable=None,
                     rebuilt: bool = False, fd_jacobian: bool | None = None) -> list[Path]:
    """Write the C sources of the FMU into ``build``; returns the files to compile. ``settable``:
    the states whose start value can be set (default: :func:`settable_starts`).
    ``fd_jacobian``: Co-Simulation's Jacobian by differences of the right-hand side in C, not
    by generated derivative code; None: where the generated code would pass :data:`C_LIMIT`
    (a steam model's derivatives were 32 of its 52 MB)."""
    o = model.ode
    prefix = f"{ident}_"
    probe_vars = _probe_variables(model)
    probe = o.probe
    if probe_vars:
        sym = probe.mx_in()
        full = probe.call(sym)[0]
        probe = ca.Function("probe", sym, [full[[i for i, _ in probe_vars]]])
    zero = o.zero
    if zero is None:     # no state events: an empty indicator function keeps the C code uniform
        zero = ca.Function("zero", o.out.mx_in(), [ca.MX(0, 1)], ["x", "u", "p", "t"], ["out"])
    start, init_start = start_functions(model)
    settable = settable_starts(model)[0] if settable is None else settable
    nd = n_discrete(model)
    funcs = dict(ode=o.ode, out=o.out, alg_res=o.alg_res, init=init_start, start=start, probe=probe,
                 zero=zero, step=None if fd_jacobian else _step_function(o, nd),
                 update=getattr(o, "update", None))
    events = _events(o)
    if events["NA"]:
        funcs["asserts"] = o.asserts
    present = {k: f for k, f in funcs.items() if f is not None}
    split, derived = parametric.split_functions(present, {k: P_ARG.get(k, 2) for k in present}, len(o.p_names))
    funcs.update(split, derived=derived)
    generators = {name: ca.CodeGenerator(name, {"with_header": True}) for name in C_FUNCTIONS}
    for key in FUNCTIONS:
        if funcs.get(key) is not None:      # update and asserts: hybrid models only
            generators[ONCE_FILE if key in ONCE else HOT_FILE].add(_renamed(funcs[key], prefix + key))
    for cg in generators.values():
        cg.generate(str(build) + "/")
    if any(_NO_CODE in (build / name).read_text() for name in C_FUNCTIONS) and model.dae is not None and not rebuilt:
        return generate_sources(for_code(model), build, ident, guid, residual_tol, tolerance, settable, True,
                                fd_jacobian)
    if fd_jacobian is None and c_size(build / name for name in C_FUNCTIONS) > C_LIMIT:
        return generate_sources(model, build, ident, guid, residual_tol, tolerance, settable, rebuilt, True)
    template = (_HERE / "fmi2_model.c").read_text()
    nq = derived.nnz_out(0) if derived is not None else 0
    values = dict(NP=len(o.p_names), NQ=nq, NU=len(o.u_names), NY=len(o.y_names), NX=len(o.x_names),
                  NV=len(probe_vars), HAS_LOOP=int(o.nonlinear_blocks > 0), FD_JACOBIAN=int(bool(fd_jacobian)),
                  RES_TOL=repr(residual_tol), TOL=repr(float(tolerance)), GUID=guid, PREFIX=prefix,
                  P_DEFAULT=_fmt(o.p_values), U_START=_fmt(o.u_start),
                  X_SETTABLE=", ".join(str(int(b)) for b in settable) or "0",
                  N_EVENTS=len(o.time_events), EVENTS=_fmt(np.asarray(o.time_events, float)),
                  NZ=n_indicators(model), ND=nd, HYBRID=int(funcs["update"] is not None), **events)
    source = re.sub(r"@(\w+)@", lambda m: str(values[m.group(1)]), template)
    (build / "fmi2_model.c").write_text(source)
    for h in ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"):
        shutil.copy(_fmi_headers() / h, build / h)
    return [build / name for name in C_SOURCES]


#: what CasADi writes in place of a solve it has no C for (a large linear block's dense QR)
_NO_CODE = "does not support code generation"


def for_code(model: CompiledModel) -> CompiledModel:
    """``model`` built again from its DAE with solvers CasADi writes C for (sparse QR for the
    large linear blocks the in-process model solves by LAPACK), with the same outputs."""
    try:        # sparse QR has no answer where the block is singular (ideal switches all open)
        with structure.for_code():
            rebuilt = CompiledModel.from_dae(model.dae, model.name, model.ode.y_names, model.info, model.structure)
        ode = rebuilt.ode
        x0 = ode.init(ode.u_start, ode.p_values, 0.0)
        ode.ode(x0, ode.u_start, ode.p_values, 0.0)
    except (RuntimeError, ModelicaError):     # (there, its initial system has no finite derivative)
        raise CompileError(f"{model.name} solves a linear block of more than {structure.SYMBOLIC_SOLVE_MAX} "
                           "unknowns that is singular at its start: CasADi writes C only for a sparse solver, "
                           "which fails there (the model runs in process, not as an FMU)") from None
    return rebuilt


def n_indicators(model: CompiledModel) -> int:
    """Event indicators of the FMU: the model's zero-crossing functions (state events)."""
    return 0 if model.ode.zero is None else int(model.ode.zero.size1_out(0))


def _changes_at_events_only(f: ca.Function, nc: int) -> list[bool]:
    """Rows of ``f(x, u, p, t)`` that depend on neither the continuous states (the first ``nc``
    entries of x), the inputs nor time: they change only where the discrete values do."""
    n = f.size1_out(0)
    if not n:
        return []
    moving = np.zeros(n, dtype=bool)
    for i in (0, 1, 3):
        if f.numel_in(i) == 0:
            continue
        sp = np.array(ca.DM(f.sparsity_jac(i, 0), 1)).reshape(n, -1)
        moving |= (sp[:, :nc] if i == 0 else sp).any(axis=1)
    return [not b for b in moving]


def derivative_unit(unit: str | None) -> str | None:
    """The unit of der(x) for x in ``unit`` (Modelica unit syntax: V -> V/s, m/s -> m/s2)."""
    if not unit:
        return None
    if unit == "1":
        return "1/s"
    if "/" not in unit:
        return f"{unit}/s"
    num, den = unit.split("/", 1)
    power = re.fullmatch(r"s(\d*)", den)
    if power:
        return f"{num}/s{int(power.group(1) or 1) + 1}"
    return f"{num}/({den}.s)" if not den.startswith("(") else None


def model_description(model: CompiledModel, ident: str, guid: str, sources: list[str],
                      experiment: Experiment | None = None, units: dict | None = None,
                      descriptions: dict | None = None, starts=None) -> str:
    """modelDescription.xml: Model Exchange and Co-Simulation; parameters tunable, inputs,
    outputs, states (their start values settable where they are initial conditions),
    derivatives, discrete variables, probes (value references in this order, as the C wrapper
    numbers them; the hidden memories of when-conditions, named $..., are left out); the model's
    units and descriptions, completed by ``units`` and ``descriptions`` (names of learned
    parameters, say). ``starts``: :func:`settable_starts`."""
    o = model.ode
    nd = n_discrete(model)
    nc = len(o.x_names) - nd
    rows, outputs, derivs, initial = [], [], [], []
    vr = iter(range(1 << 31))
    units = {**model.info.get("units", {}), **(units or {})}
    descriptions = {**model.info.get("descriptions", {}), **(descriptions or {})}
    used_units = set()

    def var(name, attrs, real="<Real/>", unit=None, desc=""):
        ref = next(vr)
        if name.startswith("$"):
            return None
        desc = desc or descriptions.get(name, "")
        unit = unit or units.get(name)
        if unit:
            used_units.add(unit)
            real = real.replace("/>", f" unit={quoteattr(unit)}/>")
        d = f" description={quoteattr(desc)}" if desc else ""
        rows.append(f'    <ScalarVariable name={quoteattr(name)} valueReference="{ref}"{d} {attrs}>'
                    f"\n      {real}\n    </ScalarVariable>")
        return len(rows)  # 1-based index

    local = 'causality="local" variability="continuous"'
    for n, v in zip(o.p_names, o.p_values):
        var(n, 'causality="parameter" variability="tunable" initial="exact"', f'<Real start="{float(v)!r}"/>')
    for n, v in zip(o.u_names, o.u_start):
        var(n, 'causality="input" variability="continuous"', f'<Real start="{float(v)!r}"/>')
    discrete_out = _changes_at_events_only(o.out, nc) if nd else [False] * len(o.y_names)
    # an output that is a state (output Real y; der(y) = ...) is one variable: the state's, an output
    state_outputs, exact_outputs = set(o.y_names) & set(o.x_names), []
    for n, disc in zip(o.y_names, discrete_out):
        if n in state_outputs:
            next(vr)            # (its value reference as an output stays unused)
            continue
        kind = "discrete" if disc else "continuous"
        outputs.append(var(n, f'causality="output" variability="{kind}" initial="calculated"'))
    settable, s0 = starts or settable_starts(model)

    def state(n, exact, v, kind="continuous"):
        attrs = f'causality="{"output" if n in state_outputs else "local"}" variability="{kind}"'
        i = (var(n, f'{attrs} initial="exact"', f'<Real start="{float(v)!r}"/>') if exact
             else var(n, f'{attrs} initial="calculated"'))
        if n in state_outputs:
            outputs.append(i)
            if exact:
                exact_outputs.append(i)
        return i

    states = [state(n, exact, v) for n, exact, v in zip(o.x_names[:nc], settable[:nc], s0[:nc])]
    for n, s in zip(o.x_names[:nc], states):
        desc = f"time derivative of {n}" + (f" ({descriptions[n]})" if descriptions.get(n) else "")
        derivs.append(var(f"der({n})", f'{local} initial="calculated"', f'<Real derivative="{s}"/>',
                          unit=derivative_unit(units.get(n)), desc=desc))
    for n, exact, v in zip(o.x_names[nc:], settable[nc:], s0[nc:]):
        state(n, exact, v, "discrete")
    for _, n in _probe_variables(model):
        var(n, f'{local} initial="calculated"')
    outputs.sort()
    initial = sorted({*outputs, *(i for i, exact in zip(states, settable) if not exact), *derivs} - {*exact_outputs})

    def section(tag, idx):  # an empty section is invalid FMI 2.0: leave it out
        if not idx:
            return ""
        body = "\n".join(f'      <Unknown index="{i}"/>' for i in idx)
        return f"    <{tag}>\n{body}\n    </{tag}>\n"

    files = "\n".join(f'      <File name="{s}"/>' for s in sources)
    unit_defs = ("  <UnitDefinitions>\n" + "\n".join(f"    <Unit name={quoteattr(u)}/>" for u in sorted(used_units))
                 + "\n  </UnitDefinitions>\n") if used_units else ""
    common = 'canNotUseMemoryManagementFunctions="true" canGetAndSetFMUstate="true" canSerializeFMUstate="true"'
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName={quoteattr(model.name)} guid="{guid}"
  generationTool="mcl" variableNamingConvention="structured" numberOfEventIndicators="{n_indicators(model)}">
  <ModelExchange modelIdentifier="{ident}" {common}>
    <SourceFiles>
{files}
    </SourceFiles>
  </ModelExchange>
  <CoSimulation modelIdentifier="{ident}" {common}
    canHandleVariableCommunicationStepSize="true" canInterpolateInputs="true" maxOutputDerivativeOrder="0">
    <SourceFiles>
{files}
    </SourceFiles>
  </CoSimulation>
{unit_defs}  <LogCategories>
    <Category name="logStatusWarning"/>
    <Category name="logStatusError"/>
    <Category name="logAll"/>
  </LogCategories>
{experiment.xml() if experiment else ""}  <ModelVariables>
{chr(10).join(rows)}
  </ModelVariables>
  <ModelStructure>
{section("Outputs", outputs)}{section("Derivatives", derivs)}{section("InitialUnknowns", initial)}  </ModelStructure>
</fmiModelDescription>
"""


def build_fmu(model: CompiledModel, out_path, validate: bool = True, *, experiment=None,
              units: dict | None = None, descriptions: dict | None = None, libraries=()) -> Path:
    """Write ``out_path`` (.fmu, Model Exchange and Co-Simulation); raises CompileError if gcc or
    FMPy validation fails.

    ``experiment``: the DefaultExperiment: data (a TimeSeries: its span and sampling interval),
    an :class:`~mcl.compile.fmu.experiment.Experiment` or a dict (start, stop, step,
    tolerance); default: the class's ``experiment`` annotation (its source found among the
    model's sources, ``libraries`` and the library path), else an estimate from the model's
    time scales.
    ``units`` / ``descriptions``: {variable name: text} added to (or replacing) what the model
    declares, e.g. for the coefficients of a learned law.

    A validated build is kept in mcl's cache (:mod:`mcl.compile.cache`), keyed by the model's
    compile key (a model as the compile cache holds it) or else by its generated sources, and
    by its model description: building the same FMU again (a cached model, the same experiment,
    units and descriptions) copies it instead of generating code and running gcc and FMPy.
    """
    out_path = Path(out_path)
    if out_path.is_dir():
        raise ConfigError("the FMU to write is an existing directory", where=str(out_path))
    o = model.ode
    if not (o.p_names or o.u_names or o.y_names or o.x_names or _probe_variables(model)):
        raise ModelicaError(f"model {model.name} has no variables: an FMU needs at least one")
    ident = model_identifier(model.name)
    experiment = Experiment.of(experiment) or for_model(model, libraries)
    _check_names(model, units, "units")
    _check_names(model, descriptions, "descriptions")
    starts = settable_starts(model)
    xml = model_description(model, ident, _GUID_SLOT, list(C_SOURCES), experiment, units, descriptions, starts)
    compiled_as = compile_cache.model_key(model)
    # a model as the compile cache holds it: its compile key says what the generated code is
    model_key = _build_key("model", compiled_as, xml, _HERE.joinpath("fmi2_model.c").read_text(),
                           Path(__file__).read_text(), ca.__version__) if compiled_as else None
    with tempfile.TemporaryDirectory(prefix="mcl-fmu-") as tmp:
        build = Path(tmp)
        fmu = compile_cache.fmu_lookup(model_key) if model_key else None
        if fmu is None:
            c_files = generate_sources(model, build, ident, _GUID_SLOT, tolerance=experiment.tolerance,
                                       settable=starts[0])
            twin = _calls_kept(model) if c_size(c_files) > C_LIMIT_O0 else None
            if twin is not None:
                for f in build.iterdir():
                    f.unlink()
                c_files = generate_sources(twin, build, ident, _GUID_SLOT, tolerance=experiment.tolerance,
                                           settable=starts[0])
            sources = sorted(p.name for p in build.iterdir() if p.suffix in (".c", ".h"))
            key = _build_key("sources", xml, *sources, *((build / s).read_text() for s in sources))
            fmu = compile_cache.fmu_lookup(key)
        if fmu is None:
            # the GUID follows from the content: the same sources and description, the same GUID
            guid = "{" + str(uuid.UUID(key[:32])) + "}"
            xml = xml.replace(_GUID_SLOT, guid)
            for f in c_files:
                f.write_text(f.read_text().replace(_GUID_SLOT, guid))
            fmu = _compile_and_pack(build, ident, c_files, sources, xml)
            if validate:
                problems = validate_fmu(fmu)
                if problems:
                    raise CompileError(f"FMPy validation of the generated FMU failed: {problems[0]}")
                for k in filter(None, (key, model_key)):   # only validated builds are reused
                    compile_cache.fmu_store(k, fmu)
        out_path.parent.mkdir(parents=True, exist_ok=True)
        staged = out_path.with_name(f".{out_path.name}.{os.getpid()}.tmp")
        try:
            shutil.copyfile(fmu, staged)
            staged.replace(out_path)
        finally:
            staged.unlink(missing_ok=True)
    return out_path


def _calls_kept(model: CompiledModel) -> CompiledModel | None:
    """``model`` compiled again with its large functions kept as calls (each one's C written once,
    not inlined at every call: a Fluid example's 200 MB of C became 8 MB), where it is a model
    as the compiler gave it (not one with a law put in) and the twin has the same variables;
    else None."""
    info = model.info
    if info.get("frontend") != "rumoca" or info.get("calls") != "inlined" or compile_cache.model_key(model) is None:
        return None
    from mcl.services import compile_model
    try:
        twin = compile_model([Path(s) for s in info["sources"]], model.name, info.get("compiler"),
                             {"calls": "kept"}, libraries=[Path(p) for p in info.get("libraries", ())])
    except (ModelicaError, CompileError):
        return None
    same = all(getattr(twin.ode, k) == getattr(model.ode, k) for k in ("x_names", "p_names", "u_names", "y_names"))
    return twin if same and _probe_variables(twin) == _probe_variables(model) else None


_GUID_SLOT = "{mcl-guid-of-this-build}"
_CFLAGS = ["-fPIC", "-fvisibility=hidden"]
#: the functions run once per run or parameter set (the initial state, the parameters derived
#: from the parameters): their C is apart and compiled unoptimised. A filter's coefficients
#: (Brent's root search unrolled) are 2 x 44 000 lines of one basic block each, which gcc -O2
#: took 270 s over (12 s at -O0); the right-hand side and its Jacobian stay at -O2
ONCE = ("init", "start", "derived")
HOT_FILE, ONCE_FILE = "mcl_funcs.c", "mcl_once.c"
C_FUNCTIONS = (HOT_FILE, ONCE_FILE)
C_SOURCES = ("fmi2_model.c", *C_FUNCTIONS)
_OPTIMISE = {"fmi2_model.c": "-O2", HOT_FILE: "-O2", ONCE_FILE: "-O0"}


def _build_key(*parts: str) -> str:
    """What decides the FMU (its code or what the code is made from, its model description),
    with the C compiler and its flags."""
    h = hashlib.sha256()
    for part in (_gcc_version(), " ".join(_CFLAGS), repr(sorted(_OPTIMISE.items())), " ".join(O1), *parts):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()[:40]


def _gcc_version() -> str:
    try:
        return subprocess.run(["gcc", "-dumpfullversion", "-dumpversion"], capture_output=True, text=True,
                              timeout=60).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


#: generated C beyond this is refused before gcc sees it: the largest MSL example's is 1.4 MB, and
#: a filter chain's 108 MB (its coefficients' functions of f_cut written out in each function
#: and derivative) took gcc past 23 GB at -O0 before it was killed
C_LIMIT = 16_000_000
#: ... and past C_LIMIT, compiled unoptimised up to this: a steam plant's 18 MB of C took gcc 64
#: CPU-s and 3.8 GB at -O0 (at -O1 more than 5 minutes), its largest function 6 MB ...
C_LIMIT_O0 = 32_000_000
#: ... where no function is larger than this: gcc's memory grows faster than a function's size
#: (an engine initialiser's 15 MB derivative function took it to 24 GB)
FUNCTION_LIMIT_O0 = 8_000_000
GCC_TIMEOUT = 600
#: a right-hand side's C past this is compiled at -O1: a Modelica.Fluid tank and pipe's 3.5 MB
#: took gcc 90 CPU-s at -O2, 54 at -O1 (23 at -O0)
O1_PAST = 2_000_000
#: ... without the dominator optimisations: on long straight-line functions their SSA updates
#: were most of gcc's time (a 45-node dense block's sparse QR, 2.9 MB: 108 CPU-s, 23 without
#: them; the FMU runs 1.1x as long)
O1 = ("-O1", "-fno-tree-dominator-opts")
_FUNCTION_START = re.compile(rb"^(?:static |CASADI_SYMBOL_EXPORT )?int \w+\(const casadi_real\*\* arg", re.M)


def c_size(files) -> int:
    """Bytes of C in ``files``."""
    return sum(f.stat().st_size for f in files)


def largest_function(path: Path) -> int:
    """Bytes of the largest function CasADi wrote in C file ``path``."""
    text = path.read_bytes()
    starts = [m.start() for m in _FUNCTION_START.finditer(text)] + [len(text)]
    return max((b - a for a, b in zip(starts, starts[1:])), default=0)


def _compile_and_pack(build: Path, ident: str, c_files: list[Path], sources: list[str], xml: str) -> Path:
    """gcc, then the archive (packed in the build directory: nothing half-written is left)."""
    size = c_size(c_files)
    if size > C_LIMIT_O0:
        raise CompileError(f"the FMU's generated C code is {size / 1e6:.0f} MB, too large to compile "
                           f"(the limit is {C_LIMIT_O0 / 1e6:.0f} MB): the model runs in process, not as an FMU")
    largest = max(largest_function(f) for f in c_files) if size > C_LIMIT else 0
    if largest > FUNCTION_LIMIT_O0:
        raise CompileError(f"the FMU's generated C code has a function of {largest / 1e6:.0f} MB, too large to "
                           f"compile (the limit is {FUNCTION_LIMIT_O0 / 1e6:.0f} MB where the code passes "
                           f"{C_LIMIT / 1e6:.0f} MB): the model runs in process, not as an FMU")
    so = build / f"{ident}.so"
    objects = [f.with_suffix(".o") for f in c_files]
    # each file at its own optimisation (none past C_LIMIT), side by side, then linked
    _gcc([["gcc", "-c", *_CFLAGS, *_optimisation(f, size), f"-I{build}", str(f), "-o", str(o)]
          for f, o in zip(c_files, objects)], size, build)
    _gcc([["gcc", "-shared", *_CFLAGS, *map(str, objects), "-o", str(so), "-lm"]], size, build)
    fmu = build / "model.fmu"
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("modelDescription.xml", xml)
        z.write(so, f"binaries/linux64/{ident}.so")
        for s in sources:
            z.write(build / s, f"sources/{s}")
    return fmu


def _optimisation(f: Path, size: int) -> tuple[str, ...]:
    """gcc's optimisation flags for C file ``f`` of code ``size`` bytes in all: its own
    (:data:`_OPTIMISE`), :data:`O1` for a right-hand side past :data:`O1_PAST`, none past
    :data:`C_LIMIT`."""
    if size > C_LIMIT:
        return ("-O0",)
    if _OPTIMISE[f.name] == "-O2" and f.stat().st_size > O1_PAST:
        return O1
    return (_OPTIMISE[f.name],)


def _gcc(commands: list[list[str]], size: int, build: Path) -> None:
    """Run the gcc ``commands`` side by side (their messages in ``build``); a CompileError where
    one fails or all take longer than GCC_TIMEOUT (``size``: the C's, for the message)."""
    logs = [build / f"gcc{i}.log" for i in range(len(commands))]
    procs = []
    try:
        for command, log in zip(commands, logs):
            with open(log, "w") as err:
                procs.append(subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=err))
        deadline = time.monotonic() + GCC_TIMEOUT
        for p in procs:
            p.wait(timeout=max(0.0, deadline - time.monotonic()))
    except FileNotFoundError:
        raise CompileError("gcc not found: a C compiler is needed to build FMUs") from None
    except subprocess.TimeoutExpired:
        raise CompileError(f"gcc did not compile the FMU's {size / 1e6:.1f} MB of C within {GCC_TIMEOUT} s: "
                           "the model runs in process, not as an FMU") from None
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
    for p, log in zip(procs, logs):
        if p.returncode:
            lines = log.read_text(errors="replace").strip().splitlines()
            raise CompileError(f"gcc failed: {lines[-1] if lines else ''}")


def _check_names(model: CompiledModel, given: dict | None, what: str) -> None:
    o = model.ode
    continuous = o.x_names[:len(o.x_names) - n_discrete(model)]
    known = {*o.p_names, *o.u_names, *o.y_names, *o.x_names, *(f"der({n})" for n in continuous),
             *(n for _, n in _probe_variables(model))}
    unknown = sorted(set(given or ()) - known)
    if unknown:
        raise ConfigError(f"{what} for variables the model does not have: {', '.join(unknown)}")


def validate_fmu(path) -> list[str]:
    """Problems FMPy finds in an FMU (empty when valid): FMPy's own checks (``fmpy.validation.
    validate_fmu``), its variable-name grammar applied only to names a plain pattern (a subset of
    that grammar) does not accept; FMPy parses each name with an Earley parser, ~7 ms a name, the
    longest part of an extended model's export at 700 variables."""
    import copy

    from fmpy import read_model_description
    from fmpy.model_description import ValidationError
    from fmpy.validation import _validate_variable_names

    problems = []
    if Path(path).is_file():
        with zipfile.ZipFile(path) as zf:
            problems += [f'The file path "{f.orig_filename}" contains a backslash.'
                         for f in zf.filelist if "\\" in f.orig_filename]
    try:
        md = read_model_description(str(path), validate=True, validate_model_structure=True)
    except ValidationError as exc:
        return [*problems, *map(str, exc.problems)]
    except Exception as exc:  # noqa: BLE001 - FMPy's own catch-all, kept
        return [*problems, str(exc)]
    odd = copy.copy(md)
    odd.modelVariables = [v for v in md.modelVariables if not _PLAIN_NAME.fullmatch(v.name)]
    return [*problems, *map(str, _validate_variable_names(odd))]


_ID = r"[A-Za-z_][A-Za-z_0-9]*(\[[0-9]+(,[0-9]+)*\])?"
_PLAIN_NAME = re.compile(rf"{_ID}(\.{_ID})*|der\({_ID}(\.{_ID})*(,[0-9]+)?\)")