"""twin.pipeline.malloc: glibc's mmap threshold held, so a freed large block goes back to the system."""

from __future__ import annotations

import platform

import numpy as np
import psutil
import pytest

from twin.pipeline.malloc import MMAP_THRESHOLD_BYTES, hold_mmap_threshold


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
