"""The fast paths under the event handling: CasADi Functions called through their buffers, and
models whose blocks sit around a run-time linear solve evaluated as a few SX functions."""
import casadi as ca
import numpy as np
import pytest

from helpers import msl_path, needs_msl
from mcl.calls import Call
from mcl.compile.structure import fused


def test_a_buffered_call_gives_what_a_plain_call_gives():
    x, p = ca.SX.sym("x", 3), ca.SX.sym("p", 2)
    sparse_out = ca.vertcat(x[0] * p[0], ca.SX(1, 1), ca.sin(x[2]))      # a structural zero inside
    f = ca.Function("f", [x, p], [sparse_out, ca.reshape(ca.vertcat(x, x * p[1]), 3, 2)])
    xv, pv = np.array([0.3, -1.0, 2.0]), np.array([1.5, -2.0])
    out, mat = Call(f)(xv, pv)
    ref = f(xv, pv)
    assert out.shape == (3, 1) and np.allclose(out, np.array(ref[0]))
    assert mat.shape == (3, 2) and np.allclose(mat, np.array(ref[1]))
    # mapped, with matrix arguments (column-major as CasADi reads them)
    X = np.random.default_rng(0).normal(size=(3, 5))
    g = f.map(5)
    assert np.allclose(Call(g)(X, np.repeat(pv[:, None], 5, 1))[0], np.array(g(X, np.repeat(pv[:, None], 5, 1))[0]))
    # a scalar that the plain call would broadcast goes through the plain call
    assert np.allclose(Call(g)(X, 1.0)[0], np.array(g(X, 1.0)[0]))


def test_a_buffered_call_that_fails_raises_as_a_plain_call_does():
    a = ca.MX.sym("a", 2)
    f = ca.Function("f", [a], [ca.solve(ca.MX(ca.DM.zeros(2, 2)) + ca.diag(a), ca.DM.ones(2), "qr")])
    assert np.allclose(Call(f)([2.0, 4.0]).ravel(), [0.5, 0.25])
    with pytest.raises(RuntimeError):
        f([0.0, 1.0])
    with pytest.raises(RuntimeError):
        Call(f)([0.0, 1.0])


def _blocks_around_a_solve():
    """An MX function as causalisation builds one: SX blocks called one by one, a linear block
    whose matrix depends on a mode solved at run time, and blocks reading its solution."""
    x, m = ca.SX.sym("x", 4), ca.SX.sym("m")
    pre = ca.Function("pre", [x], [ca.vertcat(x[0] + x[1], x[2] * x[3], ca.exp(-x[0]), x[3])])
    A_of = ca.Function("A", [x, m], [ca.vertcat(ca.horzcat(1 + m, 0.5, 0, 0), ca.horzcat(0.5, 2 - m, 0.1, 0),
                                                 ca.horzcat(0, 0.1, 3, m), ca.horzcat(m, 0, 0.2, 4 + x[0] ** 2))])
    z = ca.SX.sym("z", 4)
    post = ca.Function("post", [x, z], [ca.sin(x) + 2 * z])
    X, M = ca.MX.sym("X", 4), ca.MX.sym("M")
    inner = ca.Function("inner", [X, M], [post(X, ca.solve(A_of(X, M), pre(X), "qr"))])
    Xo, Mo = ca.MX.sym("X", 4), ca.MX.sym("M")
    return ca.Function("ode", [Xo, Mo], [3 * inner(Xo, Mo) + Xo])


def test_blocks_around_a_run_time_solve_are_fused_with_the_same_values_and_derivatives():
    f = _blocks_around_a_solve()
    g = fused(f)
    assert g is not f and g.n_instructions() < 16
    calls = [g.instruction_MX(k).which_function() for k in range(g.n_instructions()) if g.instruction_id(k) == ca.OP_CALL]
    assert calls and all(c.is_a("SXFunction") for c in calls)       # the inner MX function inlined
    rng = np.random.default_rng(1)
    for mode in (0.0, 1.0):
        xv = rng.normal(size=4)
        assert np.allclose(np.array(g(xv, mode)), np.array(f(xv, mode)), rtol=1e-12, atol=1e-12)
        J_f = ca.Function("J", f.mx_in(), [ca.jacobian(f(*f.mx_in()), f.mx_in(0))])
        J_g = ca.Function("J", g.mx_in(), [ca.jacobian(g(*g.mx_in()), g.mx_in(0))])
        assert np.allclose(np.array(J_g(xv, mode)), np.array(J_f(xv, mode)), rtol=1e-10, atol=1e-12)


def test_a_function_holding_a_newton_solve_is_left_as_it_is():
    z, p = ca.SX.sym("z"), ca.SX.sym("p")
    root = ca.rootfinder("r", "newton", ca.Function("g", [z, p], [z ** 3 + z - p]))
    P = ca.MX.sym("P", 2)
    f = ca.Function("f", [P], [ca.solve(ca.MX(ca.DM.eye(2)) + ca.diag(P), root(0.5, P[0]) * ca.DM.ones(2), "qr")])
    assert fused(f) is f


def test_more_run_time_work_than_fused_takes_is_left_as_it_is():
    from mcl.compile import structure

    P = ca.MX.sym("P", structure.FUSE_STAGES_MAX + 1)
    x = ca.MX(1.0)
    for k in range(P.numel()):        # each solve reads the one before
        x = ca.solve(ca.MX(ca.DM.zeros(1, 1)) + P[k], x, "qr")
    f = ca.Function("f", [P], [x])
    assert fused(f) is f


@needs_msl()
def test_an_amplifier_read_back_from_the_compile_cache_still_says_which_starts_are_settable(tmp_path, monkeypatch):
    """The detailed op-amp's loops are Newton solves, which CasADi cannot differentiate once
    read back from the compile cache (its 'Duplicate'): the FMU's question, which states
    start at their start values, then gets 'none' instead of stopping the build. Functions
    holding loops are not fused (fused, the same happened to more of them).
    Read back, the loops' solves are shared by the functions that call them as when compiled:
    the same C (saved one file per function, each came back with copies of its own, and an
    FMU's C held them all: HeatingSystem's 20 MB from the cache, 2 MB compiled fresh)."""
    import os

    from mcl import compile_model
    from mcl.compile.fmu.export import settable_starts

    monkeypatch.setenv("MODELICAPATH", str(msl_path()))
    monkeypatch.setenv("MCL_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("MCL_NO_COMPILE_CACHE", raising=False)
    sizes = []
    for k in range(2):           # compiled, then read back
        model = compile_model([], "Modelica.Electrical.Analog.Examples.AmplifierWithOpAmpDetailed")
        pinned, starts = settable_starts(model)
        assert len(pinned) == len(model.ode.x_names) and np.all(np.isfinite(starts))
        o = model.ode.warm or model.ode
        gen = ca.CodeGenerator(f"m{k}.c")
        for f in (o.ode, o.out, o.checks):
            gen.add(f)
        gen.generate(str(tmp_path) + os.sep)
        sizes.append((tmp_path / f"m{k}.c").stat().st_size)
    assert sizes[0] == sizes[1]
