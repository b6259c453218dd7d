"""Output and input paths: mcl writes new paths and replaces only what it provably wrote.

Every output (a run directory, a result CSV, a plot, an FMU, a saved model, an exported library,
pre-training results) is checked here, the same way, before any work starts:

- a device, FIFO or socket is never an output, nor an input (:func:`check_input`);
- a symbolic link is followed to what it names (the link stays); one naming nothing is refused;
- an existing path is replaced only with ``force``, and only when mcl wrote it. Each directory
  mcl writes into keeps a record, ``.mcl-outputs``, of the files mcl wrote there with their
  SHA-256. A file is mcl's when the record of its folder lists it with its current content (a
  result the user has edited since is theirs); a directory is mcl's when it has its own record
  and every file in it is listed there with its content. So a folder that merely holds a
  ``report.json`` or a hand-made marker, or a user's file put into a run directory, is never
  deleted.
"""
from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import shutil
import stat
import tempfile
from pathlib import Path

from .errors import ConfigError, DataError

RECORD = ".mcl-outputs"
_HEADER = "written by mcl"
_SKIP = {RECORD, ".lock"}           # the record itself; a run's lock file (removed when it ends)


def special_kind(path) -> str | None:
    """'a FIFO', 'a device' or 'a socket' when ``path`` (followed) is one, else None."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return None


def check_input(path, what: str = "file", directory_ok: bool = False, error=DataError) -> Path:
    """``path`` as an input: it exists and is a regular file (or, with ``directory_ok``, a
    directory); a FIFO or device is refused (reading one would hang or never end)."""
    p = Path(path).expanduser()
    kind = special_kind(p)
    if kind:
        raise error(f"is {kind}, not a {what}: mcl reads only regular files", where=str(path))
    if p.is_file() or (directory_ok and p.is_dir()):
        return p
    if p.is_dir():
        raise error(f"is a directory, not a {what}", where=str(path))
    if p.is_symlink():
        raise error(f"is a symbolic link to {os.readlink(p)}, which does not exist", where=str(path))
    raise error(f"no such {what}", where=str(path))


def sha256(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _read_record(directory: Path) -> dict | None:
    """The files listed by ``directory``'s record (relative path -> SHA-256), None without one."""
    f = directory / RECORD
    try:
        if not stat.S_ISREG(os.lstat(f).st_mode):
            return None
        data = json.loads(f.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    if not isinstance(data, dict) or data.get("record") != _HEADER or not isinstance(data.get("files"), dict):
        return None
    return {str(k): str(v) for k, v in data["files"].items()}


def _write_record(directory: Path, files: dict) -> None:
    text = json.dumps({"record": _HEADER, "files": dict(sorted(files.items()))}, indent=1)
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=f"{RECORD}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text + "\n")
        os.replace(tmp, directory / RECORD)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def record(path) -> None:
    """Note in its folder's record that mcl wrote the file ``path`` (as it is now)."""
    p = Path(path)
    folder = p.parent
    fd = os.open(folder, os.O_RDONLY)       # the folder locked: two mcl commands writing into it
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        files = _read_record(folder) or {}
        files[p.name] = sha256(p)
        _write_record(folder, files)
    finally:
        os.close(fd)


def record_tree(directory) -> None:
    """Mark ``directory`` as made by mcl: its record lists every file now in it."""
    d = Path(directory)
    files = {}
    for root, dirs, names in os.walk(d):
        for name in names:
            p = Path(root) / name
            if name in _SKIP or name.startswith(f"{RECORD}."):
                continue
            if stat.S_ISREG(os.lstat(p).st_mode):
                files[str(p.relative_to(d))] = sha256(p)
    _write_record(d, files)


def mark_started(directory) -> None:
    """An (empty) record in a directory mcl is about to fill (a run in progress)."""
    if _read_record(Path(directory)) is None:
        _write_record(Path(directory), {})


def has_record(directory) -> bool:
    return _read_record(Path(directory)) is not None


def not_mcls(path) -> str | None:
    """Why ``path`` is not provably mcl's (None when it is: every file listed, unchanged)."""
    p = Path(path)
    if not p.is_dir():
        want = (_read_record(p.parent) or {}).get(p.name)
        if want is None:
            return "mcl did not write it"
        return "it was changed since mcl wrote it" if want != sha256(p) else None
    own = _read_record(p)
    if own is None:
        return f"it holds no {RECORD} record of mcl"
    try:
        return _foreign(p, own)
    except OSError as exc:      # a folder that cannot be read cannot be shown to be mcl's
        return f"{exc.filename} cannot be read ({exc.strerror})"


def _foreign(p: Path, own: dict) -> str | None:
    """The first thing in the directory ``p`` that its record ``own`` (or the record of its own
    folder) does not list with its content, as a reason; None when there is none."""
    def fail(exc):
        raise exc

    for root, dirs, names in os.walk(p, onerror=fail):
        here = Path(root)
        local = _read_record(here) or {} if here != p else {}
        links = [d for d in dirs if os.path.islink(here / d)]
        for name in sorted(names) + links:
            f = here / name
            rel = str(f.relative_to(p))
            if name == RECORD or name.startswith(f"{RECORD}.") or (name == ".lock" and here == p):
                continue
            want = own.get(rel, local.get(name))
            if want is None or not stat.S_ISREG(os.lstat(f).st_mode):
                return f"it holds {rel}, which mcl did not write"
            if want != sha256(f):
                return f"{rel} was changed since mcl wrote it"
    return None


def check_output(path, force: bool = False, directory: bool = False, inputs=(), what: str = "",
                 exists: str = "exists (written by mcl earlier): use --force to replace it") -> Path:
    """The real path to write the output ``path`` to, or a ConfigError saying why not (nothing
    is changed). ``directory``: the output is a directory mcl fills; ``inputs``: the paths the
    command reads, which are never its outputs; ``what`` names the output with its article (an
    FMU); ``exists``: the refusal of an output mcl wrote when ``force`` is not given."""
    given = str(path)
    p = Path(path).expanduser()
    label = what or ("a directory" if directory else "a file")
    if p.name == RECORD or p.name.startswith(f"{RECORD}."):
        raise ConfigError("is the name of mcl's record of what it wrote: choose another output", where=given)
    if p.is_symlink() and not p.exists():
        raise ConfigError(f"is a symbolic link to {os.readlink(p)}, which does not exist: "
                          "choose another output", where=given)
    real = Path(os.path.realpath(p))
    kind = special_kind(real)
    if kind:
        raise ConfigError(f"is {kind}: never an output of mcl", where=given)
    for inp in (Path(i) for i in inputs if i is not None and Path(i).exists()):
        if real.exists() and os.path.samefile(real, inp):
            raise ConfigError("is an input of this command: choose another output", where=given)
        if real in Path(os.path.realpath(inp)).parents:
            raise ConfigError(f"holds {inp}, an input of this command: choose another output", where=given)
    if not real.exists():
        above = next(a for a in real.parents if a.exists())
        if not above.is_dir():
            raise ConfigError(f"cannot be written: {above} is a file, not a folder", where=given)
        return real
    if directory and not real.is_dir():
        raise ConfigError(f"is a file, not {label}: choose another output", where=given)
    if not directory and real.is_dir():
        raise ConfigError(f"is an existing directory, not {label}: choose another output", where=given)
    why = not_mcls(real)
    if why:
        raise ConfigError(f"exists and was not made by mcl ({why}): choose another output "
                          "(nothing was changed)", where=given)
    if not force:
        raise ConfigError(exists, where=given)
    return real


def replace_directory(new, out, force: bool = True) -> Path:
    """Put the finished directory ``new`` (a sibling of ``out``) in place of the real path
    ``out``; an existing ``out`` is checked again first (a user may have put a file into it
    meanwhile), renamed aside, and deleted only once ``new`` is in place."""
    new, out = Path(new), Path(out)
    old = None
    if out.exists() or out.is_symlink():
        if check_output(out, force=force, directory=True) != out:
            raise ConfigError("became a symbolic link while mcl was writing: nothing was replaced",
                              where=str(out))
        old = out.with_name(f".{out.name}.replaced-{os.getpid()}")
        out.rename(old)
    try:
        new.rename(out)
    except BaseException:
        if old is not None:
            old.rename(out)
        raise
    if old is not None:
        shutil.rmtree(old)
    return out


def staging(out: Path) -> Path:
    """A new empty directory beside ``out`` to build it in (same file system: renamed into place)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    return Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp"))


@contextlib.contextmanager
def new_directory(out, force: bool = False, what: str = "a directory", inputs=()):
    """Build the output directory ``out`` in a staging directory beside it (yielded), then put
    it in place, marked as mcl's; on an error nothing of ``out`` was touched."""
    target = check_output(out, force, directory=True, what=what, inputs=inputs)
    tmp = staging(target)
    try:
        yield tmp
        record_tree(tmp)
        replace_directory(tmp, target, force)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
