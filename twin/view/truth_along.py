"""The truth at estimate times that come in order, block by block: an estimate file's errors drawn a row group at a
time with the truth_shearer file read once, forwards."""

from __future__ import annotations

import numpy as np

from estimators.io.logformat import LogError
from estimators.io.metrics import TruthTrack


class TruthAlong(TruthTrack):
    """estimators.io.metrics.TruthTrack over one forward read of its blocks: `at(t)` (so truth_at, position_errors,
    attitude_errors) gives what TruthTrack gives, bit for bit, for sorted times t that do not go back before the
    previous call's; it holds the truth block the times fall in (a new TruthAlong for each pass over the estimates)."""

    def __init__(self, track: TruthTrack):
        super().__init__(track.blocks)
        self._windows = track.windows()  # not self's: a generator held by the object it reads would keep it alive
        self._window = next(self._windows, None)
        if self._window is None:
            raise LogError("truth_shearer holds no samples to score against")
        self._first = self._window[0]["t"][0]

    def _interpolate(self, t: np.ndarray) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {}
        todo = np.ones(t.size, bool)
        while True:
            cols, lo, hi = self._window
            self._fill(out, cols, t, todo & (t >= lo) & (t < hi), todo)
            following = next(self._windows, None) if todo.any() else None
            if following is None:
                break
            self._window = following
        self.check_span(t, self._first, self._window[0]["t"][-1] if todo.any() else np.inf)
        self._fill(out, self._window[0], t, todo.copy(), todo)  # the times at the last sample
        return out
