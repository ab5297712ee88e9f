"""Forked worker processes (the estimators' pools, the background compile, the Monte Carlo trials)."""

from __future__ import annotations

import multiprocessing
import signal
from collections.abc import Callable, Iterator
from contextlib import contextmanager


def leave_signals_to_parent() -> None:
    """A worker leaves Ctrl-C and SIGTERM to its parent, which stops the pool and says so once: no traceback per
    worker, and no copy of the parent's SIGTERM handler; a SIGTERM held since the fork (`forking_workers`) is taken
    now, with the default action."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGTERM})


@contextmanager
def forking_workers() -> Iterator[None]:
    """SIGTERM held (blocked) in this thread while it forks workers that start with leave_signals_to_parent. A worker
    inherits the parent's Python handler; a SIGTERM that reached it there before its start replaced the handler
    with SIG_DFL was dropped (Python runs a signal's handler later, and finds none), so the worker outlived the
    pool's terminate and the parent's join waited for ever (a run refused right after its background compile
    started, in test_cli_safety). Held, the signal waits for the worker's own disposition. The parent takes one that
    came meanwhile when the block ends."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


def worker_pool(processes: int, initializer: Callable[..., None] = leave_signals_to_parent, initargs: tuple = ()):
    """A pool of `processes` forked workers, forked with SIGTERM held (`forking_workers`); `initializer` (with
    `initargs`) starts each and calls leave_signals_to_parent."""
    with forking_workers():
        return multiprocessing.get_context("fork").Pool(processes, initializer=initializer, initargs=initargs)
