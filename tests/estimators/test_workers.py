"""Forked workers and SIGTERM (estimators.workers): a worker forked under forking_workers holds a SIGTERM until it
has its own disposition, then dies of it; the parent keeps its handler and takes one sent meanwhile. ForkedTasks:
results in order, a task's exception or death an error in the parent, the other tasks stopped."""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
import time

import pytest

from estimators.workers import ForkedTasks, WorkerLost, forking_workers, leave_signals_to_parent


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
            # Held here too until the block ends (sent to this thread: a process-wide signal may go to another
            # thread of the test process, a library's pool, which has it unblocked).
            signal.pthread_kill(threading.get_ident(), signal.SIGTERM)
            assert not taken
        assert taken  # the parent took it when the block ended
        assert parent_end.recv() is True  # the worker started with SIGTERM blocked
        os.kill(worker.pid, signal.SIGTERM)  # before its start sets SIG_DFL: without the block it would be lost
        parent_end.send("go")
        worker.join(5)
        assert worker.exitcode == -signal.SIGTERM
    finally:
        signal.signal(signal.SIGTERM, previous)


def _square(x):
    if x == "fail":
        raise ValueError("no square of 'fail'")
    if x == "die":
        os.kill(os.getpid(), signal.SIGTERM)  # as a SIGTERM to the whole process group ends a worker
    if x == "wait":
        time.sleep(60)
    return x * x, os.getpid()


def test_forked_tasks_give_each_result_in_order_from_a_process_of_its_own():
    with ForkedTasks(_square, list(range(7)), processes=2) as tasks:
        results = tasks.results()
    assert [r for r, _ in results] == [k * k for k in range(7)]
    assert len({pid for _, pid in results} | {os.getpid()}) == 8


def test_a_task_that_raises_or_dies_is_an_error_here_and_the_others_stop():
    """An exception comes back with the worker's traceback; a task's process killed by a signal is an error naming
    it, at once: the task still running (a minute's sleep) is stopped, nothing waits for it."""
    with ForkedTasks(_square, [2, "fail"], processes=2) as tasks:
        with pytest.raises(ValueError, match="no square of 'fail'") as err:
            tasks.results()
    assert "_square" in str(err.value.__cause__)
    start = time.monotonic()
    with ForkedTasks(_square, ["wait", "die", 3], processes=2) as tasks:
        with pytest.raises(WorkerLost, match=r"task 2 of 3\) ended without its result \(signal SIGTERM"):
            tasks.results()
    assert time.monotonic() - start < 30
    assert multiprocessing.active_children() == []
