"""The run directory: built in ``<output>.partial``, marked as mcl's before anything else is
written, locked against a second run, and renamed into place when the run is done.

mcl never deletes or overwrites what it did not make (:mod:`mcl.outputs`): an existing output is
refused before any work starts unless it is a run directory whose record lists every file in it
unchanged, and even that one is replaced only with ``force``. A symbolic link as the output is
followed: the run replaces the directory it names, and the link stays.
"""
from __future__ import annotations

import fcntl
import json
import os
import tempfile
from pathlib import Path

from ..errors import ConfigError
from ..outputs import check_output, has_record, mark_started, record_tree, replace_directory


class RunDirectory:
    def __init__(self, output, force: bool = False):
        self.force = force
        self.output = out = check_run_output(output, force)
        self.partial = part = out.with_name(out.name + ".partial")
        try:
            part.mkdir(parents=True, exist_ok=True)
            mark_started(part)
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
        """Put the finished run in place of ``output`` (only ever replacing a run mcl made: an
        output the user changed meanwhile is refused, and the run stays in ``.partial``)."""
        (self.partial / ".lock").unlink(missing_ok=True)
        record_tree(self.partial)
        try:
            replace_directory(self.partial, self.output, force=self.force)
        except ConfigError as exc:
            raise ConfigError(f"{exc.message}; the finished run is in {self.partial}", where=exc.where) from None
        finally:
            self._lock.close()

    def __del__(self):
        lock = getattr(self, "_lock", None)
        if lock is not None and not lock.closed:
            lock.close()


def check_run_output(output, force: bool = False) -> Path:
    """The real path of a run's output directory, or a ConfigError (nothing is changed): a new
    path, or with ``force`` a run directory mcl made; its ``.partial`` sibling, if any, mcl's."""
    out = check_output(output, force, directory=True, what="a run directory",
                       exists="holds a finished run; choose another output or use --force to replace it")
    part = out.with_name(out.name + ".partial")
    if (part.exists() or part.is_symlink()) and not (part.is_dir() and not part.is_symlink() and has_record(part)):
        raise ConfigError("exists and was not made by mcl: move it away first", where=str(part))
    return out
