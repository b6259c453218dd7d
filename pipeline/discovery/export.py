"""A learned component as a reusable Modelica library (``mcl export``, ``Discovery.export``)."""
from __future__ import annotations

import json
import re
import shutil
import textwrap
from pathlib import Path

from ..compile.sources import KEYWORDS
from ..errors import ConfigError

IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
#: top-level names of libraries a learned library is used beside (shadowing one breaks the model)
LIBRARIES = frozenset({"Modelica", "ModelicaServices", "ModelicaReference", "ModelicaTest", "Complex",
                       "ObsoleteModelica4", "MCL"})


def check_name(name) -> str:
    """``name`` as the name of an exported library, or a ConfigError saying why not."""
    if not isinstance(name, str) or not IDENT.match(name):
        raise ConfigError(f"'{name}' is not a Modelica identifier (letters, digits, _; not starting "
                          "with a digit)", where="--name")
    if name in KEYWORDS:
        raise ConfigError(f"'{name}' is a Modelica keyword: choose another library name", where="--name")
    if name in LIBRARIES:
        raise ConfigError(f"'{name}' is the name of the {name} library, which the learned class is used "
                          "beside: choose another library name", where="--name")
    return name


def _inside(run: Path, relative: str) -> Path:
    """``run/relative``, refused when it leads outside the run directory."""
    path = (run / relative).resolve()
    if run.resolve() not in path.parents:
        raise ConfigError(f"report.json names a file outside the run directory: {relative}", where=str(run))
    return path


def export_library(run_dir, output, name: str = "MCLLearned", force: bool = False) -> Path:
    """Write ``output/name/package.mo`` (the learned class) and the extended model's FMU;
    returns the package directory. Reads only files inside ``run_dir``, writes only the new
    directory ``output/name`` (with ``force``, replacing one that mcl exported: mcl.outputs)."""
    from ..compile.library import uses_annotation
    from ..outputs import check_input, check_output, new_directory

    check_name(name)
    run = check_input(run_dir, "run directory", directory_ok=True, error=ConfigError)
    check_output(Path(output).expanduser() / name, force, directory=True, what="a library", inputs=[run])
    report_file = run / "report.json"
    if not report_file.is_file():
        raise ConfigError("not a finished run directory (no report.json)", where=str(run))
    try:
        cause = json.loads(report_file.read_text()).get("cause")
    except (ValueError, UnicodeDecodeError, AttributeError) as exc:
        raise ConfigError(f"report.json is not a report of mcl ({exc})", where=str(report_file)) from None
    if not cause:
        raise ConfigError("the run learned no component (no cause was found)", where=str(run))
    try:
        source, fmu, cls = _inside(run, cause["modelica"]), _inside(run, cause["fmu"]), cause["learned_class"]
    except (KeyError, TypeError):
        raise ConfigError("report.json lacks the learned component's files", where=str(report_file)) from None
    if not IDENT.match(str(cls)) or not source.is_file():
        raise ConfigError("report.json names no learned class that exists", where=str(report_file))
    m = re.search(rf"^\s*(?:model|block) {re.escape(cls)}\b.*?^\s*end {re.escape(cls)};", source.read_text(), re.S | re.M)
    if not m:
        raise ConfigError(f"class {cls} not found", where=str(source))
    body = textwrap.indent(textwrap.dedent(m.group(0)), "  ")   # the class's own indentation kept
    # the libraries the run compiled with (recorded in its extended package), else the path's
    recorded = re.search(r"annotation\(uses\((?:[^()]|\([^()]*\))*\)\)", source.read_text())
    uses = recorded.group(0) if recorded else uses_annotation(body)
    annotation = f"  {uses};\n" if uses else ""
    with new_directory(Path(output).expanduser() / name, force, what="a library", inputs=[run]) as out:
        (out / "package.mo").write_text(
            f'within ;\npackage {name} "Components learned by mcl"\n{body}\n{annotation}end {name};\n')
        if fmu.is_file():
            shutil.copyfile(fmu, out / fmu.name)
    return Path(output) / name
