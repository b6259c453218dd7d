"""CasADi Functions called from numpy through their buffers.

A plain call converts each numpy argument to a DM and each result back: about 50 us a call,
where the evaluation itself takes a few. The event handling calls the relations and the event
iteration's update tens of times per event (a rectifier has 600 events a second), so there the
call is the cost. Through the Function's buffer the arguments are read in place: about 5 us.
"""
from __future__ import annotations

import casadi as ca
import numpy as np


class Call:
    """``f`` called with numpy arrays (or floats), giving numpy arrays shaped as ``f``'s
    outputs: one array for one output, else a list. Raises RuntimeError where the evaluation
    fails, as a plain call does. Arguments whose size is not ``f``'s (broadcast by a plain
    call) go through a plain call."""

    def __init__(self, f: ca.Function):
        self.f = f
        self.buf, self.trigger = f.buffer()
        self.n_in = [f.nnz_in(i) for i in range(f.n_in())]
        self.numel_in = [f.numel_in(i) for i in range(f.n_in())]
        self.gather = [_nonzeros(f.sparsity_in(i)) for i in range(f.n_in())]
        self.shapes = [f.size_out(i) for i in range(f.n_out())]
        self.scatter = [_nonzeros(f.sparsity_out(i)) for i in range(f.n_out())]
        self.res = [np.zeros(f.nnz_out(i)) for i in range(f.n_out())]
        for i, r in enumerate(self.res):
            self.buf.set_res(i, memoryview(r))

    def __call__(self, *args):
        held = []           # (the buffer reads the arrays at the trigger: kept alive until then)
        for i, a in enumerate(args):
            a = np.asarray(a, float)
            a = a.ravel(order="F") if a.ndim > 1 else a.ravel()
            if a.size != self.n_in[i] and self.gather[i] is not None and a.size == self.numel_in[i]:
                a = a[self.gather[i]]      # (a sparse input given dense)
            if a.size != self.n_in[i]:
                return self._plain(args)
            a = np.ascontiguousarray(a)
            held.append(a)
            self.buf.set_arg(i, memoryview(a))
        self.trigger()
        if self.buf.ret():
            raise RuntimeError(f"Evaluation of {self.f.name()} failed")
        out = [self._shaped(k) for k in range(len(self.res))]
        return out[0] if len(out) == 1 else out

    def _shaped(self, k: int) -> np.ndarray:
        shape, r = self.shapes[k], self.res[k]
        if self.scatter[k] is None:
            return r.reshape(shape, order="F").copy()
        full = np.zeros(shape[0] * shape[1])
        full[self.scatter[k]] = r
        return full.reshape(shape, order="F")

    def _plain(self, args):
        out = self.f(*args)
        return [np.array(o) for o in out] if self.f.n_out() > 1 else np.array(out)


def _nonzeros(sp: ca.Sparsity) -> np.ndarray | None:
    """The column-major positions of ``sp``'s nonzeros, or None where it is dense."""
    return None if sp.is_dense() else np.array(sp.find(), dtype=int)
