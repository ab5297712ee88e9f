"""The sample interval of a stream and the gaps in it, from its Parquet file read in row groups: memory does not
grow with the length of the log (an exact median by radix selection, 16 bits of the float64 pattern a pass)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

_BATCH_ROWS = 1 << 14
_DIGIT = 16


@dataclass
class TimeSteps:
    """Steps between consecutive distinct times of a stream file."""

    median: float
    """Median step [s] (NaN with fewer than two distinct times)."""
    gaps: list[tuple[float, float]] = field(default_factory=list)
    """(t_before, t_after) of the steps longer than `gap_factor` median steps (the first `max_listed`)."""
    gap_count: int = 0


def time_steps(path: Path, gap_factor: float = np.inf, max_listed: int = 0) -> TimeSteps:
    """The median step of the `t` column of the stream file `path`, and its gaps longer than gap_factor x median."""
    n = sum(d.size for _, d in _steps(path))
    if n == 0:
        return TimeSteps(float("nan"))
    median = _kth(path, n // 2) if n % 2 else (_kth(path, n // 2 - 1) + _kth(path, n // 2)) / 2
    out = TimeSteps(median)
    if np.isfinite(gap_factor):
        for before, d in _steps(path):
            at = np.flatnonzero(d > gap_factor * median)
            room = max(0, max_listed - len(out.gaps))
            out.gaps += [(float(before[j]), float(before[j] + d[j])) for j in at[:room]]
            out.gap_count += int(at.size)
    return out


def _steps(path: Path) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """(time before, positive step) pairs in file order, one row group batch at a time."""
    prev = None
    for batch in pq.ParquetFile(path).iter_batches(batch_size=_BATCH_ROWS, columns=["t"]):
        t = batch.column(0).to_numpy()
        if t.size == 0:
            continue
        ext = t if prev is None else np.concatenate(([prev], t))
        d = np.diff(ext)
        yield ext[:-1][d > 0], d[d > 0]
        prev = t[-1]


def _kth(path: Path, k: int) -> float:
    """The k-th smallest (0-based) positive step: positive float64 values order like their bit patterns."""
    prefix, mask = np.uint64(0), np.uint64(0)
    for shift in range(64 - _DIGIT, -1, -_DIGIT):
        counts = np.zeros(1 << _DIGIT, np.int64)
        for _, d in _steps(path):
            bits = d.view(np.uint64)
            bits = bits[(bits & mask) == prefix]
            counts += np.bincount((bits >> np.uint64(shift)) & np.uint64((1 << _DIGIT) - 1), minlength=1 << _DIGIT)
        digit = int(np.searchsorted(np.cumsum(counts), k, side="right"))
        k -= int(counts[:digit].sum())
        prefix |= np.uint64(digit) << np.uint64(shift)
        mask |= np.uint64((1 << _DIGIT) - 1) << np.uint64(shift)
    return float(np.array([prefix]).view(np.float64)[0])
