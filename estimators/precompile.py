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

from estimators.workers import leave_signals_to_parent, worker_pool


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


def _worker_start(compiled) -> None:
    from numba.core import event

    global _compiled
    _compiled = compiled
    leave_signals_to_parent()

    class Raise(event.Listener):
        def on_start(self, event) -> None:
            _compiled.value = 1

        def on_end(self, event) -> None:
            pass

    event.register("numba:compile", Raise())


def _compile(kernel: Kernel) -> None:
    try:
        kernel.compile()
    except Exception:  # noqa: BLE001 - the call itself compiles, and raises what is wrong, as without this
        pass


class Precompiler:
    """Compiles `kernels` (the ones to call first, or the longest, first) on up to `processes` forked processes,
    from construction on. `compiling` tells whether numba compiles there now; `wait` returns when every kernel is
    in the cache; leaving the context (or `close`) stops what is still running."""

    def __init__(self, kernels: Sequence[Kernel], processes: int):
        self._compiled = multiprocessing.get_context("fork").Value("b", 0, lock=False)
        self._pool = None
        if kernels and processes > 0:
            self._pool = worker_pool(min(processes, len(kernels)), _worker_start, (self._compiled,))
            self._done = self._pool.map_async(_compile, kernels, chunksize=1)
            self._pool.close()

    @property
    def compiling(self) -> bool:
        """numba compiles a kernel on the processes (it found one not in the cache) and they have not finished."""
        return self._pool is not None and bool(self._compiled.value) and not self._done.ready()

    def wait(self) -> None:
        """Until every kernel is compiled (or failed to: its call compiles it again and raises the error)."""
        if self._pool is not None:
            self._done.wait()
            self.close()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.terminate()
            self._pool.join()
            self._pool = None

    def __enter__(self) -> Precompiler:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
