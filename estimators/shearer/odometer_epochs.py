"""The odometer at the filter epochs, as the log comes (estimators.shearer.prepare.Preparer): the distance and the
odometer channel of each epoch's interval (moving, settling, standing, no data), and the runs of travel in one
direction among the epochs, of which the straight cuts are the ones that cross the face."""

from __future__ import annotations

import numpy as np

from estimators.shearer.odometer_filter import (
    MODE_MOVING,
    MODE_NO_DATA,
    MODE_SETTLING,
    MODE_STANDING,
)

ODO_PERIOD_ROWS = 1024
"""Intervals from the odometer's first sample over which its nominal period (a dropout is a gap of 2.5 of them) is
the median: known after the first minutes, so that a log fed in pieces finds the dropouts the whole log does."""


def odometer_at(t: np.ndarray, distance: np.ndarray, direction: np.ndarray, prev_distance: float,
                 active_before: float, t_kf: np.ndarray, settle_s: float, period: float, t_first: float,
                 t_last: float) -> tuple[np.ndarray, np.ndarray]:
    """Odometer distance at the epochs t_kf (E + 1,) and the odometer channel of each interval (t_kf[j-1], t_kf[j]]
    (E,) (estimators.shearer.odometer_filter MODE_*): moving where the odometer counted or showed a haulage direction;
    standing where it shows neither from settle_s before the interval to settle_s after it (the machine may still
    coast at a stop, or creep before its direction signal comes on at a start), settling in between; no data
    outside the log (t_first..t_last) or where the interval overlaps a dropout (two consecutive samples more than 2.5
    nominal periods apart).

    The samples (t, distance, direction) are a window of the log: every sample from the last at or before t_kf[0] on
    (the log's first if none is), `prev_distance` the reading before the window (NaN: none), `active_before` the time
    of the last sample before it that showed motion (-inf: none). The look-ahead makes a stand known settle_s late:
    an online run takes an interval's channel once the odometer has reached settle_s past it
    (estimators.shearer.prepare.Preparer)."""
    dist = np.interp(t_kf, t, distance)
    lo, hi = t_kf[:-1], t_kf[1:]
    covered = (lo >= t_first) & (hi <= t_last)
    if t.size > 1:
        gap = np.flatnonzero(np.diff(t) > 2.5 * period)
        if gap.size:
            gap_start, gap_end = t[gap], t[gap + 1]  # disjoint and sorted
            k = np.searchsorted(gap_end, lo, side="right")  # the first dropout ending after the interval starts
            covered &= ~((k < gap.size) & (gap_start[np.minimum(k, gap.size - 1)] < hi))
    moving = np.concatenate([[0], np.cumsum(direction != 0)])[np.searchsorted(t, t_kf, side="right")]
    moved = (np.diff(moving) > 0) | (np.abs(np.diff(dist)) > 0)
    before = distance[0] if np.isnan(prev_distance) else prev_distance
    active = (direction != 0) | (np.diff(distance, prepend=before) != 0)
    t_active = np.concatenate([[active_before], t[active]])  # -inf first: "none before"
    last = np.searchsorted(t_active, lo, side="right") - 1  # the last sample showing motion up to the start
    after = np.searchsorted(t_active, hi, side="left")  # the first one from the end on
    settled = ((lo - t_active[last] >= settle_s)
               & ((after >= t_active.size) | (t_active[np.minimum(after, t_active.size - 1)] - hi >= settle_s)))
    still = np.where(settled, MODE_STANDING, MODE_SETTLING)
    return dist, np.where(covered, np.where(moved, MODE_MOVING, still), MODE_NO_DATA).astype(np.int8)


STRAIGHT_CUT_FRACTION = 0.8
"""A run of travel in one direction longer than this fraction of the face is a straight cut (a sump or a cut-out
into the snake covers the snake and the shearer, up to about half of a short face)."""


class TravelRuns:
    """Runs of travel in one direction among the filter epochs, found as the epochs come: a run ends where the travel
    turns (the next moving epoch goes the other way) or where the log ends; stands inside a run do not end it."""

    def __init__(self):
        self.sign = 0.0  # of the open run (0: none open)
        self.first = self.last = 0
        self.closed: list[tuple[int, int]] = []
        """(first, last) epochs of each run that has ended, in order."""

    def add(self, j0: int, du: np.ndarray, mode: np.ndarray) -> None:
        """Epochs j0, j0 + 1, ... with their travel du[k] = u[j] - u[j - 1] and odometer channel."""
        moving = np.flatnonzero((mode == MODE_MOVING) & (du != 0))
        if moving.size == 0:
            return
        sign = np.sign(du[moving])
        starts = np.flatnonzero(np.diff(np.concatenate([[self.sign], sign])) != 0)  # where a run begins
        ends = [*starts[1:], moving.size]
        if starts.size == 0 or starts[0] > 0:
            self.last = j0 + int(moving[(starts[0] if starts.size else moving.size) - 1])
        for k, end in zip(starts, ends):
            self.finish()
            self.first, self.last, self.sign = j0 + int(moving[k]), j0 + int(moving[end - 1]), float(sign[k])

    def finish(self) -> None:
        """End the open run (the log ends)."""
        if self.sign != 0:
            self.closed.append((self.first, self.last))
        self.sign = 0.0


class Growing:
    """A 1-D array of numbered elements appended at its end (its storage doubles as it fills); `drop_before` lets the
    elements before a given number go, so that it holds a window of what was appended."""

    def __init__(self, dtype):
        self._a = np.zeros(1024, dtype)
        self.first = 0  # the number of the first element held
        self.n = 0  # the number of elements appended

    def extend(self, x: np.ndarray) -> None:
        held, need = self.n - self.first, self.n - self.first + x.size
        if need > self._a.size:
            grown = np.zeros(max(need, 2 * self._a.size), self._a.dtype)
            grown[:held] = self._a[:held]
            self._a = grown
        self._a[held:need] = x
        self.n += x.size

    def drop_before(self, k: int) -> None:
        """Let elements 0..k-1 go. The kept ones move to new storage: views of `data` taken before stay as they were."""
        k = min(max(k, self.first), self.n)
        kept = self.data[k - self.first:]
        self._a = np.zeros(max(1024, 2 * kept.size), self._a.dtype)
        self._a[:kept.size] = kept
        self.first = k

    @property
    def data(self) -> np.ndarray:
        """Elements first..n-1."""
        return self._a[:self.n - self.first]
