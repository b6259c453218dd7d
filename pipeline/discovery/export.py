"""A learned component as a reusable Modelica library (``mcl export``, ``Discovery.export``)."""
from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

from ..errors import ConfigError

IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def _inside(run: Path, relative: str) -> Path:
    """``run/relative``, refused when it leads outside the run directory."""
    path = (run / relative).resolve()
    if run.resolve() not in path.parents:
        raise ConfigError(f"report.json names a file outside the run directory: {relative}", where=str(run))
    return path


def export_library(run_dir, output, name: str = "MCLLearned") -> Path:
    """Write ``output/name/package.mo`` (the learned class) and the extended model's FMU;
    returns the package directory. Reads only files inside ``run_dir``, writes only inside
    ``output``."""
    from ..compile.library import uses_annotation

    run = Path(run_dir)
    if not IDENT.match(name):
        raise ConfigError(f"'{name}' is not a Modelica identifier (letters, digits, _; not starting "
                          "with a digit)", where="--name")
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
    m = re.search(rf"^\s*model {re.escape(cls)}\b.*?^\s*end {re.escape(cls)};", source.read_text(), re.S | re.M)
    if not m:
        raise ConfigError(f"class {cls} not found", where=str(source))
    out = Path(output) / name
    out.mkdir(parents=True, exist_ok=True)
    body = "\n".join("  " + line.strip() if line.strip() else "" for line in m.group(0).splitlines())
    # the libraries the run compiled with (recorded in its extended package), else the path's
    recorded = re.search(r"annotation\(uses\((?:[^()]|\([^()]*\))*\)\)", source.read_text())
    uses = recorded.group(0) if recorded else uses_annotation(body)
    annotation = f"  {uses};\n" if uses else ""
    tmp = out / "package.mo.tmp"
    tmp.write_text(f'within ;\npackage {name} "Components learned by mcl"\n{body}\n{annotation}end {name};\n')
    tmp.replace(out / "package.mo")
    if fmu.is_file():
        shutil.copyfile(fmu, out / fmu.name)
    return out
