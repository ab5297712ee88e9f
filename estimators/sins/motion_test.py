"""Is the IMU standing? The test of a stationary alignment's innovations (estimators.sins.fine_alignment).

The zero-velocity and zero-rate innovations of a standing IMU are white with the covariance the filter predicts;
their normalized squares (NIS) averaged over MOTION_WINDOW_S windows are tested against the chi-square bound of
false-alarm rate MOTION_FALSE_ALARM. A shearer that moves (starts hauling, cuts, turns) fails the test:
estimators.sins.fine_alignment.fine_align raises AlignmentError naming the time, or with on_motion="flag" returns
the result with `motion_t` set.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2

MOTION_WINDOW_S = 10.0
"""Length of the windows [s] over which the normalized innovations are averaged for the motion test."""
MOTION_FALSE_ALARM = 1e-6
"""False-alarm probability per window of the motion test (chi-square of a standing, consistent filter)."""
MOTION_SETTLE_S = 20.0
"""The first seconds, while the 3-5 deg start errors are being removed, are not tested."""


def motion_test(nis: np.ndarray, dof: int, T: float) -> float | None:
    """Start [s] of the first MOTION_WINDOW_S window (after MOTION_SETTLE_S) whose summed normalized innovation
    squared exceeds the chi-square bound of MOTION_FALSE_ALARM, or None."""
    n = max(1, round(MOTION_WINDOW_S / T))
    start = round(MOTION_SETTLE_S / T)
    k = (nis.size - start) // n
    if k < 1:
        return None
    sums = nis[start: start + k * n].reshape(k, n).sum(axis=1)
    bad = np.flatnonzero(sums > chi2.isf(MOTION_FALSE_ALARM, dof * n))
    return None if bad.size == 0 else float((start + bad[0] * n) * T)
