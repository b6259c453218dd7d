"""OpenModelica compiler plugin (OMPython 4.x): used when ``omc`` is installed and chosen by name.

It produces an FMI 2.0 FMU with OpenModelica's own code generator, so it handles what the
embedded compiler does not (events, the Modelica Standard Library); the result runs on the FMU
engine only (no in-process sensitivities).
"""
from __future__ import annotations

import importlib.util
import os
import shutil
import tempfile
from pathlib import Path

from mcl import hookimpl
from mcl.compile import Compiler
from mcl.errors import CompileError


def find_omc() -> str | None:
    home = os.environ.get("OPENMODELICAHOME")
    if home and (Path(home) / "bin" / "omc").is_file():
        return str(Path(home) / "bin" / "omc")
    return shutil.which("omc")


class OpenModelicaCompiler(Compiler):
    name = "openmodelica"
    description = "OpenModelica via OMPython: FMI 2.0 Model Exchange + Co-Simulation FMU"
    automatic = False  # the embedded compiler stays the default; choose with --compiler

    def available(self):
        if importlib.util.find_spec("OMPython") is None:
            return False, "the OMPython package is not installed (pip install OMPython)"
        if not find_omc():
            return False, "omc not found (install OpenModelica, or set OPENMODELICAHOME)"
        return True, ""

    def compile(self, sources: list[Path], model: str, options: dict | None = None):
        from OMPython import ModelicaSystemOMC

        from mcl.compile.pymoca_frontend import collect_sources
        from mcl.model import FmuModel

        files = collect_sources(sources, model, (options or {}).get("libraries", ())).files
        work = Path(tempfile.mkdtemp(prefix="mcl-omc-"))
        try:
            om = ModelicaSystemOMC(work_directory=str(work))
            for f in files[1:]:
                om._session.sendExpression(f'loadFile("{f.as_posix()}")')
            om.model(model_name=model, model_file=str(files[0]), build=False)
            fmu = Path(str(om.convertMo2Fmu(version="2.0", fmuType="me_cs")))
        except Exception as exc:  # OMPython reports compiler errors as exceptions
            raise CompileError(f"OpenModelica failed on {model}: {str(exc).strip().splitlines()[-1]}") from None
        return FmuModel.read(fmu)


@hookimpl
def mcl_compilers():
    return [OpenModelicaCompiler]
