"""The exact median of values that come in blocks, in bounded memory: the SEP of a run of any length
(estimators.io.metrics.error_stats, 001 section 4).

Up to IN_MEMORY values are held and the median is np.median's. Past that they go to a scratch file, and the two
middle values are found by radix selection over their bits: a float64 mapped to a uint64 that sorts as the float
does (positive: sign bit set; negative: every bit flipped), then 16 bits at a time from the top, each round one
read of the file counting the values under the digits fixed so far (np.bincount over 65,536 bins). Four reads
give the exact order statistic; the median of an even count is the mean of its two middle values, as np.median
computes it. Any NaN makes the median NaN, as np.median's.
"""

from __future__ import annotations

import tempfile

import numpy as np

IN_MEMORY = 1 << 20
"""Values held in memory before they go to the scratch file (8 MiB)."""
READ_VALUES = 1 << 20
"""Values read from the scratch file at a time."""
DIGIT_BITS = 16


def _sortable(x: np.ndarray) -> np.ndarray:
    """float64 -> uint64 with the same order (for non-NaN values)."""
    bits = np.ascontiguousarray(x, np.float64).view(np.uint64)
    return np.where(bits >> np.uint64(63), ~bits, bits | np.uint64(1 << 63))


def _unsortable(key: int) -> float:
    bits = np.uint64(key)
    bits = bits & ~np.uint64(1 << 63) if bits >> np.uint64(63) else ~bits
    return float(bits.view(np.float64))


class StreamMedian:
    """np.median of every value pushed (`push` 1-D blocks, `median` at the end, or at any time)."""

    def __init__(self):
        self.held: list[np.ndarray] = []
        self.count = 0
        self.nan = False
        self.scratch = None  # the scratch file once the values outgrow IN_MEMORY

    def push(self, values: np.ndarray) -> None:
        values = np.asarray(values, np.float64).ravel()
        self.count += values.size
        self.nan |= bool(np.isnan(values).any())
        if self.scratch is None and self.count <= IN_MEMORY:
            self.held.append(values.copy())
            return
        if self.scratch is None:
            self.scratch = tempfile.TemporaryFile()
            for held in self.held:
                held.tofile(self.scratch)
            self.held = []
        values.tofile(self.scratch)

    def median(self) -> float:
        if self.count == 0 or self.nan:
            return float("nan")
        if self.scratch is None:
            return float(np.median(np.concatenate(self.held)))
        middle = self._order_statistics(self.count // 2 - 1 if self.count % 2 == 0 else self.count // 2,
                                        self.count // 2)
        return float(np.mean(np.array(middle)))

    def _keys(self):
        """The scratch file's values as sortable keys, READ_VALUES at a time."""
        self.scratch.flush()
        self.scratch.seek(0)
        while (block := np.fromfile(self.scratch, np.float64, READ_VALUES)).size:
            yield _sortable(block)

    def _order_statistics(self, *ranks: int) -> list[float]:
        """The values of the given 0-based ranks in sorted order."""
        out = []
        for rank in ranks:
            prefix, below = 0, 0  # the key's top bits fixed so far; the values with smaller top bits
            for shift in range(64 - DIGIT_BITS, -1, -DIGIT_BITS):
                counts = np.zeros(1 << DIGIT_BITS, np.int64)
                top = np.uint64(shift + DIGIT_BITS)
                for keys in self._keys():
                    if shift + DIGIT_BITS < 64:
                        keys = keys[(keys >> top) == np.uint64(prefix)]
                    digits = (keys >> np.uint64(shift)) & np.uint64((1 << DIGIT_BITS) - 1)
                    counts += np.bincount(digits.astype(np.int64), minlength=1 << DIGIT_BITS)
                cumulative = below + np.cumsum(counts)
                digit = int(np.searchsorted(cumulative, rank, side="right"))
                below = int(cumulative[digit - 1]) if digit else below
                prefix = (prefix << DIGIT_BITS) | digit
            out.append(_unsortable(prefix))
        return out
