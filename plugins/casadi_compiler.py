"""The embedded default compiler: a Modelica front end -> CasADi DAE -> index reduction -> ODE.

``casadi`` uses the rumoca front end (real Modelica, the Modelica Standard Library included);
``pymoca`` keeps the older pymoca front end for comparison (chosen by name only).
"""
from __future__ import annotations

import time
from pathlib import Path

from mcl import hookimpl
from mcl.compile import Compiler


class CasadiCompiler(Compiler):
    name = "casadi"
    description = "rumoca front end + CasADi: index reduction, causalisation; in-process model and FMI 2.0 FMU"

    def available(self):
        try:
            import rumoca  # noqa: F401
        except ImportError:
            return False, "rumoca is not installed (pip install rumoca)"
        return True, ""

    def compile(self, sources: list[Path], model: str, options: dict | None = None):
        from mcl.compile import cache as compile_cache, rumoca_frontend, structure
        from mcl.compile.dae import eliminate_aliases
        from mcl.compile.equations import user_instances, with_equations
        from mcl.model import CompiledModel

        libraries = (options or {}).get("libraries", ())
        # "calls: kept": large functions stay calls (for C code: see rumoca_frontend.KEPT_CALL_PAST)
        keep_calls = (options or {}).get("calls") == "kept"
        prep = rumoca_frontend.prepare(sources, libraries, model)
        key = compile_cache.key_of(model=model, docs=sorted(h for h, _ in prep.docs.values()),
                                   libraries=compile_cache.library_fingerprint(prep.whole), compiler=self.name,
                                   **({"calls": "kept"} if keep_calls else {}))
        cached = compile_cache.load(key)
        if cached is not None:
            return cached
        start = time.perf_counter()
        ir, located = rumoca_frontend.load_ir(sources, model, libraries, prepared=prep)
        raw = rumoca_frontend.to_dae(ir, located, model, keep_calls)
        dae = eliminate_aliases(raw)
        ode = structure.build_ode(dae, model)
        resolve, in_library = _classes(located, model, prep.files, libraries)
        parts = _components(ir, model, resolve)
        components = with_equations(parts, raw, user_instances(raw, parts, in_library))
        seconds = time.perf_counter() - start
        files = sorted({path for path, _ in located.files.values()})
        info = {"compiler": self.name, "frontend": "rumoca", "sources": [str(f) for f in sources],
                "libraries": [str(p) for p in libraries], "calls": "kept" if keep_calls else "inlined",
                "files_read": len(files), "library_subset": ir.get("library_subset"), "units": dae.units, "descriptions": dae.descriptions,
                "compile_seconds": seconds}
        compiled = CompiledModel(model, ode, info, dae=raw, structure=components)
        compile_cache.store(key, compiled, seconds)
        return compiled


def _classes(located, model: str, user_files, libraries):
    """(paths -> {path: class}, paths -> {path: (class, whether a library on the path holds
    it)}): the classes of instances read from their declarations (the user's files first, then
    the package the model is in), over the texts stripped once for both."""
    from mcl.compile.components import class_resolver
    from mcl.compile.library import available, library_path

    user = {str(f): f.read_text(encoding="utf-8", errors="replace") for f in user_files}
    top = model.split(".")[0]
    rest = sorted(((p, t) for p, t in located.files.values() if p not in user), key=lambda pt: top not in pt[0])
    resolve = class_resolver(model, {**user, **dict(rest)}, libraries)
    libs = set(available(library_path(libraries)))

    def in_library(paths):
        return {n: (c, c.split(".")[0] in libs) for n, c in resolve(paths).items()}
    return resolve, in_library


def _components(ir: dict, model: str, resolve):
    """The model's component structure from the flat stage, with each component's class read
    from its declaration (``resolve``: :func:`_classes`)."""
    from mcl.compile.components import structure_of

    structure = structure_of(ir.get("flat") or {}, model)
    classes = resolve(structure.components)
    for name, comp in structure.components.items():
        comp.cls = classes.get(name, comp.cls)
    return structure


class PymocaCompiler(Compiler):
    name = "pymoca"
    description = "pymoca front end + CasADi (the earlier front end; no MSL)"
    automatic = False

    def compile(self, sources: list[Path], model: str, options: dict | None = None):
        from mcl.compile import dae, pymoca_frontend as frontend, structure
        from mcl.errors import ModelicaError
        from mcl.model import CompiledModel

        pymoca_model, srcs = frontend.load(sources, model, (options or {}).get("libraries", ()))
        try:
            ode = structure.build_ode(dae.from_pymoca(pymoca_model, model), model)
        except ModelicaError as exc:
            raise frontend.located(exc, srcs, model) from None
        info = {"compiler": self.name, "frontend": "pymoca", "sources": [str(f) for f in srcs.files]}
        return CompiledModel(model, ode, info)


@hookimpl
def mcl_compilers():
    return [CasadiCompiler, PymocaCompiler]
