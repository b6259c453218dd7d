"""Work done in a child process, its result (plain data) sent back.

rumoca keeps 100-150 MB of native memory for each model it compiled, for the life of its
process (no session call releases it: see README, "Modelica library path"); a notebook, a
server or a test worker compiling many models grew to gigabytes. Done in a child, that memory
goes with the child's exit, and a crash of the work (a segmentation fault in native code) ends
the child, not the caller.

The children are forked by a server process, started once (a fresh interpreter with mcl's
compile modules imported: about 0.3 s, then about 10 ms a child), not by the caller: a child
forked from a process in which rumoca has run hangs in rumoca (its runtime's threads are not
in the child), and the caller, a user's notebook or a test, may have run it. (multiprocessing's
own fork server imports the caller's main script again in each child: a user's script that
compiles at its top level would run again there.)
"""
from __future__ import annotations

import logging
import os
import pickle
import resource
import struct
import subprocess
import sys
import threading
import time

#: set (to anything) to do the work in the caller's process
IN_PROCESS = "MCL_RUMOCA_IN_PROCESS"
#: the stack and recursion limit of work that recurses as deep as a model's source nests (a
#: 5000-term sum): rumoca's thread (rumoca_frontend.in_rumoca_thread), pickling its IR (_dumps)
DEEP_STACK, DEEP_LIMIT = 1 << 29, 1_000_000
#: what the server imports once, for every child
PRELOAD = "mcl.compile.rumoca_frontend"
_SERVER: subprocess.Popen | None = None
_LOCK = threading.Lock()
_CHILDREN_CPU = 0.0       # CPU seconds of the server's children, as the server measured them
_INHERITED: list = []     # a parent's server, in a process forked from it (see _forgotten)
_BROKEN = False           # the server stopped by itself: the work is done in process


def cpu_seconds() -> float:
    """CPU seconds of this process, of the children it has waited for, and of the compile
    server and the work done in its children: what a benchmark of a compile counts."""
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + kids.ru_utime + kids.ru_stime + _CHILDREN_CPU + _server_cpu()


def _server_cpu() -> float:
    """The running server's own CPU seconds (its start, its imports, its forks; once it has
    been stopped and waited for, they are among this process's children's)."""
    if _SERVER is None or _SERVER.poll() is not None:
        return 0.0
    try:
        with open(f"/proc/{_SERVER.pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return 0.0


class ChildCrash(Exception):
    """The child ended without a result: its signal or exit status."""


def forks() -> bool:
    """Whether work goes to a child: on Linux (macOS's system libraries do not promise to work
    in a forked child; Windows does not fork), unless the caller said not."""
    return (sys.platform.startswith("linux") and bool(sys.executable) and not _BROKEN
            and not os.environ.get(IN_PROCESS))


def in_child(fn, *args):
    """``fn(*args)`` in a child process (in this one where :func:`forks` is false), with this
    process's environment and working directory: its value, or its exception raised here, with
    the log records it made handled here as if made here (``fn`` and ``args`` pickled: ``fn`` a
    module's function). A child that ends without either raises :class:`ChildCrash`."""
    global _CHILDREN_CPU, _BROKEN
    if not forks():
        return fn(*args)
    request = pickle.dumps((fn, args, dict(os.environ), os.getcwd()), protocol=pickle.HIGHEST_PROTOCOL)
    with _LOCK:                           # (one request at a time on the server's pipes)
        server = _server()
        try:
            _write_fd(server.stdin.fileno(), struct.pack("<Q", len(request)) + request)
            cpu, n = struct.unpack("<dQ", _read_fd(server.stdout.fileno(), 16))
            reply = _read_fd(server.stdout.fileno(), n)
        except (OSError, EOFError):
            # the server itself ended (it only forks: it did not start, or its interpreter
            # cannot import mcl): the work is done here from now on, as where there is none
            _stop()
            _BROKEN = True
            logging.getLogger(__name__).warning("the compile server stopped; rumoca runs in this process from now on")
            return fn(*args)
        except BaseException:             # (interrupted: a new server next time)
            _stop()
            raise
    _CHILDREN_CPU += cpu
    kind, value, records = pickle.loads(reply)
    if kind == "crash":
        raise ChildCrash(value)
    for record in records:
        logger = logging.getLogger(record.name)
        if logger.isEnabledFor(record.levelno):
            logger.handle(record)
    if kind == "error":
        raise value
    return value


def _server() -> subprocess.Popen:
    global _SERVER
    if _SERVER is None or _SERVER.poll() is not None:
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        # (a session of its own: a Ctrl-C at the terminal reaches the caller, which stops it)
        _SERVER = subprocess.Popen([sys.executable, "-c", f"from {__name__} import serve; serve()"],
                                   stdin=subprocess.PIPE, stdout=subprocess.PIPE, bufsize=0, env=env,
                                   start_new_session=True)
    return _SERVER


def _forgotten() -> None:
    """In a process forked from this one (a pool's worker): the server and its pipes are the
    parent's, and the lock may have been held by another thread; this process starts its own
    server if it needs one. The parent's is kept referenced, never closed or collected here:
    its pipes' buffers would be flushed into the parent's exchange."""
    global _SERVER, _LOCK
    if _SERVER is not None:
        _INHERITED.append(_SERVER)
    _SERVER, _LOCK = None, threading.Lock()


os.register_at_fork(after_in_child=_forgotten)


def _stop() -> None:
    global _SERVER
    if _SERVER is not None:
        _SERVER.kill()
        _SERVER.wait()
        _SERVER = None


def serve() -> None:
    """The server: for each request read on stdin, a forked child does the work; its reply and
    its CPU seconds are written to stdout (which nothing else writes: it goes to stderr)."""
    import importlib

    importlib.import_module(PRELOAD)
    replies = os.dup(1)
    os.dup2(2, 1)
    while True:
        head = os.read(0, 8)
        if not head:
            return                        # (the caller has gone)
        head += _read_fd(0, 8 - len(head))
        request = _read_fd(0, struct.unpack("<Q", head)[0])
        read, write = os.pipe()
        pid = os.fork()
        if pid == 0:
            os.close(read)
            os.close(replies)
            _child(request, write)
        os.close(write)
        reply = _read_fd(read, None)
        os.close(read)
        _, status, usage = os.wait4(pid, 0)
        if status != 0 or not reply:
            how = (f"signal {_signal_name(os.WTERMSIG(status))}" if os.WIFSIGNALED(status)
                   else f"exit status {os.waitstatus_to_exitcode(status)}")
            reply = pickle.dumps(("crash", f"it ended on {how}", []))
        _write_fd(replies, struct.pack("<dQ", usage.ru_utime + usage.ru_stime, len(reply)) + reply)


def _child(request: bytes, write: int) -> None:
    """In the server's child: the request's work and the log records made meanwhile, pickled
    to ``write``. Never returns."""
    code = 0
    try:
        import faulthandler

        from ..executor import die_with_parent

        faulthandler.disable()            # (a crash is the caller's error to report, in one line)
        die_with_parent()                 # (a caller that stops a compile stops the server, and this)
        fn, args, env, cwd = pickle.loads(request)
        os.environ.clear()
        os.environ.update(env)
        os.chdir(cwd)
        records: list[logging.LogRecord] = []
        root = logging.getLogger()
        root.handlers[:] = [_Keeper(records)]
        root.setLevel(logging.DEBUG)      # (the caller keeps those its loggers are enabled for)
        try:
            out = ("value", fn(*args))
        except BaseException as exc:      # noqa: BLE001 - every failure goes to the caller
            out = ("error", exc)
        try:
            data = _dumps((*out, records))
        except Exception as exc:          # noqa: BLE001 - an exception that does not pickle: its text
            data = pickle.dumps(("error", RuntimeError(f"{type(out[1]).__name__}: {out[1]}"
                                                       if out[0] == "error" else str(exc)), []))
        _write_fd(write, data)
    except BaseException:                 # noqa: BLE001 - nothing may return into the server's loop
        code = 1
    finally:
        os._exit(code)


def _read_fd(fd: int, n: int | None) -> bytes:
    """``n`` bytes from ``fd`` (all up to its end where ``n`` is None)."""
    parts, got = [], 0
    while n is None or got < n:
        chunk = os.read(fd, 1 << 20 if n is None else min(n - got, 1 << 20))
        if not chunk:
            if n is None:
                break
            raise EOFError
        parts.append(chunk)
        got += len(chunk)
    return b"".join(parts)


def _write_fd(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def _signal_name(number: int) -> str:
    import signal

    try:
        return signal.Signals(number).name
    except ValueError:
        return str(number)


def _dumps(obj) -> bytes:
    """``obj`` pickled in a thread with a large stack, as deep as it nests: pickling recurses
    once per level, and the IR of a 5000-term sum nests 5000 deep (unpickling does not recurse)."""
    out: list = []

    def work():
        limit = sys.getrecursionlimit()
        sys.setrecursionlimit(DEEP_LIMIT)
        try:
            out.append(pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL))
        except BaseException as exc:      # noqa: BLE001 - raised again in the caller's thread
            out.append(exc)
        finally:
            sys.setrecursionlimit(limit)
    old = threading.stack_size(DEEP_STACK)
    try:
        thread = threading.Thread(target=work)
        thread.start()
    finally:
        threading.stack_size(old)
    thread.join()
    if isinstance(out[0], BaseException):
        raise out[0]
    return out[0]


class _Keeper(logging.Handler):
    """Keeps the records (their messages formatted: arguments may not pickle)."""

    def __init__(self, records: list):
        super().__init__(logging.DEBUG)
        self.records = records

    def emit(self, record: logging.LogRecord) -> None:
        record.msg, record.args, record.exc_info, record.exc_text = record.getMessage(), None, None, None
        self.records.append(record)
