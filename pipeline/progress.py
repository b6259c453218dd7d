"""Progress and messages: every word mcl says goes through ``logging`` (logger ``mcl``) or one
progress bar class (tqdm, which also draws in notebooks); library code prints nothing.

``quiet()`` silences both for a block; the command line's ``--quiet`` and the API's
``verbose=False`` use it.
"""
from __future__ import annotations

import contextlib
import logging
import math
import sys
import time

log = logging.getLogger("mcl")
log.addHandler(logging.NullHandler())

_enabled = True
#: seconds between the progress lines written where stderr is not a terminal (a log file)
LOG_EVERY = 30.0


def enabled() -> bool:
    """Whether progress bars are drawn (False inside :func:`quiet`)."""
    return _enabled


@contextlib.contextmanager
def quiet(on: bool = True):
    """No progress bars and no messages below WARNING from mcl inside the block."""
    global _enabled
    if not on:
        yield
        return
    before, level = _enabled, log.level
    _enabled = False
    log.setLevel(logging.WARNING)
    try:
        yield
    finally:
        _enabled = before
        log.setLevel(level)     # not log.level = ...: setLevel also clears logging's cache of levels


@contextlib.contextmanager
def console(verbose: bool = True):
    """Show mcl's messages on stderr for a block when nobody configured logging (notebooks, scripts)."""
    root_configured = bool(logging.getLogger().handlers)
    own = [h for h in log.handlers if not isinstance(h, logging.NullHandler)]
    handler = None
    if verbose and not root_configured and not own:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("%(message)s"))
        log.addHandler(handler)
        if log.level == logging.NOTSET or log.level > logging.INFO:
            log.setLevel(logging.INFO)
    try:
        with quiet(not verbose):
            yield
    finally:
        if handler is not None:
            log.removeHandler(handler)


class Progress:
    """A progress bar for a batch of ``total`` tasks run ``workers`` at a time.

    The time left is estimated from the mean duration of the finished tasks times the number of
    rounds still to run (``ceil(left / workers)``), so it is right from the first result on even
    when tasks finish in bunches.
    """

    def __init__(self, label: str, total: int, workers: int = 1, enabled: bool = True):
        from tqdm.auto import tqdm

        self.label, self.total, self.workers = label, total, max(1, int(workers))
        self.done = self.failed = 0
        self.start = time.perf_counter()
        self.tty = getattr(sys.stderr, "isatty", lambda: False)()
        self.on = enabled and _enabled and total > 0
        self.said = self.start          # a log file gets a line now and then instead of a bar
        self.bar = tqdm(total=total, desc=label, file=sys.stderr, leave=False, dynamic_ncols=True,
                        disable=not (self.on and self.tty), mininterval=0.1,
                        bar_format="{desc}: {n_fmt}/{total_fmt} |{bar}| {elapsed}{postfix}")

    def eta(self) -> float:
        """Seconds left: mean task time x rounds left at ``workers`` tasks per round."""
        if not self.done:
            return math.nan
        rounds_done = math.ceil(self.done / self.workers)
        per_round = (time.perf_counter() - self.start) / rounds_done
        return per_round * math.ceil((self.total - self.done) / self.workers)

    def update(self, ok: bool = True) -> None:
        self.done += 1
        self.failed += not ok
        left = self.eta()
        self.bar.set_postfix_str(f"{self.failed} failed, ~{left:.0f}s left" if self.failed
                                 else f"~{left:.0f}s left", refresh=False)
        self.bar.update(1)
        now = time.perf_counter()
        if self.on and not self.tty and now - self.said >= LOG_EVERY and self.done < self.total:
            self.said = now
            log.info("%s: %d/%d, ~%.0f s left", self.label, self.done, self.total, left)
        if self.done == self.total:
            self.close()

    def tick(self, running: float = 0.0) -> None:
        """Between results (called as the batch waits): the bar's clock moves on, and a log
        file gets a line every :data:`LOG_EVERY` seconds saying how long the oldest task still
        running (``running`` seconds) has taken, so a long fit is not silence."""
        if not self.on:
            return
        now = time.perf_counter()
        if self.tty:
            if now - self.bar.last_print_t >= 1.0:
                self.bar.refresh()
            return
        if now - self.said >= LOG_EVERY:
            self.said = now
            log.info("%s: %d/%d, one running for %.0f s", self.label, self.done, self.total, running)

    def close(self) -> None:
        if self.on and self.done:
            log.info("%s: %d/%d done (%d failed) in %.0f s", self.label, self.done, self.total,
                     self.failed, time.perf_counter() - self.start)
        self.bar.close()
        self.bar.disable, self.on = True, False
