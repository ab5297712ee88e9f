"""Forked workers and SIGTERM (estimators.workers): a worker forked under forking_workers holds a SIGTERM until it
has its own disposition, then dies of it; the parent keeps its handler and takes one sent meanwhile."""

from __future__ import annotations

import multiprocessing
import os
import signal
import time

from estimators.workers import forking_workers, leave_signals_to_parent


def _report(conn) -> None:
    """Sent to the parent: SIGTERM blocked at the start; then the signal the parent sends meanwhile ends it."""
    conn.send(signal.SIGTERM in signal.pthread_sigmask(signal.SIG_BLOCK, []))
    conn.recv()  # the parent has sent SIGTERM
    leave_signals_to_parent()
    time.sleep(10)  # not reached: the held SIGTERM is taken with the default action
    conn.send("survived")


def test_a_sigterm_sent_before_the_worker_starts_is_held_and_then_ends_it():
    taken = []
    previous = signal.signal(signal.SIGTERM, lambda *_: taken.append(True))  # the parent's Python handler
    try:
        ctx = multiprocessing.get_context("fork")
        parent_end, child_end = ctx.Pipe()
        with forking_workers():
            worker = ctx.Process(target=_report, args=(child_end,))
            worker.start()
            os.kill(os.getpid(), signal.SIGTERM)  # held here too until the block ends
            assert not taken
        assert taken  # the parent took it when the block ended
        assert parent_end.recv() is True  # the worker started with SIGTERM blocked
        os.kill(worker.pid, signal.SIGTERM)  # before its start sets SIG_DFL: without the block it would be lost
        parent_end.send("go")
        worker.join(5)
        assert worker.exitcode == -signal.SIGTERM
    finally:
        signal.signal(signal.SIGTERM, previous)
