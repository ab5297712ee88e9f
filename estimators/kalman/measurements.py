"""Measurement models of the SINS/odometer error-state filters (001 section 3, 004), numba: each returns
(z, H, R) for estimators.kalman.update, z the innovation's reference, H its sensitivity to the error state of
estimators.kalman.error_state (n states, n >= 19), R its noise covariance. nav and cal are the kernels'
navigation and calibration vectors (error_state).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from estimators.arrays import put
from estimators.kalman.error_state import (
    CAL_MOUNT,
    CAL_SCALE,
    DP,
    DV,
    GYRO_BIAS,
    HGT,
    LAT,
    LON,
    NOM_SPEED,
    NOM_SPEED_LAST,
    ODO_MOUNT,
    ODO_SCALE,
    PHI,
    QUAT,
    VEL,
)
from estimators.nav.earth import nav_rates, radii_nb
from estimators.nav.rotations import cross3, quat_mat, rotvec_mat, skew3

FIX_SD_FLOOR = 1e-3
"""Least one-sigma [m] of a position fix's coordinate (position_fix). A survey stated exact (sigma 0) is valid input,
but it would leave the position covariance singular, which the federated fusion inverts (estimators.kalman.
fusion) and the detectors divide by; a millimetre is below any survey of a face."""


@nb.njit(cache=True)
def odometer_velocity(nav, cal, disp, w_sum, lever, t_span, d_odo, nominal, r_vel, tau_fwd, n):
    """Odometer + motion-constraint velocity (001 eqs. 18-20): z = C_b^m C_n^b v - [0, v_od, 0], with v the IMU's
    mean velocity over the epoch (its displacement disp / t_span) and v_od the odometer distance d_odo over the
    epoch / t_span corrected by the estimated scale; R = r_vel (3, 3). Advances the running odometer speed.

    A mean velocity belongs to the middle of its epoch, so C_n^b is the attitude there: the epoch's end attitude
    turned back by half the body's turn relative to n over the epoch, C_b^n(mid) = C_b^n(end) exp(-[a / 2 x]) with
    a = w_sum - C_n^b (w_ie + w_en) t_span. Resolved at the
    end, the velocity leaned by half the epoch's turn, on a pitching machine a share of it into the vertical, which
    the filters took for odometer scale (the exact-survey north-south trajectory of
    tests/estimators/shearer/test_independent_trajectories.py: 1.16e-4, at mid-epoch 2.6e-5).

    d_odo is the travel of the body reference point, disp the IMU's, so the IMU's turn about the lever arm,
    w_eb x l (w_sum the angle increment in b), is taken out of its velocity first (in the snake's bends it is
    0.3 w_z along the face for a lever arm of 0.3 m across). 001 eq. 20 evaluates
    H = [C_b^m C_n^b, -C_b^m C_n^b [v_n x], 0, 0, 0, -C_b^m [v_b x], -v_m] at the true velocity. Measured
    velocities there (the odometer's quantization, the IMU's vibration) would put the same noise into H and z,
    and that correlation biases the scale and mounting estimates at every update (errors in variables). H uses
    the nominal motion v_b = [0, nominal[NOM_SPEED], 0] instead: along the odometer axis at the odometer speed
    averaged up to two epochs back (the quantization error of the last reading, nominal[NOM_SPEED_LAST], is also
    in this one's, with the opposite sign); that mean then takes the last reading, with the time constant
    tau_fwd, and this one becomes the last."""
    c_nb_end = quat_mat(nav[QUAT])
    w_ie, w_en = nav_rates(nav[LAT], nav[HGT], nav[VEL])
    turn_nb = w_sum - c_nb_end.T @ (w_ie + w_en) * t_span  # the body's turn relative to n over the epoch
    c_nb = c_nb_end @ rotvec_mat(-0.5 * turn_nb)  # at mid-epoch
    c_bn = c_nb.T
    c_mb = rotvec_mat(cal[CAL_MOUNT]).T
    v_b = c_bn @ (disp / t_span) - cross3(w_sum / t_span - c_bn @ w_ie, lever)
    v_od = d_odo / t_span / (1 + cal[CAL_SCALE])
    v_b_nom = np.array([0.0, nominal[NOM_SPEED], 0.0])
    h = np.zeros((3, n))
    put(h[:, DV], c_mb @ c_bn)
    put(h[:, PHI], -c_mb @ c_bn @ skew3(c_nb @ v_b_nom))
    put(h[:, ODO_MOUNT], -c_mb @ skew3(v_b_nom))
    h[1, ODO_SCALE] = -(c_mb @ v_b_nom)[1]
    z = c_mb @ v_b - np.array([0.0, v_od, 0.0])
    nominal[NOM_SPEED] += (nominal[NOM_SPEED_LAST] - nominal[NOM_SPEED]) * min(1.0, t_span / tau_fwd)
    nominal[NOM_SPEED_LAST] = v_od
    return z, h, r_vel


@nb.njit(cache=True)
def zero_velocity(disp, t_span, nominal, r_zupt, n):
    """Zero velocity of a standing shearer (004 eq. 2): z = v_n, H = [I 0 ...], R = r_zupt^2 I; the stand also
    stops the running odometer speed (odometer_velocity).

    The zero velocity is that of the epoch's mean, disp / t_span (disp the IMU's displacement over the epoch), not
    of its last sample: a standing machine still shakes, and a tone whose period divides the epoch (a 30 Hz pick
    tone at 10 Hz updates) shows its velocity at the same phase at every epoch end. Taken as the velocity error,
    that sample holds the mechanized velocity off by it and moves the position steadily (1.4 mm/s, 0.4 m over
    seed004's 5 min alignment stand); over whole epochs the tone averages out."""
    nominal[NOM_SPEED] = nominal[NOM_SPEED_LAST] = 0.0
    h = np.zeros((3, n))
    for i in range(3):
        h[i, DV.start + i] = 1.0
    return disp / t_span, h, np.eye(3) * r_zupt ** 2


@nb.njit(cache=True)
def zero_rate(nav, w_sum, t_span, r_zaru, n):
    """Zero rate of a standing shearer: the mean gyro output (w_sum / t_span) minus the Earth rate resolved in b is
    the residual gyro bias, z = w_ib_b - C_n^b w_ie = eps + C_n^b [w_ie x] phi, R = r_zaru^2 I. It makes the
    vertical gyro bias, and so the heading drift of a MEMS gyro, observable whenever the shearer stands."""
    c_bn = quat_mat(nav[QUAT]).T
    w_ie, _w_en = nav_rates(nav[LAT], nav[HGT], nav[VEL])
    h = np.zeros((3, n))
    put(h[:, PHI], c_bn @ skew3(w_ie))
    for i in range(3):
        h[i, GYRO_BIAS.start + i] = 1.0
    return w_sum / t_span - c_bn @ w_ie, h, np.eye(3) * r_zaru ** 2


@nb.njit(cache=True)
def position_fix(nav, lever, fix_llh, fix_r, n):
    """Position fix (survey or CPOEM point, 001 eqs. 21-22) of the body reference point p = p_imu - C_b^n l:
    z = body-point position of the SINS minus the fix fix_llh (lat, lon, h), ENU metres;
    H = [0, -[(C_b^n l) x], I, 0 ...]; R = fix_r (3, 3), ENU, its variances floored at FIX_SD_FLOOR^2."""
    lat, hgt = nav[LAT], nav[HGT]
    r_m, r_n = radii_nb(lat)
    off = quat_mat(nav[QUAT]) @ lever
    z = np.array([(nav[LON] - fix_llh[1]) * (r_n + hgt) * np.cos(lat) - off[0],
                  (nav[LAT] - fix_llh[0]) * (r_m + hgt) - off[1],
                  nav[HGT] - fix_llh[2] - off[2]])
    h = np.zeros((3, n))
    put(h[:, PHI], -skew3(off))
    r = fix_r.copy()
    for i in range(3):
        h[i, DP.start + i] = 1.0
        r[i, i] = max(r[i, i], FIX_SD_FLOOR ** 2)
    return z, h, r
