"""Levels of a push-ram record: the swings of the reading and the plateaus on either side of an event.

A ram's reading is a staircase: it rises in one or several partial strokes while the support pushes its pan and
falls by about a stroke when the support advances. The CPOEM advance (estimators.shearer.cpoem.ram_stroke) and the
per-support stroke check (estimators.faults.ram_strokes) both measure steps of that staircase between two plateau
levels. A level is taken next to the event that bounds its plateau (a drop, the start or end of the record), from
the readings within a tolerance of it, cut at the most significant level change among them, so that a short last
step of a push is neither averaged with the pause before it nor lost.
"""

from __future__ import annotations

import numba as nb
import numpy as np

LEVEL_SAMPLES = 15
"""Readings next to an event whose median is the level on that side (the sensor checks' default)."""
CHANGE_SIGMAS = 4.5
"""Two-sample statistic of a level change inside the readings next to an event that shortens the plateau."""


def level_tolerance(sigma_m: float) -> float:
    """Plateau tolerance of a sensor with reading noise sigma_m: readings within this of a level belong to it
    (6 sigma, at least 5 mm: the twin's rams jitter by millimetres as the pans settle)."""
    return max(6.0 * sigma_m, 0.005)


def change_sigma(sigma_m: float) -> float:
    """Sigma of the level-change test: the reading noise, or a sixth of the 5 mm plateau tolerance of a precise
    sensor."""
    return max(sigma_m, 0.005 / 6.0)


@nb.njit(cache=True)
def swings(x, threshold):
    """(trough, peak) indices of the up-swings of x that a swing detector confirms: a swing ends when x turns back
    by more than `threshold` from its extreme, so noise below the threshold makes no swing."""
    lo_i = hi_i = 0
    rising = True
    out = []
    for i in range(1, x.size):
        if rising:
            if x[i] > x[hi_i]:
                hi_i = i
            elif x[hi_i] - x[i] > threshold:
                if x[hi_i] - x[lo_i] > threshold:
                    out.append((lo_i, hi_i))
                rising, lo_i = False, i
        else:
            if x[i] < x[lo_i]:
                lo_i = i
            elif x[i] - x[lo_i] > threshold:
                rising, hi_i = True, i
    if rising and x[hi_i] - x[lo_i] > threshold:
        out.append((lo_i, hi_i))
    return out


def side_level(r: np.ndarray, i: int, step: int, tol: float, sigma: float, samples: int = LEVEL_SAMPLES,
               min_run: int = 1) -> tuple[float, int, int]:
    """Level of the plateau next to an event, from reading i away from it (step -1: backwards).

    The run of readings within tol of each other (two passes: from reading i, then from the median of its
    run) bounds the plateau; of its first `samples` readings those before the most significant level
    change (a two-sample test of CHANGE_SIGMAS with reading noise sigma, repeated on the part next to the event)
    make the level, at least min_run of them (more than one where a reading's own noise may reach CHANGE_SIGMAS:
    one reading cannot tell a last short step from an outlier). Returns (median level, readings used, index of
    the last reading of the whole run)."""
    seg = r[i:] if step > 0 else r[i::-1]
    ref = seg[0]
    for _ in range(2):  # from the reading next to the event, then from the median of its run
        off = np.flatnonzero(np.abs(seg - ref) > tol)
        end = max(int(off[0]) if off.size else seg.size, 1)
        ref = float(np.median(seg[:min(end, samples)]))
    w = seg[:min(end, samples)]
    n = w.size
    while n > min_run:
        c = np.arange(min_run, n)
        head = np.cumsum(w[:n])[min_run - 1:-1]
        gap = np.abs(head / c - (w[:n].sum() - head) / (n - c))
        stat = gap / (sigma * np.sqrt(1.0 / c + 1.0 / (n - c)))
        k = int(np.argmax(stat))
        if stat[k] < CHANGE_SIGMAS:
            break
        n = int(c[k])
    return float(np.median(w[:n])), n, i + step * (end - 1)


def drop_levels(r: np.ndarray, lo: int, hi: int, tol: float, sigma: float, samples: int = LEVEL_SAMPLES,
                ramp_band: float = 0.0, min_run: int = 1,
                top_samples: int = 0) -> tuple[int, int, float, float, int, int, int, int]:
    """The plateaus around the drop of r from reading lo (its top) to reading hi (its bottom): the last reading
    before it and the first after it (b, a), the levels before and after (side_level), the readings each used,
    the first reading of the plateau before and the last of the plateau after (each level of at least min_run
    readings, side_level; the level before from at most top_samples readings when given, else `samples`).

    b and a bound the ramp between the plateaus: from the first reading below half-way, back up the ramp while each
    reading is more than tol below the one before, and on down it likewise. With ramp_band > 0 a reading more than
    ramp_band below the level at lo (above the level at hi) is on the ramp too: a noisy sensor's readings on a slow
    ramp step by less than its tol."""
    mid = 0.5 * (r[lo] + r[hi])
    j = lo + int(np.argmax(r[lo:hi + 1] < mid))
    top0 = side_level(r, lo, -1, tol, sigma, samples, min_run)[0] - ramp_band if ramp_band > 0 else -np.inf
    bottom0 = side_level(r, hi, 1, tol, sigma, samples, min_run)[0] + ramp_band if ramp_band > 0 else np.inf
    b, a = j - 1, j
    while b > lo and (r[b] < top0 or r[b - 1] - r[b] > tol):
        b -= 1
    while a < hi and (r[a] > bottom0 or r[a] - r[a + 1] > tol):
        a += 1
    top, n_top, top_start = side_level(r, b, -1, tol, sigma, top_samples or samples, min_run)
    post, n_post, post_end = side_level(r, a, 1, tol, sigma, samples, min_run)
    return b, a, top, post, n_top, n_post, top_start, post_end
