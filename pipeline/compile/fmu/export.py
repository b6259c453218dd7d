"""Compiled model -> FMI 2.0 Model Exchange FMU that ``fmpy validate`` accepts.

CasADi generates C for the model's functions; a short hand-written FMI 2 wrapper
(``fmi2_model.c``) calls them with work arrays sized from ``*_work`` (fixed sizes segfault:
../shared/DESIGN.md, section 5). The FMU carries its sources, so other platforms can rebuild it.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
import uuid
import zipfile
from pathlib import Path
from xml.sax.saxutils import quoteattr

import casadi as ca
import numpy as np

from ...errors import CompileError, ConfigError
from ...model import CompiledModel

_HERE = Path(__file__).parent
FUNCTIONS = ("ode", "out", "alg_res", "init", "probe", "zero")


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


def generate_sources(model: CompiledModel, build: Path, ident: str, guid: str,
                     residual_tol: float = 1e-6) -> list[Path]:
    """Write the C sources of the FMU into ``build``; returns the files to compile."""
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
    funcs = dict(ode=o.ode, out=o.out, alg_res=o.alg_res, init=o.init, probe=probe, zero=zero)
    cg = ca.CodeGenerator("mcl_funcs.c", {"with_header": True})
    for key in FUNCTIONS:
        cg.add(_renamed(funcs[key], prefix + key))
    cg.generate(str(build) + "/")
    template = (_HERE / "fmi2_model.c").read_text()
    values = dict(NP=len(o.p_names), NU=len(o.u_names), NY=len(o.y_names), NX=len(o.x_names),
                  NV=len(probe_vars), HAS_LOOP=int(o.nonlinear_blocks > 0),
                  RES_TOL=repr(residual_tol), GUID=guid, PREFIX=prefix,
                  P_DEFAULT=_fmt(o.p_values), U_START=_fmt(o.u_start),
                  N_EVENTS=len(o.time_events), EVENTS=_fmt(np.asarray(o.time_events, float)),
                  NZ=n_indicators(model))
    source = re.sub(r"@(\w+)@", lambda m: str(values[m.group(1)]), template)
    (build / "fmi2_model.c").write_text(source)
    for h in ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"):
        shutil.copy(_fmi_headers() / h, build / h)
    return [build / "fmi2_model.c", build / "mcl_funcs.c"]


def n_indicators(model: CompiledModel) -> int:
    """Event indicators of the FMU: the model's zero-crossing functions (state events)."""
    return 0 if model.ode.zero is None else int(model.ode.zero.size1_out(0))


def model_description(model: CompiledModel, ident: str, guid: str, sources: list[str]) -> str:
    """modelDescription.xml: parameters tunable, inputs, outputs, states, derivatives, probes."""
    o = model.ode
    rows, outputs, derivs, initial = [], [], [], []
    units, descriptions = model.info.get("units", {}), model.info.get("descriptions", {})
    used_units = set()

    def var(name, attrs, real="<Real/>", desc=""):
        desc = desc or descriptions.get(name, "")
        unit = units.get(name)
        if unit and "derivative=" not in real:
            used_units.add(unit)
            real = real.replace("/>", f" unit={quoteattr(unit)}/>")
        d = f" description={quoteattr(desc)}" if desc else ""
        rows.append(f'    <ScalarVariable name={quoteattr(name)} valueReference="{len(rows)}"{d} {attrs}>'
                    f"\n      {real}\n    </ScalarVariable>")
        return len(rows)  # 1-based index

    for n, v in zip(o.p_names, o.p_values):
        var(n, 'causality="parameter" variability="tunable" initial="exact"', f'<Real start="{float(v)!r}"/>')
    for n, v in zip(o.u_names, o.u_start):
        var(n, 'causality="input" variability="continuous"', f'<Real start="{float(v)!r}"/>')
    for n in o.y_names:
        outputs.append(var(n, 'causality="output" variability="continuous" initial="calculated"'))
    states = [var(n, 'causality="local" variability="continuous" initial="calculated"') for n in o.x_names]
    for n, s in zip(o.x_names, states):
        derivs.append(var(f"der({n})", 'causality="local" variability="continuous" initial="calculated"',
                          f'<Real derivative="{s}"/>'))
    for _, n in _probe_variables(model):
        var(n, 'causality="local" variability="continuous" initial="calculated"')
    initial = sorted(outputs + states + derivs)
    def section(tag, idx):  # an empty section is invalid FMI 2.0: leave it out
        if not idx:
            return ""
        body = "\n".join(f'      <Unknown index="{i}"/>' for i in idx)
        return f"    <{tag}>\n{body}\n    </{tag}>\n"

    files = "\n".join(f'      <File name="{s}"/>' for s in sources)
    unit_defs = ("  <UnitDefinitions>\n" + "\n".join(f"    <Unit name={quoteattr(u)}/>" for u in sorted(used_units))
                 + "\n  </UnitDefinitions>\n") if used_units else ""
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName={quoteattr(model.name)} guid="{guid}"
  generationTool="mcl" variableNamingConvention="structured" numberOfEventIndicators="{n_indicators(model)}">
  <ModelExchange modelIdentifier="{ident}" canNotUseMemoryManagementFunctions="true">
    <SourceFiles>
{files}
    </SourceFiles>
  </ModelExchange>
{unit_defs}  <LogCategories>
    <Category name="logStatusError"/>
    <Category name="logAll"/>
  </LogCategories>
  <ModelVariables>
{chr(10).join(rows)}
  </ModelVariables>
  <ModelStructure>
{section("Outputs", outputs)}{section("Derivatives", derivs)}{section("InitialUnknowns", initial)}  </ModelStructure>
</fmiModelDescription>
"""


def build_fmu(model: CompiledModel, out_path, validate: bool = True) -> Path:
    """Write ``out_path`` (.fmu); raises CompileError if gcc or FMPy validation fails."""
    out_path = Path(out_path)
    ident = model_identifier(model.name)
    guid = "{" + str(uuid.uuid4()) + "}"
    with tempfile.TemporaryDirectory(prefix="mcl-fmu-") as tmp:
        build = Path(tmp)
        c_files = generate_sources(model, build, ident, guid)
        so = build / f"{ident}.so"
        cmd = ["gcc", "-shared", "-fPIC", "-O2", "-fvisibility=hidden", f"-I{build}",
               *map(str, c_files), "-o", str(so), "-lm"]
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        except FileNotFoundError:
            raise CompileError("gcc not found: a C compiler is needed to build FMUs") from None
        if proc.returncode:
            raise CompileError(f"gcc failed: {proc.stderr.strip().splitlines()[-1] if proc.stderr else ''}")
        sources = sorted(p.name for p in build.iterdir() if p.suffix in (".c", ".h"))
        xml = model_description(model, ident, guid, [s for s in sources if s.endswith(".c")])
        if out_path.is_dir():
            raise ConfigError("the FMU to write is an existing directory", where=str(out_path))
        out_path.parent.mkdir(parents=True, exist_ok=True)
        tmp_fmu = build / "model.fmu"    # packed in the build directory: nothing half-written is left
        with zipfile.ZipFile(tmp_fmu, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("modelDescription.xml", xml)
            z.write(so, f"binaries/linux64/{ident}.so")
            for s in sources:
                z.write(build / s, f"sources/{s}")
        if validate:
            problems = validate_fmu(tmp_fmu)
            if problems:
                raise CompileError(f"FMPy validation of the generated FMU failed: {problems[0]}")
        staged = out_path.with_name(f".{out_path.name}.{os.getpid()}.tmp")
        try:
            shutil.copyfile(tmp_fmu, staged)
            staged.replace(out_path)
        finally:
            staged.unlink(missing_ok=True)
    return out_path


def validate_fmu(path) -> list[str]:
    """Problems FMPy finds in an FMU (empty when valid)."""
    from fmpy.validation import validate_fmu as fmpy_validate

    return [str(p) for p in fmpy_validate(str(path))]
