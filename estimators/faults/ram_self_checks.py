"""Self-checks of each push-ram sensor on its own; the readings they flag are left out of the stroke check
(estimators.faults.ram_strokes) and the neighbour check (estimators.faults.ram_neighbours).

sigma = sqrt(noise^2 + resolution^2 / 12) is the one-sigma error of a reading.

* dropout      readings flagged invalid (valid = 0), NaN or missing: the window is exact.
* noise_burst  the robust scatter of the reading-to-reading differences dx in a centred window of
               BURST_WINDOW readings, 1.4826 median|dx - median dx| / sqrt(2), exceeds BURST_RATIO sigma, and the
               readings' scatter about their median of three confirms it: median|r| / MED3_MAD over the window
               exceeds MED3_RATIO sigma, r = x[k] - median(x[k-1], x[k], x[k+1]). The first medians ignore a ram's
               short steps (under half of any window) and a drift; r vanishes wherever the readings are monotone,
               so a ram moving at its cylinder's speed (ramps, in a staircase of pushes filling a window) raises
               only the first. For white noise of sigma, median|r| = MED3_MAD sigma; at a burst's onset (half a
               window) r's median is not yet over MED3_RATIO sigma: the burst is confirmed (t_detect) once r's window
               is about three quarters in it, and dated from where dx's scatter rose.
* stuck        a run of identical readings that the noise makes improbable: a reading stays in the quantum of
               its true value with probability at most p = 2 Phi(resolution / (2 noise)) - 1, so a run of
               L = max(FLAT_MIN_RUN, 1 + log(FLAT_FALSE_ALARM) / log p) equal readings flags the support from
               the run's first reading (L = 30 for noise = resolution, 6 for 004's 0.02 m sensor). A sensor
               much finer than its quantum (L > FLAT_MAX_RUN) reads constant at rest anyway: then the neighbour
               check (b) finds a stuck ram once its neighbours move and it does not follow; its frozen readings
               are then left out as well and (a) and (b) run again (up to STUCK_PASSES times,
               estimators.faults.ram_checks).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import norm

from estimators.faults.ram_findings import Finding
from estimators.faults.ram_grid import _centred_median, _runs, _runs_1d
from estimators.faults.ram_layout import RamLayout

BURST_WINDOW = 31
"""Readings in the centred window of the scatter estimate (noise_burst)."""
MED3_MAD = 0.3138
"""Median |x[k] - median(x[k-1], x[k], x[k+1])| of unit white Gaussian noise (Monte Carlo, three runs of 2e7
samples: 0.3136-0.3140; a test checks it)."""
MED3_RATIO = 4.0
"""The scatter about the median of three, over the reading noise sigma, that confirms a noise burst."""
BURST_RATIO = 4.0
"""A window's robust scatter over the reading noise sigma that flags a noise burst."""
FLAT_FALSE_ALARM = 1e-12
"""Probability of a run of equal readings of a healthy sensor at rest that still counts as stuck."""
FLAT_MIN_RUN = 5
"""Fewest equal readings that flag a stuck sensor, however noisy."""
FLAT_MAX_RUN = 600
"""Above this run length the sensor is too fine for its quantum to tell stuck from at rest by flatness."""


def _flat_run(layout: RamLayout) -> int | None:
    """Equal readings that flag a stuck sensor (None: flatness tells nothing for this sensor)."""
    noise, q = layout.noise_m, layout.resolution_m
    if noise <= 0:
        return None
    p = 0.0 if q <= 0 else 2.0 * norm.cdf(q / (2.0 * noise)) - 1.0
    if p <= 0:
        return FLAT_MIN_RUN
    if p >= 1:
        return None
    run = max(FLAT_MIN_RUN, 1 + math.ceil(math.log(FLAT_FALSE_ALARM) / math.log(p)))
    return run if run <= FLAT_MAX_RUN else None


def _self_checks(tg: np.ndarray, x: np.ndarray, layout: RamLayout) -> tuple[list[Finding], np.ndarray]:
    """Dropout, noise-burst and stuck findings, and the mask of the samples they make unusable."""
    dt = float(np.median(np.diff(tg)))
    findings: list[Finding] = []
    bad = ~np.isfinite(x)
    for j, a, b in zip(*_runs(bad)):
        findings.append(Finding(int(j), int(j), "dropout", tg[a], tg[b], tg[a], tg[b] - tg[a] + dt,
                                float(b - a + 1), 1.0, "samples"))
    mask = bad.copy()
    sigma = layout.sigma_m
    burst_thr = max(BURST_RATIO * sigma, 1e-12)
    flat_run = _flat_run(layout)
    half = BURST_WINDOW // 2
    for j in range(x.shape[1]):
        idx = np.flatnonzero(~bad[:, j])
        if idx.size < 2:
            continue
        r = x[idx, j]
        d = np.diff(r)
        if idx.size > BURST_WINDOW:
            sd = 1.4826 * _centred_median(np.abs(d - _centred_median(d, BURST_WINDOW)), BURST_WINDOW) / math.sqrt(2.0)
            med3 = np.median(np.stack([r[:-2], r[1:-1], r[2:]]), axis=0)
            sd_med3 = _centred_median(np.abs(r[1:-1] - med3), BURST_WINDOW) / MED3_MAD  # of readings 1 .. n - 2
            hot = sd > burst_thr
            confirmed = np.flatnonzero(hot & (np.append(sd_med3, sd_med3[-1]) > MED3_RATIO * sigma))
            noisy = np.zeros(idx.size, bool)
            noisy[:-1] |= hot
            noisy[1:] |= hot
            for a, b in _runs_1d(noisy, gap=half):
                first = confirmed[(confirmed >= a) & (confirmed <= b)]
                if not first.size:
                    continue
                s = sd[a:min(b, d.size - 1) + 1]
                value = math.sqrt(max(float(np.median(s)) ** 2 - sigma ** 2, 0.0))
                t_detect = tg[idx[min(max(a, first[0]) + half, idx.size - 1)]]
                findings.append(Finding(j, j, "noise_burst", tg[idx[a]], tg[idx[b]], t_detect, value,
                                        float(s.max()), burst_thr, "m"))
                mask[idx[max(a - half, 0):b + half + 1], j] = True
        if flat_run is not None:
            for a, b in _runs_1d(d == 0):
                if b - a + 2 >= flat_run:
                    findings.append(Finding(j, j, "stuck", tg[idx[a]], tg[idx[b + 1]],
                                            tg[idx[a + flat_run - 1]], float(r[a]), float(b - a + 2),
                                            float(flat_run), "samples"))
                    mask[idx[a:b + 2], j] = True
    return findings, mask
