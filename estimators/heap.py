"""The C heap of a long run: glibc's malloc told to give large blocks back to the system, and the free memory of the
C heap and of pyarrow's pool returned after each pass of an online estimator.

glibc serves a block above its mmap threshold with its own mapping, returned to the system when freed; but the
threshold rises (up to 32 MB) each time such a block is freed, after which the run's per-chunk arrays (a few MB to
tens of MB, allocated and freed chunk after chunk by the twin's two threads) come from the heap arenas, which
fragment and never shrink: seed004's face at 20 cycles peaked at 3.2 GB against 2.5 GB with the threshold held
(benchmarks/bench_scale.py). Holding it at MMAP_THRESHOLD_BYTES keeps a streaming run's memory flat.

Below the threshold, what a pass frees stays with the process: glibc keeps the heap's free pages and pyarrow's
allocator (jemalloc or mimalloc) its freed pages, more of them as a long run goes on. `release_free_memory` gives them
back after each pass of an online estimator (estimators.shearer.methods): on panel_100 at 20 cycles malloc_trim
returned 20-40 MB of a worker's heap at a pass, and the estimators stage peaked at 1.30 GB against 1.39 GB (at 100
cycles 1.41 GB against 1.47 GB).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools

import pyarrow as pa

MMAP_THRESHOLD_BYTES = 1 << 20
"""Blocks from this size up get their own mapping (glibc's default starts at 128 KiB and adapts upwards)."""
_M_MMAP_THRESHOLD = -3
"""mallopt's parameter number for the threshold (glibc malloc.h)."""


@functools.cache
def _libc() -> ctypes.CDLL | None:
    """The C library (found once: find_library runs ldconfig); None where it cannot be loaded."""
    try:
        return ctypes.CDLL(ctypes.util.find_library("c"))
    except (OSError, TypeError):
        return None


def hold_mmap_threshold() -> bool:
    """Fix glibc's mmap threshold for this process (and the processes it forks); False where the C library is not
    glibc (the run then works as before, with the platform's allocator)."""
    mallopt = getattr(_libc(), "mallopt", None)
    return mallopt is not None and bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES))


def release_free_memory() -> None:
    """Give the free pages of the C heap (glibc's malloc_trim: a few ms) and of pyarrow's pool back to the system;
    a no-op for what a platform does not have."""
    pa.default_memory_pool().release_unused()
    trim = getattr(_libc(), "malloc_trim", None)
    if trim is not None:
        trim(0)
