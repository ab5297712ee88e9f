"""SINS/odometer/magnetometer filters of 003 as one sequential numba kernel: the adaptive federated filter (AFKF,
003 section 4) and the centralized filter it is compared with (003 section 5.2).

Both share one SINS (estimators.shearer_kf's mechanization, error states and odometer blocks):

* sub-filter 1, SINS/odometer (003 section 3.1): the 19 error states of estimators.shearer_kf, the odometer plus
  motion-constraint velocity closing error, and the zero-velocity and zero-rate updates while the shearer stands;
* sub-filter 2, SINS/magnetometer (003 section 3.2): the yaw closing error z = yaw_SINS - yaw_mag with H on phi
  from estimators.magnetic.yaw_h_phi and R estimated from its innovations over a sliding window (003 section
  4.2, estimators.adaptive), readings whose field norm or dip disagree with the geomagnetic model left out.

Both carry the same 19 error states (003's SINS/MAG sub-filter has the 15 SINS states; carrying the odometer
mounting and scale as well, unobserved by it, lets the fusion cover the whole state and keeps it exact: a
sub-filter of a subset would have to give those states back through their regression on the common ones, and
the process noise of the common states then leaks into them at every reset).

Each epoch (003 Fig. 3): time update of each sub-filter with Q / beta_i, their measurement updates, fusion (004
eqs. 10-11, estimators.federated), sharing coefficients beta_i from the traces of the sub-filters' covariances
(003 section 4.3), feedback of the global estimate into the SINS and the odometer calibration, and the reset
x_i = 0, P_i = P_g / beta_i. With fusion at every epoch and this reset the fused estimate equals that of the
centralized filter whatever the beta_i (the information P_g^-1 is split, not copied; tests/test_federated_kf.py);
the fault tolerance comes from each sub-filter's own measurement noise and disturbance test.

The centralized mode runs the same measurements on one 19-state filter with the nominal yaw noise and no
disturbance test: 003's CKF.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from estimators.adaptive import window_push, window_r
from estimators.federated import fuse_kernel, sharing_kernel
from estimators.logformat import (
    FLAG_COVARIANCE_REPAIRED,
    FLAG_SKIPPED,
    FLAG_VELOCITY,
    FLAG_ZUPT,
)
from estimators.magnetic import yaw_closing_error_nb
from estimators.shearer_kf import (
    DP,
    N_STATES,
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
    joseph_update,
    keep_covariance,
    mechanize_epoch,
    odometer_update,
    stand_update,
    transition,
)
from estimators.strapdown import quat_mat

SUB_ODOMETER, SUB_MAG = 0, 1
N_SUB = 2

FEDERATED, CENTRALIZED = 0, 1

# Indices of the magnetometer parameter vector.
(M_DECLINATION, M_H_PHI, M_INTENSITY, M_INCLINATION, M_NORM_TOL, M_DIP_TOL, M_R_YAW, M_R_MIN, M_MIN_SAMPLES,
 M_GATE, M_CHECK, M_ADAPT, M_INVERSE_SHARING) = (0, 1, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14)
N_MAG_PARAMS = 15  # M_H_PHI takes 1..3

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

    Returns (flag bits, innovation, R used, new window count). With use_check, a disturbed reading is left out
    and not put in the noise window; every other innovation goes into the window (also a gated one, so that R can
    grow to admit a real change)."""
    c_bn = quat_mat(nav[QUAT])
    if use_check and field_disturbed(mag_b, c_bn, mag_params[M_INTENSITY], mag_params[M_INCLINATION],
                                     mag_params[M_NORM_TOL], mag_params[M_DIP_TOL]):
        return MAG_READ | MAG_DISTURBED, np.nan, r_yaw, r_count
    h = np.zeros((1, x.size))
    h[0, PHI.start:PHI.start + 3] = mag_params[M_H_PHI:M_H_PHI + 3]
    z = np.array([yaw_closing_error_nb(mag_b, c_bn, mag_params[M_DECLINATION])])
    v = z[0] - (h @ x)[0]
    hph = h @ p @ h.T
    r_count = window_push(r_buf, r_count, np.array([v]), hph)
    if v * v > mag_params[M_GATE] * (hph[0, 0] + r_yaw):
        return MAG_READ | MAG_GATED, v, r_yaw, r_count
    joseph_update(x, p, z, h, np.array([[r_yaw]]))
    return MAG_READ | MAG_USED, v, r_yaw, r_count


@nb.njit(cache=True)
def _share(m, beta):
    """A sub-filter's share of a covariance, m / beta (003 section 4.3); all of it for an excluded one (beta 0)."""
    return m / beta if beta > 0.0 else m.copy()


@nb.njit(cache=True)
def fuse_epoch(x_od, p_od, x_mag, p_mag, inverse_sharing):
    """Fusion (004 eqs. 10-11) and sharing coefficients (003 section 4.3) of the two sub-filters.

    Returns (x_g, P_g, beta (2,), valid (2,), ok); the sub-filters are reset in place (x_i = 0, P_i = P_g / beta_i;
    an invalid one restarts from P_g)."""
    xs = np.empty((N_SUB, N_STATES))
    ps = np.empty((N_SUB, N_STATES, N_STATES))
    xs[SUB_ODOMETER], ps[SUB_ODOMETER] = x_od, p_od
    xs[SUB_MAG], ps[SUB_MAG] = x_mag, p_mag
    x_g, p_g, valid, ok = fuse_kernel(xs, ps)
    beta = sharing_kernel(ps, valid, inverse_sharing)
    if ok:
        p_od[:, :] = _share(p_g, beta[SUB_ODOMETER])
        p_mag[:, :] = _share(p_g, beta[SUB_MAG])
        x_od[:] = 0.0
        x_mag[:] = 0.0
    return x_g, p_g, beta, valid, ok


@nb.njit(cache=True)
def run_afkf(mode, steps, t_mech, phi_b, dv_b, odo_dist, odo_mode, mag_b, q_psd, params, mag_params, r_window,
             nav, cal, p0, out_nav, out_cal, out_sd, flags, mag_flags, beta_out, r_yaw_out, yaw_innov, sub_delta):
    """Run the federated (mode FEDERATED) or centralized (CENTRALIZED) filter over epochs 1 .. K-1.

    mag_b (K, 3): the calibrated mean magnetometer reading over each epoch (NaN where none). params are
    estimators.shearer_kf's, mag_params this module's M_* vector; r_window the length of the noise window.
    nav, cal start the run (updated in place), p0 (19, 19) is the initial covariance. Stores per epoch the
    navigation and calibration, the one-sigma of the 19 states, filter and magnetometer flags, beta (2,) (NaN in
    the centralized mode), the yaw R used, the yaw innovation and, per sub-filter, x_i - x_g of position and
    attitude (6,) before the reset (the sub-filter's own estimate relative to the global one)."""
    r_vel = np.diag(np.array([params[P_R_LATERAL], params[P_R_ALONG], params[P_R_VERTICAL]]) ** 2)
    federated = mode == FEDERATED
    adapt = federated and mag_params[M_ADAPT] > 0
    check = federated and mag_params[M_CHECK] > 0
    r_nominal = np.array([[mag_params[M_R_YAW]]])
    r_min = np.array([mag_params[M_R_MIN]])
    r_buf = np.zeros((r_window, 1, 1))
    r_count = 0
    beta = np.full(N_SUB, 1.0 / N_SUB)
    nominal = np.zeros(5)
    x_od = np.zeros(N_STATES)
    x_mag = np.zeros(N_STATES)
    p_od = _share(p0, beta[SUB_ODOMETER]) if federated else p0.copy()  # the initial information split (Carlson)
    p_mag = _share(p0, beta[SUB_MAG])
    p_mag_pred = p_mag.copy()
    out_sd[0] = np.sqrt(np.diag(p0))
    for j in range(1, out_nav.shape[0]):
        t_span, f_sum, disp, w_sum = mechanize_epoch(nav, cal, t_mech, phi_b, dv_b, (j - 1) * steps, steps)
        phi, qd = transition(nav, nominal, f_sum, t_span, q_psd, params[P_TAU_FORCE])
        p_od_pred = phi @ p_od @ phi.T + (_share(qd, beta[SUB_ODOMETER]) if federated else qd)
        p_od[:, :] = p_od_pred
        flag = 0
        if odo_mode[j] == 1:
            odometer_update(x_od, p_od, nav, cal, disp, t_span, odo_dist[j] - odo_dist[j - 1], nominal, r_vel,
                            params[P_TAU_FWD])
            flag |= FLAG_VELOCITY
        elif odo_mode[j] == 0:
            stand_update(x_od, p_od, nav, w_sum, t_span, nominal, params[P_R_ZUPT], params[P_R_ZARU])
            flag |= FLAG_ZUPT
        else:
            flag |= FLAG_SKIPPED
        if federated:
            p_mag_pred = phi @ p_mag @ phi.T + _share(qd, beta[SUB_MAG])
            p_mag[:, :] = p_mag_pred
        r_yaw = window_r(r_buf, r_count, r_nominal, r_min, int(mag_params[M_MIN_SAMPLES]))[0, 0] if adapt \
            else mag_params[M_R_YAW]
        r_yaw_out[j] = r_yaw
        mflag = 0
        if np.all(np.isfinite(mag_b[j])):
            if federated:
                mflag, yaw_innov[j], _r, r_count = mag_update(x_mag, p_mag, nav, mag_b[j], mag_params, r_yaw, r_buf,
                                                               r_count, check)
            else:
                mflag, yaw_innov[j], _r, r_count = mag_update(x_od, p_od, nav, mag_b[j], mag_params, r_yaw, r_buf,
                                                               r_count, False)
        if federated:
            if keep_covariance(x_od, p_od, p_od_pred) | keep_covariance(x_mag, p_mag, p_mag_pred):
                flag |= FLAG_COVARIANCE_REPAIRED
            delta = np.zeros((N_SUB, 6))
            x_pre_od = x_od.copy()
            x_pre_mag = x_mag.copy()
            x_g, p_g, beta_new, valid, ok = fuse_epoch(x_od, p_od, x_mag, p_mag, mag_params[M_INVERSE_SHARING] > 0)
            if not ok:  # nothing usable: drop this epoch's updates and restart both from the prediction
                p_od[:, :] = p_od_pred
                p_mag[:, :] = p_mag_pred
                x_od[:] = 0.0
                x_mag[:] = 0.0
                flag |= FLAG_COVARIANCE_REPAIRED
                p_g = p_od_pred
            else:
                beta[:] = beta_new
                if not valid.all():
                    mflag |= SUB_INVALID
                for k in range(3):
                    delta[SUB_ODOMETER, k] = x_pre_od[DP.start + k] - x_g[DP.start + k]
                    delta[SUB_ODOMETER, 3 + k] = x_pre_od[PHI.start + k] - x_g[PHI.start + k]
                    delta[SUB_MAG, k] = x_pre_mag[DP.start + k] - x_g[DP.start + k]
                    delta[SUB_MAG, 3 + k] = x_pre_mag[PHI.start + k] - x_g[PHI.start + k]
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
