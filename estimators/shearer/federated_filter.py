"""SINS/odometer/magnetometer filters of 003 as one sequential numba kernel: the adaptive federated filter (AFKF,
003 section 4) and the centralized filter it is compared with (003 section 5.2).

Both share one SINS (estimators.shearer.odometer_filter's mechanization, error states and odometer blocks):

* sub-filter 1, SINS/odometer (003 section 3.1): the error states of estimators.shearer.odometer_filter, the
  odometer plus motion-constraint velocity closing error, and the zero-velocity and zero-rate updates while the
  shearer stands;
* sub-filter 2, SINS/magnetometer (003 section 3.2): the yaw closing error z = yaw_SINS - yaw_mag with H on phi
  from estimators.nav.geomagnetic.yaw_h_phi and R estimated from its innovations over a sliding window (003 section
  4.2, estimators.kalman.adaptive_noise), readings whose field norm or dip disagree with the geomagnetic model left out.

Both carry the same error states (003's SINS/MAG sub-filter has the 15 SINS states; carrying the odometer
mounting and scale as well, unobserved by it, lets the fusion cover the whole state and keeps it exact: a
sub-filter of a subset would have to give those states back through their regression on the common ones, and
the process noise of the common states then leaks into them at every reset).

Each epoch (003 Fig. 3): time update of each sub-filter with Q / beta_i, their measurement updates, fusion (004
eqs. 10-11, estimators.kalman.fusion), sharing coefficients beta_i from the traces of the sub-filters' covariances
(003 section 4.3), feedback of the global estimate into the SINS and the odometer calibration, and the reset
x_i = 0, P_i = P_g / beta_i. With fusion at every epoch and this reset the fused estimate equals that of the
centralized filter whatever the beta_i (the information P_g^-1 is split, not copied;
tests/estimators/shearer/test_federated_filter.py); the fault tolerance comes from each sub-filter's own
measurement noise and disturbance test.

The centralized mode runs the same measurements on one filter with the nominal yaw noise and no
disturbance test: 003's CKF. 004's rail kinematics model gives sub-filter 2 position fixes instead of the
magnetometer (estimators.shearer.rail_fix_update: its fixes, fault detectors and isolation).
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from estimators.io.logformat import FLAG_COVARIANCE_REPAIRED, FLAG_ISOLATED
from estimators.kalman.adaptive_noise import window_push, window_r
from estimators.kalman.error_state import DP, N_STATES, PHI, QUAT
from estimators.kalman.fusion import fuse_kernel, sharing_kernel
from estimators.kalman.update import gated_update
from estimators.nav.geomagnetic import yaw_closing_error_nb
from estimators.nav.rotations import quat_mat
from estimators.shearer.odometer_filter import (
    P_LEVER,
    P_R_ALONG,
    P_R_LATERAL,
    P_R_VERTICAL,
    P_TAU_FORCE,
    apply_correction,
    keep_covariance,
    mechanize_epoch,
    odometer_aiding,
    transition,
)
from estimators.shearer.rail_fix_update import (
    N_BACK,
    DetectorState,
    new_snapshots,
    rail_fixes_at,
    restore_snapshot,
    take_snapshot,
)

SUB_ODOMETER, SUB_AIDING = 0, 1
N_SUB = 2

FEDERATED, CENTRALIZED = 0, 1

# Indices of the magnetometer parameter vector.
(M_DECLINATION, M_H_PHI, M_INTENSITY, M_INCLINATION, M_NORM_TOL, M_DIP_TOL, M_R_YAW, M_R_MIN, M_MIN_SAMPLES,
 M_GATE, M_CHECK, M_ADAPT, M_INVERSE_SHARING) = (0, 1, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14)
N_MAG_PARAMS = 15  # M_H_PHI takes 1..3

DELTA_POS, DELTA_ATT = slice(0, 3), slice(3, 6)
"""EpochOutput.sub_delta[j, i]: sub-filter i's x_i - x_g of the position and attitude error (ENU)."""
N_DELTA = 6

# Bits of the per-epoch magnetometer flag.
MAG_READ = 1  # a reading was available over the epoch
MAG_DISTURBED = 2  # its field norm or dip disagrees with the geomagnetic model (left out)
MAG_GATED = 4  # its normalized innovation exceeded the gate (left out)
MAG_USED = 8  # the yaw update was applied
SUB_INVALID = 16  # a sub-filter's covariance was unusable at the fusion (weight 0, restarted from the global)


class Sensors(NamedTuple):
    """The log as run_afkf reads it: the mechanization increments (steps per filter epoch; row 0 of t_mech at epoch
    mech_epoch, estimators.shearer.prepare.Mech), and per epoch j the odometer distance and mode
    (estimators.shearer.odometer_filter.run_filter) and mag_b (3,) the calibrated mean magnetometer reading over the
    epoch (NaN where none)."""

    steps: int
    mech_epoch: int
    t_mech: np.ndarray
    phi_b: np.ndarray
    dv_b: np.ndarray
    odo_dist: np.ndarray
    odo_mode: np.ndarray
    mag_b: np.ndarray


class Tuning(NamedTuple):
    """Process-noise densities, the parameter vectors of estimators.shearer.odometer_filter (P_*), of the
    magnetometer (M_*) and of the rail model's detectors (rail_fix_update.D_*)."""

    q_psd: np.ndarray
    params: np.ndarray
    mag_params: np.ndarray
    det_params: np.ndarray


class FilterState(NamedTuple):
    """The state run_afkf carries from pass to pass, updated in place: navigation, calibration, the sub-filters'
    covariances p_sub (N_SUB, N_STATES, N_STATES) and beta (N_SUB,) (initial_covariances), the nominal vector
    (zeros at the start), the yaw-noise window r_buf (W, 1, 1) with r_count[0] its count, the rail model's
    detectors (rail_fix_update.DetectorState)."""

    nav: np.ndarray
    cal: np.ndarray
    p_sub: np.ndarray
    beta: np.ndarray
    nominal: np.ndarray
    r_buf: np.ndarray
    r_count: np.ndarray
    det: DetectorState


class EpochOutput(NamedTuple):
    """run_afkf's output per epoch: navigation, calibration, one-sigma of the states, filter and magnetometer
    flags, beta (NaN in the centralized mode), the yaw R used, the yaw innovation, sub_delta (N_SUB, N_DELTA)."""

    nav: np.ndarray
    cal: np.ndarray
    sd: np.ndarray
    flags: np.ndarray
    mag_flags: np.ndarray
    beta: np.ndarray
    r_yaw: np.ndarray
    yaw_innov: np.ndarray
    sub_delta: np.ndarray


@nb.njit(cache=True)
def field_disturbed(mag_b, c_nb, intensity, inclination, norm_tol, dip_tol):
    """True when the reading's strength or dip (levelled with the SINS attitude) is off the model's."""
    b_n = c_nb @ mag_b
    norm = np.sqrt(np.sum(b_n * b_n))
    dip = np.arctan2(-b_n[2], np.hypot(b_n[0], b_n[1]))
    return abs(norm / intensity - 1.0) > norm_tol or abs(dip - inclination) > dip_tol


@nb.njit(cache=True)
def yaw_measurement(c_nb, mag_b, mag_params, r_yaw, n):
    """(z, H, R) of the yaw closing error (003 section 3.2): z = yaw_SINS - yaw_mag of the reading mag_b at the
    attitude c_nb (estimators.nav.geomagnetic.yaw_closing_error_nb), H on phi (M_H_PHI), R = r_yaw."""
    h = np.zeros((1, n))
    h[0, PHI.start:PHI.start + 3] = mag_params[M_H_PHI:M_H_PHI + 3]
    z = np.array([yaw_closing_error_nb(mag_b, c_nb, mag_params[M_DECLINATION])])
    return z, h, np.array([[r_yaw]])


@nb.njit(cache=True)
def mag_update(x, p, nav, mag_b, mag_params, r_yaw, r_buf, r_count, use_check):
    """Yaw closing-error update (003 section 3.2) of (x, P) with variance r_yaw, gated at M_GATE.

    Returns (flag bits, innovation, new window count). With use_check, a disturbed reading is left out
    and not put in the noise window; every other innovation goes into the window (also a gated one, so that R can
    grow to admit a real change)."""
    c_nb = quat_mat(nav[QUAT])
    if use_check and field_disturbed(mag_b, c_nb, mag_params[M_INTENSITY], mag_params[M_INCLINATION],
                                     mag_params[M_NORM_TOL], mag_params[M_DIP_TOL]):
        return MAG_READ | MAG_DISTURBED, np.nan, r_count
    z, h, r = yaw_measurement(c_nb, mag_b, mag_params, r_yaw, x.size)
    v = z[0] - (h @ x)[0]
    r_count = window_push(r_buf, r_count, np.array([v]), h @ p @ h.T)
    _nis, applied = gated_update(x, p, z, h, r, mag_params[M_GATE])
    return MAG_READ | (MAG_USED if applied else MAG_GATED), v, r_count


@nb.njit(cache=True)
def _share(m, beta):
    """A sub-filter's share of a covariance, m / beta (003 section 4.3); all of it for an excluded one (beta 0)."""
    return m / beta if beta > 0.0 else m.copy()


@nb.njit(cache=True)
def fuse_epoch(x_od, p_od, x_aiding, p_aiding, inverse_sharing):
    """Fusion (004 eqs. 10-11) and sharing coefficients (003 section 4.3) of the two sub-filters.

    Returns (x_g, P_g, beta (2,), valid (2,), ok); the sub-filters are reset in place (x_i = 0, P_i = P_g / beta_i;
    an invalid one restarts from P_g)."""
    xs = np.empty((N_SUB, N_STATES))
    ps = np.empty((N_SUB, N_STATES, N_STATES))
    xs[SUB_ODOMETER], ps[SUB_ODOMETER] = x_od, p_od
    xs[SUB_AIDING], ps[SUB_AIDING] = x_aiding, p_aiding
    x_g, p_g, valid, ok = fuse_kernel(xs, ps)
    beta = sharing_kernel(ps, valid, inverse_sharing)
    if ok:
        p_od[:, :] = _share(p_g, beta[SUB_ODOMETER])
        p_aiding[:, :] = _share(p_g, beta[SUB_AIDING])
        x_od[:] = 0.0
        x_aiding[:] = 0.0
    return x_g, p_g, beta, valid, ok


@nb.njit(cache=True)
def initial_covariances(p0, federated):
    """(P_sub (2, N_STATES, N_STATES), beta (2,)): the initial information split between the sub-filters (Carlson)
    or, in the centralized mode, P0 in slot SUB_ODOMETER (the one filter)."""
    beta = np.full(N_SUB, 1.0 / N_SUB)
    p_sub = np.empty((N_SUB, N_STATES, N_STATES))
    for i in range(N_SUB):
        p_sub[i] = _share(p0, beta[i]) if federated else p0
    return p_sub, beta


@nb.njit(cache=True)
def run_afkf(mode, j0, j1, sensors, fixes, results, tuning, state, out):
    """Run the federated (mode FEDERATED) or centralized (CENTRALIZED) filter over epochs j0+1 .. j1 of `sensors`
    (Sensors) with `tuning` (Tuning), from and into `state` (FilterState); stores per epoch into `out`
    (EpochOutput; sub_delta before the reset). The rail kinematics model's fixes (rail_fix_update.RailFixes) go to
    sub-filter 2 (in the centralized mode to the one filter) through the detectors, their statistics and whether
    each was applied into `results` (rail_fix_update.RailResults)."""
    steps, mech_epoch, t_mech, phi_b, dv_b, odo_dist, odo_mode, mag_b = sensors
    q_psd, params, mag_params, det_params = tuning
    nav, cal, p_sub, beta, nominal, r_buf, r_count, det = state
    r_vel = np.diag(np.array([params[P_R_LATERAL], params[P_R_ALONG], params[P_R_VERTICAL]]) ** 2)
    lever = params[P_LEVER:P_LEVER + 3].copy()
    federated = mode == FEDERATED
    adapt = federated and mag_params[M_ADAPT] > 0
    check = federated and mag_params[M_CHECK] > 0
    r_nominal = np.array([[mag_params[M_R_YAW]]])
    r_min = np.array([mag_params[M_R_MIN]])
    p_od, p_aid = p_sub[SUB_ODOMETER], p_sub[SUB_AIDING]
    x_od = np.zeros(N_STATES)
    x_aid = np.zeros(N_STATES)
    k_fix = np.searchsorted(fixes.epoch, j0 + 1)
    snaps = new_snapshots(state)  # at the start of each epoch with a rail fix to test (rail_fix_update.rail_fixes_at)
    snap_count = 0
    rejected_until = -1
    j = j0 + 1
    while j <= j1:
        if (k_fix < fixes.epoch.size and fixes.epoch[k_fix] == j and not fixes.trusted[k_fix]
                and k_fix > rejected_until):
            take_snapshot(snaps, snap_count % N_BACK, j, k_fix, state)
            snap_count += 1
        t_span, f_sum, disp, w_sum = mechanize_epoch(nav, cal, t_mech, phi_b, dv_b, (j - 1 - mech_epoch) * steps, steps)
        phi, qd = transition(nav, nominal, f_sum, t_span, q_psd, params[P_TAU_FORCE])
        p_od_pred = phi @ p_od @ phi.T + (_share(qd, beta[SUB_ODOMETER]) if federated else qd)
        p_od[:, :] = p_od_pred
        flag, _innov = odometer_aiding(x_od, p_od, odo_mode[j], nav, cal, disp, w_sum, lever, t_span,
                                       odo_dist[j] - odo_dist[j - 1], nominal, r_vel, params)
        # Sub-filter 2 (magnetometer and rail model); in the centralized mode its measurements go to the one filter.
        x2, p2 = (x_aid, p_aid) if federated else (x_od, p_od)
        p_aid_pred = p_aid
        if federated:
            p_aid_pred = phi @ p_aid @ phi.T + _share(qd, beta[SUB_AIDING])
            p_aid[:, :] = p_aid_pred
        r_yaw = window_r(r_buf, r_count[0], r_nominal, r_min, int(mag_params[M_MIN_SAMPLES]))[0, 0] if adapt \
            else mag_params[M_R_YAW]
        out.r_yaw[j] = r_yaw
        mflag = 0
        if np.all(np.isfinite(mag_b[j])):
            mflag, out.yaw_innov[j], r_count[0] = mag_update(x2, p2, nav, mag_b[j], mag_params, r_yaw, r_buf,
                                                              r_count[0], check)
        fix_flag, k_fix, rejected_until, back = rail_fixes_at(j, k_fix, rejected_until, fixes, results, x2, p2, nav,
                                                              lever, x_od, p_od, det_params, det, snaps, snap_count)
        flag |= fix_flag
        if back >= 0:
            j, k_fix = restore_snapshot(snaps, back, state)
            x_od[:] = 0.0
            x_aid[:] = 0.0
            snap_count = 0
            continue
        if det.isolated[0]:
            flag |= FLAG_ISOLATED
        if federated:
            if keep_covariance(x_od, p_od, p_od_pred) | keep_covariance(x_aid, p_aid, p_aid_pred):
                flag |= FLAG_COVARIANCE_REPAIRED
            x_pre_od = x_od.copy()
            x_pre_aid = x_aid.copy()
            x_g, p_g, beta_new, valid, ok = fuse_epoch(x_od, p_od, x_aid, p_aid, mag_params[M_INVERSE_SHARING] > 0)
            delta = np.zeros((N_SUB, N_DELTA))
            if not ok:  # nothing usable: drop this epoch's updates and restart both from the prediction
                p_od[:, :] = p_od_pred
                p_aid[:, :] = p_aid_pred
                x_od[:] = 0.0
                x_aid[:] = 0.0
                flag |= FLAG_COVARIANCE_REPAIRED
                p_g = p_od_pred
            else:
                beta[:] = beta_new
                if not valid.all():
                    mflag |= SUB_INVALID
                for k in range(3):
                    for i, x_pre in ((SUB_ODOMETER, x_pre_od), (SUB_AIDING, x_pre_aid)):
                        delta[i, DELTA_POS.start + k] = x_pre[DP.start + k] - x_g[DP.start + k]
                        delta[i, DELTA_ATT.start + k] = x_pre[PHI.start + k] - x_g[PHI.start + k]
                apply_correction(nav, cal, x_g)
            out.sub_delta[j] = delta
            out.beta[j] = beta
            out.sd[j] = np.sqrt(np.maximum(np.diag(p_g), 0.0))
        else:
            if keep_covariance(x_od, p_od, p_od_pred):
                flag |= FLAG_COVARIANCE_REPAIRED
            apply_correction(nav, cal, x_od)
            x_od[:] = 0.0
            out.beta[j] = np.nan
            out.sd[j] = np.sqrt(np.diag(p_od))
        out.nav[j] = nav
        out.cal[j] = cal
        out.flags[j] = flag
        out.mag_flags[j] = mflag
        j += 1
