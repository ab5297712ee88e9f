"""The supports' hydraulic and push-ram checks (estimators.faults.hydraulic_checks with the ram checks' findings,
estimators.faults.ram_checks) run online on a sliding window of the PUSHRAM and PRESSURE rows as they come, each
fault said once (`OnlineChecks`).

Why these windows. The checks judge a log: a push, an advance or a set is judged with the samples around it (an
advance's ADVANCE_S and its pads, SET_SETTLE_S twice, a leak's LEAK_MIN_S), and a slow valve against the face's
typical rate over the advances in the log. So the checks run, every STEP_S of simulated time the two streams are
complete to, on the rows of the last WINDOW_S (one cycle of the default face: every support's advance in it, the
face's rate from all of them), and only what the window holds whole is taken: a finding that starts within GUARD_S
of the window's start (an advance or a run cut by it; the log's start is no cut) or is confirmed within GUARD_S of
its end (a set not yet settled) is left to the windows before or after. A fault confirmed within
WINDOW_S - 2 GUARD_S - STEP_S of its start is seen whole by one window at least; each is said once: a finding of the
same support and kind within GUARD_S of one said before is that one (it extends it). The rows held are the last
window's; the findings remembered those a later window can still meet.

Limits: a fault confirmed later than that after its start (a ram drift of under 0.3 mm/s, a leak that takes longer
to empty the legs) is not said before the log's end (`take(final=True)`: the rest, no end guard); the slow valve's
face rate is the window's.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from estimators.faults.hydraulic_checks import Attribution, HydraulicLayout, check_hydraulics
from estimators.faults.ram_checks import RamLayout, check_log

CHECKED_STREAMS = ("pushram", "pressure")
"""The streams the checks read."""
WINDOW_S = 1200.0
"""Simulated time of the rows the checks run on [s]."""
STEP_S = 300.0
"""The checks run each time the streams are complete this much further [s]."""
GUARD_S = 120.0
"""Findings this near a window's ends are left to another window; findings this near one said are that one [s]."""


class OnlineChecks:
    """The checks on the rows `add`ed; `take` runs them on the windows now complete and returns the new faults."""

    def __init__(self, ram: RamLayout, hydraulics: HydraulicLayout, window_s: float = WINDOW_S,
                 step_s: float = STEP_S, guard_s: float = GUARD_S):
        if not window_s - 2 * guard_s >= step_s > 0:
            raise ValueError(f"OnlineChecks: window {window_s:g} s must hold the step {step_s:g} s (above 0) and "
                             f"the guard {guard_s:g} s at both ends")
        self.ram, self.hydraulics = ram, hydraulics
        self.window_s, self.step_s, self.guard_s = window_s, step_s, guard_s
        self.rows: dict[str, list[dict[str, np.ndarray]]] = {s: [] for s in CHECKED_STREAMS}
        self.made_until = dict.fromkeys(CHECKED_STREAMS, 0.0)
        self.t_first = np.inf  # the log's first row
        self.t_checked = 0.0  # the last window's end
        self.said: list[Attribution] = []  # those a later window can still meet

    def add(self, name: str, columns: dict[str, np.ndarray], made_until: float) -> None:
        """A stream's next rows (in time order) and the time before which it has no more; other streams are not
        read."""
        if name not in self.rows:
            return
        if columns["t"].size:
            self.rows[name].append(columns)
            self.t_first = min(self.t_first, float(columns["t"][0]))
        self.made_until[name] = made_until

    def take(self, final: bool = False) -> list[Attribution]:
        """The faults found since the last call on every window complete by now (with `final`, the log has ended:
        also its last rows, up to its end), in time order."""
        if not np.isfinite(self.t_first):
            return []
        complete = min(self.made_until.values())
        if final or not np.isfinite(complete):  # a stream with no more rows at all: up to the last row there is
            complete = max((float(p["t"][-1]) for pieces in self.rows.values() for p in pieces if p["t"].size),
                           default=self.t_checked)
        out = []
        while self.t_checked + self.step_s <= complete:
            self.t_checked += self.step_s
            out += self._check(self.t_checked, final=False)
        if final:
            out += self._check(np.inf, final=True)
        return out

    def _check(self, t_end: float, final: bool) -> list[Attribution]:
        """The new faults of the window that ends at t_end; the rows before the next window's start dropped."""
        joined = {s: {c: np.concatenate([p[c] for p in pieces]) for c in pieces[0]}
                  for s, pieces in self.rows.items() if pieces}
        if len(joined) < len(CHECKED_STREAMS):
            return []
        t_start = max(min(t_end, self.t_checked + self.step_s) - self.window_s, self.t_first)
        window = {s: {c: v[cols["t"] < t_end] for c, v in cols.items()} for s, cols in joined.items()}
        keep_from = t_end + self.step_s - self.window_s
        self.rows = {s: [{c: v[cols["t"] >= keep_from] for c, v in cols.items()}] for s, cols in joined.items()}
        if any(np.unique(w["t"]).size < 2 for w in window.values()):
            return []
        with warnings.catch_warnings():  # a window without an advance has no face rate to compare valves with
            warnings.filterwarnings("ignore", "All-NaN slice", RuntimeWarning)
            found = check_hydraulics(window["pushram"], window["pressure"], self.hydraulics,
                                     check_log(window["pushram"], self.ram))
        t_last = float(window["pushram"]["t"][-1])
        whole = [a for a in found if (t_start <= self.t_first or a.t_start >= t_start + self.guard_s)
                 and (final or a.t_detect <= t_last - self.guard_s)]
        new = []
        for a in whole:
            same = [i for i, s in enumerate(self.said) if s.support == a.support and s.kind == a.kind
                    and a.t_start <= s.t_end + self.guard_s and s.t_start <= a.t_end + self.guard_s]
            if same:
                s = self.said[same[0]]
                self.said[same[0]] = dataclasses.replace(s, t_end=max(s.t_end, a.t_end))
            else:
                self.said.append(a)
                new.append(a)
        self.said = [s for s in self.said if s.t_end + 2 * self.guard_s >= keep_from]
        return new
