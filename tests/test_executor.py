"""Batches: crashes and hangs are isolated and labelled; the Dask executor gives the same results."""
import logging
import os
import time

import pytest

from mcl import hookimpl
from mcl.executor import DaskExecutor, LocalExecutor, SerialExecutor, TaskFailed
from mcl.progress import Progress
from mcl.registry import Registry


def task(scale, x):
    if x == 3:
        os.kill(os.getpid(), 11)   # segfault in native code
    if x == 5:
        time.sleep(60)             # a simulation that hangs
    if x == 6:
        raise ValueError("bad input")
    return scale * x


def test_local_executor_isolates_crash_hang_and_error():
    t0 = time.perf_counter()
    out = LocalExecutor(workers=2).map(task, list(range(8)), context=10, timeout=2, progress=False)
    assert time.perf_counter() - t0 < 20
    assert [r for k, r in enumerate(out) if k not in (3, 5, 6)] == [0, 10, 20, 40, 70]
    assert isinstance(out[3], TaskFailed) and "crashed" in out[3].reason
    assert isinstance(out[5], TaskFailed) and "timed out" in out[5].reason
    assert isinstance(out[6], TaskFailed) and "bad input" in out[6].reason


def pid_or_crash(_, x):
    if x == 4:
        os.kill(os.getpid(), 11)
    return os.getpid()


def test_a_worker_serves_many_tasks_and_a_crashed_one_is_replaced():
    """Forked per task, a short task paid for the fork and its copied pages: a worker takes one
    task after another, and one that crashes takes only its own task with it."""
    out = LocalExecutor(workers=2).map(pid_or_crash, list(range(12)), timeout=30, progress=False)
    assert isinstance(out[4], TaskFailed) and "crashed" in out[4].reason
    pids = {r for k, r in enumerate(out) if k != 4}
    assert len(pids) <= 3 and os.getpid() not in pids     # two workers, and the crashed one's heir


def test_results_are_reported_as_they_arrive():
    seen = []
    out = LocalExecutor(workers=2).map(square, [1, 2, 3], context=0, progress=False,
                                       on_result=lambda k, r: seen.append((k, r)))
    assert sorted(seen) == [(0, 1), (1, 4), (2, 9)] and out == [1, 4, 9]


def test_serial_executor_labels_errors():
    out = SerialExecutor().map(lambda c, x: 1 / x, [1, 0], progress=False)
    assert out[0] == 1 and isinstance(out[1], TaskFailed)


def square(offset, x):
    return x * x + offset


def test_dask_local_cluster_gives_the_same_results():
    pytest.importorskip("distributed")
    with DaskExecutor(workers=2) as ex:
        out = ex.map(square, list(range(20)), context=1, timeout=60, progress=False)
        failing = ex.map(task, [6, 2], context=1, timeout=60, progress=False)
    assert out == [x * x + 1 for x in range(20)]
    assert isinstance(failing[0], TaskFailed) and failing[1] == 2


def evaluate_rate(context, x):
    """A task reading SX expressions from its context, as a discovery's fits do (the rates of the
    components' variables), which pickle only inside CasADi's pickle context."""
    import casadi as ca

    rate, sym = context["rate"], context["x"]
    return float(ca.Function("rate", [sym], [rate])(x))


def test_dask_ships_a_context_holding_casadi_expressions():
    pytest.importorskip("distributed")
    import casadi as ca

    x = ca.SX.sym("x")
    context = {"rate": 3 * x ** 2 + 1, "x": x}     # the same symbol in both: shared after the trip
    with DaskExecutor(workers=2) as ex:
        out = ex.map(evaluate_rate, [0.0, 1.0, 2.0, 3.0], context=context, timeout=60, progress=False)
    assert out == [1.0, 4.0, 13.0, 28.0]


def test_progress_eta_counts_rounds_of_workers(caplog):
    bar = Progress("batch", 4, workers=2)
    bar.start -= 10.0            # the first two tasks ran side by side for 10 s
    bar.update()
    bar.update()
    assert bar.eta() == pytest.approx(10.0, rel=0.05)   # one more round of two, not 2 x 5 s
    with caplog.at_level(logging.INFO, logger="mcl"):
        bar.update(False)
        bar.update()
    assert "batch: 4/4 done (1 failed)" in caplog.text


def nap(seconds, x):
    time.sleep(seconds)
    return x


def test_a_long_task_is_not_silence_in_a_log(caplog, monkeypatch):
    """Where stderr is a log file, a batch whose task runs long says so now and then (a
    candidate's fit of 17 minutes printed nothing at all)."""
    import mcl.progress

    monkeypatch.setattr(mcl.progress, "LOG_EVERY", 0.2)
    with caplog.at_level(logging.INFO, logger="mcl"):
        out = LocalExecutor(workers=1).map(nap, [1], context=0.7, timeout=60, label="fits")
    assert out == [1]
    assert "fits: 0/1, one running for" in caplog.text, caplog.text


class InlineExecutor(SerialExecutor):
    name = "inline"


class ExecutorPlugin:
    @hookimpl
    def mcl_executors(self):
        return [InlineExecutor]


def test_executors_are_plugins():
    reg = Registry(external=False, extra=[ExecutorPlugin()])
    assert {"local", "serial", "dask", "inline"} <= set(reg.executors)
    assert reg.executor("inline").map(square, [2], context=0, progress=False) == [4]
