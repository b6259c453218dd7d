"""Why a model does not compile, in the engineer's words, where rumoca's message names a symptom:
for fewer equations than unknowns, the inputs of its components that nothing connects or sets;
for an unresolved reference into a component, the component's class that is not found.

rumoca reports the counts alone ("38 equations for 39 unknowns"); the usual cause is a block
input left unconnected (an equation per input is missing). The model's own text is read for
its components (:class:`.classes.LibraryClasses`, the classes of the user's files and the
libraries on the path) and for each input of theirs that no ``connect``, equation or modifier
names. Only the model's own components are read: a class it extends holds its connections.
"""
from __future__ import annotations

import re
from pathlib import Path

from .classes import LibraryClasses
from .sources import masked


def unconnected_inputs(model: str, docs: dict[Path, tuple[str, set]], search) -> list[str]:
    """``component.input`` names of ``model``'s own components that its text leaves unset
    (``docs``: the user's documents, as :func:`.rumoca_frontend.documents` gives them)."""
    from .library import available

    if not any(model.split(".")[0] in names for _, names in docs.values()):
        return []
    lib = LibraryClasses.with_user(available(search), docs)
    info = lib.find(model)
    if info is None:
        return []
    text = "\n".join(masked(f.read_text(encoding="utf-8", errors="replace")) for f in _user_files(docs))
    scope = model.rsplit(".", 1)[0] if "." in model else model
    out = []
    for prefixes, type_name, name, conditional in info.declarations:
        cls = lib.resolve(type_name, info.name, info) or lib.resolve(type_name, scope)
        if cls is None or conditional or cls.kind not in ("model", "block", "class"):
            continue
        out += [f"{name}.{port}" for port in _inputs(lib, cls) if not _named(text, name, port)]
    return out


def _inputs(lib: LibraryClasses, cls) -> list[str]:
    """The unconditional input connectors of class ``cls`` that it gives no value itself (a
    binding, a modifier of a class it extends)."""
    found, bound = [], lib.bound(cls)
    for prefixes, port_cls, _, port, conditional in lib.members(cls):
        if conditional or port in bound or "protected" in prefixes or "output" in prefixes or "parameter" in prefixes:
            continue
        short = (port_cls.short or "") if port_cls is not None else ""
        if "input" in prefixes or short.split()[:1] == ["input"]:
            found.append(port)
    return found


def _user_files(docs: dict[Path, tuple[str, set]]) -> list[Path]:
    """The files of the user's documents: each file given, and every file of a package directory."""
    return [p for p in docs if p.name != "package.mo"] + [f for p in docs if p.name == "package.mo"
                                                         for f in sorted(p.parent.rglob("*.mo"))]


def _absent_library(text: str, lib) -> str:
    """A hint where ``text`` imports from or names a library that is not on the library path
    (the MSL with no MODELICAPATH set), else ''."""
    roots = set(re.findall(r"\bimport\s+(?:\w+\s*=\s*)?([A-Za-z_]\w*)\s*\.", text))
    roots |= set(re.findall(r"(?<![\w.])(Modelica)\s*\.", text))
    missing = sorted(r for r in roots if r not in lib.libraries)
    if not missing:
        return ""
    return (f" (library {', '.join(missing)} is not on the library path: set MODELICAPATH or the run "
            "file's model.libraries)")


def _named(text: str, component: str, port: str) -> bool:
    """Whether ``text`` names ``component.port`` (an index anywhere), or sets it as a modifier."""
    index = r"(?:\s*\[[^\]]*\])?"
    return bool(re.search(rf"(?<![\w.]){component}{index}\s*\.\s*{port}\b", text)
                or re.search(rf"(?<![\w.]){component}{index}\s*\([^;]*?\b{port}\s*=", text))


#: types a declaration may name that are no class of a library
_BUILTIN = {"Real", "Integer", "Boolean", "String"}


def unfound_class(model: str, instance: str, docs: dict[Path, tuple[str, set]], search) -> tuple[str, str, str] | None:
    """(``file:line`` of the declaration, its class as written, a hint where a library the file
    uses is not on the path) where ``model`` declares
    ``instance`` of a class that neither the user's files nor the libraries on the path hold
    (a misspelt ``Basic.Resistr R1``: rumoca names the first ``connect`` that reaches into it
    instead); else None."""
    from .library import available

    lib = LibraryClasses.with_user(available(search), docs)
    info = lib.find(model)
    if info is None:
        return None
    scope = model.rsplit(".", 1)[0] if "." in model else model
    for _, type_name, name, _ in info.declarations:
        if name != instance or type_name in _BUILTIN:
            continue
        if lib.resolve(type_name, info.name, info) or lib.resolve(type_name, scope):
            return None
        declared = re.compile(rf"^(.*\b{re.escape(type_name)}\s+{re.escape(instance)}\b)", re.M)
        for f in _user_files(docs):
            text = masked(f.read_text(encoding="utf-8", errors="replace"))
            m = declared.search(text)
            if m:
                return f"{f}:{text.count(chr(10), 0, m.start()) + 1}", type_name, _absent_library(text, lib)
        return None
    return None
