"""The part of a library a model uses: rumoca indexes every file of the libraries in its root on
each compile (the whole MSL: ~5.5 s for a ladder of resistors, under 1 s for the files it uses;
it resolves only the classes used), so the root holds only the files the sources reach.

The files needed are found by closure over names, file by file: the names in the user's
sources, then in each file reached, its names, read as Modelica looks them up: through the
file's imports (always fully qualified), from the library's top, or in the packages enclosing
the file (``extends Interfaces.SISO`` in ``Modelica/Blocks/Continuous.mo``). Every package.mo
on the way to a file comes with it. A name read wrongly only costs time: a compile that fails
in the subset is retried with the whole libraries (:func:`.rumoca_frontend.load_ir`).
"""
from __future__ import annotations

import functools
import os
import re
from pathlib import Path

from .overlays import files_of, rewritten
from .sources import COMMENT_OR_STRING, KEYWORDS

#: a library smaller than this (bytes of .mo) is taken whole
WHOLE = 400_000

_NAME = re.compile(r"(?<![\w.])([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*)")
_IMPORT = re.compile(r"\bimport\s+(?:(\w+)\s*=\s*)?([\w.]+?)(\.\*|\.\{([^}]*)\})?\s*;")
_EXTENDS = re.compile(r"\bextends\s+([\w.]+)")

Unit = tuple[str, ...]          # a file below the library's directory: ("Blocks", "Continuous.mo")


def units_needed(texts, libraries: dict[str, Path]) -> dict[str, set[Unit] | None]:
    """Library name -> the files of it the ``texts`` reach (``None``: the whole library)."""
    out: dict[str, set[Unit] | None] = {}
    read: dict[tuple[str, Unit], bool] = {}        # (lib, file) -> read whole (or its head only)
    todo: list[tuple[str, Unit, bool]] = []

    def reach(lib: str, unit: Unit, whole: bool) -> None:
        if lib not in out:
            out[lib] = None if _whole(libraries[lib]) else set()
        if out[lib] is None:
            return
        for k in range(len(unit) - 1):      # the packages on the way: only their heads matter
            add(lib, (*unit[:k + 1], "package.mo"), False)
        add(lib, ("package.mo",), False)
        add(lib, unit, whole or unit[-1] != "package.mo")

    def add(lib, unit, whole):
        if read.get((lib, unit)) in (True, whole) or not libraries[lib].joinpath(*unit).is_file():
            return
        read[(lib, unit)] = whole
        out[lib].add(unit)
        todo.append((lib, unit, whole))

    def resolve(names, imports, scopes, lib=None):
        """Every reading of each name that may be Modelica's (a wrong one costs only time)."""
        aliases, wild = imports
        for name in names:
            first, *rest = name.split(".")
            full = [name.split(".")]
            if first in aliases:
                full.append([*aliases[first].split("."), *rest])
            for w in wild:
                top, *inner = w.split(".")
                if top in libraries and _child(libraries[top], [tuple(inner)], first) is not None:
                    full.append([top, *inner, first, *rest])
            for top, *path in full:
                if top in libraries:
                    reach(top, *locate(libraries[top], path))
            scope = _child(libraries[lib], scopes, first) if lib else None
            if scope is not None:
                reach(lib, *locate(libraries[lib], [*scope, first, *rest]))

    for text in texts:
        names, _, imports = _read(text)
        resolve(names, imports, [])
    while todo:
        lib, unit, whole = todo.pop()
        path = libraries[lib].joinpath(*unit)
        names, head, imports = _names_in(str(path), path.stat().st_mtime_ns)
        inner = unit[:-1]
        scopes = [inner[:k] for k in range(len(inner), -1, -1)]
        resolve(names if whole else head, imports, scopes, lib)
    return out


def locate(library: Path, parts) -> tuple[Unit, bool]:
    """The file holding the class ``library.parts`` (``Name.mo``, or the package.mo of the package
    it is declared in), and whether the class is declared in the file (not the package itself)."""
    cur, unit = library, ()
    for part in parts:
        d, f = cur / part, cur / f"{part}.mo"
        if (d / "package.mo").is_file():
            cur, unit = d, (*unit, part)
        elif f.is_file():
            return (*unit, f.name), True
        else:
            return (*unit, "package.mo"), True
    return (*unit, "package.mo"), False


def _child(library: Path, scopes, first: str) -> Unit | None:
    """The innermost of ``scopes`` (packages, innermost first) that has a child ``first``."""
    for scope in scopes:
        d = library.joinpath(*scope)
        if (d / first / "package.mo").is_file() or (d / f"{first}.mo").is_file():
            return scope
    return None


def _whole(library: Path) -> bool:
    if library.is_file():
        return True
    size = 0
    for dirpath, _, files in os.walk(library):
        size += sum(os.path.getsize(os.path.join(dirpath, f)) for f in files if f.endswith(".mo"))
        if size > WHOLE:
            return False
    return True


def _read(text: str):
    """The names a text uses; those its extends and import clauses use (all a package needs of
    the file declaring it when none of its classes there is used); its imports (alias -> full
    name, wildcard packages)."""
    code = COMMENT_OR_STRING.sub(" ", text)
    aliases, wild = {}, []
    for alias, target, star, group in _IMPORT.findall(code):
        if group:
            aliases.update({n.strip(): f"{target}.{n.strip()}" for n in group.split(",") if n.strip()})
        elif star:
            wild.append(target)
        else:
            aliases[alias or target.rsplit(".", 1)[-1]] = target
    head = set(_EXTENDS.findall(code)) | {t for _, t, _, _ in _IMPORT.findall(code)}
    return set(_NAME.findall(code)) - KEYWORDS, head, (aliases, wild)


@functools.lru_cache(maxsize=8192)
def _names_in(path: str, _mtime: int):
    return _read(Path(path).read_text(encoding="utf-8", errors="replace"))


def mirror(root: Path, library: Path, units: set[Unit]) -> None:
    """``root``: the directories of ``library`` holding ``units``, with links to those files
    (a file an overlay rewrites is written out: :mod:`.overlays`)."""
    root.mkdir(exist_ok=True)
    for unit in units:
        d = root.joinpath(*unit[:-1])
        d.mkdir(parents=True, exist_ok=True)
        order = library.joinpath(*unit[:-1], "package.order")
        if order.is_file() and not (d / "package.order").exists():
            (d / "package.order").symlink_to(order)
        _place(d / unit[-1], library.joinpath(*unit), root.name, unit)


def link_whole(root: Path, library: Path) -> None:
    """``root``: all of ``library`` as one link, or, where an overlay rewrites some of its
    files, as links beside the directories leading to those files, which are written out."""
    units = [u for u in files_of(root.name, library) if rewritten(root.name, u, library.joinpath(*u)) is not None]
    if not units:
        root.symlink_to(library)
        return

    def tree(dst: Path, src: Path, below: list[Unit], depth: int) -> None:
        dst.mkdir()
        heads = {u[depth] for u in below}
        for entry in src.iterdir():
            if entry.name not in heads:
                (dst / entry.name).symlink_to(entry)
            elif entry.is_dir():
                tree(dst / entry.name, entry, [u for u in below if u[depth] == entry.name], depth + 1)
            else:
                _place(dst / entry.name, entry, root.name, next(u for u in below if u[depth] == entry.name))

    tree(root, library, units, 0)


def _place(dst: Path, src: Path, library: str, unit: Unit) -> None:
    text = rewritten(library, unit, src)
    if text is None:
        dst.symlink_to(src)
    else:
        dst.write_text(text, encoding="utf-8")
