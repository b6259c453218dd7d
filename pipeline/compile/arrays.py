"""Modelica arrays as CasADi values, for the rumoca front end: a vector is a column, a matrix
keeps its rows and columns, and flattened (a variable's elements, a record's fields) an array
is always in Modelica's row-major order."""
from __future__ import annotations

import casadi as ca
import numpy as np


def as_int(a) -> int:
    """A constant (or parameter-valued) expression as an integer: a size, an index."""
    return int(round(float(a) if a.is_constant() else float(ca.evalf(a))))


def flat(a) -> ca.SX:
    """An array as a column of its elements in Modelica's (row-major) order. Arrays keep their
    shape while translated: a vector is a column, a matrix its rows and columns."""
    a = ca.SX(a)
    return ca.vec(a.T) if a.size2() > 1 else a


def shaped(v: ca.SX, dims) -> ca.SX:
    """A variable's elements (row-major, as named) in the shape declared: a matrix for two
    dimensions; a vector otherwise (arrays of three or more dimensions stay flattened)."""
    if dims is not None and len(dims) == 2 and v.numel() == dims[0] * dims[1]:
        return ca.reshape(v, dims[1], dims[0]).T
    return v


def alike(a, b):
    """Two arrays of one size and different shapes (a matrix and the same elements held
    flattened: an array of three dimensions, a function's flattened output) as flat columns."""
    if a.shape != b.shape and not a.is_scalar() and not b.is_scalar() and a.numel() == b.numel():
        return flat(a), flat(b)
    return a, b


def multiply(a, b):
    """Modelica's ``*``: scaling, the scalar product of two vectors, matrix products."""
    if a.is_scalar() or b.is_scalar():
        return ca.times(a, b)
    (ra, ka), (rb, kb) = a.shape, b.shape
    if ka == 1 and kb == 1 and ra == rb:
        return ca.dot(a, b)
    if ka == 1 and ra == rb:                  # vector * matrix
        return ca.mtimes(a.T, b).T
    if ka == rb:
        return ca.mtimes(a, b)
    return NotImplemented


def array_of(items: list) -> ca.SX:
    """``{a, b, ...}``: a vector of scalars, or the matrix whose rows are the vectors given."""
    if items and all(i.size2() == 1 and i.size1() > 1 for i in items) \
            and len({i.size1() for i in items}) == 1:
        return ca.horzcat(*items).T
    return ca.vertcat(*[flat(i) for i in items]) if items else ca.SX(0, 1)


def repeated(v: ca.SX, n: int) -> ca.SX:
    """``v`` (a column of ``n`` elements, or one) as ``n`` elements: a scalar set to every
    element of an array."""
    return v if v.numel() == n else ca.repmat(v, n, 1)


def grown(base: ca.SX, sels: list) -> ca.SX:
    """``base`` extended with zeros to hold an element one past its end (an array a function
    fills in order: ``for i in 1:n loop r[i] := ...``); other subscripts leave it as it is."""
    def need(s):
        return max(s) if isinstance(s, list) and s else s if isinstance(s, int) else 0

    if len(sels) == 1 and base.size2() <= 1:
        n = need(sels[0])
        if n == base.size1() + 1:
            return ca.vertcat(base, ca.SX.zeros(1, 1)) if base.numel() else ca.SX.zeros(1, 1)
        return base
    if len(sels) == 2:
        rows, cols = max(base.size1(), need(sels[0])), max(base.size2(), need(sels[1]))
        if (rows, cols) != base.shape and rows <= base.size1() + 1 and cols <= base.size2() + 1:
            out = ca.SX.zeros(rows, cols)
            if base.numel():
                out[:base.size1(), :base.size2()] = base
            return out
    return base


def modelica_size(a, k=None):
    """``size(a)`` and ``size(a, k)``: a column is a vector (one dimension)."""
    shape = (a.size1(),) if a.size2() == 1 else a.shape
    if k is None:
        return ca.SX(list(shape))
    j = as_int(k) - 1
    return ca.SX(shape[j] if j < len(shape) else 1)


def dims_of(*n) -> tuple[int, int]:
    """The shape of ``zeros(n1, n2, ...)``: dimensions past the second are flattened into it."""
    n = [as_int(k) for k in n]
    return (n[0], 1) if len(n) == 1 else (n[0], int(np.prod(n[1:])))
