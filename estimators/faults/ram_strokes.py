"""The support advances in each ram's readings, and check (a): the commanded against the measured stroke.

Support advances
----------------
The ram only retracts when its support advances (lowered, pulled up to the pan by the ram, set), by the
commanded stroke s_c, to its set length. A drop is a down-swing of a quarter stroke (estimators.faults.ram_levels
`swings`), split where the ram rests on the way down (two advances without a push between them, as at a face
end); the level on each side is the median of up to LEVEL_SAMPLES readings next to it within the plateau
tolerance (6 sigma, at least 5 mm, as the CPOEM stroke measurement), cut at the most significant level change
(CHANGE_SIGMAS), so the short last step of a face-end push is not averaged with the pause before it. A drop of
ADVANCE_BAND strokes is a candidate advance; it is sure when the levels around it lie whole strokes above the
face's rest level (the median level after all candidates), within REST_TOLERANCE strokes plus the stroke
check's tolerance. Whether a candidate was an advance is settled by the neighbours
(estimators.faults.ram_neighbours._pan_advance).

(a) Commanded versus measured stroke
------------------------------------
Every push extends the ram by s_c and every advance retracts it by s_c, so

* each advance must measure s_c, and
* between two advances the level must rise by a whole number of strokes (one; none or two where the face-end
  push and advance come in the other order; the log must start between pushes; the open stretch after the
  last advance is not judged: its push may be under way),

within tau_s = STROKE_TOLERANCE s_c (the ram line is not exactly the advance direction: floor steps and pitch
change a healthy stroke by up to 2 % in the twin) + CHANGE_SIGMAS sigma sqrt(1 + 1/14) (a one-reading last
step the level-change test can miss) + STROKE_SIGMAS sigma 1.2533 sqrt(1/n1 + 1/n2) (the two plateau medians
of n1 and n2 readings): 28 mm for the default 0.1 mm sensor and a 0.8 m web, 0.17 m for 004's 0.02 m sensor
and a 1 m web. A drop across unusable readings is not judged. A failed stroke is confirmed at the advance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimators.faults.ram_grid import _runs_1d
from estimators.faults.ram_layout import RamLayout
from estimators.faults.ram_levels import (
    CHANGE_SIGMAS,
    LEVEL_SAMPLES,
    drop_levels,
    side_level,
    swings,
)

ADVANCE_BAND = (0.5, 1.5)
"""A drop of the ram this many commanded strokes may be a support advance."""
REST_TOLERANCE = 0.1
"""Strokes (on top of the stroke check's tolerance) the levels around a sure advance may differ from whole
strokes above the face's rest level."""
STROKE_SIGMAS = 5.0
"""Noise sigmas of a stroke (difference of two plateau medians) on top of the geometry tolerance."""


@dataclass
class _Advances:
    """Drops of one support that may be advances; reading indices of its usable readings."""

    top_end: np.ndarray  # last reading before the drop
    post_start: np.ndarray  # first reading after it
    top: np.ndarray  # level before [m]
    post: np.ndarray  # level after [m]
    n_top: np.ndarray  # readings in the level before
    n_post: np.ndarray
    top_run_start: np.ndarray  # first reading of the plateau before the drop
    post_run_end: np.ndarray  # last reading of the plateau after it

    def keep(self, which: np.ndarray) -> _Advances:
        return _Advances(*(getattr(self, f)[which] for f in self.__dataclass_fields__))


def _drops(r: np.ndarray, stroke: float, tol: float) -> list[tuple[int, int]]:
    """(peak, trough) of each drop of the reading: the down-swings of a quarter stroke (estimators.faults.ram_levels
    `swings` on -r), split where the ram rests on the way down (a level of at least three readings a quarter
    stroke from both ends: two advances without a push between them, as at a face end)."""
    out = []
    for lo, hi in swings(np.ascontiguousarray(-r), 0.25 * stroke):
        seg = r[lo:hi + 1]
        step_ok = np.abs(np.diff(seg)) <= tol
        flat = np.zeros(seg.size, bool)
        flat[1:-1] = step_ok[:-1] & step_ok[1:]
        start = lo
        for a, b in _runs_1d(flat):
            level = float(np.median(seg[a:b + 1]))
            if b - a >= 2 and r[start] - level > 0.25 * stroke and level - seg[-1] > 0.25 * stroke:
                out.append((start, lo + a))
                start = lo + b
        out.append((start, hi))
    return out


def _candidate_advances(r: np.ndarray, layout: RamLayout) -> _Advances:
    tol, stroke, sig = layout.level_tol_m, layout.stroke_m, layout.change_sigma_m
    rows = []
    for lo, hi in _drops(r, stroke, tol) if r.size > 2 else []:
        row = drop_levels(r, lo, hi, tol, sig)
        if ADVANCE_BAND[0] * stroke <= row[2] - row[3] <= ADVANCE_BAND[1] * stroke:
            rows.append(row)
    cols = [np.array(c) for c in zip(*rows)] if rows else [np.zeros(0)] * 8
    return _Advances(*(c.astype(float) if k in (2, 3) else c.astype(np.int64) for k, c in enumerate(cols)))


def _advances(x: np.ndarray, usable: np.ndarray, layout: RamLayout) -> tuple[list[np.ndarray], list[_Advances],
                                                                          list[np.ndarray]]:
    """Per support: its usable grid indices, its drops of about a stroke, and which of them are sure advances:
    the ram was extended by whole strokes above the face's rest level before and is at the rest level (or
    whole strokes above it, after a face-end push) after, within REST_TOLERANCE strokes and the stroke
    check's tolerance. The others (a scaled sensor, the end of a rail deviation) are left to the neighbours."""
    idxs = [np.flatnonzero(usable[:, j]) for j in range(x.shape[1])]
    cand = [_candidate_advances(x[idx, j], layout) for j, idx in enumerate(idxs)]
    posts = np.concatenate([c.post for c in cand])
    rest = float(np.median(posts)) if posts.size else 0.0
    stroke = layout.stroke_m
    sure = []
    for c in cand:
        tol = REST_TOLERANCE * stroke + _stroke_threshold(layout, c.n_top, c.n_post)
        above, below = c.top - rest, c.post - rest
        sure.append((np.abs(above - stroke * np.maximum(np.rint(above / stroke), 1.0)) <= tol)
                    & (np.abs(below - stroke * np.maximum(np.rint(below / stroke), 0.0)) <= tol))
    return idxs, cand, sure


@dataclass(frozen=True)
class _Stroke:
    """A stroke that failed the commanded-stroke check (grid indices)."""

    support: int
    first: int
    last: int
    confirmed: int
    error: float  # measured - commanded [m]
    threshold: float
    relative: float  # measured / commanded - 1


def _stroke_threshold(layout: RamLayout, n1, n2):
    """tau_s: geometry tolerance + the noise of two plateau medians + the largest step the level-change
    test can miss next to an event (one reading against LEVEL_SAMPLES - 1)."""
    n1, n2 = np.maximum(n1, 1), np.maximum(n2, 1)
    hidden = CHANGE_SIGMAS * layout.change_sigma_m * math.sqrt(1.0 + 1.0 / (LEVEL_SAMPLES - 1))
    return (layout.stroke_tol_m + hidden
            + STROKE_SIGMAS * layout.sigma_m * 1.2533 * np.sqrt(1.0 / n1 + 1.0 / n2))


def _stroke_checks(x: np.ndarray, idxs, advances: list[_Advances], layout: RamLayout,
                   drops: list[np.ndarray] | None = None) -> list[_Stroke]:
    """Check (a): every advance retracts the ram by the commanded stroke, and between advances it rises by whole
    strokes (none where a face-end push came first).

    Not judged: a drop across unusable readings (the push may have gone on unseen before it), and a drop at
    the same reading as a drop of a neighbour (`drops`: grid indices of every support's drops), as at a face
    end, where the last push step and the advance may fall within one reading."""
    stroke, tol = layout.stroke_m, layout.level_tol_m
    out = []
    for j, (idx, adv) in enumerate(zip(idxs, advances)):
        if adv.top.size == 0:
            continue
        r = x[idx, j]
        seen = idx[adv.post_start] - idx[adv.top_end] == adv.post_start - adv.top_end
        if drops is not None:
            for k in (j - 1, j + 1):
                if 0 <= k < len(drops) and drops[k].size:
                    seen &= np.abs(drops[k][None, :] - idx[adv.post_start][:, None]).min(axis=1) > 1
        err = np.where(seen, adv.top - adv.post - stroke, 0.0)
        thr = _stroke_threshold(layout, adv.n_top, adv.n_post)
        for m in np.flatnonzero(np.abs(err) > thr):
            out.append(_Stroke(j, idx[adv.top_end[m]], idx[adv.post_start[m]], idx[adv.post_start[m]],
                               float(err[m]), float(thr[m]), float(err[m] / stroke)))
        start_level, n_start, start_run_end = side_level(r, 0, 1, tol, layout.change_sigma_m)
        starts = np.concatenate([[start_level], adv.post[:-1]])
        n_starts = np.concatenate([[n_start], adv.n_post[:-1]])
        run_ends = np.concatenate([[start_run_end], adv.post_run_end[:-1]])
        rise = adv.top - starts
        k = np.maximum(np.rint(rise / stroke), 0.0)
        seen[0] &= idx[0] == 0  # a support whose first readings are missing may have been pushing already
        err = np.where(seen, rise - k * stroke, 0.0)
        thr = _stroke_threshold(layout, adv.n_top, n_starts)
        for m in np.flatnonzero(np.abs(err) > thr):
            first = min(int(run_ends[m]), int(adv.top_run_start[m]))
            out.append(_Stroke(j, idx[first], idx[adv.top_run_start[m]], idx[adv.post_start[m]],
                               float(err[m]), float(thr[m]), float(err[m] / (max(k[m], 1.0) * stroke))))
    return out
