"""rumoca's work in a forked child: results, errors, log records and crashes come back; the
memory rumoca keeps for each model goes with the child."""
import logging
import os
import signal

import pytest

from mcl.compile.isolation import ChildCrash, forks, in_child
from helpers import needs_msl, msl_path

pytestmark = pytest.mark.skipif(not forks(), reason="work goes to a child only where the platform forks (Linux)")


def _warns_and_returns(n):
    logging.getLogger("mcl.test_isolation").warning("made in the child %d", os.getpid())
    logging.getLogger("mcl.test_isolation").debug("below the level: not handled here")
    return {"pid": os.getpid(), "squares": [k * k for k in range(n)]}


def test_the_value_and_the_log_records_come_back(caplog):
    caplog.set_level(logging.INFO, logger="mcl.test_isolation")
    got = in_child(_warns_and_returns, 4)
    assert got["squares"] == [0, 1, 4, 9] and got["pid"] != os.getpid()
    messages = [r.getMessage() for r in caplog.records if r.name == "mcl.test_isolation"]
    assert messages == [f"made in the child {got['pid']}"]


def _divides(a, b):
    return a / b


def _crashes():
    os.kill(os.getpid(), signal.SIGSEGV)


def _nested(depth):
    deep: list = []
    for _ in range(depth):
        deep = [deep]
    return deep


def test_an_exception_in_the_child_is_raised_here():
    assert in_child(_divides, 6, 3) == 2
    with pytest.raises(ZeroDivisionError):
        in_child(_divides, 1, 0)


def test_a_child_that_crashes_is_a_clear_error_and_the_caller_goes_on():
    with pytest.raises(ChildCrash, match="SIGSEGV"):
        in_child(_crashes)
    assert in_child(_divides, 14, 2) == 7


def test_a_value_that_nests_deeply_comes_back():
    got, depth = in_child(_nested, 20000), 0
    while got:
        got, depth = got[0], depth + 1
    assert depth == 20000


def test_a_compile_after_rumoca_ran_in_this_process_does_not_hang(tmp_path):
    """A child forked from a process in which rumoca has run hangs in rumoca (its runtime's
    threads are not in the child): the children are forked from a server instead."""
    import rumoca

    from mcl.compile import rumoca_frontend

    rumoca.Session([]).loads("model A\n  Real x(start = 1);\nequation\n  der(x) = -x;\nend A;\n",
                             model="A", filename=str(tmp_path / "A.mo")).to_dict("dae")
    (tmp_path / "B.mo").write_text("model B\n  Real y(start = 2);\nequation\n  der(y) = -2*y;\nend B;\n")
    ir, _ = rumoca_frontend.load_ir([tmp_path / "B.mo"], "B")
    assert "y" in str(ir["flat"]["variables"])


@needs_msl()
def test_loading_models_does_not_grow_the_callers_memory(monkeypatch):
    """rumoca keeps 100-150 MB for each model it compiled, for the life of its process: loaded
    in a child, the caller's resident memory stays where it was (in process, these four grew
    it by about 400 MB)."""
    from mcl.compile import rumoca_frontend

    monkeypatch.setenv("MODELICAPATH", str(msl_path()))
    names = ["Modelica.Mechanics.MultiBody.Examples.Elementary.Pendulum",
             "Modelica.Mechanics.Rotational.Examples.CoupledClutches",
             "Modelica.Electrical.Machines.Examples.DCMachines.DCPM_Start",
             "Modelica.Thermal.HeatTransfer.Examples.Motor"]
    rumoca_frontend.load_ir([], names[0])           # (imports and caches of mcl's own made)
    before = _resident_mb()
    for name in names:
        ir, _ = rumoca_frontend.load_ir([], name)
        assert ir["flat"]["variables"]
    assert _resident_mb() - before < 100


def _resident_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6


def test_a_process_forked_from_a_caller_uses_a_server_of_its_own():
    """A pool's worker forked from a caller that has a server: its requests must not go down
    the parent's pipes (their replies would cross), nor break the parent's exchange."""
    import multiprocessing

    assert in_child(_divides, 8, 2) == 4                  # (the caller's server running)
    ctx = multiprocessing.get_context("fork")
    with ctx.Pool(2) as pool:
        assert pool.starmap(_in_child_divides, [(9, 3), (10, 5), (12, 4)]) == [3, 2, 3]
    assert in_child(_divides, 9, 3) == 3


def _in_child_divides(a, b):
    return in_child(_divides, a, b)


def test_a_server_that_cannot_start_leaves_the_work_in_process(monkeypatch, caplog):
    """An interpreter that cannot run the server (here one that exits at once): the work is
    done in the caller's process, with a warning, not refused."""
    from mcl.compile import isolation

    monkeypatch.setattr(isolation, "_SERVER", None)
    monkeypatch.setattr(isolation, "_BROKEN", False)
    monkeypatch.setattr(isolation.sys, "executable", "/bin/false")
    assert in_child(_divides, 10, 4) == 2.5
    assert isolation._BROKEN and "stopped" in caplog.text
    monkeypatch.setattr(isolation, "_SERVER", None)
