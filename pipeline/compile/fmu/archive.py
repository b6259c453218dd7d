"""FMU archives opened with care: sizes, entry count, paths and links checked before extraction.

An FMU is a zip file from anywhere; a crafted one can hold gigabytes of zeros in a few
megabytes, entries that climb out of the target directory, or links. Nothing is extracted
until the whole listing has been checked.
"""
from __future__ import annotations

import stat
import zipfile
from pathlib import Path, PurePosixPath

from ...errors import DataError

MAX_TOTAL_BYTES = 1 << 30      # 1 GiB uncompressed
MAX_ENTRIES = 20000
MAX_RATIO = 200                # uncompressed / compressed, per entry larger than 1 MiB


def check_archive(path) -> None:
    """Raise a DataError naming the FMU when its listing is unsafe to extract."""
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as z:
            infos = z.infolist()
    except (zipfile.BadZipFile, OSError) as exc:
        raise DataError(f"not a readable FMU (zip archive): {exc}", where=str(path)) from None
    if len(infos) > MAX_ENTRIES:
        raise DataError(f"FMU archive has {len(infos)} entries (at most {MAX_ENTRIES})", where=str(path))
    total = 0
    for info in infos:
        name = PurePosixPath(info.filename)
        if name.is_absolute() or ".." in name.parts or "\\" in info.filename or ":" in info.filename:
            raise DataError(f"FMU entry '{info.filename}' points outside the archive", where=str(path))
        if stat.S_ISLNK(info.external_attr >> 16):
            raise DataError(f"FMU entry '{info.filename}' is a link", where=str(path))
        if info.file_size > (1 << 20) and info.file_size > MAX_RATIO * max(info.compress_size, 1):
            raise DataError(f"FMU entry '{info.filename}' expands {info.file_size // max(info.compress_size, 1)}"
                            f"-fold (a zip bomb?)", where=str(path))
        total += info.file_size
        if total > MAX_TOTAL_BYTES:
            raise DataError(f"FMU archive expands to more than {MAX_TOTAL_BYTES >> 20} MiB", where=str(path))


def safe_extract(path, directory) -> str:
    """Check, then extract the FMU into ``directory`` (which the caller removes); returns it."""
    check_archive(path)
    with zipfile.ZipFile(path) as z:
        z.extractall(directory)
    return str(directory)
