"""One executor interface for every batch of simulations (sampling, configurations, candidates).

``local`` runs a process pool on this machine (default), ``serial`` runs in this process (for
debugging), ``dask`` sends the batch to a Dask distributed cluster (a ``LocalCluster`` when no
address is given). In every case a task that crashes its worker or hangs past its timeout
becomes a :class:`TaskFailed` result and the batch goes on. ``fn(context, item)`` gets a
``context`` shipped once per worker (a compiled model, say), not once per task.
"""
from __future__ import annotations

import faulthandler
import multiprocessing as mp
import os
import sys
import time
from dataclasses import dataclass
from typing import Any, Callable

from .errors import ConfigError
from .progress import Progress


@dataclass
class TaskFailed:
    """The result of a task that raised, crashed its worker or timed out."""

    reason: str

    def __bool__(self) -> bool:
        return False


class Executor:
    """Base class: ``map`` runs ``fn(context, item)`` for every item, results in item order."""

    name = ""

    def map(self, fn: Callable[[Any, Any], Any], items: list, context: Any = None,
            timeout: float = 300.0, label: str = "batch", progress: bool = True,
            on_result: Callable[[int, Any], None] | None = None) -> list:
        """Results in item order; ``on_result(index, result)`` is called as each one arrives
        (to checkpoint a long batch)."""
        raise NotImplementedError  # pragma: no cover - interface

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


class SerialExecutor(Executor):
    """In this process, one task after another: no isolation (for debugging)."""

    name = "serial"

    def map(self, fn, items, context=None, timeout=300.0, label="batch", progress=True, on_result=None):
        bar = Progress(label, len(items), enabled=progress)
        out = []
        for k, item in enumerate(items):
            try:
                r = fn(context, item)
            except Exception as exc:  # noqa: BLE001 - a failed task is a result
                r = TaskFailed(f"{type(exc).__name__}: {exc}")
            out.append(r)
            bar.update(not isinstance(r, TaskFailed))
            if on_result:
                on_result(k, r)
        return out


class LocalExecutor(Executor):
    """Up to ``workers`` child processes, each taking one task after another.

    A task that crashes its worker (a segfault in native code) or hangs (killed at ``timeout``)
    is marked failed and a new worker takes the next one: nothing else is lost. On Linux the
    workers are forked, so ``fn`` and ``context`` (and whatever the parent has already built,
    such as integrators cached by the in-process engine) are shared copy-on-write instead of
    pickled. A worker serves many tasks: forked for each, a pre-training sample of 26 ms
    took 47 (the fork, its copied pages and its exit).
    """

    name = "local"

    def __init__(self, workers: int | None = None):
        if workers is not None and (not isinstance(workers, int) or workers < 1):
            raise ConfigError(f"executor 'local': workers must be a whole number >= 1, not {workers!r}")
        self.workers = workers or max(1, os.cpu_count() or 2)
        self.mp = mp.get_context("fork" if sys.platform.startswith("linux") else "spawn")

    def map(self, fn, items, context=None, timeout=300.0, label="batch", progress=True, on_result=None):
        from multiprocessing.connection import wait

        bar = Progress(label, len(items), workers=self.workers, enabled=progress)
        results: dict[int, Any] = {}
        queue = list(range(len(items)))[::-1]
        idle: list[_Worker] = []
        busy: dict[Any, _Worker] = {}      # result connection -> its worker, on a task
        try:
            while queue or busy:
                while queue and len(busy) < self.workers:
                    worker = idle.pop() if idle else _Worker(self.mp, fn, context)
                    k = queue.pop()
                    if not worker.give(k, items[k]):       # (it died between tasks)
                        worker.stop()
                        worker = _Worker(self.mp, fn, context)
                        worker.give(k, items[k])
                    busy[worker.results] = worker
                ready = wait(list(busy), timeout=0.05)
                now = time.perf_counter()
                bar.tick(now - min(w.started for w in busy.values()))
                for conn, worker in list(busy.items()):
                    k = worker.task
                    if conn in ready:
                        try:
                            results[k] = conn.recv()
                            idle.append(worker)
                        except (EOFError, OSError):
                            results[k] = TaskFailed(f"worker process crashed (exit code {worker.exitcode()})")
                            worker.stop()
                    elif now - worker.started > timeout:
                        results[k] = TaskFailed(f"timed out after {timeout:g} s")
                        worker.stop()
                    else:
                        continue
                    del busy[conn]
                    bar.update(not isinstance(results[k], TaskFailed))
                    if on_result:
                        on_result(k, results[k])
        finally:
            for worker in [*idle, *busy.values()]:
                worker.stop()
        return [results[k] for k in range(len(items))]


class _Worker:
    """A child process running ``fn(context, item)`` for each task it is given."""

    def __init__(self, ctx, fn, context):
        self.results, send = ctx.Pipe(duplex=False)
        recv, self.tasks = ctx.Pipe(duplex=False)
        self.proc = ctx.Process(target=_serve, args=(fn, context, recv, send), daemon=True)
        self.proc.start()
        send.close()
        recv.close()
        self.task, self.started = None, 0.0

    def give(self, k: int, item) -> bool:
        self.task, self.started = k, time.perf_counter()
        try:
            self.tasks.send(item)
            return True
        except (BrokenPipeError, OSError):
            return False

    def exitcode(self):
        self.proc.join(1)
        return self.proc.exitcode

    def stop(self) -> None:
        if self.proc.is_alive():
            self.proc.kill()
        self.proc.join(1)
        self.results.close()
        self.tasks.close()


def die_with_parent() -> None:
    """In a forked worker: be killed when the parent dies (Linux PR_SET_PDEATHSIG), so a killed
    ``mcl run`` leaves no workers behind."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    import signal

    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)   # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _serve(fn, context, tasks, results) -> None:
    """A worker's life: each item received, its result (or TaskFailed) sent back, until the
    parent kills it (:meth:`_Worker.stop`) or its task pipe is closed."""
    die_with_parent()
    faulthandler.disable()      # (a crash is the parent's to report, as a failed task, not a dump)
    while True:
        try:
            item = tasks.recv()
        except (EOFError, OSError):
            return
        try:
            result = fn(context, item)
        except Exception as exc:  # noqa: BLE001 - a failed task is a result
            result = TaskFailed(f"{type(exc).__name__}: {exc}")
        try:
            results.send(result)
        except Exception as exc:  # noqa: BLE001 - a result that cannot be pickled
            results.send(TaskFailed(f"the result could not be sent back: {exc}"))


class _Packed:
    """A task context as Dask ships it: pickled (by cloudpickle) inside CasADi's pickle context,
    which SX expressions need (a discovery's context holds some: the rates of its components'
    variables) and which shares their symbols among them. It stays packed as Dask passes it
    from worker to worker; each worker unpacks it once, for its tasks."""

    def __init__(self, obj=None, blob: bytes | None = None):
        if blob is None:
            import casadi as ca
            import cloudpickle

            with ca.global_pickle_context():
                blob = cloudpickle.dumps(obj)
        self.blob, self._obj = blob, None

    def __reduce__(self):
        return _Packed, (None, self.blob)

    def unpacked(self):
        if self._obj is None:
            import pickle

            import casadi as ca

            with ca.global_unpickle_context():
                self._obj = pickle.loads(self.blob)
        return self._obj


def _dask_task(fn, context, item):
    try:
        return fn(context.unpacked() if isinstance(context, _Packed) else context, item)
    except Exception as exc:  # noqa: BLE001
        return TaskFailed(f"{type(exc).__name__}: {exc}")


class DaskExecutor(Executor):
    """A Dask distributed cluster: ``address`` of a scheduler, or a LocalCluster started here."""

    name = "dask"

    def __init__(self, address: str | None = None, workers: int | None = None):
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            raise ConfigError("the dask executor needs 'dask[distributed]' "
                              "(pip install 'mcl[dask]')") from None
        if address:
            try:
                self.cluster, self.client = None, Client(address, timeout="10s")
            except (OSError, TimeoutError, ValueError) as exc:
                raise ConfigError(f"executor 'dask': no scheduler answers at {address} ({exc})") from None
            self.workers = max(1, len(self.client.scheduler_info().get("workers", {})))
        else:
            self.workers = workers or 2
            self.cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1,
                                        processes=True, dashboard_address=None)
            self.client = Client(self.cluster)

    def map(self, fn, items, context=None, timeout=300.0, label="batch", progress=True, on_result=None):
        from distributed import as_completed

        bar = Progress(label, len(items), workers=self.workers, enabled=progress)
        ctx = self.client.scatter(_Packed(context), broadcast=True, hash=False) if context is not None else None
        futures = [self.client.submit(_dask_task, fn, ctx, item, pure=False) for item in items]
        index = {f.key: k for k, f in enumerate(futures)}
        results: dict[int, Any] = {}
        try:
            for f in as_completed(futures, timeout=timeout * max(1, len(items))):
                k = index[f.key]
                try:
                    results[k] = f.result()
                except Exception as exc:  # noqa: BLE001 - KilledWorker, CancelledError, ...
                    results[k] = TaskFailed(f"{type(exc).__name__}: {exc}")
                bar.update(not isinstance(results[k], TaskFailed))
                if on_result:
                    on_result(k, results[k])
        except TimeoutError:
            pass
        for k, f in enumerate(futures):
            if k not in results:
                f.cancel()
                results[k] = TaskFailed(f"timed out after {timeout:g} s")
                bar.update(False)
        return [results[k] for k in range(len(items))]

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()
