"""The MSL's interpolation tables (``Modelica.Blocks.Sources.CombiTimeTable``,
``Modelica.Blocks.Tables.CombiTable1Ds/1Dv``) as CasADi expressions.

rumoca evaluates a table's constructor (``ModelicaStandardTables_*_init2``) and hands over its
data (``external_tables`` of the IR); the C library's lookups are written here as expressions of
the abscissa, so the model stays one symbolic DAE: differentiable for the sensitivities and
generated as C into the FMU, with no external code. They follow ModelicaStandardTables.c:
linear, constant and Akima (``ContinuousDerivative``, ``ModifiedContinuousDerivative``)
segments; extrapolation holding the last point, through the last two points, or periodic.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..errors import UnsupportedConstruct

#: Modelica.Blocks.Types.Smoothness (1-based, as rumoca passes it)
LINEAR, AKIMA, CONSTANT, FRITSCH_BUTLAND, STEFFEN, MAKIMA = 1, 2, 3, 4, 5, 6
#: Modelica.Blocks.Types.Extrapolation
HOLD, LAST_TWO, PERIODIC, NONE = 1, 2, 3, 4
#: what the C library returns when no time event follows (DBL_MAX)
NO_EVENT = float(np.finfo(float).max)


@dataclass
class Table:
    data: np.ndarray          # rows; the first column is the abscissa (time)
    columns: list[int]        # the table's column (1-based) of each output
    smoothness: int
    extrapolation: int
    start: ca.SX | float = 0.0  # time tables: 0 before ``start``; abscissa = time - ``shift``
    shift: ca.SX | float = 0.0

    @classmethod
    def of(cls, record: dict, start=0.0, shift=0.0) -> "Table":
        data = np.atleast_2d(np.asarray(record.get("data") or [], float))
        if data.size == 0:
            raise UnsupportedConstruct("a table read from a file (tableOnFile = true): give the table as a parameter")
        if record["smoothness"] in (FRITSCH_BUTLAND, STEFFEN):
            raise UnsupportedConstruct("a table with monotone spline smoothness (Fritsch-Butland, Steffen)")
        return cls(data, [int(c) for c in record.get("columns", [])], int(record["smoothness"]),
                   int(record["extrapolation"]), start, shift)

    def column(self, icol) -> np.ndarray:
        k = int(round(float(ca.evalf(icol)))) if isinstance(icol, (ca.SX, ca.MX, ca.DM)) else int(icol)
        if not 1 <= k <= len(self.columns) or not 1 <= self.columns[k - 1] <= self.data.shape[1]:
            raise UnsupportedConstruct(f"table column {k} outside the table")
        return self.data[:, self.columns[k - 1] - 1]


def call(symbol: str, table: Table, args: list) -> tuple[ca.SX, ca.SX | None]:
    """The value of the C function ``symbol`` on ``table`` with (tableID, ...) ``args``, and the
    condition under which it would stop the simulation (outside a table without extrapolation)."""
    kind, _, what = symbol.removeprefix("ModelicaStandardTables_").partition("_")
    x = table.data[:, 0]
    if what in ("minimumTime", "minimumAbscissa"):
        return ca.SX(x[0]), None
    if what in ("maximumTime", "maximumAbscissa"):
        return ca.SX(x[-1]), None
    if kind == "CombiTimeTable" and what == "nextTimeEvent":
        return next_event(table, args[1]), None
    if what == "getValue" and kind == "CombiTable1D":
        return lookup(table, table.column(args[1]), args[2], right_end=False)
    if what == "getValue" and kind == "CombiTimeTable":
        t, y = args[2], table.column(args[1])
        value, outside = lookup(table, y, t - table.shift)
        if len(args) >= 5 and (table.smoothness == CONSTANT or np.any(np.diff(x) <= 0)):
            # until the event at a jump is handled, the value before it (the left limit)
            pending = ca.logic_and(args[3] == args[4], t >= args[3])
            value = ca.if_else(pending, lookup(table, y, t - table.shift, left=True)[0], value)
        return ca.if_else(t < table.start, 0.0, value), outside
    raise UnsupportedConstruct(f"table function {symbol}")


def lookup(table: Table, y: np.ndarray, u: ca.SX, left: bool = False,
           right_end: bool = True) -> tuple[ca.SX, ca.SX | None]:
    """Column ``y`` of ``table`` at abscissa ``u`` (``left``: the limit from the left at a jump);
    the condition for being outside a table without extrapolation (``right_end``: the last
    abscissa itself counts as outside, as in a time table)."""
    x = table.data[:, 0]
    if len(x) == 1:
        return ca.SX(y[0]), None
    ext, lo, hi = table.extrapolation, float(x[0]), float(x[-1])
    pieces = _pieces(table.smoothness, x, y)
    if ext == PERIODIC:
        u = lo + ca.fmod(ca.fmod(u - lo, hi - lo) + (hi - lo), hi - lo)
    value = _piecewise(pieces, x, u, left)
    if ext in (HOLD, NONE):        # the first row before the table (a jump at x_0 not yet made)
        value = ca.if_else(u < lo, y[0], ca.if_else(u > hi, y[-1], value))
    elif ext == LAST_TWO:
        value = ca.if_else(u < lo, _line(x[0], x[1], y[0], y[1], pieces[0][1], u, table.smoothness),
                           ca.if_else(u > hi, _line(x[-1], x[-2], y[-1], y[-2], _end_slope(pieces[-1], hi - x[-2]),
                                                    u, table.smoothness), value))
    outside = (ca.logic_or(u < lo, u >= hi if right_end else u > hi)) if ext == NONE else None
    return value, outside


def _line(x0, x1, y0, y1, slope, u, smoothness):
    """Extrapolation through the last two points: their line (linear and constant segments;
    the later row where both have one abscissa), the spline's end tangent (splines)."""
    if smoothness in (AKIMA, MAKIMA):
        return y0 + slope * (u - x0)
    if x1 == x0:
        return ca.SX(y0)
    return y0 + (y1 - y0) / (x1 - x0) * (u - x0)


def _end_slope(piece, h) -> float:
    _, b, c, d = piece
    return b + h * (2 * c + 3 * h * d)


def _pieces(smoothness: int, x: np.ndarray, y: np.ndarray) -> list[tuple[float, float, float, float]]:
    """Per interval [x_i, x_i+1): the cubic a + b h + c h^2 + d h^3 in h = u - x_i."""
    n = len(x) - 1
    dx = np.diff(x)
    secant = np.divide(np.diff(y), dx, out=np.zeros(n), where=dx > 0)
    if smoothness == CONSTANT:
        return [(y[i], 0.0, 0.0, 0.0) for i in range(n)]
    if smoothness not in (AKIMA, MAKIMA) or n < 2:      # two rows: linear, as the C library does
        return [(y[i], secant[i], 0.0, 0.0) for i in range(n)]
    s = _akima_slopes(secant, smoothness == MAKIMA)
    c = (3 * secant - 2 * s[:-1] - s[1:]) / dx
    d = (s[:-1] + s[1:] - 2 * secant) / dx ** 2
    return [(y[i], s[i], c[i], d[i]) for i in range(n)]


def _akima_slopes(m: np.ndarray, modified: bool) -> np.ndarray:
    """The node slopes of (modified) Akima's spline from the secants ``m``, with two secants
    extrapolated at each end as ModelicaStandardTables.c does."""
    m = np.concatenate([[3 * m[0] - 2 * m[1], 2 * m[0] - m[1]], m,
                        [2 * m[-1] - m[-2], 3 * m[-1] - 2 * m[-2]]])
    a, b, c, d = m[:-3], m[1:-2], m[2:-1], m[3:]       # m_i-2, m_i-1, m_i, m_i+1 at each node
    w1, w2 = np.abs(d - c), np.abs(b - a)
    if modified:
        w1, w2 = w1 + 0.5 * np.abs(d + c), w2 + 0.5 * np.abs(b + a)
    total = w1 + w2
    fallback = 0.0 if modified else 0.5 * (b + c)
    return np.where(total > 0, (w1 * b + w2 * c) / np.where(total > 0, total, 1.0), fallback)


def _piecewise(pieces, x: np.ndarray, u: ca.SX, left: bool = False) -> ca.SX:
    """The piece of the interval holding ``u`` (the first piece before x_0, the last after
    x_n); at a repeated abscissa (a jump in a time table) the later row holds from it on, or,
    with ``left``, up to it."""
    a, b, c, d = pieces[-1]
    h = u - x[-2]
    value = a + h * (b + h * (c + h * d))
    for i in range(len(pieces) - 2, -1, -1):
        if x[i + 1] <= x[i]:          # a zero-length interval: its jump is at x_i+1
            continue
        a, b, c, d = pieces[i]
        h = u - x[i]
        inside = u <= x[i + 1] if left else u < x[i + 1]
        value = ca.if_else(inside, a + h * (b + h * (c + h * d)), value)
    return value


def next_event(table: Table, t: ca.SX) -> ca.SX:
    """The next time event of a time table after ``t``: its start, its first and last abscissa,
    and (linear and constant segments) each abscissa between, shifted; repeated over the
    periods when periodic; NO_EVENT when none follows."""
    x = np.unique(table.data[:, 0])
    if len(x) == 1:
        return ca.if_else(t < table.start, table.start, NO_EVENT)
    if table.smoothness in (AKIMA, MAKIMA):
        x = x[[0, -1]]
    if table.extrapolation == PERIODIC:
        period = x[-1] - x[0]
        tau = t - table.shift - x[0]
        k = ca.floor(tau / period)
        event = table.shift + x[0] + k * period + _first_above(x[1:] - x[0], tau - k * period, period)
    else:
        event = _first_above([float(v) + table.shift for v in x], t, NO_EVENT)
    return ca.if_else(t < table.start, table.start, event)


def _first_above(points, t: ca.SX, otherwise) -> ca.SX:
    """The smallest of ``points`` (ascending) above ``t``, else ``otherwise``."""
    value = otherwise if isinstance(otherwise, ca.SX) else ca.SX(otherwise)
    for p in reversed(list(points)):
        value = ca.if_else(t < p, p, value)
    return value
