"""Compile once: compiled models kept on disk, keyed by everything that decides the result.

The key is the model name, the content of the user's documents, a fingerprint of every library
file the front end may read (path, size, modification time), the options, the versions of mcl,
rumoca and CasADi and the compiler's own source. A hit loads the saved CasADi functions instead
of parsing, flattening and analysing again (an MSL model: seconds -> a fraction of a second).
Only compiles that took long enough to be worth it are kept, and the oldest entries are dropped
beyond ``MAX_ENTRIES``.
``MCL_NO_COMPILE_CACHE=1`` turns it off; ``MCL_CACHE_DIR`` moves it.

Built FMUs are kept beside the compiled models (``fmu/``), keyed by the compile key of the model
(for the very model object this cache loaded or stored: :func:`model_key`) or by the generated
C sources, with the model description, the C compiler and its flags (see
:mod:`mcl.compile.fmu.export`), so ``mcl compile`` of a cached model skips the C build too.
"""
from __future__ import annotations

import functools
import hashlib
import json
import logging
import os
import shutil
import tempfile
import weakref
from pathlib import Path

log = logging.getLogger(__name__)

MIN_SECONDS = 0.5          # quicker compiles are not worth a disk entry
FORMAT = 12                # bump when what a compiled model holds changes (events 2, checks 3, fixed algebraics 4, state events 5, start values 6, DAE and structure 7, symbolic blocks 8, Newton form 9, assert relations 10, loop guesses 11, functions in one file 12)
MAX_ENTRIES = 200
MAX_FMUS = 50


def base_dir() -> Path:
    """mcl's cache directory (compiled models, the rumoca library root)."""
    return Path(os.environ.get("MCL_CACHE_DIR") or Path.home() / ".cache" / "mcl")


def cache_dir() -> Path:
    return base_dir() / "compile"


def enabled() -> bool:
    return os.environ.get("MCL_NO_COMPILE_CACHE", "").strip().lower() not in ("1", "true", "yes")


def library_fingerprint(paths) -> str:
    """Path, size and modification time of every Modelica file under ``paths``."""
    h = hashlib.sha256()
    for root in sorted(str(Path(p).resolve()) for p in paths):
        h.update(root.encode())
        for dirpath, dirnames, filenames in os.walk(root, followlinks=True):
            dirnames.sort()
            for f in sorted(filenames):
                if f.endswith(".mo"):
                    st = os.stat(os.path.join(dirpath, f))
                    h.update(f"{dirpath}/{f}:{st.st_size}:{st.st_mtime_ns}".encode())
    return h.hexdigest()


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """The compiler's own source (an editable install changes without a new version)."""
    h = hashlib.sha256()
    for f in sorted(Path(__file__).parent.rglob("*.py")):
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def key_of(**parts) -> str:
    from .library import distribution_versions

    versions = distribution_versions("mcl", "rumoca", "casadi")
    return hashlib.sha256(json.dumps({**parts, "versions": versions, "format": FORMAT, "code": code_fingerprint()},
                                     sort_keys=True, default=str).encode()).hexdigest()[:32]


def load(key: str):
    """The cached model for ``key``, or None."""
    from ..model import CompiledModel

    entry = cache_dir() / key
    if not enabled() or not (entry / "model.json").is_file():
        return None
    try:
        model = CompiledModel.load(entry)
    except Exception as exc:  # noqa: BLE001 - a damaged entry is a miss, never a failure
        log.debug("compile cache entry %s unreadable: %s", key, exc)
        return None
    os.utime(entry)     # recently used
    model.info = {**model.info, "cached": True}
    _remember(model, key)
    return model


def store(key: str, model, seconds: float) -> None:
    """Keep ``model`` under ``key`` when its compile took ``seconds`` >= MIN_SECONDS."""
    if not enabled() or seconds < MIN_SECONDS:
        return
    base = cache_dir()
    try:
        base.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=base, prefix=".new-"))
        model.save(tmp / "m")
        try:
            (tmp / "m").rename(base / key)
        except OSError:        # another process stored it first
            pass
        shutil.rmtree(tmp, ignore_errors=True)
        _remember(model, key)
        _prune(base)
    except OSError as exc:      # a full or read-only disk costs speed, never the compile
        log.debug("compile cache not written: %s", exc)


def _prune(base: Path) -> None:
    entries = sorted((p for p in base.iterdir() if p.is_dir() and not p.name.startswith(".")),
                     key=lambda p: p.stat().st_mtime)
    for old in entries[:-MAX_ENTRIES]:
        shutil.rmtree(old, ignore_errors=True)


_keys: dict[int, tuple] = {}     # id(model) -> (weak reference, compile key)


def _remember(model, key: str) -> None:
    ident = id(model)

    def forget(ref, ident=ident):
        if _keys.get(ident, (None,))[0] is ref:
            del _keys[ident]

    _keys[ident] = (weakref.ref(model, forget), key)


def model_key(model) -> str | None:
    """The compile key of ``model`` when it is the very object this cache loaded or stored (a
    model derived from it, with outputs added or a law put in, is another object: None)."""
    entry = _keys.get(id(model))
    return entry[1] if entry is not None and entry[0]() is model else None


def fmu_lookup(key: str) -> Path | None:
    """The FMU built before for ``key``, or None."""
    path = base_dir() / "fmu" / f"{key}.fmu"
    if not enabled() or not path.is_file():
        return None
    os.utime(path)      # recently used
    return path


def fmu_store(key: str, fmu: Path) -> None:
    """Keep a copy of the built (and validated) ``fmu`` under ``key``."""
    if not enabled():
        return
    base = base_dir() / "fmu"
    tmp = None
    try:
        base.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=base, prefix=".new-", suffix=".fmu")
        os.close(fd)
        shutil.copyfile(fmu, tmp)
        os.replace(tmp, base / f"{key}.fmu")
        old = sorted((p for p in base.glob("*.fmu") if not p.name.startswith(".")), key=lambda p: p.stat().st_mtime)
        for p in old[:-MAX_FMUS]:
            p.unlink(missing_ok=True)
    except OSError as exc:      # costs speed, never the build
        log.debug("FMU cache not written: %s", exc)
    finally:
        if tmp and os.path.exists(tmp):
            os.unlink(tmp)
