"""The C heap of a long run: glibc's malloc told to give large blocks back to the system.

glibc serves a block above its mmap threshold with its own mapping, returned to the system when freed; but the
threshold rises (up to 32 MB) each time such a block is freed, after which the run's per-chunk arrays (a few MB to
tens of MB, allocated and freed chunk after chunk by the twin's two threads) come from the heap arenas, which
fragment and never shrink: seed004's face at 20 cycles peaked at 3.2 GB against 2.5 GB with the threshold held
(benchmarks/bench_scale.py). Holding it at MMAP_THRESHOLD_BYTES keeps a streaming run's memory flat.
"""

from __future__ import annotations

import ctypes
import ctypes.util

MMAP_THRESHOLD_BYTES = 1 << 20
"""Blocks from this size up get their own mapping (glibc's default starts at 128 KiB and adapts upwards)."""
_M_MMAP_THRESHOLD = -3
"""mallopt's parameter number for the threshold (glibc malloc.h)."""


def hold_mmap_threshold() -> bool:
    """Fix glibc's mmap threshold for this process (and the processes it forks); False where the C library is not
    glibc (the run then works as before, with the platform's allocator)."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError, TypeError):
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES))
