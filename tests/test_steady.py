"""The pseudo-transient walk to a steady state (mcl.compile.steady)."""
import numpy as np

from mcl.compile import steady


def _flow_and_heat():
    """A flow q driven to 2 and a temperature T carried by it towards 1: der(q) = 2 - q,
    der(T) = q (1 - T). Started at rest (q = 0) the steady system's Jacobian has a zero
    column (no flow carries heat), so Newton's method has no step there."""
    f = lambda x: np.array([2.0 - x[0], x[0] * (1.0 - x[1])])                  # noqa: E731
    jf = lambda x: np.array([[-1.0, 0.0], [1.0 - x[1], -x[0]]])                 # noqa: E731
    step = lambda x, xp, inv_h: (f(x) - inv_h * (x - xp), jf(x) - inv_h * np.eye(2))   # noqa: E731
    return f, jf, step


def test_a_steady_state_singular_at_the_start_is_reached_by_the_models_own_dynamics():
    f, jf, step = _flow_and_heat()
    start = np.zeros(2)
    assert np.linalg.matrix_rank(jf(start)) == 1
    x = steady.walk(step, lambda x: float(np.max(np.abs(f(x)))), start, 1e-10)
    assert x is not None
    assert np.allclose(x, [2.0, 1.0], atol=1e-8)


def test_a_walk_that_cannot_move_reports_none():
    """With no dynamics to follow (a steady residual that no step reduces), no start is made up."""
    step = lambda x, xp, inv_h: (np.array([1.0]) - inv_h * (x - xp), np.array([[-inv_h]]))   # noqa: E731
    assert steady.walk(step, lambda x: 1.0, np.zeros(1), 1e-10) is None
