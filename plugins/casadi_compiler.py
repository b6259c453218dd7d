"""The embedded default compiler: pymoca front end -> CasADi DAE -> index reduction -> ODE."""
from __future__ import annotations

from pathlib import Path

from mcl import hookimpl
from mcl.compile import Compiler


class CasadiCompiler(Compiler):
    name = "casadi"
    description = "pymoca + CasADi: index reduction, causalisation; in-process model and FMI 2.0 FMU"

    def compile(self, sources: list[Path], model: str, options: dict | None = None):
        from mcl import dae, frontend, structure
        from mcl.model import CompiledModel

        from mcl.errors import ModelicaError

        pymoca_model, srcs = frontend.load(sources, model, (options or {}).get("libraries", ()))
        try:
            ode = structure.build_ode(dae.from_pymoca(pymoca_model, model), model)
        except ModelicaError as exc:
            raise frontend.located(exc, srcs, model) from None
        info = {"compiler": self.name, "sources": [str(f) for f in srcs.files]}
        return CompiledModel(model, ode, info)


@hookimpl
def mcl_compilers():
    return [CasadiCompiler]
