"""The rows of a plotted series a person can see (twin.view.row_cuts' module docstring): at most the record rate,
without the samples the drawn line passes within a pixel of, a noisy stretch by its band. Over a series given whole
(`visible_rows`) or in blocks, in two passes (`SeriesRange` for its span, then `VisibleCut`), the same rows bit for
bit."""

from __future__ import annotations

import numpy as np

from twin.view.record_rate import FULL
from twin.view.row_cuts import Decimation, LineCut, series_matrix

LINE_TOLERANCE = 2e-3
"""Largest distance between a plotted line and a sample left out of it, as a fraction of the entity's span of values
(a pixel of a plot 500 pixels high; the stacked plots of the layout are smaller)."""

BAND_ROWS = 10
"""Rows at the record rate per interval of which a noisy series keeps its band (first, lowest, highest row): 1 s at
10 Hz."""
BAND_TURNS = 1
"""Turns (a value changing direction) in such an interval from which it is busy (noise, a vibration faster than the
interval): drawn by its band, the interval's extremes, as a min/max plot does."""


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
        y = series_matrix(t, values)
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
        t, y = np.asarray(t, float), series_matrix(t, values)
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
