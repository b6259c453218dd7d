"""The run directory: built in ``<output>.partial``, marked as mcl's before anything else is
written, locked against a second run, and renamed into place when the run is done.

mcl never deletes or overwrites what it did not make: an existing output that carries no mark
(and no ``report.json`` of an older mcl) is refused before any work starts, and ``force`` only
replaces a directory mcl made.
"""
from __future__ import annotations

import fcntl
import json
import os
import shutil
import tempfile
from pathlib import Path

from ..errors import ConfigError

MARK = ".mcl-run"


def made_by_mcl(directory: Path) -> bool:
    return (directory / MARK).is_file() or (directory / "report.json").is_file()


class RunDirectory:
    def __init__(self, output, force: bool = False):
        self.output = out = Path(output)
        if out.exists():
            if not out.is_dir():
                raise ConfigError("the output is a file, not a run directory", where=str(out))
            if not made_by_mcl(out):
                raise ConfigError("the output directory exists and was not made by mcl: "
                                  "choose another output (nothing was changed)", where=str(out))
            if (out / "report.json").is_file() and not force:
                raise ConfigError("holds a finished run; choose another output or use --force",
                                  where=str(out))
        self.partial = part = out.with_name(out.name + ".partial")
        if part.exists() and not (part.is_dir() and made_by_mcl(part)):
            raise ConfigError("exists and was not made by mcl: move it away first", where=str(part))
        try:
            part.mkdir(parents=True, exist_ok=True)
            (part / MARK).write_text("made by mcl; an interrupted run resumes from here\n")
        except OSError as exc:
            raise OSError(exc.errno, f"cannot write the run directory: {exc.strerror}", str(part)) from None
        self._lock = open(part / ".lock", "w")
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._lock.close()
            raise ConfigError("another mcl run is writing this run directory; wait for it to end",
                              where=str(out)) from None

    def write_json(self, relative: str, obj) -> Path:
        """``partial/relative`` written atomically (a reader never sees half a file)."""
        path = self.partial / relative
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "w") as fh:
                json.dump(obj, fh, indent=1)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return path

    def finish(self) -> None:
        """Put the finished run in place of ``output`` (only ever replacing a run mcl made)."""
        out, old = self.output, None
        if out.exists():
            old = out.with_name(f".{out.name}.replaced-{os.getpid()}")
            out.rename(old)
        self.partial.rename(out)
        (out / ".lock").unlink(missing_ok=True)
        self._lock.close()
        if old is not None and made_by_mcl(old):
            shutil.rmtree(old)

    def __del__(self):
        lock = getattr(self, "_lock", None)
        if lock is not None and not lock.closed:
            lock.close()
