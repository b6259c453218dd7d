"""Measured time series: CSV files with a header row and ``time`` in the first column."""
from __future__ import annotations

import csv
import io
import numbers
import os
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import DataError


@dataclass
class TimeSeries:
    """Samples of named signals on a strictly increasing time grid; ``values`` is (N, n).

    NaN marks a value that was not measured (a blank cell: a signal logged at a lower rate, or
    partial measurements as in paper 004); each output is compared where it is measured.
    """

    time: np.ndarray
    values: np.ndarray
    names: list[str]
    source: str = "<memory>"
    #: each output's weight in a fit's residual (:meth:`weighted`): outputs in different units
    #: or with different noise counted in units of their noise; None: all 1
    weights: dict | None = None

    def __post_init__(self):
        self.time = np.asarray(self.time, dtype=float).ravel()
        self.values = np.asarray(self.values, dtype=float).reshape(len(self.time), -1)
        if self.values.shape[1] != len(self.names):
            raise DataError(f"{self.values.shape[1]} columns for {len(self.names)} names",
                            where=self.source)

    def column(self, name: str) -> np.ndarray:
        if name not in self.names:
            raise DataError(f"no column '{name}' (columns: {', '.join(self.names)})", where=self.source)
        return self.values[:, self.names.index(name)]

    def select(self, names) -> "TimeSeries":
        """The columns ``names`` in that order (DataError naming the missing ones)."""
        missing = [n for n in names if n not in self.names]
        if missing:
            held = "the data have" if self.source.startswith("<") else "the file has"
            raise DataError(f"missing column(s) {', '.join(missing)}; {held}: "
                            f"{', '.join(self.names) or 'only time'}", where=self.source)
        idx = [self.names.index(n) for n in names]
        return TimeSeries(self.time, self.values[:, idx], list(names), self.source, self.weights)

    def head(self, n: int) -> "TimeSeries":
        """The first ``n`` samples (where a model's initial state holds)."""
        return TimeSeries(self.time[:n], self.values[:n], list(self.names), self.source, self.weights)

    def weighted(self, weights: dict | None) -> "TimeSeries":
        """The same samples, their residuals weighted by ``weights`` (by output name) in fits."""
        return TimeSeries(self.time, self.values, list(self.names), self.source, weights or None)

    def weight_of(self, names) -> np.ndarray:
        """The weights of the outputs ``names`` (1 where none is set)."""
        w = self.weights or {}
        return np.array([float(w.get(n, 1.0)) for n in names])

    def to_frame(self):
        """A pandas DataFrame indexed by ``time``, one column per signal."""
        import pandas as pd

        return pd.DataFrame(self.values, index=pd.Index(self.time, name="time"), columns=list(self.names))

    def fingerprint(self) -> str:
        """SHA-256 of the names and samples (identifies in-memory data in a report)."""
        import hashlib

        h = hashlib.sha256(repr(list(self.names)).encode())
        h.update(np.ascontiguousarray(self.time).tobytes())
        h.update(np.ascontiguousarray(self.values).tobytes())
        return h.hexdigest()

    def validate(self) -> "TimeSeries":
        """Raise a DataError for NaN/inf values or a time column that is not increasing."""
        if len(self.time) < 2:
            raise DataError("needs at least two samples", where=self.source)
        bad_t = np.nonzero(~np.isfinite(self.time))[0]
        if bad_t.size:
            raise DataError(f"time is not a finite number (data row {bad_t[0] + 1})", where=self.source)
        step = np.nonzero(np.diff(self.time) <= 0)[0]
        if step.size:
            raise DataError(f"time is not strictly increasing at data row {step[0] + 2} "
                            f"(t = {self.time[step[0] + 1]:g})", where=self.source)
        bad = np.argwhere(np.isinf(self.values))
        if bad.size:
            r, c = bad[0]
            raise DataError(f"column '{self.names[c]}' has an infinite value at data row "
                            f"{r + 1} (t = {self.time[r]:g})", where=self.source)
        empty = [n for n, col in zip(self.names, self.values.T) if not np.isfinite(col).any()]
        if empty:
            raise DataError(f"column '{empty[0]}' has no measured value", where=self.source)
        return self

    def measured(self) -> np.ndarray:
        """(N, n) mask of the values that were measured (not blank)."""
        return np.isfinite(self.values)

    def filled(self) -> "TimeSeries":
        """Blank values interpolated linearly from the column's measured samples (inputs logged
        at a lower rate); a column measured fewer than twice cannot be filled."""
        vals = self.values.copy()
        for k, name in enumerate(self.names):
            ok = np.isfinite(vals[:, k])
            if ok.all():
                continue
            if ok.sum() < 2:
                raise DataError(f"input column '{name}' is measured at fewer than two times", where=self.source)
            vals[:, k] = np.interp(self.time, self.time[ok], vals[ok, k])
        return TimeSeries(self.time, vals, list(self.names), self.source, self.weights)


def as_timeseries(data, what: str = "data", time: str | None = None) -> TimeSeries:
    """A :class:`TimeSeries` from a TimeSeries, a pandas DataFrame, a NumPy structured array, a
    mapping of columns, or a CSV path.

    Time is the column named ``time``; ``time="t"`` names another column, and ``time="index"``
    takes a DataFrame's index (an index named ``time``, as :meth:`TimeSeries.to_frame` makes,
    is taken without asking). Row numbers are never taken for time.
    """
    if isinstance(data, TimeSeries):
        return data.validate()
    if isinstance(data, (str, os.PathLike)):
        return read_csv(data)
    key = time or "time"
    try:
        if hasattr(data, "columns") and hasattr(data, "index"):   # a pandas DataFrame
            cols = [str(c) for c in data.columns]
            if len(set(cols)) < len(cols):
                raise DataError(f"{what}: duplicate column name(s) "
                                f"{', '.join(sorted({c for c in cols if cols.count(c) > 1}))}")
            values = _numeric(data.to_numpy(), cols, what)
            if key in cols:
                k = cols.index(key)
                return TimeSeries(values[:, k], np.delete(values, k, axis=1), cols[:k] + cols[k + 1:],
                                  f"<{what}>").validate()
            if time == "index" or (time is None and getattr(data.index, "name", None) == "time"):
                t = _numeric(np.asarray(data.index), ["the index"], what).ravel()
                return TimeSeries(t, values, cols, f"<{what}>").validate()
            raise DataError(f"{what}: no '{key}' column (columns: {', '.join(cols) or 'none'}); "
                            + ("name the time column with time='...', or time='index' for the index"
                               if time is None else "time='index' takes the index"))
        if isinstance(data, np.ndarray) and data.dtype.names:
            columns = {n: data[n] for n in data.dtype.names}
        elif isinstance(data, dict):
            columns = {str(k): v for k, v in data.items()}
        else:
            raise DataError(f"{what}: give a pandas DataFrame, a NumPy structured array, a mapping of "
                            f"columns, a TimeSeries or a CSV path, not {type(data).__name__}")
        if key not in columns:
            raise DataError(f"{what}: no '{key}' column (columns: {', '.join(map(str, columns)) or 'none'})"
                            + ("; name the time column with time='...'" if time is None else ""))
        names = [n for n in columns if n != key]
        arrays = [np.asarray(columns[n]).ravel() for n in [key, *names]]
        if len({len(a) for a in arrays}) > 1:
            raise DataError(f"{what}: the columns have different lengths "
                            f"({', '.join(f'{n}: {len(a)}' for n, a in zip([key, *names], arrays))})")
        values = np.column_stack([_numeric(a, [n], what)[:, 0] for n, a in zip([key, *names], arrays)])
        return TimeSeries(values[:, 0], values[:, 1:], names, f"<{what}>").validate()
    except MemoryError:
        raise DataError(f"{what}: too large to hold in memory") from None


def _numeric(array, names, what) -> np.ndarray:
    """``array`` as floats (None, NaN and pandas' NA are not measured), or a DataError naming
    the first value that is not a number (text is never read as a number here)."""
    array = np.asarray(array)
    array = array.reshape(-1, 1) if array.ndim == 1 else array
    if array.dtype.kind in "biuf":
        return array.astype(float)
    out = np.empty(array.shape)
    for (r, k), v in np.ndenumerate(array):
        if v is None or v is getattr(_pandas_na(), "NA", None) or (isinstance(v, float) and v != v):
            out[r, k] = np.nan
        elif isinstance(v, (numbers.Real, np.number)) and not isinstance(v, (bool, np.bool_)):
            out[r, k] = float(v)
        else:
            shown = v.item() if isinstance(v, np.generic) else v
            raise DataError(f"{what}: column '{names[k]}' holds {shown!r} at row {r + 1}, which is not a number")
    return out


def _pandas_na():
    import sys

    return sys.modules.get("pandas")


#: a decimal number as CSV files write it (Python's float() also takes 1_000 and non-ASCII digits)
_NUMBER = re.compile(r"[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?")
_NOT_MEASURED = {"nan", "+nan", "-nan", "inf", "+inf", "-inf", "infinity", "+infinity", "-infinity"}


def _cell(text: str) -> float:
    """A cell's value: a decimal number (ValueError otherwise); blank is NaN (not measured);
    nan/inf parse as themselves and are refused by the caller."""
    text = text.strip()
    if not text:
        return np.nan
    if _NUMBER.fullmatch(text) or text.lower() in _NOT_MEASURED:
        return float(text)
    raise ValueError(text)


def _delimiter(text: str) -> str:
    """The separator of a CSV's fields, read from its header: a comma, or the semicolon (with
    decimal commas in the numbers) or tab a spreadsheet set to a European locale writes."""
    header = next((line for line in text.splitlines() if line.strip()), "")
    return max(",;\t", key=header.count) if any(c in header for c in ";\t") else ","


def read_csv(path) -> TimeSeries:
    """Read a CSV time series; errors name the file and line."""
    from .outputs import check_input

    path = check_input(path, "data file")
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:
            text = fh.read()
        delimiter = _delimiter(text)
        rows = list(csv.reader(io.StringIO(text, newline=""), delimiter=delimiter))
    except UnicodeDecodeError as exc:
        raise DataError(f"not UTF-8 text ({exc.reason} at byte {exc.start}); save the CSV as UTF-8",
                        where=str(path)) from None
    except csv.Error as exc:
        raise DataError(f"not a readable CSV file: {exc}", where=str(path)) from None
    if any("\0" in cell for row in rows[:50] for cell in row):
        raise DataError("not a text CSV file (it holds NUL bytes)", where=str(path))
    rows = [r for r in rows if r and any(c.strip() for c in r)]
    if not rows:
        raise DataError("empty file", where=str(path))
    rows = _without_blank_tail(rows)
    header = [h.strip() for h in rows[0]]
    if header[0].lower() != "time":
        raise DataError(f"the first column must be 'time', not '{header[0]}'", where=f"{path}:1")
    dup = {h for h in header if header.count(h) > 1}
    if dup:
        raise DataError(f"duplicate column name(s) {', '.join(sorted(dup))}", where=f"{path}:1")
    if len(rows) < 3:
        raise DataError(f"a header row and at least two samples are needed ({len(rows) - 1} sample(s))",
                        where=str(path))
    data = np.empty((len(rows) - 1, len(header)))
    for i, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise DataError(f"{len(row)} fields, the header has {len(header)}", where=f"{path}:{i}")
        for j, cell in enumerate(row):
            try:
                data[i - 2, j] = _cell(cell if delimiter == "," else cell.replace(",", "."))   # blank: not measured
            except ValueError:
                raise DataError(f"column '{header[j]}': '{cell}' is not a number",
                                where=f"{path}:{i}") from None
            if not np.isfinite(data[i - 2, j]) and cell.strip():
                raise DataError(f"column '{header[j]}': '{cell.strip()}' is not a measured value "
                                "(leave the cell blank where nothing was measured)", where=f"{path}:{i}")
    return TimeSeries(data[:, 0], data[:, 1:], header[1:], str(path)).validate()


def _without_blank_tail(rows: list[list[str]]) -> list[list[str]]:
    """``rows`` without trailing columns that are blank throughout, header included: a
    spreadsheet's export ends each line with a delimiter (``1.0,2.0,``)."""
    width = len(rows[0])
    while width > 1 and all(len(r) == width and not r[-1].strip() for r in rows):
        rows = [r[:-1] for r in rows]
        width -= 1
    return rows


def write_csv(path, series: TimeSeries) -> None:
    """Write atomically (temporary file + rename): a reader never sees half a file. A value
    not computed (NaN) is a blank cell, as :func:`read_csv` reads one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["time", *series.names])
            for t, row in zip(series.time, series.values):
                w.writerow([repr(float(t)), *(repr(float(v)) if v == v else "" for v in row)])
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
