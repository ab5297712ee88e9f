"""Forked worker processes (the estimators' tasks, the background compile)."""

from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import signal
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from multiprocessing.pool import ExceptionWithTraceback


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


class WorkerLost(ChildProcessError):
    """A task's process ended without its result: killed by a signal (the system's out-of-memory killer, a SIGTERM
    to the whole process group) or ended by its own code."""


class ForkedTasks:
    """fn(arg) for each of `args` on forked processes, up to `processes` at once, from construction on: a process per
    task (forked with SIGTERM held, `forking_workers`, and started by `initializer(*initargs)`, which calls
    leave_signals_to_parent), its result or exception sent back over a pipe of its own. The processes share no queue
    or lock: one stopped by a signal (SIGTERM sent to the whole process group) cannot leave the others or this one
    waiting for ever, as a multiprocessing.Pool's worker killed while it waits for a task holds its queue's lock for
    good (Pool.terminate then never returns). A task's process that ends without a result is a WorkerLost naming its
    exit; `results` waits for every result, in the order of `args`, and raises the first error; `stop` (and leaving
    the context) ends the processes still running."""

    def __init__(self, fn: Callable, args: list, processes: int,
                 initializer: Callable[..., None] = leave_signals_to_parent, initargs: tuple = ()):
        self._ctx = multiprocessing.get_context("fork")
        self._start = (fn, initializer, initargs)
        self._todo = list(enumerate(args))
        self._n = len(self._todo)
        self._processes = max(processes, 1)
        self._running: dict[int, tuple] = {}  # task -> (process, the pipe's reading end)
        self._results: dict[int, object] = {}
        self._error: BaseException | None = None
        self._fill()

    def _fill(self) -> None:
        while self._todo and len(self._running) < self._processes and self._error is None:
            k, arg = self._todo.pop(0)
            reader, writer = self._ctx.Pipe(duplex=False)
            with forking_workers():
                process = self._ctx.Process(target=_task_main, args=(*self._start, arg, writer), daemon=True)
                process.start()
            writer.close()
            self._running[k] = (process, reader)

    def _collect(self, timeout: float | None) -> None:
        """Take the results (and ends) of the tasks that finished within `timeout` [s] (None: until one does)."""
        ends = {reader: k for k, (_, reader) in self._running.items()}
        for reader in multiprocessing.connection.wait(list(ends), timeout):
            k = ends[reader]
            process, _ = self._running.pop(k)
            try:
                ok, value = reader.recv()
            except EOFError:  # it ended without sending
                ok, value = False, None
            reader.close()
            process.join()
            if value is None and not ok:
                value = WorkerLost(f"a worker process (task {k + 1} of {self._n}) ended without its result "
                                   f"({_exit_text(process)})")
            if ok:
                self._results[k] = value
            elif self._error is None:
                self._error = value
        self._fill()

    @property
    def done(self) -> bool:
        """Every task has ended (without waiting)."""
        if self._running:
            self._collect(0)
        return not self._running and (not self._todo or self._error is not None)

    def results(self) -> list:
        while self._error is None and (self._running or self._todo):
            self._collect(None)
        if self._error is not None:
            self.stop()
            raise self._error
        return [self._results[k] for k in sorted(self._results)]

    def stop(self) -> None:
        for process, reader in self._running.values():
            process.terminate()
            process.join()
            reader.close()
        self._running.clear()
        self._todo.clear()

    def __enter__(self) -> ForkedTasks:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def _exit_text(process) -> str:
    code = process.exitcode
    if code == -signal.SIGKILL:
        return "SIGKILL: the system may have run out of memory"
    return f"signal {signal.Signals(-code).name}" if code is not None and code < 0 else f"exit code {code}"


def _task_main(fn: Callable, initializer: Callable[..., None], initargs: tuple, arg, writer) -> None:
    """A task's process: its result, or its exception with the traceback's text (as multiprocessing.Pool sends it),
    to the parent."""
    initializer(*initargs)
    try:
        reply = (True, fn(arg))
    except BaseException as err:  # noqa: BLE001 - raised in the parent
        reply = (False, ExceptionWithTraceback(err, err.__traceback__))
    try:
        writer.send(reply)
    except Exception as err:  # noqa: BLE001 - a result or exception that does not pickle
        writer.send((False, RuntimeError(f"a worker's {'result' if reply[0] else 'exception'} could not be sent: "
                                         f"{err}")))
    writer.close()
