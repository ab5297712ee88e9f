"""The rows of a series a person can see, over a stream given whole or in blocks: at most the record rate
(`decimate`, `Decimation`), without the samples a drawn line passes within a pixel of (`line_rows`, `LineCut`), a noisy
stretch by its band (`band_rows`, `visible_rows`), a moving marker's positions (`marker_rows`, `MarkerCut`) and a
path's strips (`path_strips`, `PathStrips`). The helpers that carry their state across blocks give the whole stream's
rows bit for bit. twin.view.rerun_columns sends what they keep.

The record rate (twin.view.record_rate) is a rate in Hz, or FULL (None): every sample, neither decimated nor thinned.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator

import numpy as np
import pyarrow as pa

from twin.view.line_kernel import line_kernel
from twin.view.record_rate import FULL

PATH_TOLERANCE_M = 0.005
"""Largest distance between a drawn 3-D path and a sample left out of it [m]."""
MARKER_STEP_M = 0.05
"""Distance a moving marker (the shearer, an estimate's point) travels between its logged positions [m]: it is drawn
where it was last logged, at most this far behind."""


def col(table: pa.Table, name: str) -> np.ndarray:
    return table.column(name).to_numpy()


Blocks = pa.Table | Iterable[pa.Table]
"""A stream as one table, or as consecutive blocks of rows that can be read more than once (a long stream's file read a
row group at a time: estimators.io.logformat.StreamBlocks, whose `column` gives one column over the whole file)."""


BLOCK_ROWS = 32_768
"""Rows of a stream cut and drawn at a time (`bounded`): a row group of 131,072 rows is taken in four."""


def blocks_of(data: Blocks) -> Iterable[pa.Table]:
    return [data] if isinstance(data, pa.Table) else data


def bounded(data: Blocks, rows: int = BLOCK_ROWS) -> Iterator[pa.Table]:
    """A stream's blocks cut to at most `rows` rows (slices: no copy); an empty block as it is."""
    for block in blocks_of(data):
        for start in range(0, max(block.num_rows, 1), rows):
            yield block.slice(start, rows)


class RowsOf:
    """A stream given in blocks, read on `take` k rows at a time (the blocks cut and joined as needed)."""

    def __init__(self, blocks: Iterable[pa.Table]):
        self._blocks, self._held = iter(blocks), None

    def take(self, k: int) -> pa.Table:
        parts = []
        while k > 0 or not parts:
            if self._held is None or (self._held.num_rows == 0 and k > 0):
                self._held = next(self._blocks)
            part = self._held.slice(0, k)
            parts.append(part)
            self._held, k = self._held.slice(part.num_rows), k - part.num_rows
        return pa.concat_tables(parts)


class Decimation:
    """`decimate` over a series given in blocks, carrying the last row's interval: `push` each block's times, then
    `last_kept` says whether the series' last row is among the rows kept (decimate adds it)."""

    def __init__(self, rate_hz: float | None):
        self.rate_hz, self._bin, self.last_kept = rate_hz, -np.inf, True

    def push(self, t: np.ndarray) -> np.ndarray:
        """Indices into the block `t` of its rows that begin an interval (every row at FULL rate)."""
        if self.rate_hz is FULL or t.size == 0:
            return np.arange(t.size)
        bins = np.floor(np.asarray(t, float) * self.rate_hz + 1e-9)
        keep = np.flatnonzero(np.diff(bins, prepend=self._bin) > 0)
        self._bin, self.last_kept = bins[-1], keep.size > 0 and keep[-1] == t.size - 1
        return keep


def decimate(t: np.ndarray, rate_hz: float | None) -> np.ndarray:
    """Indices of the first sample in each 1/rate_hz interval (plus the last sample); every index at FULL rate."""
    cut = Decimation(rate_hz)
    keep = cut.push(t)
    return keep if cut.last_kept else np.r_[keep, t.size - 1]


def decimated_blocks(data: Blocks, rate_hz: float | None,
                     each: Callable[[pa.Table], None] | None = None) -> Iterator[pa.Table]:
    """The rows of a stream (one table, or one or more blocks) that `decimate` keeps of its times, a block at a time
    (the stream's last row, when decimate adds it, as one more; an empty stream as its empty block); `each` is called
    with every block as it is read (one pass for what else is drawn of the stream)."""
    cut, last = Decimation(rate_hz), None
    for block in blocks_of(data):
        if each is not None:
            each(block)
        if block.num_rows:
            yield block.take(pa.array(cut.push(col(block, "t"))))
            last = block.slice(block.num_rows - 1)
        elif last is None:
            last = block
    if not cut.last_kept or last.num_rows == 0:
        yield last


class IntervalReduce:
    """`reduce.reduceat(values, decimate(t, rate_hz))` at the times `t[decimate(t, rate_hz)]` over a series given in
    blocks: the rows of each 1/rate_hz interval reduced into one (flags OR-ed: np.bitwise_or, peaks kept: np.fmax;
    an exact reduction gives the whole series' values bit for bit), the series' last row on its own. `push` each
    block's times and values (K, ...), then `finish`: both return the intervals completed (times, values). Held:
    the open interval's rows."""

    def __init__(self, rate_hz: float | None, reduce: np.ufunc):
        self._time, self._reduce = Decimation(rate_hz), reduce
        self._t, self._open = np.zeros(0), None  # the open interval's first time, its rows' values
        self._t_last = np.zeros(0)  # the last row's time

    def push(self, t: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        t, values = np.asarray(t, float), np.asarray(values)
        starts = self._time.push(t)
        self._t_last = t[-1:] if t.size else self._t_last
        held = 0 if self._open is None else len(self._open)
        rows = values if self._open is None else np.concatenate([self._open, values])
        cuts = np.unique(np.r_[0, held + starts]) if rows.size else np.zeros(1, np.int64)
        times = np.r_[self._t, t[starts]][-cuts.size:]
        done = (self._reduce.reduceat(rows[:cuts[-1]], cuts[:-1], axis=0) if cuts.size > 1
                else rows[:0])
        self._t, self._open = times[-1:], rows[cuts[-1]:]
        return times[:-1], done

    def finish(self) -> tuple[np.ndarray, np.ndarray]:
        """The open interval, and the series' last row on its own when decimate adds it."""
        if self._open is None:
            return np.zeros(0), np.zeros(0)
        if not len(self._open):
            return self._t[:0], self._open
        if self._time.last_kept:
            return self._t, self._reduce.reduce(self._open, axis=0, keepdims=True)
        return (np.r_[self._t, self._t_last],
                np.concatenate([self._reduce.reduce(self._open[:-1], axis=0, keepdims=True), self._open[-1:]]))


class MarkerCut:
    """`marker_rows` over a marker's positions given in blocks, carrying the decimation, the last position it kept
    and the distance travelled: `push` each block, then `finish`; both return the rows decided kept, as indices over
    all the rows pushed."""

    def __init__(self, rate_hz: float | None):
        self._time = Decimation(rate_hz)
        self._step = Decimation(FULL if rate_hz is FULL else 1.0 / MARKER_STEP_M)
        self._p, self._travelled, self._rows, self._last = None, 0.0, 0, -1

    def push(self, t: np.ndarray, p: np.ndarray) -> np.ndarray:
        keep = self._time.push(t)
        start, self._rows = self._rows, self._rows + t.size
        if keep.size == 0:
            return keep
        p = np.asarray(p, float)[keep]
        step = np.diff(np.concatenate([p[:1] if self._p is None else self._p, p]), axis=0)
        moved = np.linalg.norm(step.reshape(keep.size, -1, 3), axis=2).max(axis=1)  # the point that moves most
        travelled = np.cumsum(np.r_[self._travelled, moved])[1:]
        kept = start + keep[self._step.push(travelled)]
        self._p, self._travelled = p[-1:], travelled[-1]
        self._last = kept[-1] if kept.size else self._last
        return kept

    def finish(self) -> np.ndarray:
        """The last row pushed, unless it was kept."""
        return np.arange(max(self._last + 1, self._rows - 1), self._rows)


def marker_rows(t: np.ndarray, p: np.ndarray, rate_hz: float | None) -> np.ndarray:
    """Rows of a moving marker's positions p (K, 3) (or of several points of a body, (K, 3m)) to log: at most rate_hz
    (decimate), and of those the first after each MARKER_STEP_M of travel (of the point that moves most) along the
    path (plus the last); every row at FULL rate."""
    cut = MarkerCut(rate_hz)
    return np.r_[cut.push(np.asarray(t, float), p), cut.finish()]


class PathStrips:
    """`path_strips` over a path given in blocks (each cycle's line carried on: LineCut), and the time of each
    cycle's first sample: `push` each block, then `strips` and `start_times` (the strips' order if the cycles come in
    order)."""

    def __init__(self, rate_hz: float | None):
        self.rate_hz = rate_hz
        self._lines: dict[int, LineCut] = {}
        self._kept: dict[int, list[np.ndarray]] = {}
        self._first: dict[int, tuple[int, float]] = {}
        self._rows = 0

    def push(self, t: np.ndarray, p: np.ndarray, cycle: np.ndarray | None = None) -> None:
        cycle = np.zeros(t.size, np.int64) if cycle is None else cycle
        for c, first in zip(*np.unique(cycle, return_index=True)):
            c = int(c)
            rows = np.flatnonzero(cycle == c)
            self._first.setdefault(c, (self._rows + first, float(t[first])))
            if self.rate_hz is FULL:
                self._kept.setdefault(c, []).append(p[rows])
            else:
                line = self._lines.setdefault(c, LineCut(PATH_TOLERANCE_M))
                self._kept.setdefault(c, []).append(line.push(t[rows], p[rows])[1])
        self._rows += t.size

    def strips(self) -> list[np.ndarray]:
        """The path as float32 strips, one per cycle in cycle order."""
        for c, line in self._lines.items():
            self._kept[c].append(line.finish()[1])
        self._lines = {}
        return [np.concatenate(self._kept[c]).astype(np.float32) for c in sorted(self._kept)]

    def start_times(self) -> np.ndarray:
        """Each cycle's first sample time, in the order of the samples."""
        return np.array([t for _, t in sorted(self._first.values())])


def path_strips(t: np.ndarray, p: np.ndarray, cycle: np.ndarray | None, rate_hz: float | None) -> list[np.ndarray]:
    """A path (K, 3) as float32 strips, one per cycle (one without `cycle`), each without the samples it passes within
    PATH_TOLERANCE_M of (the line through the others, in time: stops and reversals are kept); every sample at FULL
    rate."""
    path = PathStrips(rate_hz)
    path.push(np.asarray(t, float), np.asarray(p, float), cycle)
    return path.strips()


def series_matrix(t: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Values (K,) or (K, n...) over K times as float (K, n)."""
    y = np.asarray(values, float)
    return y.reshape(len(t), -1) if len(t) else y.reshape(0, int(np.prod(y.shape[1:])))


class LineCut:
    """`line_rows` over a series given in blocks, the same rows bit for bit: between blocks it holds the greedy scan's
    anchor, the last row scanned from it and its slope bounds (line_kernel), and the block's last row (whose NaN edge
    waits for the next row). `push` and `finish` return the rows decided kept: (indices over all the rows pushed,
    their values (k, n))."""

    def __init__(self, tolerance: float | np.ndarray):
        self.tolerance = tolerance
        self._t = np.zeros(0)
        self._y = self._index = self._must = self._lo = self._hi = None
        self._scanned, self._rows = 0, 0

    def push(self, t: np.ndarray, values: np.ndarray, must: np.ndarray | None = None,
             final: bool = False) -> tuple[np.ndarray, np.ndarray]:
        t, y = np.asarray(t, float), series_matrix(t, values)
        if self._y is None:
            m = y.shape[1]
            self._y, self._index, self._must = np.zeros((0, m)), np.zeros(0, np.int64), np.zeros(0, bool)
            self._lo, self._hi = np.full(m, -np.inf), np.full(m, np.inf)
            self._tol = np.broadcast_to(np.asarray(self.tolerance, float), (m,)).copy()
        t, y = np.r_[self._t, t], np.concatenate([self._y, y])
        index = np.r_[self._index, self._rows + np.arange(t.size - self._t.size)]
        edge = np.r_[self._must, np.zeros(index.size - self._index.size, bool) if must is None else must]
        self._rows += index.size - self._index.size
        if not t.size:
            return index, y
        nan = np.isnan(y)
        turned = (nan[1:] != nan[:-1]).any(axis=1)  # between the scanned rows too: their edges are not read
        edge[1:] |= turned
        edge[:-1] |= turned
        n = t.size if final else t.size - 1  # the last row's edge waits for the next row
        keep, a, end = line_kernel(t[:n], np.ascontiguousarray(y[:n]), self._tol, edge[:n], self._lo, self._hi,
                                   max(self._scanned, 1), final)
        reported = min(self._scanned, 1)  # the anchor was, when it was kept
        decided = np.flatnonzero(keep[reported:]) + reported
        carried = np.unique([a, end, *range(n, t.size)]) if n else np.arange(t.size)
        self._t, self._y, self._index, self._must = t[carried], y[carried], index[carried], edge[carried]
        self._scanned = min(n, 1 + (end > a))
        return index[decided], y[decided]

    @property
    def decided(self) -> int:
        """Rows pushed whose keeping is decided (those kept returned): all before the carried row after the anchor
        (the rows between them are left out)."""
        k = min(self._scanned, 1)
        return int(self._index[k]) if self._index is not None and k < self._index.size else self._rows

    def finish(self) -> tuple[np.ndarray, np.ndarray]:
        """The rows kept at the series' end (its last among them)."""
        if self._y is None:
            return np.zeros(0, np.int64), np.zeros((0, 1))
        return self.push(np.zeros(0), np.zeros((0, self._y.shape[1])), final=True)


def line_rows(t: np.ndarray, values: np.ndarray, tolerance: float | np.ndarray,
              must: np.ndarray | None = None) -> np.ndarray:
    """Indices of the rows of `values` (K,) or (K, n) over times `t` that a line drawn through them keeps within
    `tolerance` (per column, or one for all) of every row left out; rows where a value turns NaN or back, rows marked
    in `must` (K,) bool, the first and the last are kept."""
    line = LineCut(tolerance)
    rows = line.push(t, values, must)[0]
    return np.r_[rows, line.finish()[0]]
