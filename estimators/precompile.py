"""numba kernels compiled into numba's on-disk cache before their first call, on background processes: a first run
after installing compiles them while it does other work, and the processes that call them load them from the cache
(estimators.kernel_cache) instead of each compiling them again.

A kernel is named with the argument types of the call that will use it (`Kernel.args`, numba's signature syntax:
"i8, f8[::1], f8[:, ::1]"). A call with other types misses the cache and compiles as it always did: a stale list
costs time, never a result. In a warm run every kernel loads from the cache and the processes end at once.
numba writes a cache file under a temporary name and renames it, so processes compiling at once leave whole files.
"""

from __future__ import annotations

import importlib
import multiprocessing
from collections.abc import Sequence
from dataclasses import dataclass

from estimators.workers import ForkedTasks, leave_signals_to_parent


F8_1D, F8_2D = "f8[::1]", "f8[:, ::1]"
"""The argument types of a contiguous float64 vector and matrix in a Kernel's `args`."""


@dataclass(frozen=True)
class Kernel:
    """A numba dispatcher (module and attribute name) and the argument types of its call."""

    module: str
    name: str
    args: str

    def dispatcher(self):
        return getattr(importlib.import_module(self.module), self.name)

    def signature(self) -> tuple:
        """The argument types as numba's dispatcher types a call's arguments (the key of its cache entry)."""
        from numba.core import sigutils

        args, _ = sigutils.normalize_signature(f"({self.args},)")
        return tuple(args)

    def compile(self) -> None:
        """Compile (or load from the cache) the kernel for its argument types; a compiled one is written to the
        cache."""
        self.dispatcher().compile(self.signature())


_compiled = None
"""In a worker: the flag it raises when numba compiles (multiprocessing.Value shared with the parent)."""
_next = None
"""In a worker: the index of the next kernel no process has taken up (multiprocessing.Value shared among them)."""


def _worker_start(compiled, next_kernel) -> None:
    from numba.core import event

    global _compiled, _next
    _compiled, _next = compiled, next_kernel
    leave_signals_to_parent()

    class Raise(event.Listener):
        def on_start(self, event) -> None:
            _compiled.value = 1

        def on_end(self, event) -> None:
            pass

    event.register("numba:compile", Raise())


def _compile_in_turn(kernels: Sequence[Kernel]) -> None:
    """Compile the kernels no other process has taken up, the next in order each time, until none is left."""
    while True:
        with _next.get_lock():
            k = _next.value
            _next.value += 1
        if k >= len(kernels):
            return
        try:
            kernels[k].compile()
        except Exception:  # noqa: BLE001 - the call itself compiles, and raises what is wrong, as without this
            pass


class Precompiler:
    """Compiles `kernels` (the ones to call first, or the longest, first) on up to `processes` forked processes,
    each taking up the next kernel in order, from construction on. `compiling` tells whether numba compiles there
    now; `wait` returns when every kernel is in the cache; leaving the context (or `close`) stops what is still
    running."""

    def __init__(self, kernels: Sequence[Kernel], processes: int):
        ctx = multiprocessing.get_context("fork")
        self._compiled = ctx.Value("b", 0, lock=False)
        self._tasks = None
        if kernels and processes > 0:
            n = min(processes, len(kernels))
            self._tasks = ForkedTasks(_compile_in_turn, [tuple(kernels)] * n, n, _worker_start,
                                      (self._compiled, ctx.Value("i", 0)))

    @property
    def compiling(self) -> bool:
        """numba compiles a kernel on the processes (it found one not in the cache) and they have not finished."""
        return self._tasks is not None and bool(self._compiled.value) and not self._tasks.done

    def wait(self) -> None:
        """Until every kernel is compiled (or failed to: its call compiles it again and raises the error)."""
        if self._tasks is not None:
            self._tasks.results()
            self.close()

    def close(self) -> None:
        if self._tasks is not None:
            self._tasks.stop()
            self._tasks = None

    def __enter__(self) -> Precompiler:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
