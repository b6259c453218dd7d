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
from .sources import CONNECT, class_body, masked


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


#: a redeclared component or model class (not a package: a medium changes no member)
_REDECLARED = re.compile(r"\bredeclare\s+(?:(?:replaceable|final|each)\s+)*(\w+)")


def dangling_connect(model: str, docs: dict[Path, tuple[str, set]], search, names=None) -> tuple[str, str] | None:
    """(``file:line``, message) of the first ``connect`` of ``model``'s own text that names a
    member its component's class does not declare (``tank.heatTransfer.heatPort``, where the
    class has ``heatPorts``); else None. rumoca drops such a connection without a word where the
    component's class is a replaceable one (the fluid library's heat transfer and flow models),
    and the model compiles with a connector left open. ``names``: the compiled variables; only
    references none of them lies under are looked up, and only classes found whole are judged
    (a member of a conditional component switched off is declared, and is no error); None:
    the model did not compile, every reference is looked up."""
    from .library import available

    flat = {re.sub(r"\[[^\]]*\]", "", n) for n in names or ()}
    under = {".".join(n.split(".")[:k]) for n in flat for k in range(1, n.count(".") + 2)} if names is not None else None
    found = _model_text(model, docs)
    if found is None:
        return None
    path, text, start, body = found
    if any(m.group(1) not in ("package", "function", "type") for m in _REDECLARED.finditer(body)):
        return None
    lib = None
    for m in CONNECT.finditer(body):
        for ref in (m.group(1), m.group(2)):
            parts = re.sub(r"\s+", "", re.sub(r"\[[^\]]*\]", "", ref)).split(".")
            if len(parts) < 2 or (under is not None and ".".join(parts) in under):
                continue
            lib = lib or LibraryClasses.with_user(available(search), docs)
            why = _no_member(lib, model, parts, under)
            if why:
                line = text.count("\n", 0, start + m.start()) + 1
                return f"{path}:{line}", f"connect({m.group(1).strip()}, {m.group(2).strip()}): {why}"
    return None


def _model_text(model: str, docs) -> tuple[Path, str, int, str] | None:
    """(file, its masked text, where the class body begins, the body) of ``model`` in the user's files."""
    for f in _user_files(docs):
        text = masked(f.read_text(encoding="utf-8", errors="replace"))
        found = class_body(text, model.rsplit(".", 1)[-1])
        if found:
            return f, text, found[1], text[found[1]:found[2]]
    return None


def _no_member(lib: LibraryClasses, model: str, parts: list[str], under: set | None) -> str | None:
    """Why ``parts`` (a reference into a component of ``model``) names nothing: the first part
    its component's class does not declare, with the closest member it does; None where a class
    on the way is not found whole (a base class unresolved, a short class not followed) or the
    part before is not compiled (``under``: the compiled names' prefixes; None: not known)."""
    import difflib

    info = lib.find(model)
    for k, part in enumerate(parts):
        if info is None or not _whole(lib, info):
            return None
        members = {name: cls for _, cls, _, name, _ in lib.members(info)}
        if part not in members:
            if not k or (under is not None and ".".join(parts[:k]) not in under) or info.kind == "connector":
                return None     # (the model's own: rumoca's to name; an expandable connector's members are its connections)
            close = difflib.get_close_matches(part, members, n=1)
            hint = f" (did you mean {close[0]}?)" if close else ""
            return f"{'.'.join(parts[:k])} ({info.name}) has no member {part}{hint}"
        info = lib.followed(members[part])
    return None


def _whole(lib: LibraryClasses, info, seen=None) -> bool:
    """Whether every class ``info`` extends, and they in turn, is found."""
    seen = seen if seen is not None else set()
    if info.name in seen:
        return True
    seen.add(info.name)
    bases = lib.bases(info)
    return len(bases) == len(info.extends) and all(_whole(lib, b, seen) for b in bases)
