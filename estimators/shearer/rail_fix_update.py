"""The rail kinematics model's position fixes inside the federated filter kernel (004; estimators.shearer.
federated_filter.run_afkf), numba: the fix's measurement (004 eq. 9: the body point's position fix,
estimators.kalman.measurements.position_fix), the three fault detectors on its innovation (004 section IV,
eqs. 15-24) and the isolation of the model while a fault holds, and the snapshots the filter goes back to when
the fading SPRT raises a fault.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from estimators.faults.detectors import (
    FSPRT_LAMBDA,
    chi2_dual_state,
    chi2_residual,
    fsprt_update,
    hysteresis,
)
from estimators.io.logformat import FLAG_POSITION, FLAG_SKIPPED
from estimators.kalman.error_state import DP
from estimators.kalman.measurements import position_fix
from estimators.kalman.update import joseph_update

# Indices of the detector parameter vector, and of the detector statistics per fix.
D_FADING, D_T_ON, D_T_OFF, D_CHI2, D_CHI2_DUAL, D_ISOLATE_BY, D_CAP, D_ARM, D_WINDOW, D_SD_FLOOR = range(10)
N_DET_PARAMS = 10
DET_RESIDUAL, DET_DUAL, DET_FSPRT = range(3)
"""Detectors (004 section IV): residual chi-square, dual-state chi-square, fading SPRT; D_ISOLATE_BY names the
one whose fault flag keeps the rail model's fixes out (-1: none)."""
DET_DOF = 1
"""The residual chi-square and the fading SPRT test one component of a rail fix's innovation (rail_fix_update);
the dual-state chi-square compares the position, DUAL_DOF = 3 components."""
DUAL_DOF = 3
N_BACK = 16
"""Rail fixes the filter can go back over when the fading SPRT raises a fault."""
COUNT_TESTED, COUNT_BUFFERED = 0, 1
"""DetectorState.counts: the fixes tested in this pass, the fixes' innovations in the ring buffer."""
N_COUNTS = 2


class RailFixes(NamedTuple):
    """The rail model's fixes of a pass, in epoch order (see rail_fix_update)."""

    epoch: np.ndarray  # (F,) filter epoch
    llh: np.ndarray  # (F, 3) predicted point, lat/lon/h
    r: np.ndarray  # (F, 3, 3) ENU covariance
    advance: np.ndarray  # (F, 3) unit advance direction in n
    var_floor: np.ndarray  # (F,)
    trusted: np.ndarray  # (F,) bool: a surveyed face end, applied without the detectors


class RailResults(NamedTuple):
    """Per rail fix of a pass: the detector statistics (F, 3) (NaN: not tested) and whether it was applied."""

    stats: np.ndarray
    applied: np.ndarray


class DetectorState(NamedTuple):
    """The detectors' state, carried from pass to pass: the fading SPRT's, its fault flag isolated[0], the
    counts (COUNT_*) and the ring buffer (W, 2) of the last applied fixes' v^2 and h P h^T + R."""

    fsprt: np.ndarray
    isolated: np.ndarray
    counts: np.ndarray
    buf: np.ndarray


class Snapshots(NamedTuple):
    """The filter state at the start of the last N_BACK epochs with a rail fix to test (ring slots): epoch,
    fix index, navigation, calibration, sub-filter covariances, beta, nominal vector, detector buffer and count."""

    j: np.ndarray
    k: np.ndarray
    nav: np.ndarray
    cal: np.ndarray
    p_sub: np.ndarray
    beta: np.ndarray
    nominal: np.ndarray
    buf: np.ndarray
    buf_count: np.ndarray


@nb.njit(cache=True)
def rail_fix_update(x, p, nav, lever, fixes, k, x_other, p_other, det_params, det, stats):
    """Fix k of `fixes` (RailFixes) with the three detectors on its innovation (004 eqs. 15-24): residual
    chi-square, dual-state chi-square against the other sub-filter (x_other, p_other), fading SPRT (with its
    hysteresis in det.isolated[0]). stats[:] = the three statistics. Applied unless the isolating detector holds a
    fault; returns True when applied. A trusted fix (a surveyed face end) is applied without the detectors.

    The residual chi-square and the fading SPRT test the innovation's component v along the fix's advance
    direction (unit, n): the rail model's faults are in the push-ram strokes, and a stroke moves a predicted
    point along that direction only (004's scalar form, eqs. 18-19). Its variance (004 eq. 16's sigma_k^2) is
    kappa (h P h^T + R): with det_params[D_WINDOW] > 0, kappa = sum v^2 / sum (h P h^T + R) over the last
    D_WINDOW applied fixes (det.buf), sigma_k^2 floored at D_SD_FLOOR^2; before the window is full, and with
    D_WINDOW = 0, kappa = 1. A rail-model fix comes from the filter's own previous pass: its error and the
    filter's are largely the same error, so v^2 falls far below h P h^T + R (seed004: 0.012 m against 0.07 m rms
    across the face; R - 2 cov(fix error, filter error) is negative, and a window estimate of it as 003's R is a
    small difference of large numbers). A fault would hide below the model's variance. With kappa the variance
    still follows P where it grows (a stretch without fixes).

    var_floor: a further floor of sigma_k^2, for the part of a fix's error the filter does not share: the ram
    stroke's, measured anew at each pass, and the face survey's. The smoothed survey's error (0.021 m) is
    correlated along the face over +-14.5 m (estimators.shearer.face_line), and the filter, riding the INS, does
    not follow its swings; in a calm stretch of the survey kappa takes sigma_k down to D_SD_FLOOR (5 mm), where a
    4 cm swing over three chutes read as a fault (seed004 trials 9 and 10)."""
    z, h, r = position_fix(nav, lever, fixes.llh[k], fixes.r[k], x.size)
    if fixes.trusted[k]:
        joseph_update(x, p, z, h, r)
        stats[:] = np.nan
        return True
    advance, counts, isolated = fixes.advance[k], det.counts, det.isolated
    v = z - h @ x
    ha = advance @ h
    v_a = np.array([advance @ v])
    s_model = ha @ p @ ha + advance @ r @ advance
    s_a = np.array([[s_model]])
    window = int(det_params[D_WINDOW])
    if window > 0 and counts[COUNT_BUFFERED] >= window:
        kappa = np.sum(det.buf[:, 0]) / np.sum(det.buf[:, 1])
        s_a[0, 0] = max(kappa * s_model, det_params[D_SD_FLOOR] ** 2, fixes.var_floor[k])
    stats[DET_RESIDUAL] = chi2_residual(v_a, s_a)
    # The detectors are armed once the aiding sub-filter has taken the pass's first fixes (before, the fading SPRT
    # only shows what it would say, from a copy of its state; a fault flag raised earlier holds).
    counts[COUNT_TESTED] += 1
    armed = counts[COUNT_TESTED] > det_params[D_ARM]
    state = det.fsprt if armed else det.fsprt.copy()
    lam = min(fsprt_update(state, v_a, s_a, det_params[D_FADING]), det_params[D_CAP])
    state[FSPRT_LAMBDA] = lam  # capped: a large fault must not delay the readmission by its size
    stats[DET_FSPRT] = lam
    if armed:
        flag = hysteresis(isolated[0], lam, det_params[D_T_ON], det_params[D_T_OFF])
        # Readmitted only on a fix that passes the residual test as well (chi-square and SPRT combined, 004 ref
        # [23]): when a large fault shrinks, the fix no longer looks like the fading mean and lambda drops below
        # T0 in one step, while the fix is still far off.
        isolated[0] = flag or (isolated[0] and stats[DET_RESIDUAL] > det_params[D_CHI2])
    # The dual-state test compares the estimate with this fix (a trial update) against the one without it.
    x_try, p_try = x.copy(), p.copy()
    joseph_update(x_try, p_try, z, h, r)
    stats[DET_DUAL] = chi2_dual_state(x_try[DP], p_try[DP, DP].copy(), x_other[DP], p_other[DP, DP].copy())
    by = int(det_params[D_ISOLATE_BY])
    reject = (by == DET_FSPRT and isolated[0]) or (armed and (
        (by == DET_RESIDUAL and stats[DET_RESIDUAL] > det_params[D_CHI2])
        or (by == DET_DUAL and stats[DET_DUAL] > det_params[D_CHI2_DUAL])))
    if reject:
        return False
    if armed and window > 0:
        det.buf[counts[COUNT_BUFFERED] % window] = v_a[0] ** 2, s_model
        counts[COUNT_BUFFERED] += 1
    x[:] = x_try
    p[:, :] = p_try
    return True


@nb.njit(cache=True)
def rail_fixes_at(j, k_fix, rejected_until, fixes, results, x, p, nav, lever, x_other, p_other, det_params,
                  det, snaps, snap_count):
    """The rail fixes of epoch j from fix k_fix on (rail_fix_update) into (x, p); a fix at or before
    rejected_until, rolled back over, is left out. Returns (filter flag bits, next k_fix, rejected_until, the
    snapshot slot to go back to (-1: none)): when the fading SPRT raises a fault, the fixes of the rise that led to
    it were already applied and have bent the estimate (a soft fault is partly absorbed); the filter goes back to
    before them (onset_slot) and goes on without them, and with the trusted fixes among them again."""
    flag, back = 0, -1
    while k_fix < fixes.epoch.size and fixes.epoch[k_fix] == j:
        if k_fix <= rejected_until and not fixes.trusted[k_fix]:  # rolled back: already tested, left out
            results.applied[k_fix] = 0
            flag |= FLAG_SKIPPED
            k_fix += 1
            continue
        was = det.isolated[0]
        if rail_fix_update(x, p, nav, lever, fixes, k_fix, x_other, p_other, det_params, det,
                           results.stats[k_fix]):
            results.applied[k_fix] = 1
            flag |= FLAG_POSITION
        else:
            results.applied[k_fix] = 0
            flag |= FLAG_SKIPPED
        if det.isolated[0] and not was and int(det_params[D_ISOLATE_BY]) == DET_FSPRT:
            back = onset_slot(snaps.k, snap_count, results.stats, k_fix)
            rejected_until = k_fix
        k_fix += 1
    return flag, k_fix, rejected_until, back


@nb.njit(cache=True)
def new_snapshots(state):
    """Empty Snapshots for a filter state (estimators.shearer.federated_filter.FilterState)."""
    return Snapshots(np.full(N_BACK, -1, np.int64), np.full(N_BACK, -1, np.int64),
                     np.zeros((N_BACK, state.nav.size)), np.zeros((N_BACK, state.cal.size)),
                     np.zeros((N_BACK,) + state.p_sub.shape), np.zeros((N_BACK, state.beta.size)),
                     np.zeros((N_BACK, state.nominal.size)), np.zeros((N_BACK,) + state.det.buf.shape),
                     np.zeros(N_BACK, np.int64))


@nb.njit(cache=True)
def take_snapshot(snaps, slot, j, k, state):
    """The state at the start of epoch j, whose first fix to test is k, into ring slot `slot`."""
    snaps.j[slot], snaps.k[slot] = j, k
    snaps.nav[slot], snaps.cal[slot], snaps.p_sub[slot] = state.nav, state.cal, state.p_sub
    snaps.beta[slot], snaps.nominal[slot] = state.beta, state.nominal
    snaps.buf[slot], snaps.buf_count[slot] = state.det.buf, state.det.counts[COUNT_BUFFERED]


@nb.njit(cache=True)
def restore_snapshot(snaps, slot, state):
    """The state of ring slot `slot` back into `state`; returns (its epoch, its first fix)."""
    state.nav[:], state.cal[:], state.p_sub[:] = snaps.nav[slot], snaps.cal[slot], snaps.p_sub[slot]
    state.beta[:], state.nominal[:] = snaps.beta[slot], snaps.nominal[slot]
    state.det.buf[:], state.det.counts[COUNT_BUFFERED] = snaps.buf[slot], snaps.buf_count[slot]
    return snaps.j[slot], snaps.k[slot]


@nb.njit(cache=True)
def onset_slot(snap_k, snap_count, fix_stats, k_now):
    """Ring slot of the stored fix at which the fault began as the fading SPRT saw it (the change-time estimate
    of a CUSUM): the fix before which the statistic was at its lowest over the stored fixes, the latest of equal
    lows; -1 when there is nothing to go back over. A fix without a statistic (a trusted survey fix) is passed
    over to the last one tested before it."""
    best, best_k, low = -1, -1, np.inf
    for i in range(min(snap_count, N_BACK)):
        k = snap_k[i]
        if k >= k_now:
            continue
        before = 0.0
        for m in range(k - 1, -1, -1):
            if np.isfinite(fix_stats[m, DET_FSPRT]):
                before = fix_stats[m, DET_FSPRT]
                break
        if before < low or (before == low and k > best_k):
            best, best_k, low = i, k, before
    return best
