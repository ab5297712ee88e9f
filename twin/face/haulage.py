"""Haulage controller: the shearer's arc-length profile s(t) over the bi-directional cutting cycles.

Each cycle (001 Fig. 3) is a straight cut from one face end to the other (A-B), then snake sumping at that
end: reverse into the snake at sumping speed (B-C), stop while the end pans are pushed (C-D), cut out to
the face end (D-E). The next cycle starts in the other direction, first at return speed over the coal the
sump already cut, then at cutting speed. Motion is rest-to-rest with a symmetric acceleration limit; the
feasible speed at distance x is v(x)^2 = min_y (v_lim(y)^2 + 2 a |x - y|), evaluated exactly per leg, and
between grid points the acceleration is constant, so s(t) is exact piecewise-quadratic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.config.scenario import Scenario, travel_length_m

# Haulage phases (truth column `phase`).
STOPPED, CUTTING, RETURN, SUMPING, CUT_OUT = range(5)

GRID_M = 0.002
"""Distance grid of the speed profile [m]."""


@dataclass(frozen=True)
class Leg:
    length: float  # > 0
    speed: float  # m/s
    phase: int


@dataclass(frozen=True)
class Segment:
    """A rest-to-rest run over its legs (a stop when it has none) placed on the timeline. Its speed profile's grid
    (run_profile, GRID_M apart: 5 MB a 360 m cut) is made again where it is sampled, not held: a run's timeline
    holds its legs only, whatever its number of cycles."""

    t0: float
    s0: float
    direction: int
    legs: tuple[Leg, ...]
    accel: float
    duration: float
    cycle: int

    def grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """run_profile's (t relative to t0, x from s0 along direction, v, phase per cell)."""
        return run_profile(list(self.legs), self.accel)


def run_profile(legs: list[Leg], accel: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Grid (t, x, v, phase per cell) of a rest-to-rest run over consecutive legs."""
    bounds = np.concatenate([[0.0], np.cumsum([leg.length for leg in legs])])
    total = bounds[-1]
    n = max(2, int(np.ceil(total / GRID_M)) + 1)
    x = np.linspace(0.0, total, n)
    v2 = np.minimum(2 * accel * x, 2 * accel * (total - x))
    for k, leg in enumerate(legs):
        dist = np.maximum(0.0, np.maximum(bounds[k] - x, x - bounds[k + 1]))
        v2 = np.minimum(v2, leg.speed ** 2 + 2 * accel * dist)
    v = np.sqrt(np.maximum(v2, 0.0))
    dt = 2 * np.diff(x) / np.maximum(v[:-1] + v[1:], 1e-12)
    t = np.concatenate([[0.0], np.cumsum(dt)])
    mid = 0.5 * (x[:-1] + x[1:])
    leg_of_cell = np.clip(np.searchsorted(bounds, mid, side="right") - 1, 0, len(legs) - 1)
    phase = np.array([leg.phase for leg in legs], np.int8)[leg_of_cell]
    return t, x, v, phase


@dataclass
class CyclePlan:
    cycle: int
    direction: int
    t_start: float
    t_cut_end: float
    t_sump_end: float
    t_push_end: float
    t_end: float
    s_sump: float


class Timeline:
    """The whole run's s(t): segments in time order, and the cycle table."""

    def __init__(self, scn: Scenario):
        self.scn = scn
        h, sh, f = scn.haulage, scn.shearer, scn.face
        self.s_min = sh.length_m / 2
        self.s_max = f.pan_count * f.pan_length_m - sh.length_m / 2
        # Back past the snake and one more pan, so the end push (which drags the next pan a little) leaves
        # the pans under the shearer alone.
        self.sump_m = sh.length_m + (scn.pattern.push_lag_pans + scn.pattern.snake_length_pans + 2) * f.pan_length_m
        accel = h.acceleration_m_s2
        cut, ret, sump = (v / 60.0 for v in (h.cutting_speed_m_min, h.return_speed_m_min, h.sump_speed_m_min))
        travel = travel_length_m(scn)
        self.segments: list[Segment] = []
        self.cycles: list[CyclePlan] = []
        t, s = 0.0, self.s_min
        for k in range(scn.cycles):
            d = 1 if k % 2 == 0 else -1
            t_start = t
            t = self._stop(t, s, h.reversal_stop_s, k)
            # Straight cut, split at the scripted stops; the first sump_m is return travel after cycle 0.
            cut_legs = [Leg(self.sump_m, ret, RETURN), Leg(travel - self.sump_m, cut, CUTTING)] if k else \
                [Leg(travel, cut, CUTTING)]
            done = 0.0
            for stop in sorted((st for st in h.stops if st.cycle == k), key=lambda st: st.at_m):
                legs = _slice_legs(cut_legs, done, stop.at_m)
                if legs:  # a stop at the start of the cut (at_m 0) extends the stand before it
                    t, s = self._run(t, s, d, legs, accel, k)
                t = self._stop(t, s, stop.duration_s, k)
                done = stop.at_m
            t, s = self._run(t, s, d, _slice_legs(cut_legs, done, travel), accel, k)
            t_cut_end = t
            t = self._stop(t, s, h.reversal_stop_s, k)
            t, s = self._run(t, s, -d, [Leg(self.sump_m, sump, SUMPING)], accel, k)
            t_sump_end, s_sump = t, s
            t = self._stop(t, s, h.end_push_stop_s, k)
            t_push_end = t
            t, s = self._run(t, s, d, [Leg(self.sump_m, cut, CUT_OUT)], accel, k)
            self.cycles.append(CyclePlan(k, d, t_start, t_cut_end, t_sump_end, t_push_end, t, s_sump))
        self.duration = t

    def _stop(self, t: float, s: float, duration: float, cycle: int) -> float:
        if duration > 0:
            self.segments.append(Segment(t, s, 1, (), 0.0, duration, cycle))
        return t + duration

    def _run(self, t: float, s: float, d: int, legs: list[Leg], accel: float, cycle: int) -> tuple[float, float]:
        tg, xg, _, _ = run_profile(legs, accel)
        self.segments.append(Segment(t, s, d, tuple(legs), accel, tg[-1], cycle))
        return t + tg[-1], s + d * xg[-1]

    def sample(self, times: np.ndarray) -> dict[str, np.ndarray]:
        """Arc length s, speed ds/dt, acceleration, phase and cycle at `times` (vectorized per segment)."""
        out = {k: np.zeros(times.size) for k in ("s", "ds", "dds")}
        phase = np.zeros(times.size, np.int8)
        cycle = np.zeros(times.size, np.int32)
        starts = np.array([seg.t0 for seg in self.segments])
        which = np.clip(np.searchsorted(starts, times, side="right") - 1, 0, len(self.segments) - 1)
        for k in np.unique(which):
            seg = self.segments[k]
            sel = which == k
            cycle[sel] = seg.cycle
            if not seg.legs:
                out["s"][sel] = seg.s0
                continue
            t_g, x_g, v_g, phase_g = seg.grid()
            tau = np.clip(times[sel] - seg.t0, 0.0, seg.duration)
            i = np.clip(np.searchsorted(t_g, tau, side="right") - 1, 0, t_g.size - 2)
            dt_cell = t_g[i + 1] - t_g[i]
            acc = (v_g[i + 1] - v_g[i]) / np.maximum(dt_cell, 1e-12)
            r = tau - t_g[i]
            out["s"][sel] = seg.s0 + seg.direction * (x_g[i] + v_g[i] * r + 0.5 * acc * r * r)
            out["ds"][sel] = seg.direction * (v_g[i] + acc * r)
            out["dds"][sel] = seg.direction * acc
            phase[sel] = phase_g[i]
        out["phase"] = phase
        out["cycle"] = cycle
        return out

    def crossings(self, cycle: int, offset: float, step: float) -> tuple[np.ndarray, np.ndarray]:
        """Times when s + offset crosses multiples of `step` during the straight cut of `cycle`.

        Returns (times, crossed positions), in time order.
        """
        plan = self.cycles[cycle]
        times, points = [], []
        for seg in self.segments:
            if seg.cycle != cycle or not seg.legs or not (plan.t_start <= seg.t0 < plan.t_cut_end):
                continue
            t_g, x_g, _, _ = seg.grid()
            pos = seg.s0 + seg.direction * x_g + offset
            lo, hi = sorted((pos[0], pos[-1]))
            marks = np.arange(np.ceil(lo / step), np.floor(hi / step) + 1) * step
            if seg.direction < 0:
                marks = marks[::-1]
            # pos is monotone along the grid: interpolate the time of each mark.
            order = slice(None) if seg.direction > 0 else slice(None, None, -1)
            times.append(seg.t0 + np.interp(marks, pos[order], t_g[order]))
            points.append(marks)
        if not times:
            return np.zeros(0), np.zeros(0)
        return np.concatenate(times), np.concatenate(points)


def _slice_legs(legs: list[Leg], a: float, b: float) -> list[Leg]:
    """The part of consecutive legs between distances a and b."""
    out, pos = [], 0.0
    for leg in legs:
        lo, hi = max(a, pos), min(b, pos + leg.length)
        if hi - lo > 1e-9:
            out.append(Leg(hi - lo, leg.speed, leg.phase))
        pos += leg.length
    return out
