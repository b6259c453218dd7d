"""The Modelica library path: where classes that the sources only refer to are found.

Searched in order: directories given by the caller (``--library``, ``model.libraries:``), the
entries of ``MODELICAPATH`` (``os.pathsep``-separated, as in OpenModelica and Dymola), then the
project's own ``MCL`` library, which is installed with mcl as package data. An entry is either a
library itself (a directory with ``package.mo``) or a directory holding libraries
(``Name/package.mo``, ``Name.mo`` or ``Name 1.2.3/package.mo``).
"""
from __future__ import annotations

import os
import re
from pathlib import Path

from ..modelica import MCL_LIBRARY
from .sources import masked

ENV = "MODELICAPATH"


def distribution_versions(*names: str) -> dict[str, str]:
    """Installed versions of the named distributions (absent ones left out)."""
    from importlib import metadata

    out = {}
    for name in names:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return out


def mcl_version() -> str:
    """The version of the installed mcl distribution (the MCL library carries the same)."""
    return distribution_versions("mcl").get("mcl", "0+unknown")


def library_path(libraries=()) -> list[Path]:
    """The search path: ``libraries``, then ``MODELICAPATH``, then the MCL library's directory."""
    env = [p for p in os.environ.get(ENV, "").split(os.pathsep) if p.strip()]
    return [Path(p) for p in (*libraries, *env)] + [MCL_LIBRARY.parent]


def available(path) -> dict[str, Path]:
    """Top-level library name -> its directory or file, first entry of the path wins."""
    found: dict[str, Path] = {}
    for entry in map(Path, path):
        if (entry / "package.mo").is_file():
            found.setdefault(_bare(entry.name), entry)
            continue
        if not entry.is_dir():
            continue
        for child in sorted(entry.iterdir()):
            if child.is_dir() and (child / "package.mo").is_file():
                found.setdefault(_bare(child.name), child)
            elif child.suffix == ".mo" and child.is_file():
                found.setdefault(child.stem, child)
    return found


def _bare(dirname: str) -> str:
    """``Modelica 4.0.0`` -> ``Modelica``."""
    return dirname.split(" ")[0]


def _uses(library: Path) -> set[str]:
    """Libraries named in the ``uses`` annotation of a library's top package."""
    top = library / "package.mo" if library.is_dir() else library
    try:
        text = top.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return set()
    m = re.search(r"\buses\s*\(", text)
    if not m:
        return set()
    depth, k = 1, m.end()          # the annotation's balanced parentheses (each library has its own)
    while k < len(text) and depth:
        depth += {"(": 1, ")": -1}.get(text[k], 0)
        k += 1
    return set(re.findall(r"\b([A-Za-z_]\w*)\s*\(\s*version", text[m.end():k]))


def needed(texts, defined: set[str], model: str | None, path) -> list[Path]:
    """Libraries from ``path`` that the source ``texts`` (or the ``model`` name) refer to.

    A library is needed when its name is used as a qualified prefix (``MCL.Interfaces.Pin``) and
    the sources do not define that top-level class themselves; libraries a needed library
    ``uses`` come along.
    """
    libs = available(path)
    wanted = {model.split(".")[0]} if model else set()
    joined = "\n".join(texts)
    wanted |= {name for name in libs if re.search(rf"(?<![\w.]){re.escape(name)}\.\w", joined)}
    # a top-level class used by its bare name, as a type or a call (Complex a; Complex(0, 0))
    code = masked(joined)
    wanted |= {name for name in libs if re.search(rf"(?<![\w.]){re.escape(name)}(?=\s*\(|\s+[A-Za-z_]\w*\s*[;,(=\[])", code)}
    out: list[Path] = []
    todo = sorted(wanted - defined)
    while todo:
        name = todo.pop()
        if name in libs and libs[name] not in out:
            out.append(libs[name])
            todo.extend(sorted(_uses(libs[name]) - defined - {n for n in libs if libs[n] in out}))
    return out


def library_version(library: Path) -> str | None:
    """The ``version`` a library's top package declares in its annotation."""
    top = library / "package.mo" if library.is_dir() else library
    try:
        head = top.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return None
    m = re.search(r"\bversion\s*=\s*\"([^\"]+)\"", head)
    return m.group(1) if m else None


def uses_annotation(text: str, libraries=()) -> str:
    """``annotation(uses(Modelica(version="4.0.0"), ...))`` for the libraries ``text`` refers to
    (empty when it refers to none), with the versions of the copies on the library path."""
    found = available(library_path(libraries))
    used = [n for n in sorted(found) if re.search(rf"(?<![\w.]){re.escape(n)}\.\w", text)]
    parts = [f'{n}(version="{library_version(found[n]) or ""}")' for n in used]
    return f"annotation(uses({', '.join(parts)}))" if parts else ""
