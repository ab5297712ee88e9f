"""SINS/odometer/magnetometer filters of 003 as one sequential numba kernel: the adaptive federated filter (AFKF,
003 section 4) and the centralized filter it is compared with (003 section 5.2).

Both share one SINS (estimators.shearer.odometer_filter's mechanization, error states and odometer blocks):

* sub-filter 1, SINS/odometer (003 section 3.1): the error states of estimators.shearer.odometer_filter, the odometer plus
  motion-constraint velocity closing error, and the zero-velocity and zero-rate updates while the shearer stands;
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
centralized filter whatever the beta_i (the information P_g^-1 is split, not copied; tests/estimators/shearer/test_federated_filter.py);
the fault tolerance comes from each sub-filter's own measurement noise and disturbance test.

The centralized mode runs the same measurements on one filter with the nominal yaw noise and no
disturbance test: 003's CKF.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from estimators.faults.detectors import (
    FSPRT_LAMBDA,
    chi2_dual_state,
    chi2_residual,
    fsprt_update,
    hysteresis,
)
from estimators.io.logformat import (
    FLAG_COVARIANCE_REPAIRED,
    FLAG_ISOLATED,
    FLAG_POSITION,
    FLAG_SKIPPED,
    FLAG_VELOCITY,
    FLAG_ZUPT,
)
from estimators.kalman.adaptive_noise import window_push, window_r
from estimators.kalman.fusion import fuse_kernel, sharing_kernel
from estimators.kalman.update import joseph_update
from estimators.nav.geomagnetic import yaw_closing_error_nb
from estimators.nav.rotations import quat_mat
from estimators.shearer.odometer_filter import (
    CAL_SCALE,
    DP,
    N_STATES,
    ODO_SCALE,
    P_LEVER,
    P_R_ALONG,
    P_R_LATERAL,
    P_R_VERTICAL,
    P_R_ZARU,
    P_R_ZUPT,
    P_TAU_FORCE,
    P_TAU_FWD,
    PHI,
    QUAT,
    apply_correction,
    fix_measurement,
    keep_covariance,
    mechanize_epoch,
    odometer_update,
    stand_update,
    transition,
)

SUB_ODOMETER, SUB_AIDING = 0, 1
N_SUB = 2

FEDERATED, CENTRALIZED = 0, 1

# Indices of the magnetometer parameter vector.
(M_DECLINATION, M_H_PHI, M_INTENSITY, M_INCLINATION, M_NORM_TOL, M_DIP_TOL, M_R_YAW, M_R_MIN, M_MIN_SAMPLES,
 M_GATE, M_CHECK, M_ADAPT, M_INVERSE_SHARING) = (0, 1, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14)
N_MAG_PARAMS = 15  # M_H_PHI takes 1..3

# Indices of the detector parameter vector, and of the detector statistics per fix.
D_FADING, D_T_ON, D_T_OFF, D_CHI2, D_CHI2_DUAL, D_ISOLATE_BY, D_CAP, D_ARM, D_WINDOW, D_SD_FLOOR = range(10)
N_DET_PARAMS = 10
DET_RESIDUAL, DET_DUAL, DET_FSPRT = range(3)
"""Detectors (004 section IV): residual chi-square, dual-state chi-square, fading SPRT; D_ISOLATE_BY names the
one whose fault flag keeps the rail model's fixes out (-1: none)."""
DET_DOF = 1
"""The residual chi-square and the fading SPRT test one component of a rail fix's innovation (_fix_update); the
dual-state chi-square compares the position, DUAL_DOF = 3 components."""
DUAL_DOF = 3
N_BACK = 16
"""Rail fixes the filter can go back over when the fading SPRT raises a fault."""

# Bits of the per-epoch magnetometer flag.
MAG_READ = 1  # a reading was available over the epoch
MAG_DISTURBED = 2  # its field norm or dip disagrees with the geomagnetic model (left out)
MAG_GATED = 4  # its normalized innovation exceeded the gate (left out)
MAG_USED = 8  # the yaw update was applied
SUB_INVALID = 16  # a sub-filter's covariance was unusable at the fusion (weight 0, restarted from the global)


@nb.njit(cache=True)
def field_disturbed(mag_b, c_bn, intensity, inclination, norm_tol, dip_tol):
    """True when the reading's strength or dip (levelled with the SINS attitude) is off the model's."""
    b_n = c_bn @ mag_b
    norm = np.sqrt(np.sum(b_n * b_n))
    dip = np.arctan2(-b_n[2], np.hypot(b_n[0], b_n[1]))
    return abs(norm / intensity - 1.0) > norm_tol or abs(dip - inclination) > dip_tol


@nb.njit(cache=True)
def mag_update(x, p, nav, mag_b, mag_params, r_yaw, r_buf, r_count, use_check):
    """Yaw closing-error update (003 section 3.2) of (x, P) with variance r_yaw.

    Returns (flag bits, innovation, new window count). With use_check, a disturbed reading is left out
    and not put in the noise window; every other innovation goes into the window (also a gated one, so that R can
    grow to admit a real change)."""
    c_bn = quat_mat(nav[QUAT])
    if use_check and field_disturbed(mag_b, c_bn, mag_params[M_INTENSITY], mag_params[M_INCLINATION],
                                     mag_params[M_NORM_TOL], mag_params[M_DIP_TOL]):
        return MAG_READ | MAG_DISTURBED, np.nan, r_count
    h = np.zeros((1, x.size))
    h[0, PHI.start:PHI.start + 3] = mag_params[M_H_PHI:M_H_PHI + 3]
    z = np.array([yaw_closing_error_nb(mag_b, c_bn, mag_params[M_DECLINATION])])
    v = z[0] - (h @ x)[0]
    hph = h @ p @ h.T
    r_count = window_push(r_buf, r_count, np.array([v]), hph)
    if v * v > mag_params[M_GATE] * (hph[0, 0] + r_yaw):
        return MAG_READ | MAG_GATED, v, r_count
    joseph_update(x, p, z, h, np.array([[r_yaw]]))
    return MAG_READ | MAG_USED, v, r_count


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
    """(P_sub (2, N_STATES, N_STATES), beta (2,)): the initial information split between the sub-filters (Carlson) or, in
    the centralized mode, P0 in slot SUB_ODOMETER (the one filter)."""
    beta = np.full(N_SUB, 1.0 / N_SUB)
    p_sub = np.empty((N_SUB, N_STATES, N_STATES))
    for i in range(N_SUB):
        p_sub[i] = _share(p0, beta[i]) if federated else p0
    return p_sub, beta


@nb.njit(cache=True)
def _fix_update(x, p, nav, cal, lever, fix_llh, fix_r, scale_h, advance, var_floor, trusted, x_other, p_other,
                det_params, fsprt, isolated, counters, det_buf, stats):
    """Position fix of the rail kinematics model (004 eq. 9) with the three detectors on its innovation (004
    eqs. 15-24): residual chi-square, dual-state chi-square against the other sub-filter, fading SPRT (with its
    hysteresis in isolated[0]). stats[:] = the three statistics. Applied unless the isolating detector holds a
    fault; returns True when applied. A `trusted` fix (a surveyed face end) is applied without the detectors.
    counters[1] counts the fixes tested in this pass, counters[2] the fixes in the ring buffer det_buf (W, 2).

    The residual chi-square and the fading SPRT test the innovation's component v along the fix's `advance`
    direction (unit, n): the rail model's faults are in the push-ram strokes, and a stroke moves a predicted
    point along that direction only (004's scalar form, eqs. 18-19). Its variance (004 eq. 16's sigma_k^2) is
    kappa (h P h^T + R): with det_params[D_WINDOW] > 0, kappa = sum v^2 / sum (h P h^T + R) over the last
    D_WINDOW applied fixes (det_buf holds their v^2 and h P h^T + R), sigma_k^2 floored at D_SD_FLOOR^2; before
    the window is full, and with D_WINDOW = 0, kappa = 1. A rail-model fix comes from the filter's own previous
    pass: its error and the filter's are largely the same error, so v^2 falls far below h P h^T + R (seed004:
    0.012 m against 0.07 m rms across the face; R - 2 cov(fix error, filter error) is negative, and a window
    estimate of it as 003's R is a small difference of large numbers). A fault would hide below the model's
    variance. With kappa the variance still follows P where it grows (a stretch without fixes).

    var_floor: a further floor of sigma_k^2, for the part of a fix's error the filter does not share: the ram
    stroke's, measured anew at each pass, and the face survey's. The smoothed survey's error (0.021 m) is correlated
    along the face over +-14.5 m (estimators.shearer.face_line), and the filter, riding the INS, does not follow its swings;
    in a calm stretch of the survey kappa takes sigma_k down to D_SD_FLOOR (5 mm), where a 4 cm swing over three
    chutes read as a fault (seed004 trials 9 and 10).

    scale_h (3,): for a point whose face coordinate is a true distance (the face survey), the along-face
    direction in n times the odometer travel u at the fix. Such a fix lies u k_true along the face from where the
    odometer (scale k) puts the shearer, so z += scale_h k_est and H on the scale state (truth - estimate, as in
    the odometer update) is -scale_h: the face survey calibrates the odometer."""
    z, h = fix_measurement(nav, lever, fix_llh, x.size)
    z += scale_h * cal[CAL_SCALE]
    h[:, ODO_SCALE] = -scale_h
    if trusted:
        joseph_update(x, p, z, h, fix_r)
        stats[:] = np.nan
        return True
    v = z - h @ x
    ha = advance @ h
    v_a = np.array([advance @ v])
    s_model = ha @ p @ ha + advance @ fix_r @ advance
    s_a = np.array([[s_model]])
    window = int(det_params[D_WINDOW])
    if window > 0 and counters[2] >= window:
        kappa = np.sum(det_buf[:, 0]) / np.sum(det_buf[:, 1])
        s_a[0, 0] = max(kappa * s_model, det_params[D_SD_FLOOR] ** 2, var_floor)
    stats[DET_RESIDUAL] = chi2_residual(v_a, s_a)
    # The detectors are armed once the aiding sub-filter has taken the pass's first fixes (before, the fading SPRT
    # only shows what it would say, from a copy of its state; a fault flag raised earlier holds).
    counters[1] += 1
    armed = counters[1] > det_params[D_ARM]
    state = fsprt if armed else fsprt.copy()
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
    joseph_update(x_try, p_try, z, h, fix_r)
    stats[DET_DUAL] = chi2_dual_state(x_try[DP], p_try[DP, DP].copy(), x_other[DP], p_other[DP, DP].copy())
    by = int(det_params[D_ISOLATE_BY])
    reject = (by == DET_FSPRT and isolated[0]) or (armed and (
        (by == DET_RESIDUAL and stats[DET_RESIDUAL] > det_params[D_CHI2])
        or (by == DET_DUAL and stats[DET_DUAL] > det_params[D_CHI2_DUAL])))
    if reject:
        return False
    if armed and window > 0:
        det_buf[counters[2] % window] = v_a[0] ** 2, s_model
        counters[2] += 1
    x[:] = x_try
    p[:, :] = p_try
    return True


@nb.njit(cache=True)
def run_afkf(mode, j0, j1, steps, t_mech, phi_b, dv_b, odo_dist, odo_mode, mag_b, fix_epoch, fix_llh, fix_r,
             fix_scale_h, fix_advance, fix_var_floor, fix_trusted, q_psd, params, mag_params, det_params, nav, cal,
             p_sub, beta, nominal, r_buf, counters, fsprt, isolated, det_buf, out_nav, out_cal, out_sd, flags,
             mag_flags, beta_out, r_yaw_out, yaw_innov, sub_delta, fix_stats, fix_applied):
    """Run the federated (mode FEDERATED) or centralized (CENTRALIZED) filter over epochs j0+1 .. j1.

    Inputs per epoch j: odometer distance and mode (estimators.shearer.odometer_filter.run_filter), mag_b (3,) the calibrated
    mean magnetometer reading over the epoch (NaN where none). Position fixes of the rail kinematics model
    (fix_epoch sorted, fix_llh (F, 3), fix_r (F, 3, 3), fix_scale_h (F, 3), fix_advance (F, 3), fix_var_floor
    (F,), fix_trusted (F,): see _fix_update)
    go to sub-filter 2 (in the centralized mode to the one
    filter) through the detectors of det_params (D_*). params are estimators.shearer.odometer_filter's, mag_params the M_*
    vector. The state carried across calls, updated in place: nav, cal, p_sub (2, N_STATES, N_STATES) (initial_covariances),
    beta (2,), nominal (N_NOMINAL,) (zeros at the start), the yaw-noise window r_buf (W, 1, 1) with counters[0] its
    count, counters[1] the rail fixes tested so far in the pass, counters[2] the rail-fix innovations in the detectors' ring
    buffer det_buf (W, 2) (_fix_update), the FSPRT state fsprt and its fault flag isolated[0].

    Stores per epoch: navigation and calibration, one-sigma of the states, filter and magnetometer flags, beta
    (NaN in the centralized mode), the yaw R used, the yaw innovation, per sub-filter x_i - x_g of position and
    attitude (6,) before the reset; per fix the detector statistics (3,) and whether it was applied."""
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
    k_fix = np.searchsorted(fix_epoch, j0 + 1)
    # Snapshots of the state at the start of the last N_BACK epochs with a rail fix: when the fading SPRT raises a
    # fault, the fixes of the rise that led to it were already applied and have bent the estimate (a soft fault is
    # partly absorbed); the filter goes back to before them and goes on without them, and with the trusted fixes
    # (surveyed face ends) among them again.
    snap_j = np.full(N_BACK, -1, np.int64)
    snap_k = np.full(N_BACK, -1, np.int64)
    snap_nav, snap_cal = np.zeros((N_BACK, nav.size)), np.zeros((N_BACK, cal.size))
    snap_p = np.zeros((N_BACK, N_SUB, N_STATES, N_STATES))
    snap_beta, snap_nominal = np.zeros((N_BACK, N_SUB)), np.zeros((N_BACK, nominal.size))
    snap_buf, snap_buf_count = np.zeros((N_BACK,) + det_buf.shape), np.zeros(N_BACK, np.int64)
    snap_count = 0
    rejected_until = -1
    j = j0 + 1
    while j <= j1:
        if k_fix < fix_epoch.size and fix_epoch[k_fix] == j and not fix_trusted[k_fix] and k_fix > rejected_until:
            slot = snap_count % N_BACK
            snap_j[slot], snap_k[slot] = j, k_fix
            snap_nav[slot], snap_cal[slot], snap_p[slot] = nav, cal, p_sub
            snap_beta[slot], snap_nominal[slot] = beta, nominal
            snap_buf[slot], snap_buf_count[slot] = det_buf, counters[2]
            snap_count += 1
        t_span, f_sum, disp, w_sum = mechanize_epoch(nav, cal, t_mech, phi_b, dv_b, (j - 1) * steps, steps)
        phi, qd = transition(nav, nominal, f_sum, t_span, q_psd, params[P_TAU_FORCE])
        p_od_pred = phi @ p_od @ phi.T + (_share(qd, beta[SUB_ODOMETER]) if federated else qd)
        p_od[:, :] = p_od_pred
        flag = 0
        if odo_mode[j] == 1:
            odometer_update(x_od, p_od, nav, cal, disp, w_sum, lever, t_span, odo_dist[j] - odo_dist[j - 1], nominal,
                            r_vel, params[P_TAU_FWD])
            flag |= FLAG_VELOCITY
        elif odo_mode[j] == 0:
            stand_update(x_od, p_od, nav, disp, w_sum, t_span, nominal, params[P_R_ZUPT], params[P_R_ZARU])
            flag |= FLAG_ZUPT
        else:
            flag |= FLAG_SKIPPED
        # Sub-filter 2 (magnetometer and rail model); in the centralized mode its measurements go to the one filter.
        x2, p2 = (x_aid, p_aid) if federated else (x_od, p_od)
        p_aid_pred = p_aid
        if federated:
            p_aid_pred = phi @ p_aid @ phi.T + _share(qd, beta[SUB_AIDING])
            p_aid[:, :] = p_aid_pred
        r_yaw = window_r(r_buf, counters[0], r_nominal, r_min, int(mag_params[M_MIN_SAMPLES]))[0, 0] if adapt \
            else mag_params[M_R_YAW]
        r_yaw_out[j] = r_yaw
        mflag = 0
        if np.all(np.isfinite(mag_b[j])):
            mflag, yaw_innov[j], counters[0] = mag_update(x2, p2, nav, mag_b[j], mag_params, r_yaw, r_buf,
                                                             counters[0], check)
        back = -1
        while k_fix < fix_epoch.size and fix_epoch[k_fix] == j:
            if k_fix <= rejected_until and not fix_trusted[k_fix]:  # rolled back: already tested, left out
                fix_applied[k_fix] = 0
                flag |= FLAG_SKIPPED
                k_fix += 1
                continue
            was = isolated[0]
            if _fix_update(x2, p2, nav, cal, lever, fix_llh[k_fix], fix_r[k_fix], fix_scale_h[k_fix],
                           fix_advance[k_fix], fix_var_floor[k_fix], fix_trusted[k_fix], x_od, p_od, det_params, fsprt,
                           isolated, counters, det_buf, fix_stats[k_fix]):
                fix_applied[k_fix] = 1
                flag |= FLAG_POSITION
            else:
                fix_applied[k_fix] = 0
                flag |= FLAG_SKIPPED
            if isolated[0] and not was and int(det_params[D_ISOLATE_BY]) == DET_FSPRT:
                back = _onset_slot(snap_k, snap_count, fix_stats, k_fix)
                rejected_until = k_fix
            k_fix += 1
        if back >= 0:
            j, k_fix = snap_j[back], snap_k[back]
            nav[:], cal[:], p_sub[:] = snap_nav[back], snap_cal[back], snap_p[back]
            beta[:], nominal[:] = snap_beta[back], snap_nominal[back]
            det_buf[:], counters[2] = snap_buf[back], snap_buf_count[back]
            x_od[:] = 0.0
            x_aid[:] = 0.0
            snap_count = 0
            continue
        if isolated[0]:
            flag |= FLAG_ISOLATED
        if federated:
            if keep_covariance(x_od, p_od, p_od_pred) | keep_covariance(x_aid, p_aid, p_aid_pred):
                flag |= FLAG_COVARIANCE_REPAIRED
            x_pre_od = x_od.copy()
            x_pre_aid = x_aid.copy()
            x_g, p_g, beta_new, valid, ok = fuse_epoch(x_od, p_od, x_aid, p_aid, mag_params[M_INVERSE_SHARING] > 0)
            delta = np.zeros((N_SUB, 6))
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
                        delta[i, k] = x_pre[DP.start + k] - x_g[DP.start + k]
                        delta[i, 3 + k] = x_pre[PHI.start + k] - x_g[PHI.start + k]
                apply_correction(nav, cal, x_g)
            sub_delta[j] = delta
            beta_out[j] = beta
            out_sd[j] = np.sqrt(np.maximum(np.diag(p_g), 0.0))
        else:
            if keep_covariance(x_od, p_od, p_od_pred):
                flag |= FLAG_COVARIANCE_REPAIRED
            apply_correction(nav, cal, x_od)
            x_od[:] = 0.0
            beta_out[j] = np.nan
            out_sd[j] = np.sqrt(np.diag(p_od))
        out_nav[j] = nav
        out_cal[j] = cal
        flags[j] = flag
        mag_flags[j] = mflag
        j += 1


@nb.njit(cache=True)
def _onset_slot(snap_k, snap_count, fix_stats, k_now):
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
