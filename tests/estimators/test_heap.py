"""estimators.heap: glibc's mmap threshold held, so a freed large block goes back to the system."""

from __future__ import annotations

import platform

import numpy as np
import psutil
import pytest

from estimators.heap import MMAP_THRESHOLD_BYTES, hold_mmap_threshold, release_free_memory


@pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc", reason="glibc's mallopt")
def test_blocks_above_the_threshold_are_returned_after_the_threshold_would_have_risen():
    assert hold_mmap_threshold()
    proc = psutil.Process()
    # Freeing a 16 MiB mapped block raises glibc's adaptive threshold above 8 MiB; held, it stays at 1 MiB, so
    # 8 MiB blocks are still mapped and their memory goes back when they are freed.
    np.ones(16 << 17).sum()
    before = proc.memory_info().rss
    blocks = [np.ones(1 << 20) for _ in range(64)]  # 64 blocks of 8 MiB
    del blocks[::2]  # every other one: a heap could give none of them back (the survivors pin its top)
    assert proc.memory_info().rss - before < 300 * 2 ** 20 + 8 * MMAP_THRESHOLD_BYTES


@pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc", reason="glibc's malloc_trim")
def test_released_heap_pages_go_back_to_the_system():
    """Small blocks (heap, below the threshold) freed behind a survivor that pins the heap's top: glibc keeps their
    pages until release_free_memory trims them."""
    assert hold_mmap_threshold()
    proc = psutil.Process()
    before = proc.memory_full_info().uss
    blocks = [np.ones(1 << 15) for _ in range(2048)]  # 2,048 blocks of 256 KiB on the heap: 512 MiB
    pin = np.ones(1 << 15)
    del blocks
    held = proc.memory_full_info().uss - before
    release_free_memory()
    after = proc.memory_full_info().uss - before
    assert held > 400 * 2 ** 20 and after < 100 * 2 ** 20, (held, after)
    del pin
