"""Push-advance controller: pan push targets forming the S-shaped snake behind the shearer, support advances.

During the straight cut of cycle k the pans behind the shearer's trailing end (after `push_lag_pans`) are
pushed along the snake: the fraction of the web a pan joint has been pushed is G(u), u the joint's distance
behind the snake head in pans, G the normalised offset of an S-curve whose yaw ramps up and down by one
equal bend per pan (a triangle) so neighbouring pans never exceed the bend limit. A pan's target is the mean
of its two joints' fractions, never decreasing. Supports advance (lowered, pulled up by their rams, set) in
one of two sequences (`supports.sequence`):

* "after_push" (conventional): once its pan and the `advance_lag_pans` pans nearer the shearer are fully
  pushed; the rams rest retracted.
* "before_push" (immediate forward support): as soon as the shearer's trailing end is `advance_lag_pans`
  pans past it, up to its still unpushed pan, so the fresh roof is supported at once; the rams rest extended
  by a web, and the push that follows extends them again.

At the face end the remaining pans are pushed fully while the shearer stands in the new web (snake
sumping). Every push adds the per-support offset (metres; for face alignment), zero unless set.
"""

from __future__ import annotations

import numpy as np

from twin.config.scenario import Scenario
from twin.face import snake
from twin.face.layout import support_stations


class PushAdvanceController:
    """Targets in metres of advance (towards the coal wall, face frame x) for every pan and support."""

    def __init__(self, scn: Scenario):
        self.scn = scn
        self.n = scn.face.pan_count
        self.stations = support_stations(scn)
        self.g = snake.fractions(scn.pattern.snake_length_pans)
        self.pan_target = np.zeros(self.n)  # advance of each pan [m]
        self.sup_target = np.zeros(self.stations.size)  # advance of each support [m]
        self.cycle_start = np.zeros(self.n)  # pan targets when the current cycle began
        self.push = np.full(self.n, scn.face.web_depth_m)  # this cycle's push of each pan [m]
        self.direction = 1

    def begin_cycle(self, direction: int, offsets_m: np.ndarray | None = None) -> None:
        """Start a cycle: every pan will be pushed one web plus its support's offset (metres)."""
        offsets = np.zeros(self.stations.size) if offsets_m is None else np.asarray(offsets_m, float)
        if offsets.shape != self.stations.shape:
            raise ValueError(f"push offsets: {offsets.size} values for {self.stations.size} supports")
        group = np.clip(np.searchsorted(self.stations, np.arange(self.n)), 0, self.stations.size - 1)
        self.cycle_start = self.pan_target.copy()
        self.push = self.scn.face.web_depth_m + offsets[group]
        self.direction = direction

    def _pan_fraction(self, s_trail: float) -> np.ndarray:
        length = self.scn.face.pan_length_m
        joints = np.arange(self.n + 1) * length
        u = self.direction * (s_trail - joints) / length - self.scn.pattern.push_lag_pans
        frac_joint = np.interp(u, np.arange(self.g.size), self.g, left=0.0, right=1.0)
        return 0.5 * (frac_joint[:-1] + frac_joint[1:])

    def update(self, s_trail: float | None) -> tuple[np.ndarray, np.ndarray]:
        """New targets after the shearer's trailing end reaches `s_trail` (None: push the rest fully).

        Returns the advance target of each support's pan [m] and the flag of the supports that advance
        now (their support targets become their pans' targets).
        """
        frac = np.ones(self.n) if s_trail is None else self._pan_fraction(s_trail)
        self.pan_target = np.maximum(self.pan_target, self.cycle_start + self.push * frac)
        lag = self.scn.supports.advance_lag_pans
        if self.scn.supports.sequence == "before_push":
            goal = self.cycle_start[self.stations] + self.support_lag_m()
            if s_trail is None:
                ready = np.ones(self.stations.size, bool)
            else:
                length = self.scn.face.pan_length_m
                ready = self.direction * (s_trail - (self.stations + 0.5) * length) >= lag * length
        else:
            goal = self.pan_target[self.stations]
            full = frac >= 1.0
            ready = full[self.stations]
            if s_trail is not None:
                ready &= full[np.clip(self.stations + self.direction * lag, 0, self.n - 1)]
        advancing = ready & (goal > self.sup_target + 1e-12)
        self.sup_target = np.where(advancing, goal, self.sup_target)
        return self.pan_target[self.stations], advancing

    def support_lag_m(self) -> float:
        """How far a support stands behind its set position at the start: a web when supports advance
        before the push (their rams rest extended), none otherwise. Support targets count from there, so
        after every cycle a support has advanced as far as its pan."""
        return self.scn.face.web_depth_m if self.scn.supports.sequence == "before_push" else 0.0
