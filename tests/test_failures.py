"""A failed simulation is a result that says why; nothing hangs or crashes the caller."""
import zipfile

import numpy as np
import pytest

from helpers import multisine, series
from mcl.api import simulate
from mcl.compile.fmu.export import build_fmu
from mcl.model import FmuModel

T = np.linspace(0, 30, 301)
U = series(T, u=multisine(T))


@pytest.fixture(scope="module")
def cauer_fmu(tmp_path_factory, cauer):
    return FmuModel.read(build_fmu(cauer, tmp_path_factory.mktemp("f") / "cauer.fmu"))


@pytest.mark.parametrize("engine", ["casadi", "fmu"])
@pytest.mark.parametrize("params,why", [
    ({"Rnl.w1": -0.1}, ("algebraic loop", "solver", "non-finite")),         # paper 000: w1 < 0
])
def test_infeasible_parameters_are_detected(cauer, cauer_fmu, engine, params, why):
    model = cauer if engine == "casadi" else cauer_fmu
    # the reason is what is asserted, not the time limit: at w1 < 0 the FMU's solver crawls
    # towards the loop's singularity (~4 s on a quiet machine to see it), so the limit is far
    res = simulate(model, U, params, options={"time_limit": 300})
    assert not res.ok
    assert any(w in res.reason.lower() for w in why), res.reason
    assert np.all(np.isnan(res.outputs))


def test_w1_zero_is_the_limit_of_a_vanishing_w1(cauer):
    """Paper 000 counts w1 = 0 as infeasible: 0*i = w2 v^2 + w3 v^3 no longer gives i, and
    Newton's method on the whole loop meets a singular Jacobian. Torn, the loop solves for v = 0
    with i from the circuit: the resistor is a short, the limit of w1 -> 0."""
    zero = simulate(cauer, U, {"Rnl.w1": 0.0})
    tiny = simulate(cauer, U, {"Rnl.w1": 1e-9})
    assert zero.ok and tiny.ok, (zero.reason, tiny.reason)
    span = np.ptp(tiny.outputs)
    assert np.abs(zero.outputs - tiny.outputs).max() < 0.01 * span


def test_feasible_negative_w1_is_not_flagged(cauer):
    """w1 = -1 with w3 = -0.01 is the same law as w1 = 1, w3 = 0.01 (G is homogeneous in w)."""
    a = simulate(cauer, U, {"Rnl.w1": -1.0, "Rnl.w3": -0.01})
    b = simulate(cauer, U)
    assert a.ok and b.ok
    assert np.allclose(a.outputs, b.outputs, atol=1e-6)


@pytest.mark.parametrize("engine", ["casadi", "fmu"])
def test_time_limit_stops_the_run(cauer, cauer_fmu, engine):
    model = cauer if engine == "casadi" else cauer_fmu
    t = np.linspace(0, 2000, 200001)
    res = simulate(model, series(t, u=multisine(t)), options={"time_limit": 0.05, "rtol": 1e-10})
    assert not res.ok and "time limit" in res.reason
    assert res.seconds < 10


def test_an_fmu_run_stopped_at_its_time_limit_leaves_no_unpacked_fmu(cauer_fmu, tmp_path, monkeypatch):
    """The child process that runs the FMU is killed at the time limit; the directory the FMU
    was unpacked into is the parent's, and removed (the child's own was left behind, one per
    killed run)."""
    import tempfile

    (tmp_path / "tmp").mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    t = np.linspace(0, 2000, 200001)
    res = simulate(cauer_fmu, series(t, u=multisine(t)), options={"time_limit": 0.05, "rtol": 1e-10})
    assert not res.ok and "time limit" in res.reason
    assert list((tmp_path / "tmp").iterdir()) == []


def test_broken_fmu_binary_is_a_failed_result(tmp_path, cauer_fmu):
    broken = tmp_path / "broken.fmu"
    with zipfile.ZipFile(cauer_fmu.path) as src, zipfile.ZipFile(broken, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            dst.writestr(item, b"\x7fELF garbage" if item.filename.endswith(".so") else data)
    res = simulate(FmuModel.read(broken), U)
    assert not res.ok and "FMU" in res.reason
