"""Modelica front end on rumoca: sources (and the libraries they use) -> flat DAE IR -> :class:`Dae`.

rumoca (Rust) parses and flattens real Modelica — the Modelica Standard Library included:
conditional components, package constants, enumerations, connectors such as ``RealInput`` —
and classifies the flat model's variables (its ``dae`` stage). We read that IR, an expression
DAG whose coordinates point at variables, and build the scalar CasADi DAE our own chain
(index reduction, causalisation, CVODES, FMU export) takes from there. Nothing is guessed: a
construct the IR holds that we do not translate is refused with its name and file:line.
"""
from __future__ import annotations

import dataclasses
import functools
import hashlib
import itertools
import logging
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

from . import complexops, homotopy, overlays, scalarloops, tables, xorshift
from .arrays import alike, array_of, as_int, dims_of, flat, grown, modelica_size, multiply, repeated, shaped
from .balance import dangling_connect, unconnected_inputs, unfound_class
from .bindings import restated
from .classes import LibraryClasses
from .records import bound_records, copied, declared_records
from .redeclares import lifted, lifted_tree, tree_copy
from .scalarloops import scalarised
from .isolation import DEEP_STACK, ChildCrash, in_child
from .dae import (RELATION_TRUTH, Dae, check_balance, fold_initial_parameters, guard_branches, merge_common, resolve_parameters,
                  rows_reading)
from .sources import KEYWORDS, first_line
from ..errors import ConfigError, ModelicaError, UnsupportedConstruct

log = logging.getLogger(__name__)

_UNARY = {"negate": lambda a: -a, "plus": lambda a: a, "not": ca.logic_not}
_BINARY = {
    "add": ca.plus, "subtract": ca.minus, "multiply": multiply, "divide": ca.rdivide, "power": ca.power,
    "elementwise_add": ca.plus, "elementwise_subtract": ca.minus, "elementwise_multiply": ca.times,
    "elementwise_divide": ca.rdivide, "elementwise_power": ca.power,
    "greater": ca.gt, "greater_equal": ca.ge, "less": ca.lt, "less_equal": ca.le, "equal": ca.eq,
    "not_equal": ca.ne, "and": ca.logic_and, "or": ca.logic_or,
}
_RELATIONS = ("greater", "greater_equal", "less", "less_equal")
#: a held relation changes at an event only once lhs - rhs is past 0 by this times
#: 1 + |lhs| + |rhs| (see _hysteresis)
HYSTERESIS = 1e-10
#: exp's argument is cut where its value is still finite: past it exp is inf, and its derivative
#: in a quotient inf/inf, NaN (a regularised sign force, 2/(1 + exp(-v/c)) - 1 with c = 8e-4 m/s,
#: stopped the solver's Newton iteration once v < -0.6 m/s: IMC_Conveyor)
EXP_MAX = 709.0
#: coordinates that index the model's variables (the roles rumoca gives them)
_VARIABLE_KINDS = {"state", "algebraic", "output", "input", "parameter", "constant", "discrete_value",
                   "discrete_real", "variable"}
_FUNCTIONS = {
    "sin": ca.sin, "cos": ca.cos, "tan": ca.tan, "asin": ca.asin, "acos": ca.acos, "atan": ca.atan,
    "atan2": ca.atan2, "sinh": ca.sinh, "cosh": ca.cosh, "tanh": ca.tanh, "exp": lambda a: ca.exp(ca.fmin(a, EXP_MAX)), "log": ca.log,
    # sqrt offset by 1e-200, as in mcl's templates: sqrt(|h|)*tanh(h/s) at h = 0 (a tank that
    # starts empty, a learned outflow) differentiates to inf * 0 = NaN, offset to 5e99 * 0 = 0
    "log10": ca.log10, "sqrt": lambda a: ca.sqrt(a + 1e-200), "abs": ca.fabs, "sign": ca.sign, "floor": ca.floor,
    "ceil": ca.ceil, "min": lambda a, *b: ca.fmin(a, b[0]) if b else ca.mmin(a),
    "max": lambda a, *b: ca.fmax(a, b[0]) if b else ca.mmax(a), "sum": lambda a: ca.sum1(flat(a)), "size": modelica_size,
    "ones": lambda *n: ca.SX.ones(*dims_of(*n)), "zeros": lambda *n: ca.SX.zeros(*dims_of(*n)),
    "fill": lambda v, *n: ca.repmat(v, *dims_of(*n)),
    "scalar": lambda a: a[0], "vector": flat,
    # [a; b] and [a, b]: scalars and vectors are promoted to one-column matrices
    "promoted_cat1": lambda *a: ca.vertcat(*a), "promoted_cat2": lambda *a: ca.horzcat(*a),
    "product": lambda a: functools.reduce(ca.times, ca.vertsplit(flat(a)), ca.SX(1)), "noEvent": lambda a: a, "no_event": lambda a: a, "smooth": lambda _o, a: a,
    "homotopy": homotopy.homotopy, "div": lambda a, b: ca.sign(a / b) * ca.floor(ca.fabs(a / b)),   # truncation toward zero
    "mod": lambda a, b: a - ca.floor(a / b) * b, "rem": lambda a, b: ca.fmod(a, b), "integer": ca.floor,
    "asinh": ca.asinh, "acosh": ca.acosh, "atanh": ca.atanh, "exp10": lambda a: 10 ** a,
    "identity": lambda n: ca.SX.eye(as_int(n)), "transpose": lambda a: a.T,
    "cross": lambda a, b: ca.cross(flat(a), flat(b)), "skew": lambda a: ca.skew(flat(a)),
    "outerProduct": lambda a, b: ca.mtimes(flat(a), flat(b).T), "diagonal": lambda a: ca.diag(flat(a)),
    "symmetric": lambda a: ca.triu(a) + ca.triu(a, False).T, "ndims": lambda a: ca.SX(1 if a.size2() == 1 else 2),
    "linspace": lambda a, b, n: a + (b - a) * ca.SX(np.linspace(0, 1, as_int(n))),
    "matrix": lambda a: a, "linear_solve": lambda a, b: ca.solve(a, b),
}
_FUNCTIONS["outer_product"] = _FUNCTIONS["outerProduct"]


@dataclass
class Located:
    """Text of the files rumoca read, to turn spans and names into ``file:line``."""

    files: dict[int, tuple[str, str]]

    def find(self, pattern: str) -> str | None:
        """``file:line`` of the first line of a user's file (not a library's) matching ``pattern``."""
        return first_line(((path, text) for path, text in self.files.values()
                           if not path.startswith(VIRTUAL) and "/Modelica" not in path), pattern)

    def span(self, span) -> str | None:
        if not span or span.get("source") not in self.files:
            return None
        path, text = self.files[span["source"]]
        return f"{path}:{text.count(chr(10), 0, span.get('start', 0)) + 1}"


class _Front:
    """One rumoca session per library path: libraries are parsed once per process. The user's
    own documents are loaded into it; when one changed, or another file defines the same
    top-level class, the session is cleared first (rumoca refuses two definitions of a class)."""

    def __init__(self, roots: list[str]):
        import rumoca

        self.session = rumoca.Session(list(roots))
        self.roots = list(roots)
        self.docs: dict[str, str] = {}      # path -> content hash
        self.owner: dict[str, str] = {}     # top-level class -> path
        self.uses = False                   # the libraries named (:meth:`_use_libraries`)

    def compile(self, docs: dict[Path, tuple[str, set]], model: str, restate: bool = False, records=(),
                scalar: bool = False):
        """rumoca's compiled ``model`` from ``docs``; ``restate``: each document restated
        (:func:`.bindings.restated`); ``records``: its record components bound by declaration
        written as modifiers (:func:`.records.copied`); ``scalar``: its for-equations on arrays
        written element by element (:mod:`.scalarloops`)."""
        import rumoca

        mark, rewrite = _mark(restate, records), _rewrite(restate, tuple(records))
        calls = self._complex_calls(docs)
        if calls is not None:
            mark, rewrite = mark + complexops.MARK, _composed(rewrite, calls)
        if scalar:
            classes = self._classes(docs)
            mark, rewrite = mark + _SCALAR, _composed(rewrite, lambda text: scalarised(text, classes))
        if mark:
            docs = {p: (h + mark, names) for p, (h, names) in docs.items()}
        if any(self.docs.get(str(p), h) != h or any(self.owner.get(n, str(p)) != str(p) for n in names)
               for p, (h, names) in docs.items()):
            self.session.clear()
            self.docs, self.owner, self.uses = {}, {}, False
        for p, (h, names) in docs.items():
            if str(p) not in self.docs:
                if p.name == "package.mo" and not self.uses:
                    self._use_libraries()
                try:   # registers the document; naming no class of it, nothing is compiled yet
                    self._load(p, h, "MclNoClass_", rewrite)
                except rumoca.RumocaError:
                    pass
                self.docs[str(p)] = h
                self.owner.update({n: str(p) for n in names})
        top = model.split(".")[0]
        if top in self.owner:
            p = Path(self.owner[top])
            return self._load(p, self.docs[str(p)], model, rewrite)
        # a class of a library on the path: compiled through a one-line model extending it
        stub = f"model {ENTRY}\n  extends {model};\nend {ENTRY};\n"
        return self.session.loads(stub, model=ENTRY, filename=f"{VIRTUAL}/{ENTRY}.mo")

    def _complex_calls(self, docs: dict[Path, tuple[str, set]]):
        """The rewrite of Complex operators as calls (:mod:`.complexops`), for documents that use
        Complex; else None."""
        if not any(complexops.MENTIONS.search(text) for text in _doc_texts(docs)):
            return None
        classes = self._classes(docs)
        return lambda text: complexops.rewrite(text, classes)

    def _classes(self, docs: dict[Path, tuple[str, set]]) -> LibraryClasses:
        """The classes of the libraries on the path and of the user's documents."""
        from .library import available

        return LibraryClasses.with_user(available(self.roots), docs)

    def _use_libraries(self):
        """Register a document that imports every library of the roots. rumoca reads the
        libraries a package directory uses from its ``package.mo`` alone: an import in another
        file of the tree is unresolved where ``package.mo`` names no library (no ``uses``
        annotation), unless a document loaded before named it."""
        import rumoca

        self.uses = True
        names = sorted({Path(e).stem for r in self.roots for e in os.listdir(r)} - KEYWORDS)
        stub = "".join(f"  import {n};\n" for n in names if n.isidentifier())
        try:
            self.session.loads(f"model {USES}\n{stub}end {USES};\n", model="MclNoClass_",
                               filename=f"{VIRTUAL}/{USES}.mo")
        except rumoca.RumocaError:
            pass

    def reset(self):
        """Forget every document (after rumoca failed inside, its session is not trusted)."""
        self.session.clear()
        self.docs, self.owner, self.uses = {}, {}, False

    def _load(self, path: Path, digest: str, model: str, rewrite=None):
        """A package directory is read as a tree; a single file under a name of its own, so that
        rumoca does not also read the files beside it (a run directory holds many). ``rewrite``:
        the change to its text that ``digest``'s mark stands for (:func:`_rewrite`)."""
        if path.name == "package.mo":
            tree = lifted_tree(path, _copies(digest), rewrite)
            return self.session.load(str(tree), model=model)
        text = lifted(path.read_text(encoding="utf-8", errors="replace"))
        return self.session.loads(rewrite(text) if rewrite else text, model=model,
                                  filename=virtual_name(path, digest))


#: rumoca's errors on the constructs :func:`.bindings.restated` writes in forms it reads
_RESTATE_ON = re.compile(r"unbalanced model|expression shape mismatch|without a checked DAE owner|"
                         r"unresolved Flat reference|function shape proof|found Enumeration|unknown modifier|"
                         r"resolved variable-reference operand")
#: the digest's mark of a document compiled restated (:func:`.bindings.restated`)
_RESTATED = "+restated"
#: the mark of a document compiled with its for-equations on arrays element by element
_SCALAR = "+scalar" + hashlib.sha256(Path(scalarloops.__file__).read_bytes()).hexdigest()[:8]
#: rumoca's error on a for-equation on an array of one element (:mod:`.scalarloops`)
_SCALAR_ON = "expected a scalar expression"
#: the length of a document's own digest (sha256, hex), before the marks of its rewrites
_DIGEST = 64


def _mark(restate: bool, records) -> str:
    """The mark a document's digest carries when compiled rewritten (:func:`_rewrite`): a
    document is loaded again when its mark changes."""
    mark = _RESTATED if restate else ""
    return mark + ("+records" + hashlib.sha256(repr(records).encode()).hexdigest()[:12] if records else "")


@functools.lru_cache(maxsize=32)
def _rewrite(restate: bool, records: tuple):
    """The rewrite of a document's text: restated, and its ``records`` copied as modifiers
    (:func:`.records.copied`); None for the text as written. (One function for the same
    arguments: a tree's lifted copy is looked up by it.)"""
    if restate:
        return lambda text: copied(restated(text), records)
    if records:
        return lambda text: copied(text, records, calls=False)
    return None


def _composed(first, then):
    """``then`` after ``first`` (None: nothing)."""
    return then if first is None else (lambda text: then(first(text)))


def _doc_texts(docs: dict[Path, tuple[str, set]]):
    """The text of every file of the user's documents (a package directory's, each)."""
    for path in docs:
        for f in sorted(path.parent.rglob("*.mo")) if path.name == "package.mo" else [path]:
            yield f.read_text(encoding="utf-8", errors="replace")


def _restatable(docs: dict[Path, tuple[str, set]], records=()) -> bool:
    """Whether restating (and ``records`` copied: :func:`.records.copied`) changes any of the
    documents' files (:meth:`_Front._load`): a model unbalanced for another reason is not
    compiled twice."""
    for text in _doc_texts(docs):
        try:
            if copied(restated(text), records) != text:
                return True
        except Exception:     # noqa: BLE001 - text rumoca refused, which a rewrite misread: no retry
            return False
    return False


VIRTUAL = "/mcl-source"
#: rumoca's parser and passes recurse as deep as the source nests: they run in one thread of
#: their own with a large stack (isolation.DEEP_STACK; rumoca's objects may not change thread)
_RUMOCA_POOL = None


def in_rumoca_thread(fn, *args):
    """``fn(*args)`` in the thread that owns every rumoca object of this process."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    global _RUMOCA_POOL
    if _RUMOCA_POOL is None:
        old = threading.stack_size(DEEP_STACK)
        try:
            pool = ThreadPoolExecutor(1, thread_name_prefix="rumoca")
            pool.submit(lambda: None).result()      # the thread starts now, with the large stack
        finally:
            threading.stack_size(old)
        _RUMOCA_POOL = pool
    return _RUMOCA_POOL.submit(_without_modelicapath, fn, *args).result()


def _without_modelicapath(fn, *args):
    """``fn(*args)`` with MODELICAPATH out of the environment: rumoca reads it itself, and the
    libraries on it are already in the session's root (first entry winning); read twice, a
    library such as the MSL's Complex.mo is a duplicate class to rumoca."""
    import os

    saved = os.environ.pop("MODELICAPATH", None)
    try:
        return fn(*args)
    finally:
        if saved is not None:
            os.environ["MODELICAPATH"] = saved


def _real(path: str, roots: str) -> str:
    """A library file by its real path, not through the links of a library root under ``roots``
    (a file an overlay rewrote, held in the root itself: the library's file it stands for)."""
    if not path.startswith(roots):
        return path
    real = os.path.realpath(path)
    if real.startswith(roots) and os.path.isdir(os.path.dirname(path)):
        beside = next((e for e in os.scandir(os.path.dirname(path)) if e.is_symlink()), None)
        if beside is not None:
            return os.path.join(os.path.dirname(os.path.realpath(beside.path)), os.path.basename(path))
    return real


def _copies(digest: str) -> Path:
    """Where the lifted copy of a package directory of content ``digest`` is made: a rewritten
    copy (:func:`_mark`) in a folder named by the rewrite and the rewriting code's version."""
    place = roots_dir() / "lifted" / digest[:16]
    mark = digest[_DIGEST:]
    if not mark:
        return place
    return place / ("rewritten-" + hashlib.sha256((mark + overlays.VERSION).encode()).hexdigest()[:12])


def virtual_name(path: Path, digest: str) -> str:
    return f"{VIRTUAL}/{digest[:16]}/{path.name}"


ENTRY = "MclEntry_"
#: the document naming the libraries of the roots (:meth:`_Front._use_libraries`)
USES = "MclUses_"
#: the names of the relations held between events, among the discrete states
HELD_PREFIX = "$rel"


class FrontEndCrash(Exception):
    """rumoca panicked (a Rust panic): its message, to be said in the model's words."""


_FRONTS: dict[tuple, _Front] = {}


def _front(roots) -> _Front:
    """The session for ``roots`` (called in the rumoca thread). The sessions live as long as the
    process: the table is never freed, so no session is dropped by another thread at exit."""
    if not _FRONTS:
        import ctypes

        ctypes.pythonapi.Py_IncRef(ctypes.py_object(_FRONTS))
    key = tuple(roots)
    if key not in _FRONTS:
        _FRONTS[key] = _Front(list(roots))
    return _FRONTS[key]


def documents(paths) -> tuple[dict[Path, tuple[str, set]], list[Path]]:
    """The top-level documents of ``paths`` (a package directory's root ``package.mo``, or a
    file of top-level classes) with their content hash and class names, and every file."""
    from .sources import checked, expand, top_level_names

    files = expand(checked(paths))
    docs: dict[Path, tuple[str, set]] = {}
    for f in files:
        root = f.parent if f.name == "package.mo" else None
        text = f.read_text(encoding="utf-8", errors="replace")
        if re.search(r"^\s*within\s+\w", text, re.M) or root is not None:
            d = f.parent
            while (d.parent / "package.mo").is_file():     # up to the top package of the directory tree
                d = d.parent
            if not (d / "package.mo").is_file():
                continue
            top = d / "package.mo"
            names = {d.name.split(" ")[0]}
        else:
            top, names = f, top_level_names([f], {f: text})
        if top not in docs:
            h = hashlib.sha256()
            for part in sorted(top.parent.rglob("*.mo")) if top.name == "package.mo" else [top]:
                h.update(part.read_bytes())
            docs[top] = (h.hexdigest(), names)
    return docs, files


def library_roots(libraries=(), shadowed=(), used=None, texts=None) -> list[str]:
    """One rumoca root: a directory of links to the libraries on the path, first entry winning,
    less those the sources define themselves (``shadowed``: the user's copy is the one used);
    with ``used`` (library paths), only those: rumoca parses every library of its root, so a
    model that uses none of the MSL must not have it there (89 s and 1.75 GB otherwise); with
    ``texts`` (the sources), only the files of them the texts reach (:mod:`.subset`)."""
    import tempfile

    from .library import available, library_path
    from .subset import link_whole, mirror, units_needed

    libs = {n: p.resolve() for n, p in available(library_path(libraries)).items() if n not in shadowed}
    if used is not None:
        keep = {Path(u).resolve() for u in used}
        libs = {n: p for n, p in libs.items() if p in keep}
    units = units_needed(texts, libs) if texts is not None else {}
    parts = {n: sorted(units[n]) if units.get(n) is not None else None for n in libs}
    key = hashlib.sha256(repr((sorted((n, str(p), parts[n]) for n, p in libs.items()), overlays.VERSION))
                         .encode()).hexdigest()[:16]
    base = roots_dir()
    root = base / key
    if not root.is_dir():
        tmp = Path(tempfile.mkdtemp(dir=base, prefix=".new-"))
        for n, p in libs.items():
            if parts[n] is None and p.is_dir():
                link_whole(tmp / n, p)
            elif parts[n] is None:
                (tmp / f"{n}.mo").symlink_to(p)
            else:
                mirror(tmp / n, p, set(parts[n]))
        try:
            tmp.rename(root)
        except OSError:        # another process made it first
            import shutil

            shutil.rmtree(tmp, ignore_errors=True)
    return [str(root)]


def roots_dir() -> Path:
    """Where the library roots are made: rumoca keeps what it learnt of a library (parsed files,
    semantic summaries) in its own cache, keyed by the root's path, so the roots stay in one
    place per user (not in ``MCL_CACHE_DIR``: a new compile cache would make rumoca analyse the
    MSL again, ~10 s); mcl's cache directory when that place cannot be written."""
    from .cache import base_dir

    home = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "mcl" / "roots"
    for place in (home, base_dir() / "roots"):
        try:
            place.mkdir(parents=True, exist_ok=True)
            if os.access(place, os.W_OK):
                return place
        except OSError:
            continue
    raise ConfigError(f"no writable cache directory for the library roots ({home}; set MCL_CACHE_DIR)")


@dataclass
class Prepared:
    """What a compile reads: the user's documents (hash, class names), every user file, and the
    rumoca root of the libraries (``whole``); computed once for the cache key and the compile.
    ``roots``, the root of only the library files the sources reach, is made when a compile
    needs it: reading the closure costs ~2 s for an MSL model, a cache hit nothing."""

    docs: dict[Path, tuple[str, set]]
    files: list[Path]
    whole: list[str]        # the whole libraries: a compile failing in ``roots`` is retried there
    texts: list[str] | None = None       # the sources and the model's name (None: no subset)
    #: the library path when prepared: ``roots`` is made in the rumoca thread, which runs
    #: without MODELICAPATH (read there, the MSL on it was missing and every subset empty)
    search: tuple = ()
    shadowed: set = field(default_factory=set)
    used: list | None = None

    @property
    def virtual(self) -> dict[str, str]:
        """The names single files are registered under, and the files of a package directory's
        lifted copy (:func:`.redeclares.lifted_tree`) -> their real paths."""
        out = {}
        for p, (h, _) in self.docs.items():
            if p.name != "package.mo":
                out[virtual_name(p, h)] = str(p)
                continue
            base = _copies(h)
            rewritten = [d for d in base.glob("rewritten-*") if d.is_dir()] if base.is_dir() else []
            for place in (base, *rewritten):
                copy = tree_copy(p, place).parent
                out.update({str(copy / f.relative_to(p.parent)): str(f) for f in p.parent.rglob("*.mo")})
        return out

    @functools.cached_property
    def roots(self) -> list[str]:
        if self.texts is None:
            return self.whole
        return library_roots(self.search, shadowed=self.shadowed, used=self.used, texts=self.texts)


def prepare(paths, libraries=(), model: str | None = None) -> Prepared:
    """The user's documents and the libraries the compile needs: those the sources (or the
    ``model`` name) refer to, with the ones they use; every library on the path when neither
    says (no sources and no model name)."""
    from .library import library_path, needed

    docs, files = documents(paths)
    defined = {n for _, names in docs.values() for n in names}
    search = tuple(library_path(libraries))
    used, texts = None, None
    if files or model:
        texts = [f.read_text(encoding="utf-8", errors="replace") for f in files]
        if any(complexops.MENTIONS.search(t) for t in texts):
            texts.append(f"{complexops.REAL} {complexops.IMAG}")     # what the rewrite of Complex operators calls
        used = needed(texts, defined, model, search)
        texts.append(model or "")
    return Prepared(docs, files, library_roots(search, shadowed=defined, used=used), texts,
                    search, defined, used)


#: a compile error of a library subset that may be a file the subset missed
_MISSED = re.compile(r"not found|unresolved (?:component reference|type|class)|does not exist", re.IGNORECASE)


def load_ir(paths, model: str, libraries=(), prepared: Prepared | None = None) -> tuple[dict, Located]:
    """rumoca's DAE-stage IR of ``model`` and the text of the files it read."""
    import rumoca

    from .library import available

    prep = prepared or prepare(paths, libraries, model)
    libs = available(prep.search)     # (the rumoca thread runs without MODELICAPATH)
    top = model.split(".")[0]
    if not any(top in names for _, names in prep.docs.values()):
        if top not in libs:
            raise ModelicaError(f"class '{model}' not found: no source and no library on the path "
                                f"defines '{top}'", where=str(paths[0]) if paths else None)
    real = prep.virtual

    prep.roots      # (the library subset made here, in this process's settings, and sent with prep)
    try:
        # (in a child process: rumoca keeps each model's memory for the life of its process)
        ir = in_child(in_rumoca_thread, _work, prep, model, libs)
    except rumoca.RumocaError as exc:
        raise _with_suspects(_located_error(exc, model, prep.files, real), exc, model, prep) from None
    except (FrontEndCrash, ChildCrash) as exc:
        raise UnsupportedConstruct(f"cannot compile {model}: the Modelica front end (rumoca) stopped on an "
                                   f"internal error ({exc}); a construct of the model it cannot translate",
                                   where=str(prep.files[0]) if prep.files else None) from None
    dangling = _dangling(model, prep, ir["flat"].get("variables", {}))
    if dangling:
        raise ModelicaError(f"cannot compile {model}: {dangling[1]}", where=dangling[0])
    roots = str(roots_dir())
    located = Located({f[0]: (real.get(f[1]) or _real(f[1], roots), f[2]) for f in ir.get("source_map", {}).get("files", [])})
    return ir, located


def _work(prep: Prepared, model: str, libs: dict) -> dict:
    """rumoca's IR of ``model`` (run in the rumoca thread of a child process: see load_ir)."""
    import rumoca

    subset = prep.whole != prep.roots
    try:
        compiled = _compile(prep, prep.roots, model, libs)
    except rumoca.RumocaError as first:
        if not subset:
            raise
        try:
            compiled, subset = _compile(prep, prep.whole, model, libs), False   # a file the subset missed
        except rumoca.RumocaError:
            # the whole libraries lack the subset's Complex rewrites: their error is the
            # subset's own unless the subset's names a class it did not find
            if _MISSED.search(str(first)):
                raise
            raise first from None
    flat = compiled.to_dict("flat")
    records = _bound_records(prep, flat, libs)
    if records:
        try:
            compiled = _compile(prep, prep.whole if not subset else prep.roots, model, libs, records)
            flat = compiled.to_dict("flat")
        except rumoca.RumocaError as exc:
            log.warning("%s: records passed whole may have lost array members or sizes (rumoca refused "
                        "them written as modifiers: %s)", model, _first_line(exc))
    again = _outer_restated(prep, prep.whole if not subset else prep.roots, model, flat)
    if again is not None:
        compiled, flat = again, again.to_dict("flat")
    ir = compiled.to_dict("dae")
    ir["library_subset"] = subset
    # the flat stage names each equation's origin (a component's own equation, a flow
    # sum, a connection) and each variable's flow prefix: the model's component structure
    ir["flat"] = flat
    return ir


def _bound_records(prep: Prepared, flat: dict, libs: dict[str, Path]) -> tuple:
    """The record components of ``flat``, and the records passed whole in modifications, where
    one of the user's files binds one to another record (:mod:`.records`): rumoca reads them
    right only written as modifiers."""
    texts = list(_doc_texts(prep.docs))
    passed = [r for r in _declared_records(texts, prep, libs) if not r[0]]
    records = bound_records(flat, passed)
    return records if any(copied(text, records, calls=False) != text for text in texts) else ()


def _declared_records(texts: list[str], prep: Prepared, libs: dict[str, Path]) -> tuple:
    """:func:`.records.declared_records` of the user's files' ``texts``."""
    return declared_records(texts, LibraryClasses.with_user(libs, prep.docs))


def _compile(prep: Prepared, roots: list[str], model: str, libs: dict[str, Path], records=()):
    """rumoca's compiled ``model``. Where rumoca cannot lower a discrete signal fanned out to
    vector elements (:mod:`.fanout`): a copy of the model with those connections as equations.
    Where it needs the value of a parameter declared with a start value alone (a sample()
    time): the model with the start values as the parameters' values, as other tools take
    them (with a warning)."""
    import rumoca

    front = _front(roots)
    try:
        return _guarded(front, lambda: front.compile(prep.docs, model, records=records))
    except rumoca.RumocaError as exc:
        restate = _RESTATE_ON.search(str(exc)) is not None
        if restate:
            records = records or _declared_records(list(_doc_texts(prep.docs)), prep, libs)
        if restate and _restatable(prep.docs, records):
            # a construct rumoca misreads (:func:`.bindings.restated`): the model again with its
            # files restated, else rumoca's own error
            try:
                compiled = _guarded(front, lambda: front.compile(prep.docs, model, restate=True, records=records))
            except rumoca.RumocaError:
                raise exc from None
            log.info("%s: compiled restated as rumoca reads it (bindings to calls as f(...) + 0, array "
                     "modifiers of component arrays element by element, while loops as bounded for loops, Integer() of "
                     "an enumeration as comparisons, replaceable components' own modifiers in short classes, loops on der() of "
                     "a component array's members unrolled)", model)
            return compiled
        if _SCALAR_ON in str(exc):
            try:
                return _guarded(front, lambda: front.compile(prep.docs, model, records=records, scalar=True))
            except rumoca.RumocaError:
                raise exc from None
        if _UNVALUED.search(str(exc)):
            compiled = _started(front, prep, model, libs, exc)
            if compiled is None:
                raise
            return compiled
        source = _fanned_out(prep, model, libs) if "Appendix B" in str(exc) else None
        if source is None:
            raise
        try:
            return _guarded(front, lambda: front.session.loads(source, model=_in_package(model, ENTRY),
                                                               filename=f"{VIRTUAL}/{ENTRY}.mo"))
        except rumoca.RumocaError:
            raise exc from None


def _outer_bound(flat: dict) -> dict[str, str]:
    """{parameter: the inner's parameter it is bound to} for the parameters that pick branches of
    the model (if-equations on them: which equations it has) and that a class binds to an outer
    component's parameter the user modified (``energyDynamics = system.energyDynamics``, with
    ``inner System system(energyDynamics = FixedInitial)``), or that read such a parameter
    through the outer itself (``if world.driveTrainMechanics3D``). rumoca 0.10.2 picks those
    branches with the outer class's defaults (DynamicFreeInitial: a tank's initial equations
    are dropped without a word); the same binding given as a modifier from the model is read
    right, also on the outer's instance in the component (``cell(settings(fixedStart = ...))``)."""
    variables = flat.get("variables") or {}
    finals = flat.get("variable_final_flags") or {}
    picked = {ref[0] for sel in flat.get("parameter_branch_selections") or [] for ref in sel.get("references", [])}
    modified = lambda n: bool((variables.get(n) or {}).get("binding_from_modification"))   # noqa: E731
    bound = {}
    for name in sorted(picked):
        if name not in variables and "[" not in name:
            # read through the outer itself (cell.settings.fixedStart): rumoca reads it from an
            # instance of the outer's class; a modifier of that instance is read
            parts = name.split(".")
            inner = next((".".join(parts[k:]) for k in range(1, len(parts) - 1) if modified(".".join(parts[k:]))), None)
            if inner is not None:
                bound[name] = inner
            continue
        for _ in range(8):          # along a chain of bindings (a pipe's flow model's, from the pipe's)
            v = variables.get(name)
            ref = ((v or {}).get("binding") or {}).get("VarRef")
            if not ref or ref.get("subscripts") or "[" in name:
                break
            target = ref["name"]["name"]
            owner = name.rpartition(".")[0]
            if (not v.get("binding_from_modification") and owner and not target.startswith(owner + ".")
                    and modified(target)
                    and not v.get("is_protected") and not finals.get(name)):
                bound[name] = target
                break
            name = target
    return bound


def _outer_restated(prep: Prepared, roots: list[str], model: str, flat: dict):
    """rumoca's compiled ``model`` with :func:`_outer_bound`'s bindings restated as modifiers of
    an entry model extending it, or None where there are none or rumoca refuses them."""
    import rumoca

    bound = _outer_bound(flat)
    if not bound:
        return None
    try:
        return _modified(_front(roots), model, bound)
    except rumoca.RumocaError as exc:
        log.warning("%s: the branches chosen by %s may follow the outer class's defaults (rumoca: %s)",
                    model, ", ".join(bound), _first_line(exc))
        return None


def _guarded(front: _Front, compile_):
    """``compile_()``; a Rust panic in rumoca (pyo3's PanicException, a BaseException) is a
    :class:`FrontEndCrash`, and the session it happened in is reset."""
    try:
        return compile_()
    except BaseException as exc:
        if type(exc).__name__ != "PanicException":
            raise
        front.reset()
        raise FrontEndCrash(_first_line(exc, "panic")) from None


def _first_line(exc, empty: str = "") -> str:
    lines = str(exc).strip().splitlines()
    return lines[0] if lines else empty


def _in_package(model: str, name: str) -> str:
    package = model.rpartition(".")[0]
    return f"{package}.{name}" if package else name


#: rumoca needs a parameter's value that only has a start value
_UNVALUED = re.compile(r"not parameter-evaluable: unknown variable: ([\w.]+)")
#: parameters given their start values in one compile, at most (each found by one failure)
MAX_STARTED = 8


def _started(front: _Front, prep: Prepared, model: str, libs: dict[str, Path], exc):
    """rumoca's compiled model extending ``model`` that gives each parameter rumoca needs, and
    that has only a start value, that value; None where one has no literal start value."""
    import rumoca

    from .classes import LibraryClasses

    lib, values = LibraryClasses(libs), {}
    for _ in range(MAX_STARTED):
        hit = _UNVALUED.search(str(exc))
        if hit is None:
            break
        name = hit[1]
        value = None if name in values else _start_value(name, model, prep, lib)
        if value is None:
            return None
        values[name] = value
        try:
            compiled = _modified(front, model, values)
        except rumoca.RumocaError as again:
            exc = again
            continue
        for n, v in values.items():
            log.warning("parameter %s has no value: its start value %s is used", n, v)
        return compiled
    return None


def _modified(front: _Front, model: str, values: dict[str, str]):
    """rumoca's compiled :data:`ENTRY`, ``model`` extended with ``values`` as its modifiers."""
    source = f"model {ENTRY}\n  extends {model}({_modifiers(values)});\nend {ENTRY};\n"
    return _guarded(front, lambda: front.session.loads(source, model=ENTRY, filename=f"{VIRTUAL}/{ENTRY}.mo"))


def _modifiers(values: dict[str, str]) -> str:
    """``{"p.period": "1", "p.startTime": "0", "T": "2"}`` -> ``p(period=1, startTime=0), T=2``."""
    tree: dict = {}
    for name, value in values.items():
        *path, last = name.split(".")
        node = tree
        for part in path:
            node = node.setdefault(part, {})
        node[last] = value

    def text(node):
        return ", ".join(f"{k}({text(v)})" if isinstance(v, dict) else f"{k}={v}" for k, v in node.items())
    return text(tree)


def _start_value(name: str, model: str, prep: Prepared, lib) -> str | None:
    """The literal start value parameter ``name`` (a path in ``model``) is declared with."""
    from .components import _Texts, declared_classes

    *path, param = name.split(".")
    texts = _model_texts(prep, model, lib)
    owner = declared_classes([".".join(path)], model, texts, lib=lib).get(".".join(path)) if path else model
    if owner is None:
        return None
    info = lib.find(owner)
    if info is None:                      # a class of the user's own files
        body = _Texts(texts).class_body(owner.split(".")[-1])
        info = lib.parse(owner, "model", body) if body is not None else None
    return lib.start_of(info, param) if info is not None else None


def _fanned_out(prep: Prepared, model: str, libs: dict[str, Path]) -> str | None:
    """The source of :data:`ENTRY` in ``model``'s package: the model with its fanned-out
    discrete connections as equations (:mod:`.fanout`); None where it has none."""
    from .classes import LibraryClasses
    from .fanout import rewritten_entry

    lib = LibraryClasses(libs)
    return next((src for text in _model_texts(prep, model, lib).values()
                 if (src := rewritten_entry(model, text, ENTRY, lib)) is not None), None)


def _model_texts(prep: Prepared, model: str, lib) -> dict[str, str]:
    """{path: text} of the files that may define ``model``: the user's (as :func:`prepare` read
    them), then, for a library's class, the library file that holds it."""
    texts = (dict(zip(map(str, prep.files), prep.texts)) if prep.texts is not None else
             {str(f): f.read_text(encoding="utf-8", errors="replace") for f in prep.files})
    located = lib.file_of(model) if model.split(".")[0] not in prep.shadowed else None
    if located is not None and located[0].is_file():
        texts.setdefault(str(located[0]), located[0].read_text(encoding="utf-8", errors="replace"))
    return texts


# rumoca's words -> (error class, our words, a pattern that finds the place in the user's files)
_KNOWN = [
    (r"unbalanced model: (\d+) equations, (\d+) unknowns", ModelicaError,
     lambda m, model: f"model {model} is unbalanced: {m[1]} equations for {m[2]} unknowns", None),
    (r"der\(\.\.\.\) must have exactly one", UnsupportedConstruct,
     lambda m, model: "unsupported Modelica construct: der() of an expression (write der(x) of a variable)",
     r"\bder\s*\(\s*[^)]*[*/+-]"),
    (r"resolve/parse failed", ModelicaError, None, None),
    # a parameter declared with a start value and no binding, where its value must be known
    # when compiling (a sample() interval or start, an array size): other tools warn and take
    # the start value; rumoca stops
    (r"not parameter-evaluable: unknown variable: ([\w.]+)", ModelicaError,
     lambda m, model: f"parameter {m[1]} of {model} has no value, only a start value, and the compiler needs "
                      f"it (a sample() time, an array size): set it, e.g. {_modifiers({m[1]: '...'})}",
     lambda m: rf"\b{re.escape(m[1].split('.')[0])}\b\s*[(;\[]"),
]


def _find(files: list[Path], pattern: str) -> str | None:
    return first_line(((f, f.read_text(errors="replace")) for f in files), pattern)


def _with_suspects(err: ModelicaError, exc, model: str, prep: Prepared) -> ModelicaError:
    """``err`` of a model with fewer equations than unknowns with the inputs of its components
    that nothing connects (:mod:`.balance`): the usual cause, which rumoca's counts do not name;
    an unresolved reference into a component whose class is not found, at its declaration."""
    ref = re.search(r"unresolved component reference: '(\w+)[.\[']", str(exc))
    if ref:
        try:
            found = unfound_class(model, ref[1], prep.docs, prep.search)
        except Exception:      # noqa: BLE001 - a hint only: rumoca's message stands
            found = None
        if found:
            return type(err)(f"cannot compile {model}: class {found[1]} of {ref[1]} is not found{found[2]}", where=found[0])
    counts = re.search(r"unbalanced model: (\d+) equations, (\d+) unknowns", str(exc))
    # (a connection rumoca dropped leaves its connectors unbalanced)
    dangling = _dangling(model, prep) if counts is not None else None
    if dangling:
        return type(err)(f"cannot compile {model}: {dangling[1]}", where=dangling[0])
    if counts is None or int(counts[1]) >= int(counts[2]):
        return err
    try:
        loose = unconnected_inputs(model, prep.docs, prep.search)
    except Exception:      # noqa: BLE001 - a hint only, read from text mcl did not check: the counts stand
        return err
    if not loose:
        return type(err)(err.message + _COMPLEX_HINT, where=err.where) if _in_complex(model, prep) else err
    more = f" and {len(loose) - 8} more" if len(loose) > 8 else ""
    return type(err)(f"{err.message}: nothing connects or sets the input{'s' * (len(loose) > 1)} "
                     f"{', '.join(loose[:8])}{more}", where=err.where)


_COMPLEX_HINT = ("; rumoca 0.10 translates an operator on Complex values (a + b, 2*a) as one equation short, "
                 "and mcl writes it as a call (Complex.'+'(a, b)) only in the statements it reads (not through "
                 "an array of arrays, nor in a function it cannot find): write the others with the calls")


def _dangling(model: str, prep: Prepared, names=None) -> tuple[str, str] | None:
    """:func:`.balance.dangling_connect`'s finding, or None where the check itself fails on
    text mcl did not parse (the compile, or rumoca's message, stands)."""
    try:
        return dangling_connect(model, prep.docs, prep.search, names)
    except Exception:      # noqa: BLE001 - a check only
        log.warning("%s: the connections were not checked against the classes", model, exc_info=True)
        return None


def _in_complex(model: str, prep: Prepared) -> bool:
    """Whether the model or the user's files name Complex or a package built on it."""
    texts = [model]
    for f in prep.files:
        try:
            texts.append(Path(f).read_text(encoding="utf-8", errors="replace"))
        except OSError:
            pass
    return any(complexops.MENTIONS.search(t) for t in texts)


def _located_error(exc, model: str, files: list[Path], real: dict | None = None) -> ModelicaError:
    """rumoca's error as one line with the file:line it names (or the line that uses the name)."""
    text = str(exc)
    for virtual, path in (real or {}).items():
        text = text.replace(virtual, path)
    m = re.search(r"\[([^\]\s]+\.mo):(\d+):(\d+)\]", text)
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    detail = next((ln.lstrip("×").strip() for ln in lines if ln.startswith("×")), None)
    detail = detail or (lines[0].split(": ", 1)[-1] if lines else type(exc).__name__)
    detail = re.sub(rf"^(?:{re.escape(model)}|{ENTRY}) (could not be compiled|failed in \w+):?\s*", "", detail)
    import rumoca

    if isinstance(exc, rumoca.ParseError) or re.search(r"parse|unexpected", text, re.I):
        # the syntax error of the file rumoca names (all the user's files when it names none)
        named = [f for f in files if str(f) in text] or files
        syntax = _syntax_error(named)
        if syntax is not None:
            return syntax
    where = f"{m[1]}:{m[2]}" if m else None
    if where is None:                   # a function rumoca cannot lower: its offending statement
        fn = re.search(r"`([\w.]+)` (contains|does not have|requires)", detail)
        if fn:
            where = _in_function(files, fn.group(1).split(".")[-1], r"\b(while|for|return|break)\b")
            if where is not None:
                return UnsupportedConstruct(f"unsupported in {model}: a statement of function {fn.group(1)} the "
                                            f"front end cannot translate (a while-loop, a loop whose bounds are "
                                            f"not constant, a return in a loop: {detail})", where=where)
    for rx, cls, words, place in _KNOWN:
        hit = re.search(rx, text)
        if not hit:
            continue
        if words is None:          # a class that is not there: say what is
            return _missing_class(model, files) or ModelicaError(f"cannot compile {model}: {detail}", where=where)
        place = place(hit) if callable(place) else place
        return cls(words(hit, model), where=where or (_find(files, place) if place else
                                                      _find(files, rf"\b(model|block|class)\s+{model.split('.')[-1]}\b")))
    if where is None:
        name = re.search(r"['`]([\w.\[\]]+)['`]", detail)
        if name:
            where = _find(files, rf"(?<![\w.]){re.escape(name.group(1))}\b") or \
                _find(files, rf"\b{re.escape(name.group(1).split('.')[-1])}\b")
    cls = UnsupportedConstruct if "not supported" in detail.lower() or "unsupported" in detail.lower() else ModelicaError
    if _INTERNAL.search(detail):        # rumoca's own terms: say whose limit it is
        return UnsupportedConstruct(f"cannot compile {model}: the Modelica front end (rumoca) cannot translate a "
                                    f"construct of it ({detail})", where=where)
    return cls(f"cannot compile {model}: {detail}", where=where)


#: rumoca's words for a construct it cannot translate (its limits, not the model's errors)
_INTERNAL = re.compile(r"Flat semantic owner|Flat reference|certificate|shape proof|canonical DAE")


def _in_function(files: list[Path], name: str, pattern: str) -> str | None:
    """``file:line`` of the first line matching ``pattern`` in function ``name`` of the user's
    files (of its header when none does)."""
    for f in files:
        lines = f.read_text(errors="replace").splitlines()
        head = next((n for n, ln in enumerate(lines) if re.search(rf"\bfunction\s+{re.escape(name)}\b", ln)), None)
        if head is None:
            continue
        for n in range(head, len(lines)):
            code = lines[n].split("//", 1)[0]
            if re.search(pattern, code):
                return f"{f}:{n + 1}"
            if re.search(rf"\bend\s+{re.escape(name)}\s*;", code):
                break
        return f"{f}:{head + 1}"
    return None


def _syntax_error(files: list[Path]) -> ModelicaError | None:
    """The first syntax error in the user's files, with file:line:column (rumoca's validator)."""
    import rumoca

    for f in files:
        try:
            diags = in_rumoca_thread(lambda text, name: rumoca.validate_source(text, filename=name),
                                     f.read_text(encoding="utf-8", errors="replace"), str(f))
        except Exception:  # noqa: BLE001 - the validator is a help for the message, never a failure
            continue
        for d in diags:
            if d.level == "error" and (d.rule or "").startswith("syntax"):
                inner = re.search(r":(\d+):(\d+)\]", d.message or "")
                line, col = (inner[1], inner[2]) if inner else (d.line, d.column)
                what = next((ln.strip().lstrip("×").strip() for ln in (d.message or "").splitlines()
                             if ln.strip().startswith("×")), "unexpected input")
                line, col, what = _statement_end(f, int(line), int(col), what)
                return ModelicaError(f"syntax error: {what}", where=f"{f}:{line}:{col}")
    return None


def _statement_end(f: Path, line: int, col: int, what: str) -> tuple[int, int, str]:
    """An unexpected token that opens its line most often means the statement before it was not
    ended (a missing ';'): the error is then placed at the end of that statement's last line."""
    lines = f.read_text(errors="replace").splitlines()
    if not 1 <= line <= len(lines) or lines[line - 1][: max(col - 1, 0)].strip():
        return line, col, what
    prev = line - 1
    while prev >= 1 and not lines[prev - 1].split("//", 1)[0].strip():
        prev -= 1
    if prev < 1:
        return line, col, what
    code = lines[prev - 1].split("//", 1)[0].rstrip()
    if code.endswith((";", "then", "loop", "else", "equation", "algorithm", "protected", "public")):
        return line, col, what
    return prev, len(code) + 1, f"{what} (is a ';' missing at the end of this line?)"


def _missing_class(model: str, files: list[Path]) -> ModelicaError | None:
    """``class 'P.Nope' not found`` with the classes its package does define, when it is missing."""
    *pkg, short = model.split(".")
    decl = r"^\s*(?:(?:partial|encapsulated|final|replaceable|operator|expandable)\s+)*(?:model|block|class|package|connector|record|function|type)\s+(\w+)"
    defined = {n for f in files for n in re.findall(decl, f.read_text(errors="replace"), re.M)}
    if short in defined:
        return None
    inside = sorted(defined - set(pkg)) if pkg else sorted(defined)
    return ModelicaError(f"class '{model}' not found ('{short}' not in {'.'.join(pkg) or 'the sources'}: "
                         f"{', '.join(inside[:12]) or 'nothing'})")


def _nodes(a: ca.SX) -> tuple:
    """A call argument's identity by its nodes' addresses."""
    return tuple(e.element_hash() for e in ca.vertsplit(ca.vec(a)))


def _within(a: ca.SX, limit: int) -> bool:
    """Whether ``a`` has at most ``limit`` nodes, counted until past it (n_nodes walks all of a
    medium's state: 23 ms an argument, 32 of a ventilated room's 120 s compile)."""
    seen, stack = set(), ca.vertsplit(ca.vec(a))
    while stack:
        e = stack.pop()
        h = e.element_hash()
        if h not in seen:
            seen.add(h)
            if len(seen) > limit:
                return False
            stack.extend(e.dep(i) for i in range(e.n_dep()))
    return True


def _form(a: ca.SX):
    """A call argument's identity for the memo of calls: its nodes where each is a symbol or a
    constant, else its expression's form (serialised) with the symbols it reads. Equal
    arguments built twice (a medium's state at a port, written at each use) are then one
    call, inlined once: a pumping system's water functions had 1.2 of their 3 million
    instructions inlined again so, and its common-subexpression pass took 11 CPU-s, now 7.
    (Asked only where the nodes are new: serialising is 0.8 ms an argument.)"""
    if all(e.is_leaf() for e in ca.vertsplit(ca.vec(a))) or not _within(a, FORM_NODES_MAX):
        return _nodes(a)
    leaves = ca.symvar(a)
    return ca.Function("form", leaves, [a]).serialize(), tuple(v.element_hash() for v in leaves)


class _Translator:
    """The IR's expression DAG as CasADi SX. Nodes are translated without recursion (an explicit
    stack, children before parents), so a 5000-term sum or a long binding chain has no depth
    limit; a function call interprets the function's body in its own context."""

    def __init__(self, storage: dict, model: str, located: "Located | None" = None, keep_calls: bool = False):
        self.st, self.model, self.located = storage, model, located
        self.keep_calls = keep_calls
        expr = storage["expressions"]
        self.nodes, self.operand_list = expr["nodes"], expr["operands"]
        self.subscripts = expr.get("subscripts", [])
        self.offsets, self.sub_offsets, pos, spos = [], [], 0, 0
        for n in self.nodes:
            self.offsets.append(pos)
            self.sub_offsets.append(spos)
            body = n[next(iter(n))] if isinstance(n, dict) else None
            pos += body.get("operand_count", 0) if isinstance(body, dict) else 0
            spos += body.get("subscript_count", 0) if isinstance(body, dict) else 0
        self.functions = storage.get("functions", [])
        self.cache: dict[int, ca.SX] = {}
        self.coord = None   # set by the caller: (kind, index) -> SX
        # relations that generate events (rumoca lists them; those inside noEvent() it does not)
        self.event_nodes = {r["relation"]["expression"] for r in storage.get("relations", [])
                            if isinstance(r, dict) and "relation" in r}
        self.relations: list[ca.SX] = []   # lhs - rhs of the event-generating relations met
        self.relation_ops: list = []       # their operators (None: a quotient's integer crossing)
        self.held: list = []     # (its index in relations, symbol, relation, value at an event, crossing)
        self.span = None                   # provenance of what is being translated (for errors)
        self.fn_asserts: list = []         # (violated, level, message) of asserts in functions called
        self.table_records: dict = {}      # the MSL's interpolation tables by their id (rumoca's data)
        self.tables: dict[int, tables.Table] = {}   # ... translated when first looked up
        self._compiled: dict = {}          # (function, argument pattern) -> SX Function
        self._texts: dict = {}             # hash -> a constant string passed to a function
        self._calls: dict = {}             # (its name, its arguments' nodes) -> (arguments, outputs)
        self._forms: dict = {}             # (its name, its arguments' forms: _form) -> outputs
        self._function_tags: dict = {}     # its name -> (number of outputs, [(level, message)])
        self._unassigned: dict = {}        # its name -> outputs it never assigns
        # a loop index met outside its loop: rumoca keeps the for-equations of an if-equation's
        # branches a parameter rules out; this symbol stands in and must vanish once the
        # branch is dropped (a condition that turns constant), else the model is refused
        self.unbound = ca.SX.sym("$loop_index_outside_its_loop")
        self.unbound_span = None
        # rumoca lists the event-generating relations of continuous equations only; those of a
        # discrete value defined at all times (a pulse's ``time < pulseStart + Twidth``) are
        # events too (``live``: translating such a value), unless inside noEvent()
        self.live = 0
        self._quiet = None
        self._call_groups = None           # (owner, function) -> the call carrying the arguments
        self.projected: set = set()       # domains of the array equation being translated whole
        self.memory0 = _resident_bytes()
        self.memory_limit = float(os.environ.get("MCL_COMPILE_MEMORY_GB") or COMPILE_MEMORY_GB) * 1e9

    def check_memory(self, function: str):
        """Refuse a function whose unrolled loops outgrow the memory allowed to a compile: a
        medium's property function iterating over another (Water IF97's rho_ph) unrolls into
        an expression of many GB, which would take the machine's memory and then crash."""
        if _resident_bytes() - self.memory0 > self.memory_limit:
            self.refuse(f"function {function} unrolls into an expression larger than the "
                        f"{self.memory_limit / 1e9:g} GB of memory a compile may use (MCL_COMPILE_MEMORY_GB)")

    def live_sx(self, root: int) -> ca.SX:
        """Node ``root``, a discrete value defined at all times: its relations are events."""
        self.live += 1
        try:
            return self.sx(root)
        finally:
            self.live -= 1

    @property
    def quiet(self) -> set:
        """The nodes inside noEvent() or smooth(), whose relations generate no events."""
        if self._quiet is None:
            stack = [o for k, n in enumerate(self.nodes) if isinstance(n, dict) and
                     n.get("builtin", {}).get("builtin", "").split(".")[-1] in ("noEvent", "no_event", "smooth")
                     for o in self.operands(k)]
            self._quiet = set()
            while stack:
                k = stack.pop()
                if k not in self._quiet:
                    self._quiet.add(k)
                    stack.extend(self.children(k))
        return self._quiet

    def operands(self, k: int) -> list[int]:
        body = self.nodes[k][next(iter(self.nodes[k]))]
        n = body.get("operand_count", 0)
        return self.operand_list[self.offsets[k]: self.offsets[k] + n]

    def call_operands(self, k: int) -> list[int]:
        """The arguments of call ``k``. The calls for the outputs of one multi-output call share
        an owner (the first call, or the equation holding them all), and only one of them
        carries the arguments."""
        body = self.nodes[k]["call"]
        if body.get("operand_count", 0) or body.get("owner") is None:
            return self.operands(k)
        if self._call_groups is None:
            self._call_groups = {}
            for j, n in enumerate(self.nodes):
                b = n.get("call") if isinstance(n, dict) else None
                if b and b.get("operand_count", 0) and b.get("owner") is not None:
                    self._call_groups.setdefault((b["owner"], b["function"]), j)
        first = self._call_groups.get((body["owner"], body["function"]))
        if first is None:
            owner = self.nodes[body["owner"]]
            return self.operands(body["owner"]) if isinstance(owner, dict) and "call" in owner else []
        return self.operands(first)

    def refuse(self, what: str):
        where = self.located.span(self.span) if self.located is not None else None
        raise UnsupportedConstruct(f"unsupported in {self.model}: {what}", where=where)

    def children(self, k: int) -> list[int]:
        node = self.nodes[k]
        if isinstance(node, str):
            return []
        kind = next(iter(node))
        body = node[kind]
        if kind == "unary":
            return [body["operand"]]
        if kind in ("binary", "runtime_quotient_owner"):
            return [body["lhs"], body["rhs"]]
        if kind == "call":
            return self.call_operands(k)
        if kind == "builtin" and self.strings_size(k) is not None:
            return self.operands(k)[1:]
        if kind in ("conditional", "builtin", "array"):
            return self.operands(k)
        if kind in ("index", "array_update"):
            subs = self.subscripts[self.sub_offsets[k]: self.sub_offsets[k] + body["subscript_count"]]
            value = [body["value"]] if kind == "array_update" else []
            return [body["base"], *value] + [n for s in subs if isinstance(s["kind"], dict)
                                             for sk, n in s["kind"].items() if sk in ("index", "slice")]
        if kind == "range":
            return [n for n in (body["start_expression"], body.get("explicit_step_expression"),
                                body["stop_expression"]) if n is not None]
        if kind == "field":
            return [body["base"]]
        if kind == "record":
            return self.operands(k)
        return []

    def sx(self, root: int, bound: dict | None = None) -> ca.SX:
        """Node ``root`` as SX; ``bound`` is a function call's context (its values are not cached)."""
        done = self.cache if bound is None else {}
        if root in done:
            return done[root]
        stack = [(root, False)]
        spans: dict = {}     # node -> (first, end) of the function asserts its subtree added
        while stack:
            k, state = stack.pop()
            if k in done:
                continue
            if state is False:
                spans[k] = (len(self.fn_asserts), None)
                compared = self.string_comparison(k)
                if compared is None:
                    compared = self.string_hash(k)
                if compared is None:
                    compared = self.strings_compared(k)
                if compared is not None:
                    done[k] = compared
                    continue
                self.text_arguments(k, done)
                if self._kind(k) == "conditional":       # its conditions first, then its branches
                    stack.append((k, "branches"))
                    stack.extend((c, False) for c in self.operands(k)[0:-1:2] if c not in done)
                else:
                    stack.append((k, True))
                    stack.extend((c, False) for c in self.children(k) if c not in done)
                continue
            if state == "branches":
                stack.append((k, True))
                stack.extend((c, False) for _, c in self.live_branches(k, done) if c not in done)
                continue
            done[k] = self.build(k, done, bound)
            spans[k] = (spans[k][0], len(self.fn_asserts))
            if self.fn_asserts and self._kind(k) == "conditional":
                self.gate_asserts(self.operands(k), spans, done)
        return done[root]

    def string_comparison(self, k: int) -> ca.SX | None:
        """``a == b`` or ``a <> b`` of two constant strings, as 1 or 0 (None for anything else):
        a transformer's connections are picked by its vector group's letters, C1 = "D"."""
        node = self.nodes[k]
        body = node.get("binary") if isinstance(node, dict) else None
        if not body or body.get("operator") not in ("equal", "not_equal"):
            return None
        a, b = self.string_value(body["lhs"]), self.string_value(body["rhs"])
        if a is None or b is None:
            return None
        return ca.SX(float((a == b) == (body["operator"] == "equal")))

    def called(self, k: int) -> dict | None:
        """The function node ``k`` calls, where it is a call of a Modelica function (else None)."""
        node = self.nodes[k]
        body = node.get("call") if isinstance(node, dict) else None
        if not body or not isinstance(body.get("function"), int):
            return None
        return self.functions[body["function"]]

    def text_arguments(self, k: int, done: dict):
        """A constant string passed to a Modelica function (the message of Fluid's
        assertPositiveDifference) as its hash: the function is then interpreted for that string,
        and an assert in it that names the parameter as its message says the string."""
        f = self.called(k)
        if f is None or f.get("external"):
            return
        for o in self.call_operands(k):
            lit = self.nodes[o]
            if o in done or not (isinstance(lit, dict) and "string" in (lit.get("literal") or {})):
                continue
            text = lit["literal"]["string"]
            key = xorshift.hash_string(text)
            self._texts[key] = text
            done[o] = ca.SX(key)

    def string_hash(self, k: int) -> ca.SX | None:
        """Modelica.Utilities.Strings.hashString of a constant string (a noise block's automatic
        seed, from its instance's name), as its value; None for anything else."""
        f = self.called(k)
        if f is None or (f.get("external") or {}).get("symbol") != "ModelicaStrings_hashString":
            return None
        ops = self.call_operands(k)
        if len(ops) != 1:
            return None
        text = self.string_value(ops[0])
        return None if text is None else ca.SX(xorshift.hash_string(text))

    def strings_compared(self, k: int) -> ca.SX | None:
        """Modelica.Utilities.Strings.isEqual or compare() of two constant strings, as its value
        (compare's Types.Compare: Less 1, Equal 2, Greater 3); None for anything else. A trace
        substance sensor finds its substance's index among the medium's names so."""
        f = self.called(k)
        if f is None:
            return None
        name = f.get("name", "")
        compare = (f.get("external") or {}).get("symbol") == "ModelicaStrings_compare" or name.endswith("Strings.compare")
        if not (compare or name.endswith("Strings.isEqual")):
            return None
        ops = self.call_operands(k)
        if len(ops) not in (2, 3):
            return None
        a, b = self.string_value(ops[0]), self.string_value(ops[1])
        sensitive = self.sx(ops[2]) if len(ops) == 3 else ca.SX(1)
        if a is None or b is None or not sensitive.is_constant():
            return None
        if not float(sensitive):
            a, b = a.lower(), b.lower()
        if not compare:
            return ca.SX(float(a == b))
        return ca.SX(2.0 if a == b else 1.0 if a < b else 3.0)

    def string_value(self, k: int, depth: int = 0, hole: str | None = None) -> str | None:
        """Node ``k``'s value where it is a constant string: a literal, a String variable bound
        to one, substring() of one, or two joined with +; else None. With ``hole``, a join's
        operand that is not constant (String(T) in an assert's message) is written as it."""
        node = self.nodes[k]
        if depth > 16 or not isinstance(node, dict):
            return hole
        kind = next(iter(node))
        body = node[kind]
        if kind == "literal":
            return body.get("string")
        if kind == "coordinate" and isinstance(body, dict) and len(body) == 1:
            i = next(iter(body.values()))
            variables = self.st["variables"]
            if not isinstance(i, int) or i >= len(variables) or \
                    self.st["value_types"][variables[i]["value_type"]].get("scalar") != "string":
                return hole
            binding = variables[i]["attributes"].get("binding")
            return hole if binding is None else self.string_value(binding, depth + 1, hole)
        if kind == "index" and body.get("subscript_count") == 1:      # {"CO2", "H2O"}[i], i a constant
            items = self.string_items(body["base"], depth)
            sub = self.subscripts[self.sub_offsets[k]]["kind"] if items is not None else None
            at = self.sx(sub["index"]) if isinstance(sub, dict) and "index" in sub else None
            if at is not None and at.is_constant() and at.numel() == 1 and 1 <= int(float(at)) <= len(items):
                return items[int(float(at)) - 1]
            return hole
        if kind == "binary" and body.get("operator") == "add":
            a, b = (self.string_value(body[side], depth + 1, hole) for side in ("lhs", "rhs"))
            return None if a is None or b is None else a + b
        if kind == "call" and isinstance(body.get("function"), int):
            name = self.functions[body["function"]].get("name", "")
            args = self.call_operands(k)
            if name.endswith("Strings.substring") and len(args) == 3:
                text = self.string_value(args[0], depth + 1)
                ends = [self.sx(a) for a in args[1:]]
                if text is not None and all(e.is_constant() and e.numel() == 1 for e in ends):
                    return text[int(float(ends[0])) - 1:int(float(ends[1]))]
        if kind == "string_conversion" and hole is not None:   # String(x) of a constant: its value
            try:
                v = self.sx(body["value"])
            except Exception:  # noqa: BLE001 - a message is written with what can be read
                return hole
            if v.is_constant() and v.numel() == 1:
                x = float(v)
                return str(int(x)) if x.is_integer() and abs(x) < 1e15 else f"{x:.6g}"
        return hole

    def string_items(self, k: int, depth: int) -> list[str] | None:
        """The elements of node ``k`` where it is an array of constant strings (a literal, or a
        String array bound to one), else None."""
        node = self.nodes[k]
        if isinstance(node, dict) and "array" in node:
            items = [self.string_value(o, depth + 1) for o in self.operands(k)]
            return None if any(i is None for i in items) else items
        return None

    def live_branches(self, k: int, done: dict) -> list:
        """(condition, branch) of conditional ``k`` that a constant condition does not rule
        out (the else branch's condition None): a branch ruled out is never translated, as a
        recursive function's call in the branch its argument rules out
        (Polyphase's numberOfSymmetricBaseSystems(m) calls itself for even m)."""
        ops = self.operands(k)
        live = []
        for j in range(0, len(ops) - 1, 2):
            cond = done[ops[j]]
            if cond.is_constant() and cond.numel() == 1:
                if float(cond) != 0:
                    return [*live, (None, ops[j + 1])]
                continue
            live.append((cond, ops[j + 1]))
        return [*live, (None, ops[-1])]

    def _kind(self, k: int) -> str:
        node = self.nodes[k]
        return node if isinstance(node, str) else next(iter(node))

    def gate_asserts(self, ops: list[int], spans: dict, done: dict):
        """The asserts of functions called in a branch of ``if c1 then a1 elseif c2 then a2 ...
        else b`` hold only where that branch is taken: Water IF97 computes its steam region's
        Gibbs function on every call, and its assert T >= 273.15 there must not fail a run in
        the liquid region."""
        taken = ca.SX(1)       # no earlier condition holds
        for j in range(0, len(ops) - 1, 2):
            cond = done[ops[j]]
            if cond.numel() != 1:
                return
            self._gate(spans.get(ops[j + 1]), ca.logic_and(taken, cond))
            taken = ca.logic_and(taken, ca.logic_not(cond))
        self._gate(spans.get(ops[-1]), taken)

    def _gate(self, span, gate):
        if span is None or span[1] is None:
            return
        for i in range(*span):
            violated, level, message = self.fn_asserts[i]
            self.fn_asserts[i] = (ca.logic_and(violated, gate), level, message)

    def build(self, k: int, done: dict, bound) -> ca.SX:
        node = self.nodes[k]
        kind = self._kind(k)
        body = None if isinstance(node, str) else node[kind]
        if kind == "literal":
            (lk, value), = body.items()
            if lk == "string":
                self.refuse(f"a string value ({value!r}) in an equation")
            return ca.SX(float(value))
        if kind == "coordinate":
            if body == "time":
                return self.coord("time", 0)
            (ck, idx), = body.items()
            if ck == "binder":
                try:
                    return ca.SX(bound["binders"][(idx["domain"], idx["ordinal"])])
                except (TypeError, KeyError):
                    self.unbound_span = self.unbound_span or self.span
                    return self.unbound
            if ck == "function_parameter":
                ordinal = idx["ordinal"] if isinstance(idx, dict) else idx
                if bound is None or ordinal not in bound["params"]:
                    self.refuse("a function parameter outside a function call")
                return bound["params"][ordinal]
            return self.coord(ck, idx)
        if kind == "unary":
            op = body["operator"]
            if op not in _UNARY:
                self.refuse(f"unary operator '{op}'")
            return _UNARY[op](done[body["operand"]])
        if kind == "binary":
            op = body["operator"]
            if op not in _BINARY:
                self.refuse(f"operator '{op}'")
            lhs, rhs = done[body["lhs"]], done[body["rhs"]]
            if op != "multiply":
                lhs, rhs = alike(lhs, rhs)
            try:
                out = _BINARY[op](lhs, rhs)
            except RuntimeError:          # CasADi's dimension mismatch
                out = NotImplemented
            if out is NotImplemented:
                self.refuse(f"operator {op!r} on values of shapes {getattr(lhs, 'shape', lhs)} and {getattr(rhs, 'shape', rhs)}")
            if op in _RELATIONS and bound is None and lhs.numel() == rhs.numel() == 1 and self.events_at(k):
                return self.held_relation(op, lhs, rhs, out)
            return out
        if kind == "runtime_quotient_owner":          # div, mod, rem: an event where a/b crosses an integer
            a, b = alike(done[body["lhs"]], done[body["rhs"]])
            if bound is None and a.numel() == 1 and k not in self.quiet:
                self.relations.append(ca.sin(np.pi * a / b))
                self.relation_ops.append(None)
            return self.call_builtin(body["builtin"], [a, b])
        if kind == "conditional":       # if c1 then a1 elseif c2 then a2 ... else b
            live = self.live_branches(k, done)
            out = done[live[-1][1]]
            for cond, branch in reversed(live[:-1]):
                out = ca.if_else(cond, *alike(done[branch], out))
            return out
        if kind == "builtin":
            n = self.strings_size(k)
            if n is not None:
                return ca.SX(n)
            args = [done[o] for o in self.operands(k)]
            if body["builtin"].split(".")[-1] == "sign" and bound is None and len(args) == 1 and \
                    args[0].numel() == 1 and k not in self.quiet:
                # an event where the sign changes, as Modelica has it: an arc's voltage
                # Vmax*sign(i) flips with its current, and the arc quenches at that event; without
                # it the solver steps through the jump (30 000 steps a second, the arc never out).
                # rumoca lists no sign() among its event nodes: every one outside noEvent()
                a, zero = args[0], ca.SX(0)
                return (self.held_relation("greater", a, zero, a > 0) - self.held_relation("less", a, zero, a < 0))
            return self.call_builtin(body["builtin"], args)
        if kind == "call":
            return self.call_function(body, [done[o] for o in self.call_operands(k)])
        if kind == "array":
            return array_of([done[o] for o in self.operands(k)])
        if kind == "record":                 # its fields flattened, in order
            return ca.vertcat(*[flat(done[o]) for o in self.operands(k)])
        if kind == "field":
            return self.field(body, done)
        if kind == "index":
            return self.element(k, body, done)
        if kind == "array_update":
            return self.updated(k, body, done)
        if kind == "comprehension":
            return self.comprehension(body, bound)
        if kind == "range":
            return ca.SX(self.range_values(body, done))
        if kind == "function_value":
            value = (bound or {}).get("values", {}).get(body["definition_ordinal"])
            return value if value is not None else self.unassigned(body)
        self.refuse(f"expression node '{kind}'")

    def unassigned(self, body: dict) -> ca.SX:
        """A function's array read before it is assigned as a whole: an empty array, which
        assignments to its elements in order (a loop filling it) extend. Its declared size is
        not used: it may depend on the call's arguments, and rumoca gives one size for all
        calls. A scalar read before any assignment is undefined (NaN): rumoca writes an
        if-statement's assignment as ``v := if c then e else v``, whose else-branch reads v
        before it has a value; the condition masks it where the branch is taken, and a real
        use of it shows as NaN."""
        f = self.functions[body["function"]]
        held = [*f.get("outputs", []), *f.get("locals", [])]
        dims = self.st["value_types"][held[body["value"]]["value_type"]].get("dimensions") or []
        if len(dims) > 2:
            self.refuse("a function array of more than two dimensions read before it is assigned")
        return ca.SX(0, 1) if dims else ca.SX(np.nan)

    def strings_size(self, k: int) -> int | None:
        """``size(a, 1)`` of an array of strings (a medium's names): its length, which is all
        that is read of strings in equations."""
        node = self.nodes[k]
        if node.get("builtin", {}).get("builtin", "").split(".")[-1] != "size":
            return None
        ops = self.operands(k)
        arr = self.nodes[ops[0]] if ops else None
        if not (isinstance(arr, dict) and "array" in arr):
            return None
        items = [self.nodes[o] for o in self.operands(ops[0])]
        if not items or not all(isinstance(i, dict) and "string" in i.get("literal", {}) for i in items):
            return None
        if len(ops) > 1 and not (isinstance(self.nodes[ops[1]], dict)
                                 and self.nodes[ops[1]].get("literal", {}).get("integer") == 1):
            return None
        return len(items)

    def binders(self, d: int, outer: bool = True) -> list:
        """(domain, binder id, range of values) of a domain's binders (its parents' first)."""
        out = []
        while d is not None:
            dom = self.st["domains"][d]
            out = [(d, b["id"], range(b["lower"], b["upper"] + (1 if b["step"] > 0 else -1), b["step"]))
                   for b in dom["domain"]["binders"]] + out
            d = dom.get("parent") if outer else None
        return out

    def comprehension(self, body: dict, bound) -> ca.SX:
        """``{f(i) for i in 1:n}``: the body at each value of the domain's binders (row-major);
        binders of an enclosing loop keep the values they have."""
        bound = bound or {"params": {}, "values": {}, "binders": {}}
        binders = [b for b in self.binders(body["domain"]) if (b[0], b[1]) not in bound["binders"]
                   and b[0] not in self.projected]
        out = []
        for values in itertools.product(*[r for _, _, r in binders]):
            inner = {**bound, "binders": {**bound["binders"], **{(d, i): v for (d, i, _), v in zip(binders, values)}}}
            out.append(self.sx(body["body"], inner))
        if len(binders) == 2 and out and all(o.is_scalar() for o in out):   # {a[i, j] for i in .., j in ..}
            return shaped(ca.vertcat(*out), [len(binders[0][2]), len(binders[1][2])])
        return array_of(out)

    def range_values(self, body: dict, done: dict) -> list[float]:
        """``start:step:stop`` with constant bounds, as its values."""
        ends = [done[body["start_expression"]], done[body["stop_expression"]]]
        step = done[body["explicit_step_expression"]] if body.get("explicit_step_expression") is not None else ca.SX(1)
        if not all(e.is_constant() for e in (*ends, step)):
            self.refuse("a range whose bounds are not constant")
        a, b, h = float(ends[0]), float(ends[1]), float(step)
        if h == 0:
            self.refuse("a range with step 0")
        n = int(np.floor((b - a) / h + 1e-9)) + 1
        return [a + j * h for j in range(max(n, 0))]

    def selectors(self, k: int, body: dict, done: dict) -> list:
        """The subscripts of node ``k``, one per dimension: an index (1-based, an expression),
        the indices of a slice (a list), or None for the whole dimension."""
        subs = self.subscripts[self.sub_offsets[k]: self.sub_offsets[k] + body["subscript_count"]]
        return [self._selector(s, done) for s in subs]

    def _selector(self, sub: dict, done: dict):
        if sub["kind"] == "whole":
            return None
        if not isinstance(sub["kind"], dict):
            self.refuse(f"a '{sub['kind']}' subscript")
        kind, node = next(iter(sub["kind"].items()))
        if kind == "slice":
            target = self.nodes[node]
            if isinstance(target, dict) and "range" in target:
                return [int(round(v)) for v in self.range_values(target["range"], done)]
            values = done[node]
            if not values.is_constant():
                self.refuse("a slice whose indices are not constant")
            return [int(round(v)) for v in np.array(ca.DM(values)).ravel()]
        if kind != "index":
            self.refuse(f"a '{kind}' subscript")
        i = done[node]
        return as_int(i) if i.is_constant() else i

    def _places(self, base: ca.SX, sels: list) -> tuple[list, list, list[bool]]:
        """Rows and columns (0-based) that constant subscripts select, and which dimensions
        remain (a slice keeps its dimension, an index drops it). A vector is one column; a
        matrix with one subscript is indexed by row."""
        dims = (base.size1(), base.size2())
        if len(sels) == 1:
            sels = [sels[0], None] if dims[1] > 1 else [sels[0], 1]
        out, keep = [], []
        for s, n in zip(sels, dims):
            picked = list(range(1, n + 1)) if s is None else s if isinstance(s, list) else [s]
            if not all(1 <= j <= n for j in picked):
                self.refuse(f"subscript {picked} outside an array of {n}")
            out.append([j - 1 for j in picked])
            keep.append(isinstance(s, list) or s is None)
        return out[0], out[1], keep

    def _each_value(self, base: ca.SX, sels: list):
        """(condition, constant subscripts) for every value the non-constant subscripts take."""
        sym = [j for j, s in enumerate(sels) if isinstance(s, ca.SX)]
        if not sym:
            yield None, sels
            return
        dims = (base.numel(),) if len(sels) == 1 and base.size2() == 1 else (base.size1(), base.size2())
        for values in itertools.product(*[range(1, dims[j] + 1) for j in sym]):
            fixed, cond = list(sels), None
            for j, v in zip(sym, values):
                fixed[j] = v
                c = sels[j] == v
                cond = c if cond is None else ca.logic_and(cond, c)
            yield cond, fixed

    def element(self, k: int, body: dict, done: dict):
        """``a[i]``, ``m[i, j]``, ``m[:, 1]`` (1-based); a subscript that is not a constant
        selects among the elements with conditionals."""
        base = done[body["base"]]
        sels = self.selectors(k, body, done)
        if len(sels) > 2:
            return self.element_nd(body["base"], base, sels)
        out = None
        for cond, fixed in self._each_value(base, sels):
            rows, cols, keep = self._places(base, fixed)
            value = base[rows, cols]
            if keep == [False, True]:
                value = value.T          # a row of a matrix: a vector
            if cond is None:
                return value
            out = ca.if_else(cond, value, ca.SX.zeros(*value.shape) if out is None else out)
        return out

    def element_nd(self, node: int, base: ca.SX, sels: list) -> ca.SX:
        """A part of an array of three or more dimensions (held flattened, row-major), by
        constant subscripts: the array's declared dimensions place its elements."""
        dims = self.declared_dims(node)
        if dims is None or len(dims) != len(sels) or int(np.prod(dims)) != base.numel():
            self.refuse(f"an array of {len(sels)} dimensions whose size is not known")
        if any(isinstance(s, ca.SX) for s in sels):
            self.refuse(f"an array of {len(sels)} dimensions subscripted by a variable")
        picked = [list(range(1, n + 1)) if s is None else s if isinstance(s, list) else [s]
                  for s, n in zip(sels, dims)]
        if not all(1 <= j <= n for p, n in zip(picked, dims) for j in p):
            self.refuse(f"a subscript outside an array of dimensions {dims}")
        strides = [int(np.prod(dims[j + 1:])) for j in range(len(dims))]
        elements = flat(base)
        out = ca.vertcat(*[elements[sum((j - 1) * st for j, st in zip(at, strides))] for at in itertools.product(*picked)]) \
            if all(picked) else ca.SX(0, 1)
        kept = [len(p) for p, s in zip(picked, sels) if isinstance(s, list) or s is None]
        return shaped(out, kept) if len(kept) == 2 else out

    def declared_dims(self, k: int) -> list[int] | None:
        """The declared dimensions of node ``k``, a variable of the model or of a function."""
        node = self.nodes[k]
        body = node.get("coordinate") if isinstance(node, dict) else None
        vt = None
        if isinstance(body, dict) and "function_parameter" not in body:
            (ck, idx), = body.items()
            if ck.removeprefix("pre_") in _VARIABLE_KINDS and isinstance(idx, int):
                vt = self.st["variables"][idx]["value_type"]
        elif isinstance(body, dict) or (isinstance(node, dict) and "function_value" in node):
            vt = self.value_type(k)
        dims = self.st["value_types"][vt].get("dimensions") if vt is not None else None
        return dims if dims and all(isinstance(n, int) and n >= 0 for n in dims) else None

    def updated(self, k: int, body: dict, done: dict) -> ca.SX:
        """``a`` with ``a[i] := v``, ``m[i, :] := v`` (a function's assignment to a part)."""
        base, value = done[body["base"]], done[body["value"]]
        sels = self.selectors(k, body, done)
        out = grown(ca.SX(base), sels)
        for cond, fixed in self._each_value(base, sels):
            rows, cols, _ = self._places(base, fixed)
            v = flat(value)
            if v.numel() not in (1, len(rows) * len(cols)):
                self.refuse("an assignment to a part of an array of another size")
            new = ca.SX(out) if cond is not None else out
            for n, (r, c) in enumerate(itertools.product(rows, cols)):
                new[r, c] = v[n] if v.numel() > 1 else v[0]
            out = new if cond is None else ca.if_else(cond, new, out)
        return out

    def size_of(self, vt: int) -> int:
        """Number of scalars of a value type (a record's: all its fields')."""
        t = self.st["value_types"][vt]
        n = int(np.prod(t.get("dimensions") or [1]))
        if t.get("scalar") == "record":
            n *= sum(self.size_of(f["value_type"]) for f in t.get("record_fields", []))
        return n

    def value_type(self, k: int) -> int:
        """The value type of node ``k`` (a record value, an array of a function): a call's
        output, a constructor, a function's parameter or variable, a field of one, either
        branch of a conditional."""
        node = self.nodes[k]
        kind = self._kind(k)
        body = node[kind] if isinstance(node, dict) else None
        if kind == "call":
            return self.functions[body["function"]]["outputs"][body.get("output", 0)]["value_type"]
        if kind == "record":
            return body["value_type"]
        if kind == "function_value":
            f = self.functions[body["function"]]
            held = [*f.get("outputs", []), *f.get("locals", [])]
            return held[body["value"]]["value_type"]
        if kind == "coordinate" and isinstance(body, dict) and "function_parameter" in body:
            ref = body["function_parameter"]
            return self.functions[ref["function"]]["parameters"][ref["ordinal"]]["value_type"]
        if kind == "field":
            fields = self.st["value_types"][self.value_type(body["base"])].get("record_fields", [])
            return fields[body["field"]]["value_type"]
        if kind == "conditional":
            return self.value_type(self.operands(k)[1])
        self.refuse(f"a record field of a '{kind}' expression")

    def field(self, body: dict, done: dict):
        """Field ``body["field"]`` of a record value (a record-valued call or constructor)."""
        vt = self.value_type(body["base"])
        fields = self.st["value_types"][vt].get("record_fields", [])
        start = sum(self.size_of(f["value_type"]) for f in fields[: body["field"]])
        n = self.size_of(fields[body["field"]]["value_type"])
        value = flat(done[body["base"]])
        if value.numel() < start + n:
            self.refuse("a record field outside its record")
        return shaped(value[start:start + n], self.st["value_types"][fields[body["field"]]["value_type"]].get("dimensions"))

    def function_assert(self, body: dict, bound: dict):
        """An assert in a function: checked like the model's own (a failed result naming it)."""
        ok = flat(self.sx(body["condition"], bound))
        lit = self.nodes[body["message"]] if body.get("message") is not None else None
        text = lit.get("literal", {}).get("string") if isinstance(lit, dict) else None
        param = (lit.get("coordinate") or {}) if isinstance(lit, dict) else {}
        if text is None and isinstance(param, dict) and "function_parameter" in param:
            ref = param["function_parameter"]
            value = bound["params"].get(ref["ordinal"] if isinstance(ref, dict) else ref)
            if value is not None and value.is_constant() and value.numel() == 1:
                text = self._texts.get(int(float(value)))
        where = self.located.span(self.span) if self.located is not None else None
        text = text or "assert"
        self.fn_asserts.append((ca.logic_not(ok[0]), body.get("level", "error"),
                                f"{text} ({where})" if where else text))

    def events_at(self, k: int) -> bool:
        """Whether the relation at node ``k`` generates events (not in noEvent() or smooth())."""
        return k in self.event_nodes or (self.live and k not in self.quiet)

    def held_relation(self, op: str, lhs: ca.SX, rhs: ca.SX, value: ca.SX) -> ca.SX:
        """``lhs op rhs`` (``value``) watched for crossings and held between events, as Modelica
        has it: a symbol, its value set at events."""
        self.relations.append(lhs - rhs)
        self.relation_ops.append(op)
        held = ca.SX.sym(f"{HELD_PREFIX}{len(self.relations) - 1}")
        self.held.append((len(self.relations) - 1, held, value, *_hysteresis(op, lhs, rhs, held)))
        return held

    def call_builtin(self, name: str, args):
        short = name.split(".")[-1]
        if short not in _FUNCTIONS:
            self.refuse(f"built-in function {name}()")
        try:
            return _FUNCTIONS[short](*args)
        except TypeError:
            self.refuse(f"{name}() with {len(args)} argument(s)")

    def call_function(self, body: dict, args):
        f = self.functions[body["function"]]
        ext = f.get("external")
        if body.get("derivative") is not None:
            self.refuse(f"function {f['name']} (its derivative)")
        bound = {"params": dict(enumerate(args)), "values": {}, "binders": {}}
        if ext and (ext.get("language") == "builtin" or ext.get("symbol", "").startswith("ModelicaStandardTables_")):
            actual = [self.sx(a["input"], bound) for a in ext.get("arguments", []) if "input" in a]
            if ext.get("language") == "builtin":
                return self.call_builtin(ext.get("symbol", f["name"]), actual)
            return self.call_table(ext["symbol"], actual)
        if ext and ext.get("symbol") in xorshift.GENERATORS:
            return self.call_generator(ext, body.get("output", 0), bound)
        if ext:
            self.refuse(f"external function {f['name']} ({ext.get('language', '?')} code)")
        compiled, symbolic = self.compiled_function(body["function"], args)
        actual = [args[i] for i in symbolic]
        # one expansion per call on the same expressions: a record-valued call read field by
        # field (Water IF97's rho_ph reads waterBaseProp_ph's record 16 times) is otherwise
        # inlined once per field (14.7 million nodes for rho_ph instead of 0.9)
        key = (compiled.name(), tuple(_nodes(a) for a in actual))
        if key not in self._calls:
            # (and one on equal expressions built twice: see _form)
            form = (compiled.name(), tuple(_form(a) for a in actual))
            if form not in self._forms:
                # kept as a call node (keep_calls), a large function's C is written once, not at each call
                kept = self.keep_calls and compiled.n_instructions() > KEPT_CALL_PAST
                self._forms[form] = compiled.call(actual, False, kept)
            self._calls[key] = (actual, self._forms[form])   # the arguments kept: the keys hold their nodes' addresses
        outs = self._calls[key][1]
        n_out, tags = self._function_tags[compiled.name()]
        for violated, (level, message) in zip(outs[n_out:], tags):
            self.fn_asserts.append((violated, level, message))
        output = body.get("output", 0)
        if output >= n_out or output in self._unassigned[compiled.name()]:
            self.refuse(f"function {f['name']} assigns no value to its output {output + 1}")
        return outs[output]

    def call_generator(self, ext: dict, output: int, bound: dict):
        """Output ``output`` of one of the MSL's random number generators (its C function as an
        expression: :mod:`.xorshift`), whose C arguments are (state in, state out, number)."""
        (state,) = [self.sx(a["input"], bound) for a in ext.get("arguments", []) if "input" in a]
        outputs = [a["output"] for a in ext.get("arguments", []) if "output" in a]
        try:
            number, new = xorshift.generate(ext["symbol"], state)
        except ValueError as exc:
            self.refuse(str(exc))
        return dict(zip(outputs, (new, number)))[output]

    def call_table(self, symbol: str, args):
        """A lookup in one of the MSL's tables (the C library's function, as an expression)."""
        ident = args[0] if args else None
        key = as_int(ident) if ident is not None and ident.is_constant() else None
        if key not in self.table_records:
            self.refuse(f"table function {symbol} on a table that is not a constant of the model")
        try:
            if key not in self.tables:
                self.tables[key] = tables.Table.of(*self.table_records[key])
            value, outside = tables.call(symbol, self.tables[key], args)
        except UnsupportedConstruct as exc:
            self.refuse(str(exc))
        if outside is not None:
            self.fn_asserts.append((outside, "error", "the table's abscissa is outside the table "
                                    "(extrapolation = NoExtrapolation)"))
        return value

    def compiled_function(self, index: int, args) -> tuple[ca.Function, list[int]]:
        """Function ``index`` interpreted once per pattern of its arguments (the constant ones
        by value: they may size arrays or pick branches; the others as symbols of their size),
        as an SX Function of the non-constant arguments: a function called many times (in a
        loop, by other functions) is not interpreted again at every call."""
        key = [index]
        symbolic = []
        for i, a in enumerate(args):
            if a.is_constant():
                key.append(("c", a.shape, tuple(np.array(ca.DM(a)).ravel(order="F").tolist())))
            else:
                key.append(("s", a.shape))
                symbolic.append(i)
        key = tuple(key)
        if key in self._compiled:
            return self._compiled[key], symbolic
        f = self.functions[index]
        syms = {i: ca.SX.sym(f"a{i}", *args[i].shape) for i in symbolic}
        params = {i: syms.get(i, a) for i, a in enumerate(args)}
        bound = {"params": params, "values": {}, "binders": {}}
        before = len(self.fn_asserts)
        run = _Run(self, f, bound)
        run.block(f.get("statements", []))
        self.check_memory(f["name"])
        found, self.fn_asserts = _merged(self.fn_asserts[before:]), self.fn_asserts[:before]
        n_out = len(f.get("outputs", [])) or 1
        outs = [run.latest.get(j, ca.SX(0, 1)) for j in range(n_out)]
        name = f"fn{len(self._compiled)}"
        compiled = ca.Function(name, [syms[i] for i in symbolic], outs + [v for v, _, _ in found])
        self._function_tags[name] = (n_out, [(level, message) for _, level, message in found])
        self._unassigned[name] = {j for j in range(n_out) if j not in run.latest}
        self._compiled[key] = compiled
        return compiled, symbolic


#: with keep_calls, a function of more instructions than this stays a call in the expressions
#: (smaller ones are inlined, where they simplify). Kept calls evaluate every output and branch
#: of the function: a steam model's right-hand side took 106 ms kept against 1.9 ms inlined, so
#: calls are kept only for code (an FMU whose inlined C would be too large to compile)
KEPT_CALL_PAST = 100
FORM_NODES_MAX = 500       # (nodes: a larger argument is known by its nodes alone)

#: growth of the process's memory a compile's translation may use (MCL_COMPILE_MEMORY_GB)
COMPILE_MEMORY_GB = 4.0


def _resident_bytes() -> int:
    """This process's resident memory (0 where /proc is missing: the check is then off)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


def _independent_of(asserts: list, syms: ca.SX) -> list:
    """The asserts whose condition reads none of ``syms``: one sparsity sweep over all of them
    (depends_on per assert walked a plant's shared media expressions once for each of its
    hundreds of asserts)."""
    if not asserts or not syms.numel():
        return list(asserts)
    reads = set(ca.jacobian_sparsity(ca.vertcat(*[a[0] for a in asserts]), syms).get_triplet()[0])
    return [a for k, a in enumerate(asserts) if k not in reads]


def _merged(asserts: list) -> list:
    """One check per assert message: an assert met in every pass of a loop, or in a function
    called at each (a medium's), would otherwise be an output of its own each time."""
    out: dict = {}
    for violated, level, message in asserts:
        key = (level, message)
        out[key] = violated if key not in out else ca.logic_or(out[key], violated)
    return [(v, level, message) for (level, message), v in out.items()]


class _Run:
    """One call of an algorithmic function. Each definition has an ordinal, in the order
    written: an assignment one; a for-loop (rumoca's lowering of a while-loop included: a
    bounded loop whose body is guarded by the condition) one per variable it changes on entry
    (the value carried into an iteration), then its body's, then one per variable on exit (the
    value after the loop). A read names the definition it sees; an if-statement's assignments
    are already conditional expressions. Loops are unrolled."""

    def __init__(self, tr: "_Translator", f: dict, bound: dict):
        self.tr, self.f, self.bound = tr, f, bound
        self.defs = bound["values"]          # definition ordinal -> value
        self.latest: dict[int, ca.SX] = {}   # variable -> its last value
        self.next = 0                        # ordinal of the next definition

    def define(self, target: int, value):
        self.defs[self.next] = value
        self.next += 1
        if value is not None:
            self.latest[target] = value

    @classmethod
    def count(cls, stmts: list) -> int:
        n = 0
        for stmt in stmts:
            kind = next(iter(stmt))
            if kind == "assignment":
                n += 1
            elif kind == "assignment_group":
                n += len(stmt[kind]["assignments"])
            elif kind == "for":
                n += 2 * len(stmt[kind]["targets"]) + cls.count(stmt[kind]["statements"])
        return n

    def block(self, stmts: list):
        for stmt in stmts:
            kind = next(iter(stmt))
            body = stmt[kind]
            self.tr.span = (body.get("provenance") or body.get("begin_provenance") or {}).get("span") or self.tr.span
            if kind in ("assignment", "assignment_group"):
                for a in [body] if kind == "assignment" else body["assignments"]:
                    self.define(a["target"], self.tr.sx(a["rhs"], self.bound))
            elif kind == "assertion":
                self.tr.function_assert(body, self.bound)
            elif kind == "for":
                self.loop(body)
            else:
                self.tr.refuse(f"a '{kind}' statement in function {self.f['name']}")

    def loop(self, body: dict):
        targets = body["targets"]
        carried = self.next
        for v in targets:                     # carried into the first iteration
            self.define(v, self.latest.get(v))
        first, n = self.next, self.count(body["statements"])
        binders = self.tr.binders(body["domain"], outer=False)
        outer = self.bound["binders"]
        for values in itertools.product(*[r for _, _, r in binders]):
            self.bound["binders"] = {**outer, **{(d, i): v for (d, i, _), v in zip(binders, values)}}
            self.next = first
            self.block(body["statements"])
            self.tr.check_memory(self.f["name"])
            for j, v in enumerate(targets):   # carried into the next
                self.defs[carried + j] = self.latest.get(v)
        self.bound["binders"] = outer
        self.next = first + n
        for v in targets:                     # after the loop
            self.define(v, self.latest.get(v))


def _scalar_names(name: str, dims: list[int]) -> list[str]:
    """``x`` -> [x]; ``x`` of dims [2, 3] -> [x[1,1], x[1,2], ..., x[2,3]] (row-major)."""
    if not dims:
        return [name]
    return [f"{name}[{','.join(str(k + 1) for k in idx)}]" for idx in np.ndindex(*dims)]


def to_dae(ir: dict, located: Located, model: str, keep_calls: bool = False) -> Dae:
    """The DAE-stage IR as a scalar :class:`Dae` (arrays split into scalars, balance checked,
    parameters resolved to the free ones). The IR is another program's schema: a shape we do
    not know (a missing key, an index outside a table) is a one-line refusal, not a crash."""
    try:
        return _to_dae(ir, located, model, keep_calls)
    except (KeyError, IndexError, TypeError) as exc:
        raise UnsupportedConstruct(f"cannot translate rumoca's IR of {model} ({type(exc).__name__}: {exc}); "
                                   "try --compiler pymoca, or report the model",
                                   where=located.find(rf"\b(model|block|class)\s+{model.split('.')[-1]}\b")) from None


#: arena slots rumoca 0.10.2 keeps after a model's div/mod/rem node (its event quotient) but does
#: not serialise; one in a function's body has none (it makes no event)
_QUOTIENT_SLOTS = 6


def _whole_arena(st: dict):
    """rumoca's expression list lacks the nodes a ``runtime_quotient_owner`` (div, mod, rem)
    owns, while every reference counts them: each later node would be read as another.
    Placeholders restore the numbering (once, where the IR comes in; nothing references them)."""
    ex = st["expressions"]

    def gapped(n):
        return isinstance(n, dict) and "runtime_quotient_owner" in n and \
            "function" not in (n["runtime_quotient_owner"].get("kind") or {})

    if ex.get("whole") or not any(gapped(n) for n in ex["nodes"]):
        ex["whole"] = True
        return
    nodes, prov = [], []
    for n, p in zip(ex["nodes"], ex["provenance"]):
        nodes.append(n)
        prov.append(p)
        if gapped(n):
            nodes += [{"quotient_slot": {}}] * _QUOTIENT_SLOTS
            prov += [p] * _QUOTIENT_SLOTS
    ex["nodes"], ex["provenance"], ex["whole"] = nodes, prov, True


def _evaluated(ir: dict) -> set[str]:
    """The parameters rumoca's flat model marks evaluated: annotation(Evaluate = true), or
    final and bound to such a one (a circuit's capacitances all set from one CapVal = 0). Their
    values are the model's structure, as in other tools: a zero capacitance's C*der(v) is no
    term at all, and its voltage no state."""
    flat = ir.get("flat", {}).get("variables", {}) or {}
    return {re.sub(r"\[[^\]]*\]$", "", n) for n, v in flat.items() if v.get("evaluate")}


def _to_dae(ir: dict, located: Located, model: str, keep_calls: bool = False) -> Dae:
    st = ir["storage"]
    _whole_arena(st)
    variables = st["variables"]
    _refuse_events(st, located, model)
    dims = [list(st["value_types"][v["value_type"]]["dimensions"] or []) for v in variables]
    size = [int(np.prod(d)) if d else 1 for d in dims]
    tr = _Translator(st, model, located, keep_calls)
    role = [v["role"] for v in variables]
    attrs = [v["attributes"] for v in variables]
    # an external object (a table's id: rumoca evaluated its constructor) and a String (a
    # table's name) are constants, not parameters to fit
    objects = _external_objects(ir)
    strings = {i for i, v in enumerate(variables) if st["value_types"][v["value_type"]].get("scalar") == "string"}
    role = ["constant" if v["name"] in objects or i in strings else r for i, (v, r) in enumerate(zip(variables, role))]
    # parameters computed during initialisation (fixed = false, no binding) become constant states
    init_params = {i for i, v in enumerate(variables) if role[i] == "parameter" and attrs[i]["binding"] is None
                   and attrs[i].get("fixed") in ([False], False)}
    # a discrete value defined at all times by one expression without pre() (a Boolean of
    # parameters, x > 0) is that expression, evaluated live like a relation in an equation;
    # the others (assigned in when-clauses, or reading pre()) are held between events
    pre_read = _pre_reads(st)
    always = {}
    for owner in st.get("discrete_value_owners", []):
        branches = owner.get("branches", [])
        if len(branches) == 1 and branches[0].get("activation") == "always" and len(owner["targets"]) == 1:
            node = branches[0]["values"][0]["value"]
            target = owner["targets"][0]
            if target not in pre_read and not _reads_pre(tr, node):
                always[target] = node
    index = {"x": [], "z": [], "u": [], "p": [], "c": [], "d": []}
    for i, r in enumerate(role):
        if r == "discrete_value" and i in always:
            continue
        if r == "state" or i in init_params:
            index["x"].append(i)
        elif r in ("algebraic", "output"):
            index["z"].append(i)
        elif r == "input":
            index["u"].append(i)
        elif r == "parameter":
            index["p"].append(i)
        elif r == "constant":
            index["c"].append(i)
        elif r in ("discrete_value", "discrete_real"):
            index["d"].append(i)
        else:
            raise UnsupportedConstruct(f"unsupported in {model}: {r} variable {variables[i]['name']}",
                                       where=located.span(variables[i].get("declaration", {}).get("span")))
    names = {k: [n for i in idx for n in _scalar_names(variables[i]["name"], dims[i])] for k, idx in index.items()}
    x, dx, z = (ca.SX.sym(s, len(names[k])) for s, k in (("x", "x"), ("dx", "x"), ("z", "z")))
    u, p_all, t = ca.SX.sym("u", len(names["u"])), ca.SX.sym("p_all", len(names["p"])), ca.SX.sym("t")
    # the hybrid part: discrete variables, then one memory per condition that triggers a
    # when-clause (its value at the last event: a when-clause fires on its rising edge)
    conditions = st.get("conditions", [])
    memory = {c: k for k, c in enumerate(sorted(_triggers(st)))}
    nd = len(names["d"]) + len(memory)
    d, d_pre = ca.SX.sym("d", nd), ca.SX.sym("d_pre", nd)
    x_pre = ca.SX.sym("x_pre", x.numel())
    z_pre = ca.SX.sym("z_pre", z.numel())      # pre() of an algebraic variable: its value before the event
    clocks = _clocks(st, located, model)
    flags = ca.SX.sym("flags", 2 + len(clocks))      # initial(), terminal(), a tick of each clock
    slot, der, pre_slot = {}, {}, {}
    for k, vec, pre in (("x", x, x_pre), ("z", z, z_pre), ("u", u, u), ("p", p_all, None), ("d", d, d_pre)):
        pos = 0
        for i in index[k]:
            slot[i] = vec[pos:pos + size[i]]
            if k == "x":
                der[i] = dx[pos:pos + size[i]]
            if pre is not None:
                pre_slot[i] = pre[pos:pos + size[i]]
            pos += size[i]

    def coord(kind, i):
        if kind == "time":
            return t
        if kind == "derivative":
            if i not in der:
                tr.refuse(f"der() of {variables[i]['name']}, which is not a state")
            return shaped(der[i], dims[i])        # (der(c[i, :]) of a matrix reads a row)
        if kind == "terminal":
            return flags[1]
        if kind == "initial":
            return flags[0]
        if kind == "condition":          # an if-equation's branch condition (initial(), a relation)
            return events.value(i)
        if kind.removeprefix("pre_") not in _VARIABLE_KINDS:    # another index space: never a variable
            tr.refuse(f"a reference of kind '{kind}'")
        if kind.startswith("pre_"):
            if i in pre_slot:
                return shaped(pre_slot[i], dims[i])
            if i in always:          # never changed at an event: pre() is the value
                return tr.live_sx(always[i])
            tr.refuse(f"pre() of {variables[i]['name']}")
        if i in structural and i not in resolving:
            # an Integer, Boolean or enumeration parameter bound to a constant is its value
            # (see the parameters below), here already: a recursive function it is passed to
            # then picks its branches by it (numberOfSymmetricBaseSystems(m) calls itself for even m)
            resolving.add(i)
            value = tr.sx(attrs[i]["binding"] if attrs[i]["binding"] is not None else attrs[i]["start"])
            resolving.discard(i)
            if value.is_constant():
                return shaped(flat(value), dims[i])
            structural.discard(i)
        if i in slot:
            return shaped(slot[i], dims[i])
        if i in always:
            return tr.live_sx(always[i])
        if role[i] == "constant":
            value = tr.sx(attrs[i]["binding"] if attrs[i]["binding"] is not None else attrs[i]["start"])
            return shaped(flat(value), dims[i])
        tr.refuse(f"variable {variables[i]['name']} ({kind})")

    evaluated = _evaluated(ir)
    structural = {i for i, v in enumerate(variables) if role[i] == "parameter" and i not in init_params
                  and (st["value_types"][v["value_type"]].get("scalar") in ("integer", "boolean", "enumeration")
                       or v["name"] in evaluated)
                  and (attrs[i]["binding"] is not None or attrs[i]["start"] is not None)}
    resolving: set = set()
    tr.coord = coord
    events = _Events(st, tr, conditions, memory, d, d_pre, flags, located, model)
    tr.table_records = _table_records(ir, variables, objects, attrs, tr)
    eqs = [_residual(op, tr, model) for op in st["continuous_equation_operations"]]
    eqs += [der[i] for i in sorted(init_params)]       # d/dt of an initialisation parameter is 0
    residual = ca.vertcat(*[flat(e) for e in eqs]) if eqs else ca.SX(0, 1)
    check_balance(residual, x.numel(), z.numel(), model)
    init = [flat(_residual(op, tr, model)) for op in st["initialization_equation_operations"]]
    # an Integer or Boolean parameter computed at initialisation (fixed = false): rumoca hands
    # its initial equation over apart, as the value it is set to
    for set_to in st.get("initial_parameter_values", []):
        i = set_to["target"]
        tr.span = (set_to.get("provenance") or {}).get("span")
        if i not in init_params:
            tr.refuse(f"an initial equation setting parameter {variables[i]['name']}, which has a value")
        value = flat(tr.sx(set_to["value"]))
        init.append(flat(slot[i]) - repeated(value, size[i]))
    # an algebraic variable with fixed = true starts at its start value (inertia.a(fixed=true))
    init += [flat(slot[i]) - flat(tr.sx(attrs[i]["start"])) for i in index["z"]
             if attrs[i].get("fixed") in ([True], True) and attrs[i]["start"] is not None]
    init_residual = ca.vertcat(*init) if init else ca.SX(0, 1)
    d_update = events.discrete_update(index["d"], slot, pre_slot, size, variables)
    x_reinit = events.reinit(x, index["x"], slot, variables)
    # an assert's condition is checked, not located: its relations are not state events (as in
    # other tools; the MSL's resistors assert on their temperature, a sign change never seen)
    met = len(tr.relations)
    asserts, assert_info = events.asserts()
    del tr.relations[met:], tr.relation_ops[met:]
    # the relations of state events are held between events: discrete variables, each set to
    # its relation at an event (the solver then integrates a smooth right-hand side, and a
    # diode's switching costs it a restart, not a fight with a jump it cannot step over); the
    # others (on time alone, in asserts, parameters or when-conditions) are evaluated where
    # they are read. Those a discrete variable reads outside a when are held too: held, they
    # change past a band, where an arc's quenched = abs(i) <= abs(v)*Goff or pre(quenched),
    # equal up to rounding once quenched, crossed at every step (SMEE_LoadDump: 45 000 a second)
    n_d = len(names["d"])
    # the relations a when-condition reads (time > t0 of a when-clause: a time event, at the
    # instant the compiled parameters give; see ``timed`` below)
    when_read = (set(ca.jacobian_sparsity(d_update[n_d:], ca.vertcat(*[h[1] for h in tr.held])).get_triplet()[1])
                 if tr.held and d_update[n_d:].numel() else set())     # (indices into tr.held)
    in_whens = {tr.held[j][0] for j in when_read}
    whole_values = ca.vertcat(*[flat(slot[i]) for i in index["d"] if st["value_types"][variables[i]["value_type"]].get(
        "scalar") in ("integer", "boolean", "enumeration")], d[len(names["d"]):], *[h for _, h, _, _, _ in tr.held])
    # relations constant in time are read as the parameters make them (see _constant_in_time)
    steady = _constant_in_time(tr, met, residual, z, ca.vertcat(x, dx, u, d, d_pre, t, x_pre, z_pre, flags))
    keep = [rel for rel in _held(tr, met, ca.vertcat(x, dx, z), ca.vertcat(d, d_pre), residual, d_update[:n_d],
                                 when_read, whole_values, ca.vertcat(u, x_pre, z_pre)) if rel[0] not in steady]
    live = _Live(tr, keep, stay={str(h) for k, h, _, _, _ in tr.held if k in steady})
    residual, init_residual, d_update, x_reinit, asserts = map(
        live, (residual, init_residual, d_update, x_reinit, asserts))
    if keep:
        d = ca.vertcat(d, *[h for _, h, _, _ in keep])
        d_pre = ca.vertcat(d_pre, ca.SX.sym("rel_pre", len(keep)))
        d_update = ca.vertcat(d_update, *[live(e) for _, _, e, _ in keep])
        nd = d.numel()
        for k, _, _, cross in keep:
            tr.relations[k] = live(cross)

    def value_of(i, key_order=("binding", "start")):
        if size[i] == 0:        # (an empty array's binding, fill(x, 0) or a record's default, has no element)
            return ca.SX(0, 1)
        node = next((attrs[i][k] for k in key_order if attrs[i][k] is not None), None)
        e = tr.sx(node) if node is not None else ca.SX.zeros(size[i], 1)
        e = live(flat(e))
        return ca.repmat(e, size[i], 1) if e.numel() == 1 and size[i] > 1 else e

    # parameters: an element whose binding depends on other parameters is a dependent one;
    # an Integer, Boolean or enumeration is structural (it sizes arrays, picks an element or
    # a branch: a filter's order and kind) and stays at its value, as other tools evaluate it
    values = ca.vertcat(*[value_of(i) for i in index["p"]]) if index["p"] else ca.SX(0, 1)
    elements = ca.vertsplit(values)
    # (a Real parameter the model evaluates, Evaluate = true or final and bound to one, is a
    # constant of it: not a parameter to set or fit)
    real = [st["value_types"][variables[i]["value_type"]].get("scalar") == "real"
            and not (i in structural and variables[i]["name"] in evaluated)
            for i in index["p"] for _ in range(size[i])]
    free = [j for j, v in enumerate(elements) if v.is_constant() and real[j]]
    p_names = [names["p"][j] for j in free]
    p_values = np.array([float(elements[j]) for j in free])
    p, resolved = resolve_parameters(values, p_all, free, model, names["p"], p_values)
    settle = _settled(tr, steady, p_all, resolved, p, p_values)

    # between events pre(v) is v, initial() and terminal() are false (initial() true in the
    # initial equations) and no clock ticks
    held = ca.vertcat(d_pre, x_pre, z_pre, flags)

    def bind(e, initial=0.0):
        e = settle(ca.substitute(live(e), p_all, resolved))
        if held.numel() > flags.numel():
            e = ca.substitute(e, held, ca.vertcat(d, x, z, ca.SX([initial] + [0.0] * (flags.numel() - 1))))
        return e

    def starts(k):
        return bind(ca.vertcat(*[value_of(i, ("start",)) for i in index[k]])) if index[k] else ca.SX(0, 1)

    residual, init_residual = bind(residual), bind(init_residual, 1.0)
    # an Integer or Boolean initialisation parameter is a state the solver holds constant up to
    # its rounding, and a condition reads 1e-26 as true (JointRRR's positiveBranch flipped its
    # branch at the first step): the equations read it rounded to its whole value
    whole = [i for i in sorted(init_params)
             if st["value_types"][variables[i]["value_type"]].get("scalar") in ("integer", "boolean", "enumeration")]
    if whole:
        held_whole = ca.vertcat(*[flat(slot[i]) for i in whole])
        residual = ca.substitute(residual, held_whole, ca.floor(held_whole + 0.5))
    if ca.depends_on(ca.vertcat(residual, init_residual), tr.unbound):
        tr.span = tr.unbound_span
        tr.refuse("a for-loop index outside its loop")

    x_fixed = np.array([attrs[i].get("fixed") in ([True], True) and i not in init_params
                        for i in index["x"] for _ in range(size[i])], bool)
    u_start = starts("u")
    u_start = np.array([float(ca.evalf(e)) if not ca.depends_on(e, p) else 0.0
                        for e in ca.vertsplit(u_start)]) if u_start.numel() else np.zeros(0)
    exprs: dict[str, ca.SX] = {}
    for k, vec in (("x", x), ("z", z), ("u", u), ("d", d)):
        for j, n in enumerate(names[k]):
            exprs[n] = vec[j]
    for j, n in enumerate(names["p"]):
        exprs[n] = resolved[j]
    for i in index["c"]:
        if i in strings:
            continue        # no number to name (a table's name)
        for n, e in zip(_scalar_names(variables[i]["name"], dims[i]), ca.vertsplit(flat(coord("constant", i)))):
            exprs[n] = e
    for i, node in always.items():
        exprs.setdefault(variables[i]["name"], bind(flat(tr.live_sx(node))[0]))
    top = [i for i, v in enumerate(variables) if attrs[i].get("causality") == "output" and "." not in v["name"]]
    outputs = [n for i in top for n in _scalar_names(variables[i]["name"], dims[i])]
    units = {v["name"]: v["attributes"]["unit"] for v in variables if v["attributes"].get("unit")}
    descriptions = {v["name"]: v["attributes"]["description"] for v in variables
                    if v["attributes"].get("description")}
    # relations on the unknowns are state events; on time alone they are time events (above);
    # time against a discrete value (time >= pre(nextEvent): the MSL's tables) a state event too
    unknowns = ca.vertcat(x, dx, z, d, d_pre)
    on = set(ca.jacobian_sparsity(ca.vertcat(*tr.relations), unknowns).get_triplet()[0]) - set(steady) \
        if tr.relations else set()
    # and a when-condition on time against a parameter a run may set (when time > t0): its
    # time event sits where the compiled t0 puts it, and with another t0 the clause waited for
    # the run's end; watched, its crossing is found where the run's t0 puts it (on time alone:
    # foreseen, without integrating)
    timed = {k for k in in_whens if ca.depends_on(tr.relations[k], t) and ca.depends_on(bind(tr.relations[k]), p)}
    on |= timed
    rel = [r for k, r in enumerate(tr.relations) if k in on]
    rel_ops = tuple(o for k, o in enumerate(tr.relation_ops) if k in on)
    relations = bind(ca.vertcat(*rel)) if rel else ca.SX(0, 1)
    d_start = ca.vertcat(starts("d"), ca.SX.zeros(len(memory) + len(keep), 1)) if nd else ca.SX(0, 1)
    # initial equations pre(v) = value: the value v's pre() has at initialisation
    offsets, pos = {}, 0
    for i in index["d"]:
        offsets[i], pos = pos, pos + size[i]
    # time and the inputs are known at the start: those stay, and the parameters computed at
    # initialisation (a noise block's seed: their folding, below, puts in their values)
    moving = [e for i in index["x"] if i not in init_params for e in ca.vertsplit(flat(slot[i]))]
    others = ca.vertcat(*moving, z, d)
    for j in range(d_start.numel()):     # a start value read from a variable: the iteration sets it
        if ca.depends_on(d_start[j], others):
            d_start[j] = 0
    later = {}        # pre(v) = a value read from the variables: set by the initial event's iteration
    for init_value in st.get("initial_discrete_values", []):
        i = init_value["target"]
        tr.span = (init_value.get("provenance") or {}).get("span")
        if i not in offsets:        # not held: its pre() is read nowhere (MultiSwitch's pre(u) = false)
            continue
        v = flat(bind(flat(tr.sx(init_value["value"]))))
        for j in range(size[i]):
            e = v[j] if v.numel() > 1 else v[0]
            reads = ca.depends_on(e, others)
            d_start[offsets[i] + j] = e if not reads else 0
            if reads and not ca.depends_on(e, dx):
                later[offsets[i] + j] = e
    given = {offsets[v["target"]] + j for v in st.get("initial_discrete_values", []) if v["target"] in offsets
             for j in range(size[v["target"]])}
    given |= {offsets[i] + j for i in index["d"] if attrs[i].get("fixed") in ([True], True) for j in range(size[i])}
    given |= set(range(len(names["d"]), nd))            # (the memories and held relations: 0)
    d_start, init_residual, at_start = _discrete_starts(d, d_start, init_residual, given, ca.vertcat(x, z), dx)
    at_start.update(later)

    def bind_event(e):            # pre(), initial() and the ticks stay symbols in the update
        return settle(ca.substitute(e, p_all, resolved))

    # asserts in the functions the model calls, where they read the model's values (not der())
    fn = _independent_of(tr.fn_asserts, ca.vertcat(dx, held))
    if fn:
        asserts = ca.vertcat(asserts, *[a[0] for a in fn])
        assert_info = [*assert_info, *[(level, message) for _, level, message in fn]]
    # rumoca's own check that a function read a variable its path never assigned: a record
    # copied whole with a field left unset (the MSL's water properties' cv), a value nothing
    # then reads. Other tools do not check it: a warning, not a stop
    assert_info = [("warning" if _UNASSIGNED.search(m) else lv, m) for lv, m in assert_info]

    # pre() of algebraic variables read at events: each from the variable's value before it
    d_update = bind_event(d_update) if nd else ca.SX(0, 1)
    for j, e in at_start.items():        # (the initial event's iteration sets them: initial() true)
        d_update[j] = ca.if_else(flags[0], e, d_update[j])
    x_reinit = bind_event(x_reinit) if x.numel() else ca.SX(0, 1)
    read = sorted(set(ca.jacobian_sparsity(ca.vertcat(d_update, x_reinit), z_pre).get_triplet()[1]))
    z_pre = z_pre[read] if read else ca.SX(0, 1)
    exprs.update({f"$pre[{k}]": z[j] for k, j in enumerate(read)})

    preferred, state_select = {}, {}
    for i in index["x"] + index["z"]:
        if attrs[i].get("state_select") not in (None, "Default"):
            state_select.update(dict.fromkeys(_scalar_names(variables[i]["name"], dims[i]), attrs[i]["state_select"]))
        if attrs[i].get("state_select") in ("Prefer", "Always") and attrs[i]["start"] is not None:
            value = bind(value_of(i, ("start",)))
            preferred.update(zip(_scalar_names(variables[i]["name"], dims[i]), ca.vertsplit(value)))
    preferred = {n: e for n, e in preferred.items() if not ca.depends_on(e, ca.vertcat(x, z, u, t, d))}
    if ca.depends_on(ca.vertcat(residual, init_residual, relations, d_update, x_reinit, asserts,
                                *[ca.vec(ca.SX(e)) for e in exprs.values()]), homotopy.SYMBOL):
        p, p_names, p_values = ca.vertcat(p, homotopy.SYMBOL), [*p_names, homotopy.NAME], np.append(p_values, 0.0)

    return guard_branches(merge_common(_started_discretes(fold_initial_parameters(Dae(x=x, dx=dx, z=z, u=u, p=p, t=t, residual=residual, init_residual=init_residual,
               x_names=names["x"], z_names=names["z"], u_names=names["u"], p_names=p_names,
               p_values=p_values, x_start=starts("x"), x_fixed=x_fixed, z_start=starts("z"), u_start=u_start,
               outputs=outputs, exprs=exprs, units=units, descriptions=descriptions,
               time_events=_time_events(st), relations=relations, relation_ops=rel_ops,
               d=d, d_names=names["d"] + [f"$when{c}" for c in sorted(memory)] + [str(h) for _, h, _, _ in keep],
               d_start=d_start,
               d_pre=d_pre, x_pre=x_pre, z_pre=z_pre, flags=flags, d_update=d_update, x_reinit=x_reinit,
               clocks=clocks, asserts=bind(asserts) if asserts.numel() else ca.SX(0, 1),
               assert_info=assert_info, preferred=preferred, state_select=state_select)))))


def _discrete_starts(d: ca.SX, d_start: ca.SX, init: ca.SX, given: set, continuous: ca.SX, dx: ca.SX):
    """(start values, initial equations left, {discrete value: its value at the start}): the
    initial equations on discrete values alone (y = 2*x, a noise block's r = f(pre(state)))
    solved, in turn, for the start of the one value each sets that no start or pre() equation
    ``given`` sets (:func:`_solved_for`); the initial system then solves for the continuous
    unknowns. Without this the start read 0. Those that read the continuous unknowns (a mode
    set from the start temperature, mode = if T < T_low then 1 else 0) give the value at the
    start, which the initial event's iteration sets once the continuous start is known (they
    were dropped: the mode started at 0), where they read the continuous values only through
    relations (x = n sets x, not n)."""
    rows = ca.vertsplit(init) if init.numel() and d.numel() else []
    moving = ca.vertcat(continuous, dx)
    candidates = [r for r, row in enumerate(rows) if ca.depends_on(row, d) and not ca.depends_on(row, moving)]
    starts, known, solved = ca.vertsplit(d_start), set(given), set()
    progress = True
    while progress:
        progress = False
        for r in candidates:
            if r in solved:
                continue
            at = sorted(known)
            e = ca.substitute(rows[r], d[at], ca.vertcat(*[starts[j] for j in at])) if at else rows[r]
            free = [j for j in range(d.numel()) if j not in known and ca.depends_on(e, d[j])]
            value = _solved_for(e, d[free[0]]) if len(free) == 1 else None
            if value is None:
                continue
            starts[free[0]] = value
            known.add(free[0])
            solved.add(r)
            progress = True
    at_start = {}
    for r, row in enumerate(rows):
        if r in solved or not ca.depends_on(row, d) or not ca.depends_on(row, continuous) or ca.depends_on(row, dx):
            continue
        if not ca.jacobian(row, continuous).is_zero():     # (it sets a continuous value: x = n)
            continue
        free = [j for j in range(d.numel()) if j not in known and j not in at_start and ca.depends_on(row, d[j])]
        value = _solved_for(row, d[free[0]]) if len(free) == 1 else None
        if value is not None:
            at_start[free[0]] = value
            solved.add(r)
    if not solved:
        return d_start, init, at_start
    left = [row for r, row in enumerate(rows) if r not in solved]
    return ca.vertcat(*starts), (ca.vertcat(*left) if left else ca.SX(0, 1)), at_start


def _solved_for(e: ca.SX, v: ca.SX) -> ca.SX | None:
    """The ``v`` where ``e`` = 0, or None: explicit where ``e`` is linear in ``v`` (a constant,
    nonzero coefficient); where ``e`` reads ``v`` only through comparisons with constants (an
    enumeration's mode == Mode.Heating), the whole number next to those constants that makes
    ``e`` nearest 0."""
    coef = ca.jacobian(e, v)
    if not coef.is_constant():
        return None
    if float(coef) != 0:
        return ca.substitute(-e / float(coef), v, ca.SX(0))
    compared = sorted(_compared_with(e, v))
    # (the constants themselves first, then past them: an enumeration's Integer() is written as
    # if v == 1 then 1 elseif v == 2 then 2 else 3, which v = 0 satisfies as well as v = 3)
    if not compared:
        return None
    values = list(dict.fromkeys([*compared, *[c + 1 for c in compared], *[c - 1 for c in compared], 0.0, 1.0]))
    best, err = ca.SX(values[0]), ca.fabs(ca.substitute(e, v, ca.SX(values[0])))
    for c in values[1:]:
        r = ca.fabs(ca.substitute(e, v, ca.SX(c)))
        best, err = ca.if_else(r < err, c, best), ca.fmin(r, err)
    return best


def _compared_with(e: ca.SX, v: ca.SX) -> set:
    """The whole-number constants ``v`` is compared with in ``e``."""
    key, out = v.element_hash(), set()
    for a in _sx_nodes(e, lambda a: [a.dep(i) for i in range(a.n_dep())]):
        if a is None:
            break
        if a.op() in (ca.OP_EQ, ca.OP_NE, ca.OP_LT, ca.OP_LE) and a.n_dep() == 2:
            for x, y in ((a.dep(0), a.dep(1)), (a.dep(1), a.dep(0))):
                if x.element_hash() == key and y.is_constant() and float(y) == round(float(y)):
                    out.add(float(y))
    return out


def _sx_nodes(e: ca.SX, children, limit: int = 10_000):
    """The distinct nodes of the scalar ``e`` that ``children`` (a node's list) leads to, each
    once; past ``limit`` of them, None (a graph too large to read whole) and no more."""
    todo, seen = [e], set()
    while todo:
        a = todo.pop()
        h = a.element_hash()
        if h in seen:
            continue
        if len(seen) >= limit:
            yield None
            return
        seen.add(h)
        yield a
        todo += children(a)


def _started_discretes(dae: Dae) -> Dae:
    """``dae`` with each start of a discrete value that still reads a state (a parameter computed
    at initialisation that no explicit equation gives) at 0: the event iteration at the start sets it."""
    if not dae.d_start.numel() or not ca.depends_on(dae.d_start, dae.x):
        return dae
    starts = [0 if ca.depends_on(e, dae.x) else e for e in ca.vertsplit(dae.d_start)]
    return dataclasses.replace(dae, d_start=ca.vertcat(*starts))


def _hysteresis(op: str, lhs: ca.SX, rhs: ca.SX, held: ca.SX) -> tuple[ca.SX, ca.SX]:
    """A held relation's (value at an event, crossing function): it changes only once lhs - rhs
    is past 0 by HYSTERESIS x (1 + |lhs| + |rhs|), the way it is going, and its crossing is
    located there. At a diode that stops conducting, current and voltage both vanish: off,
    rounding leaves its voltage at +2e-14 V and on, its current at -7e-10 A, and without the
    band the event iteration flips it on and off for ever."""
    g = lhs - rhs
    band = HYSTERESIS * (1 + ca.fabs(lhs) + ca.fabs(rhs)) * (1 - 2 * held)    # +: false now
    if op in ("less", "less_equal"):
        return g < -band, g + band
    return g > band, g - band


def _constant_in_time(tr, met: int, residual: ca.SX, z: ca.SX, moving: ca.SX) -> dict:
    """{relation index: its value in the parameters} for the relations of state events that are
    constant in time: between algebraic variables that equations of parameters alone fix (a
    vessel's fluidLevel = 0, its ports' heights), found by peeling rows of one such unknown,
    each solved for it where it is linear (:func:`_solved_for`). Held, such a relation started
    false (a ventilated room's regularFlow = fluidLevel >= portsData_height, the tie 0 >= 0,
    shut its ports, and its initial equations had no solution); other tools evaluate it as a
    parameter that fixes the structure, and so does mcl (:func:`_settled`). ``moving``:
    everything else a row may read that changes in time."""
    rels = [(k, h, tr.relations[k]) for k, h, _, _, _ in tr.held if k < met]
    if not rels or not z.numel() or not residual.numel():
        return {}
    hs = ca.vertcat(*[h for _, h, _ in rels])
    cols = ca.vertcat(z, hs, moving)
    nz, nh = z.numel(), hs.numel()
    # rows of an equation (its index) or a relation (-1 - its index) by the columns they read;
    # a row that reads anything moving never becomes constant
    rows = [(i, set(r)) for i, r in enumerate(rows_reading(ca.jacobian_sparsity(residual, cols)))]
    rows += [(-1 - j, set(r)) for j, r in enumerate(rows_reading(ca.jacobian_sparsity(
        ca.vertcat(*[g for _, _, g in rels]), cols)))]
    rows = [(i, r) for i, r in rows if r and max(r) < nz + nh]
    readers: dict = {}
    for n, (_, r) in enumerate(rows):
        for c in r:
            readers.setdefault(c, []).append(n)
    order: list = []          # (column, the row that fixes it), in the order found
    fixed: set = set()
    todo = list(range(len(rows)))
    while todo:
        i, r = rows[todo.pop()]
        left = r - fixed
        col = (nz + (-1 - i) if i < 0 and not left else
               next(iter(left)) if i >= 0 and len(left) == 1 and next(iter(left)) < nz else None)
        if col is not None and col not in fixed:
            fixed.add(col)
            order.append((col, i))
            todo += readers.get(col, [])
    # the values in the parameters, in that order (None where a row is not solved explicitly)
    syms, values, out = [], [], {}
    for col, i in order:
        known = lambda e: ca.substitute(e, ca.vertcat(*syms), ca.vertcat(*values)) if syms else e
        if i >= 0:
            v = _solved_for(known(residual[i]), z[col])
        else:
            k, _, g = rels[-1 - i]
            v = RELATION_TRUTH[tr.relation_ops[k]](known(g))
        if v is None or ca.depends_on(v, cols):
            continue
        if i < 0:
            out[k] = v
        syms.append(cols[col])
        values.append(v)
    return out


def _settled(tr, steady: dict, p_all: ca.SX, resolved: ca.SX, p: ca.SX, p_values: np.ndarray):
    """e -> e with the relations constant in time at their values at the compiled parameter
    values, as other tools evaluate a parameter that fixes the structure: the branch they pick
    is then the equations' only one, which index reduction sees (a room whose port is joined
    straight to a boundary of fixed pressure: its pressure fixed, its mass is not a state)."""
    syms, values = [], []
    for k, h, live, _, _ in tr.held:
        if k in steady:
            v = ca.evalf(ca.substitute(ca.substitute(steady[k], p_all, resolved), p, ca.DM(p_values)))
            syms.append(h)      # (where not finite, read where it is evaluated, as before)
            values.append(float(v) if np.isfinite(float(v)) else ca.substitute(live, p_all, resolved))
    if not syms:
        return lambda e: e
    syms, values = ca.vertcat(*syms), ca.vertcat(*map(ca.SX, values))
    return lambda e: ca.substitute(e, syms, values) if e.numel() and ca.depends_on(e, syms) else e


def _held(tr, met: int, continuous: ca.SX, discrete_vars: ca.SX, residual: ca.SX, discrete: ca.SX,
          when_read: set, whole: ca.SX, varying: ca.SX) -> list:
    """(index, symbol, value at an event, crossing) of the relations held between events: those
    the continuous equations read that read an unknown, and those the discrete equations read
    outside when-conditions that read a continuous one (not asserts, nor when-conditions
    alone, nor time against a discrete variable: an event's iteration reads them there anyway).
    ``when_read``: the held relations (indices into ``tr.held``) the when-conditions read.
    ``whole``: the symbols of Integer and Boolean values (a relation between whole numbers is
    read at an event as it is, see :func:`_integral`). A relation on time, discrete values and
    parameters alone (not ``varying`` either: the inputs and pre() values) is held with no
    band: it is exact at an event as the relations read live there are (a StateGraph's three
    transitions whose timers ran out together, two held and one live: banded, only the live
    one fired, and the alternative took its third branch instead of its first)."""
    if not tr.held or not (residual.numel() or discrete.numel()):
        return []
    syms = ca.vertcat(*[h[1] for h in tr.held])
    read_by = lambda e: set(ca.jacobian_sparsity(e, syms).get_triplet()[1]) if e.numel() else set()
    by_residual, by_discrete = read_by(residual), read_by(discrete) - when_read
    unknowns = ca.vertcat(continuous, discrete_vars)
    ints = {v.element_hash() for v in ca.vertsplit(whole)}

    moving = ca.vertcat(continuous, varying)

    def banded(k, e, cross):  # (an Integer's n > 0 at n = 0 is false, where the band kept it true)
        g = tr.relations[k]
        if not ca.depends_on(g, moving):
            return RELATION_TRUTH[tr.relation_ops[k]](g), g
        return (RELATION_TRUTH[tr.relation_ops[k]](g) if _integral(g, ints) else e), cross

    return [(k, h, *banded(k, e, cross)) for j, (k, h, _, e, cross) in enumerate(tr.held) if k < met and (
            j in by_residual and ca.depends_on(tr.relations[k], unknowns)
            or j in by_discrete and ca.depends_on(tr.relations[k], continuous))]


#: operations whose value is a whole number (comparisons and logic: 0 or 1), and those that keep
#: whole numbers whole
_WHOLE_OPS = {ca.OP_FLOOR, ca.OP_CEIL, ca.OP_LT, ca.OP_LE, ca.OP_EQ, ca.OP_NE, ca.OP_NOT, ca.OP_AND, ca.OP_OR}
_WHOLE_KEEPING = {ca.OP_ADD, ca.OP_SUB, ca.OP_MUL, ca.OP_NEG, ca.OP_IF_ELSE_ZERO, ca.OP_ASSIGN}


def _integral(e: ca.SX, ints: set) -> bool:
    """Whether the scalar ``e`` takes only whole values: whole constants, the symbols ``ints``
    (element hashes of Integer and Boolean variables), floor, ceil, comparisons, and sums,
    products and branches of those. No drift by rounding can cross such a relation: it needs
    no band (an Integer's n > 0 read through integer() of a sum of flows, a StateGraph's count
    of its active steps)."""
    def children(a):        # (not below a whole-valued operation, nor a branch's condition)
        if a.is_leaf() or a.op() in _WHOLE_OPS:
            return []
        return [a.dep(i) for i in range(a.n_dep()) if not (a.op() == ca.OP_IF_ELSE_ZERO and i == 0)]
    for a in _sx_nodes(e, children):
        if a is None:
            return False
        if a.is_constant():
            if float(a) != round(float(a)):
                return False
        elif a.is_symbolic():
            if a.element_hash() not in ints:
                return False
        elif a.op() not in _WHOLE_OPS and a.op() not in _WHOLE_KEEPING:
            return False
    return True


class _Live:
    """An expression with every relation that is not held read where it is evaluated (nested
    relations too); ``stay``: the names of those left as symbols (constant in time: settled
    later, :func:`_settled`)."""

    def __init__(self, tr, keep: list, stay: set = frozenset()):
        self.tr, self.kept = tr, {str(h) for _, h, _, _ in keep} | stay
        self.seen, self.drop = -1, None      # (translating more nodes may meet more relations)

    def __call__(self, e):
        if self.seen != len(self.tr.held):
            drop = [(h, c) for _, h, c, _, _ in self.tr.held if str(h) not in self.kept]
            self.seen = len(self.tr.held)
            self.drop = (ca.vertcat(*[h for h, _ in drop]), ca.vertcat(*[c for _, c in drop])) if drop else None
        for _ in range(self.seen + 1):
            if self.drop is None or not e.numel() or not ca.depends_on(e, self.drop[0]):
                return e
            e = ca.substitute(e, *self.drop)
        return e


def _external_objects(ir: dict) -> set[str]:
    """Names of the variables holding an MSL table (an ExternalObject: ``tableID``)."""
    types = ir.get("flat", {}).get("variable_type_names", {}) or {}
    return {name for name, t in types.items() if t.startswith("Modelica.Blocks.Types.External")}


def _table_records(ir: dict, variables, objects: set[str], attrs, tr) -> dict:
    """rumoca's evaluated tables by id, with a time table's start and shift (arguments of the
    constructor that rumoca does not pass on) from the parameters of the block holding it."""
    index = {v["name"]: i for i, v in enumerate(variables)}
    owner = {}
    for name in objects:
        binding = attrs[index[name]]["binding"] if name in index else None
        ident = tr.sx(binding) if binding is not None else None
        if ident is not None and ident.is_constant():
            owner[as_int(ident)] = name.rpartition(".")[0]

    def parameter(prefix, name, default):
        i = index.get(f"{prefix}.{name}")
        return tr.coord("variable", i) if i is not None else default

    records = {}
    for record in ir.get("external_tables", []) or []:
        prefix = owner.get(record["id"], "")
        scale = parameter(prefix, "timeScale", 1.0)
        records[record["id"]] = (record, parameter(prefix, "startTime", 0.0) / scale,
                                 parameter(prefix, "shiftTime", 0.0) / scale)
    return records


def _reads_pre(tr: "_Translator", root: int) -> bool:
    """Whether the expression at ``root`` reads a pre() value."""
    nodes = tr.nodes
    stack, seen = [root], set()
    while stack:
        k = stack.pop()
        if k in seen:
            continue
        seen.add(k)
        node = nodes[k]
        if isinstance(node, str):
            continue
        kind = next(iter(node))
        body = node[kind]
        if kind == "coordinate" and isinstance(body, dict) and next(iter(body)).startswith("pre_"):
            return True
        stack += tr.children(k)
    return False


def _pre_reads(st: dict) -> set[int]:
    """Variables whose pre() value is read somewhere: they must be held between events."""
    out = set()
    for node in st["expressions"]["nodes"]:
        if isinstance(node, dict) and "coordinate" in node and isinstance(node["coordinate"], dict):
            (ck, idx), = node["coordinate"].items()
            if ck in ("pre_discrete_value", "pre_discrete_real") and isinstance(idx, int):
                out.add(idx)
    return out


def _triggers(st: dict) -> set[int]:
    """Conditions whose rising edge fires something (a when-clause, an action): each needs a
    memory of its value at the last event."""
    conds = st.get("conditions", [])
    found = set()

    def add(c):
        node = conds[c]["node"]
        if node == "always":
            return
        if isinstance(node, dict) and "any_rise" in node:
            add(node["any_rise"]["lhs"])
            add(node["any_rise"]["rhs"])
            return
        found.add(c)

    acts = [b["activation"] for o in st.get("discrete_value_owners", []) for b in o.get("branches", [])]
    acts += [e["activation"] for e in st.get("discrete_real_equations", [])]
    acts += [{"when": {"trigger": a["trigger"], "guard": a["guard"]}} for a in st.get("event_actions", [])]
    for a in acts:
        if isinstance(a, dict) and "when" in a:
            add(a["when"]["trigger"])
    return found


def _clocks(st: dict, located: Located, model: str) -> list[tuple[float, float]]:
    """(start, period) of each periodic clock (``sample(start, interval)``)."""
    out = []
    for c in st.get("clocks", []):
        kind = c.get("kind", {})
        lat = kind.get("periodic", {}).get("lattice") if isinstance(kind, dict) else None
        try:
            period = lat["period"]["num"] / lat["period"]["den"]
            phase = lat["phase"]["num"] / lat["phase"]["den"]
        except (TypeError, KeyError, ZeroDivisionError):
            raise UnsupportedConstruct(f"unsupported in {model}: a clock that is not periodic with a constant "
                                       "period", where=located.span(c.get("provenance", {}).get("span"))) from None
        out.append((phase, period))
    for own in st.get("clock_ownerships", []):
        if own.get("sampled"):
            raise UnsupportedConstruct(f"unsupported in {model}: clocked (synchronous) equations",
                                       where=located.span(own.get("provenance", {}).get("span")))
    return out


class _Events:
    """The when-clauses, reinit() and assert() of the IR as expressions of the update at an
    event: a discrete variable takes the value of its first active branch, else keeps pre()."""

    def __init__(self, st, tr, conditions, memory, d, d_pre, flags, located, model):
        self.st, self.tr, self.conds, self.memory = st, tr, conditions, memory
        self.d, self.d_pre, self.flags = d, d_pre, flags
        self.located, self.model = located, model
        self.nvars = d.numel() - len(memory)
        self._value: dict[int, ca.SX] = {}

    def where(self, prov):
        return self.located.span((prov or {}).get("span"))

    def value(self, c: int) -> ca.SX:
        """The Boolean value of condition ``c`` now."""
        if c in self._value:
            return self._value[c]
        node = self.conds[c]["node"]
        f = self.flags
        if node == "always":
            out = ca.SX(1)
        elif node == "initial":
            out = f[0]
        elif node == "terminal":
            out = f[1]
        else:
            kind, body = next(iter(node.items()))
            if kind == "relation":
                out = self.tr.sx(self.st["relations"][body]["relation"]["expression"])
            elif kind == "not":
                out = ca.logic_not(self.value(body))
            elif kind in ("and", "or", "any_rise"):
                op = ca.logic_and if kind == "and" else ca.logic_or
                out = op(self.value(body["lhs"]), self.value(body["rhs"]))
            elif kind == "clock":
                out = f[2 + body]
            elif kind == "discrete":
                out = self.tr.sx(body)
            else:
                raise UnsupportedConstruct(f"unsupported in {self.model}: event condition '{kind}'",
                                           where=self.where(self.conds[c].get("provenance")))
        self._value[c] = out
        return out

    def fired(self, c: int) -> ca.SX:
        """Whether the rising edge of condition ``c`` fires now; during initialisation only a
        condition that holds initial() fires (a when-clause is otherwise not active then)."""
        node = self.conds[c]["node"]
        if node == "always":
            return ca.SX(1)
        if isinstance(node, dict) and "any_rise" in node:
            return ca.logic_or(self.fired(node["any_rise"]["lhs"]), self.fired(node["any_rise"]["rhs"]))
        now = self.value(c)
        m = self.nvars + self.memory[c]
        edge = ca.logic_and(now, ca.logic_not(self.d_pre[m]))
        at_init = edge if ca.depends_on(now, self.flags[0]) else ca.SX(0)
        return ca.if_else(self.flags[0], at_init, edge)

    def holds(self, trigger: int, guard: int) -> ca.SX:
        """Whether a when-clause's condition holds now (its level, not its rising edge)."""
        node = self.conds[trigger]["node"]
        if node == "always":
            now = ca.SX(1)
        elif isinstance(node, dict) and "any_rise" in node:
            rise = node["any_rise"]
            now = ca.logic_or(self.holds(rise["lhs"], rise["lhs"]), self.holds(rise["rhs"], rise["rhs"]))
        else:
            now = self.value(trigger)
        return now if guard == trigger else ca.logic_and(now, self.value(guard))

    def active(self, activation) -> ca.SX:
        if activation == "always":
            return ca.SX(1)
        if isinstance(activation, dict) and "when" in activation:
            w = activation["when"]
            if w["trigger"] == w["guard"]:
                return self.fired(w["trigger"])
            return ca.logic_and(self.fired(w["trigger"]), self.value(w["guard"]))
        raise UnsupportedConstruct(f"unsupported in {self.model}: activation {activation!r}")

    def discrete_update(self, held: list[int], slot, pre_slot, size, variables) -> ca.SX:
        """The new value of every held discrete variable, then of every condition memory."""
        sequenced = self._transactions(held, slot, pre_slot, size, variables)
        branches: dict[int, list] = {i: [] for i in held if i not in sequenced}
        for owner in self.st.get("discrete_value_owners", []):
            for b in owner.get("branches", []):
                for target, v in zip(owner["targets"], b["values"]):
                    if target in branches:
                        self.tr.span = (v.get("provenance") or {}).get("span")
                        value = (self.tr.live_sx if b.get("activation") == "always" else self.tr.sx)(v["value"])
                        branches[target].append((self.active(b["activation"]), value))
        for eq in self.st.get("discrete_real_equations", []):
            self.tr.span = (eq.get("provenance") or {}).get("span")
            target, value = self._solved(eq["residual"], slot, held, variables)
            if target in branches:
                branches[target].append((self.active(eq["activation"]), value))
        out = []
        for i in held:
            if i in sequenced:
                out.append(sequenced[i])
                continue
            new = pre_slot[i]
            for act, val in reversed(branches[i]):
                new = ca.if_else(act, repeated(flat(val), size[i]), new)
            out.append(flat(new))
        out += [flat(self.value(c)) for c in sorted(self.memory)]
        return ca.vertcat(*out) if out else ca.SX(0, 1)

    def _transactions(self, held, slot, pre_slot, size, variables) -> dict[int, ca.SX]:
        """The variables an algorithm's when-statements assign (rumoca's event transactions):
        the steps run in order, a later assignment over an earlier one, each reading the
        values assigned before it; a variable no step assigns at this event keeps pre()."""
        new: dict[int, ca.SX] = {}
        for tx in self.st.get("model_event_transactions", []):
            for step in tx.get("steps", []):
                self.tr.span = (step.get("provenance") or {}).get("span")
                before = list(new)
                syms = ca.vertcat(*[flat(slot[j]) for j in before]) if before else None

                def now(e):          # read the values this algorithm assigned so far
                    return ca.substitute(e, syms, ca.vertcat(*[new[j] for j in before])) if before else e

                act = now(self.active({"when": {"trigger": step["trigger"], "guard": step["guard"]}}))
                for d in step.get("definitions", []):
                    target = d.get("target") or {}
                    i = target.get("variable")
                    if set(target) - {"kind", "variable"} or i not in held:
                        self.tr.refuse("a when-statement assigning part of a variable")
                    value = flat(now(self.tr.sx(d["value"])))
                    value = repeated(value, size[i])
                    new[i] = ca.if_else(act, value, new.get(i, flat(pre_slot[i])))
        return new

    def _solved(self, residual: int, slot, held, variables):
        """(target, value) of a discrete equation ``target = value`` given as a residual."""
        r = self.tr.sx(residual)
        targets = [i for i in held if variables[i]["role"] == "discrete_real" and ca.depends_on(r, slot[i])]
        node = self.st["expressions"]["nodes"][residual]
        lhs = node.get("binary", {}).get("lhs") if isinstance(node, dict) else None
        lhs_node = self.st["expressions"]["nodes"][lhs] if lhs is not None else None
        if isinstance(lhs_node, dict) and isinstance(lhs_node.get("coordinate"), dict):
            (ck, idx), = lhs_node["coordinate"].items()
            if ck == "discrete_real" and idx in targets:
                targets = [idx]
        if len(targets) != 1:
            self.tr.refuse("a discrete equation that does not define one discrete variable")
        i = targets[0]
        s = slot[i]
        coef = ca.jacobian(r, s)
        if ca.depends_on(coef, s) or coef.is_zero():
            self.tr.refuse(f"a discrete equation not solvable for {variables[i]['name']}")
        rest = ca.substitute(r, s, ca.SX.zeros(s.sparsity()))
        return i, -ca.solve(coef, rest) if s.numel() > 1 else -rest / coef

    def reinit(self, x, states: list[int], slot, variables) -> ca.SX:
        """The states after the reinit() actions that fire (x itself where none does)."""
        new = ca.SX(x)
        offsets, pos = {}, 0
        for i in states:
            offsets[i] = pos
            pos += slot[i].numel()
        for a in self.st.get("event_actions", []):
            kind, body = (next(iter(a["kind"].items())) if isinstance(a["kind"], dict) else (a["kind"], None))
            if kind != "reinitialize":
                continue
            self.tr.span = (a.get("provenance") or {}).get("span")
            i = body["state"]
            if i not in offsets:
                self.tr.refuse(f"reinit() of {variables[i]['name']}, which is not a state")
            act = self.active({"when": {"trigger": a["trigger"], "guard": a["guard"]}})
            val = flat(self.tr.sx(body["value"]))
            for j in range(slot[i].numel()):
                k = offsets[i] + j
                new[k] = ca.if_else(act, val[j] if val.numel() > 1 else val[0], new[k])
        return new

    def asserts(self):
        """(1 where an assert is violated, [(level, message)])."""
        out, info = [], []
        for a in self.st.get("event_actions", []):
            kind, body = (next(iter(a["kind"].items())) if isinstance(a["kind"], dict) else (a["kind"], None))
            if kind == "reinitialize":
                continue
            self.tr.span = (a.get("provenance") or {}).get("span")
            if kind == "assert":
                level, violated = "error", self.active({"when": {"trigger": a["trigger"], "guard": a["guard"]}})
            elif kind == "warning":
                level, violated = "warning", ca.logic_not(self.tr.sx(body["condition"]))
            elif kind == "terminate":
                # checked where a run's points are, between events (pre(c) = c there, so not
                # as an edge): the run ends at the first point its when-condition holds
                level, violated = "terminate", self.holds(a["trigger"], a["guard"])
            else:
                self.tr.refuse(f"event action '{kind}'")
            out.append(flat(violated)[0])
            info.append((level, self._message(body.get("message"), a)))
        return (ca.vertcat(*out) if out else ca.SX(0, 1)), info

    def _message(self, node, action) -> str:
        # (a literal, or a String parameter: TerminateSimulation's terminationText)
        text = self.tr.string_value(node, hole="...") if node is not None else None
        where = self.where(action.get("provenance"))
        text = " ".join(text.split()) if text and text != "..." else "assert"
        return f"{text} ({where})" if where else text


_UNASSIGNED = re.compile(r"is used without a value: the executed path never assigned it")


def _time_events(st: dict) -> list[float]:
    """Instants at which a condition on time switches (``time > startTime`` of a step source):
    the integrator is restarted there instead of stepping over the jump."""
    out = []
    for ev in st.get("time_events", []):
        inst = ev.get("instant") if isinstance(ev, dict) else None
        if isinstance(inst, dict) and "num" in inst and inst.get("den"):
            out.append(inst["num"] / inst["den"])
    return sorted(set(out))


def _residual(op: dict, tr: _Translator, model: str) -> ca.SX:
    """One equation's residual; a for-equation (``structured``) gives one row per index value."""
    kind = next(iter(op))
    tr.span = ((op[kind].get("provenance") if isinstance(op[kind], dict) else None) or {}).get("span")
    if kind == "residual":
        return flat(tr.sx(op[kind]["residual"]))
    if kind != "structured":
        raise UnsupportedConstruct(f"unsupported in {model}: equation of kind '{kind}'")
    eq = op[kind]
    if eq["scalar_view"] == "RowMajorProjection":      # an array equation: its elements
        # translated as whole arrays: a comprehension in it does not run over the equation's
        # own domain, which rumoca gives as its parent
        tr.projected = {d for d, _, _ in tr.binders(eq["domain"])} if eq.get("domain") is not None else set()
        try:
            return ca.vertcat(*[flat(tr.sx(b)) for b in eq["bodies"]])
        finally:
            tr.projected = set()
    binders = tr.binders(eq["domain"])
    view = eq["scalar_view"]
    if isinstance(view, dict) and "BinderPrefixProjection" in view:
        # a for-equation on arrays (``ports[i].C = c``): rumoca adds the element binders, and
        # the body at the loop's own binders is already the whole array
        own = len(tr.st["domains"][eq["domain"]]["domain"]["binders"])
        binders = binders[:len(binders) - own + view["BinderPrefixProjection"]["binder_count"]]
    rows = []
    for values in itertools.product(*[r for _, _, r in binders]):
        bound = {"params": {}, "values": {}, "binders": {(dd, i): v for (dd, i, _), v in zip(binders, values)}}
        rows += [flat(tr.sx(b, bound)) for b in eq["bodies"]]
    return ca.vertcat(*rows) if rows else ca.SX(0, 1)


def _refuse_events(st: dict, located: Located, model: str) -> None:
    """What the event handling does not cover: delays, clocked partitions' previous()."""
    for key, what, pattern in (
            ("delays", "delay()", r"\bdelay\s*\("), ("previous_values", "previous() of a clocked variable",
                                                     r"\bprevious\s*\(")):
        if st.get(key):
            entry = st[key][0] if isinstance(st[key][0], dict) else {}
            where = located.span((entry.get("provenance") or {}).get("span")) or located.find(pattern)
            raise UnsupportedConstruct(f"unsupported Modelica construct: {what}", where=where)
