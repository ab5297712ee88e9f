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

LINE_TOLERANCE = 2e-3
"""Largest distance between a plotted line and a sample left out of it, as a fraction of the entity's span of values
(a pixel of a plot 500 pixels high; the stacked plots of the layout are smaller)."""
PATH_TOLERANCE_M = 0.005
"""Largest distance between a drawn 3-D path and a sample left out of it [m]."""
BAND_ROWS = 10
"""Rows at the record rate per interval of which a noisy series keeps its band (first, lowest, highest row): 1 s at
10 Hz."""
BAND_TURNS = 1
"""Turns (a value changing direction) in such an interval from which it is busy (noise, a vibration faster than the
interval): drawn by its band, the interval's extremes, as a min/max plot does."""
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


def _matrix(t: np.ndarray, values: np.ndarray) -> np.ndarray:
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
        t, y = np.asarray(t, float), _matrix(t, values)
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


def _intervals(t: np.ndarray, width_s: float) -> np.ndarray:
    """The interval of width width_s seconds each of the (sorted) times falls in, numbered from 0."""
    group = np.floor(np.asarray(t, float) / width_s + 1e-9)
    return np.cumsum(np.r_[True, np.diff(group) > 0]) - 1


def band_rows(t: np.ndarray, values: np.ndarray, width_s: float) -> np.ndarray:
    """Indices of the rows that hold, in each interval of width_s seconds, the first row and each column's lowest and
    highest value (the band a person sees of a series that swings faster than the eye follows), and the rows where a
    value turns NaN or back."""
    t = np.asarray(t, float)
    y = np.asarray(values, float).reshape(t.size, -1)
    if t.size < 3:
        return np.arange(t.size)
    ident = _intervals(t, width_s)
    starts = np.flatnonzero(np.r_[True, np.diff(ident) > 0])
    keep = np.zeros(t.size, bool)
    keep[starts] = True
    nan = np.isnan(y)
    turned = (nan[1:] != nan[:-1]).any(axis=1)
    keep[1:] |= turned
    keep[:-1] |= turned
    for extreme, blank in ((np.maximum, -np.inf), (np.minimum, np.inf)):
        filled = np.where(nan, blank, y)
        at = (filled == extreme.reduceat(filled, starts, axis=0)[ident]) & ~nan
        first = np.zeros(t.size, bool)  # the first row at each column's extreme in each interval
        for j in range(y.shape[1]):
            rows = np.flatnonzero(at[:, j])
            if rows.size:  # none where the column is NaN throughout
                first[rows[np.r_[True, np.diff(ident[rows]) > 0]]] = True
        keep |= first
    return np.flatnonzero(keep)


class SeriesRange:
    """Pass 1 of `visible_rows` over a series given in blocks: how many rows decimate keeps (`rows`) and the span of
    their finite values (`span`; `finite`: whether there is one); `push` each block, then `finish`."""

    def __init__(self, rate_hz: float | None):
        self._time, self.rows = Decimation(rate_hz), 0
        self._lo, self._hi, self._last = np.inf, -np.inf, None

    def push(self, t: np.ndarray, values: np.ndarray) -> None:
        y = _matrix(t, values)
        self._add(y[self._time.push(np.asarray(t, float))])
        self._last = y[-1:] if len(t) else self._last

    def finish(self) -> None:
        """The series' last row, when decimate adds it."""
        if not self._time.last_kept:
            self._add(self._last)

    def _add(self, y: np.ndarray) -> None:
        finite = y[np.isfinite(y)]
        self.rows += y.shape[0]
        if finite.size:
            self._lo, self._hi = min(self._lo, finite.min()), max(self._hi, finite.max())

    @property
    def finite(self) -> bool:
        return bool(self._hi >= self._lo)

    @property
    def span(self) -> float:
        return float(self._hi - self._lo) if self.finite else 0.0


class VisibleCut:
    """Pass 2 of `visible_rows` over a series given in blocks, the same rows bit for bit; `measured` is pass 1
    (SeriesRange over the same blocks). `push` each block, then `finish`: both return the rows decided kept (indices
    over all the rows pushed, their times, their values (k, n) as float). Held between blocks: the block's last row
    (decimate adds the series' last), the line's carried rows (LineCut) and the record-rate rows from the first
    interval of BAND_ROWS not decided (the line has decided its rows and the next interval has begun: a few rows)."""

    def __init__(self, rate_hz: float | None, measured: SeriesRange, band: bool = True):
        self._time, self._band = Decimation(rate_hz), band
        self._thin = rate_hz is not FULL and measured.rows >= 3  # else every row decimate keeps
        self._line = LineCut(LINE_TOLERANCE * measured.span)
        self._width = BAND_ROWS / rate_hz if self._thin else 0.0
        self._rows, self._last = 0, None  # rows pushed; the last of them (index, time, values)
        self._held: tuple[np.ndarray, ...] | None = None  # record-rate rows: index, time, values, on the line
        self._first = 0  # the first held row's number among the line's rows
        self._before: tuple[np.ndarray, np.ndarray] | None = None  # the row before the held ones (time, values)

    def push(self, t: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t, y = np.asarray(t, float), _matrix(t, values)
        keep = self._time.push(t)
        if t.size:
            self._last = (np.array([self._rows + t.size - 1]), t[-1:], y[-1:])
        self._rows += t.size
        return self._cut(self._rows - t.size + keep, t[keep], y[keep], final=False)

    def finish(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The rows decided at the series' end (the last row pushed, when decimate adds it)."""
        if self._last is None or self._time.last_kept:
            m = 0 if self._last is None else self._last[2].shape[1]
            return self._cut(np.zeros(0, np.int64), np.zeros(0), np.zeros((0, m)), final=True)
        return self._cut(*self._last, final=True)

    def _cut(self, index: np.ndarray, t: np.ndarray, y: np.ndarray,
             final: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Of the record-rate rows so far (these appended), those decided kept by the line and the bands."""
        if not self._thin:
            return index, t, y
        on_line = self._line.push(t, y, final=final)[0]
        held = (index, t, y, np.zeros(t.size, bool))
        if self._held is not None:
            held = tuple(np.concatenate([a, b]) for a, b in zip(self._held, held))
        held[3][on_line - self._first] = True
        decided = held[0].size if final else self._line.decided - self._first
        if self._band:
            done = held[0].size if final else self._decided_intervals(held[1], decided)
            rows = self._band_cut(held, done, final)
        else:
            done = decided
            rows = np.flatnonzero(held[3][:done])
        if done:
            self._before = (held[1][done - 1:done], held[2][done - 1:done])
        self._held, self._first = tuple(a[done:] for a in held), self._first + done
        return held[0][rows], held[1][rows], held[2][rows]

    def _decided_intervals(self, t: np.ndarray, decided: int) -> int:
        """Held rows in the intervals before the last one that begins at or before row `decided`."""
        group = np.floor(t / self._width + 1e-9)
        starts = np.flatnonzero(np.diff(group) > 0) + 1  # the held rows begin an interval
        starts = starts[starts <= decided]
        return int(starts[-1]) if starts.size else 0

    def _band_cut(self, held: tuple[np.ndarray, ...], done: int, final: bool) -> np.ndarray:
        """visible_rows' choice in the first `done` held rows (whole intervals): the line's rows, the band's in a busy
        interval; computed with the rows either side of them (NaN edges and turns read their neighbours)."""
        if not done:
            return np.zeros(0, np.int64)
        _, t, y, on_line = (a[:done] for a in held)
        pad_before = self._before is not None
        pad_after = done < held[0].size
        t_pad = np.r_[self._before[0] if pad_before else [], t, held[1][done:done + 1]]
        y_pad = np.concatenate([self._before[1] if pad_before else y[:0], y, held[2][done:done + 1]])
        inner = slice(int(pad_before), int(pad_before) + done)
        extremes = band_rows(t_pad, y_pad, self._width)
        extremes = extremes[(extremes >= inner.start) & (extremes < inner.stop)] - inner.start
        slope = np.sign(np.diff(y_pad, axis=0))
        turns = np.r_[False, ((slope[1:] * slope[:-1]) < 0).any(axis=1), False][inner]
        ident = _intervals(t, self._width)
        n = ident[-1] + 1
        line = np.flatnonzero(on_line)
        noisy = ((2 * np.bincount(ident[line], minlength=n) > np.bincount(ident, minlength=n))
                 & (np.bincount(ident, turns, n) >= BAND_TURNS)
                 & (np.bincount(ident[extremes], minlength=n) < np.bincount(ident[line], minlength=n)))
        return np.union1d(line[~noisy[ident[line]]], extremes[noisy[ident[extremes]]])


def visible_rows(t: np.ndarray, values: np.ndarray, rate_hz: float | None, band: bool = True) -> np.ndarray:
    """Rows of a plotted series a person can tell apart (every row at FULL rate): at most rate_hz (decimate), and of
    those the rows a line drawn through keeps within LINE_TOLERANCE of the entity's span of every row left out
    (line_rows); with `band`, in each busy interval of BAND_ROWS / rate_hz seconds (1 s at 10 Hz: the line keeps
    more than half its rows and the values turn BAND_TURNS times or more: noise, vibration), the interval's band
    instead when that is fewer rows (band_rows: its first row and extremes, what a min/max plot draws of it). Without
    `band` (0/1 flags, steps) the line keeps every edge. A series given in blocks: SeriesRange, then VisibleCut."""
    measured = SeriesRange(rate_hz)
    measured.push(t, values)
    measured.finish()
    cut = VisibleCut(rate_hz, measured, band)
    return np.r_[cut.push(t, values)[0], cut.finish()[0]].astype(np.int64)
