"""The SINS/odometer error Kalman filter of 001 section 3 (19 states) plus the accelerometer triad's
non-orthogonality (3 states) as one sequential numba kernel.

Error state (001 eq. 12, this order, then the non-orthogonality; errors are estimate - truth):

    x = [dv_n (ENU, m/s), phi (attitude error, C_b^n' = (I - [phi x]) C_b^n, rad), dp (ENU, m),
         eps (gyro bias, b, rad/s), nabla (accelerometer bias, b, m/s^2), dalpha (odometer mounting, rad),
         dk_D (odometer scale-factor error), da (accelerometer non-orthogonality a_xy, a_xz, a_yz, rad)]

The non-orthogonality is not in 001. A symmetric A in f~ = (I + A) f + nabla is, while the body stays level, one
more bias (A [0, 0, g]); but as the pitch follows the floor the z accelerometer reads a_yz g sin(theta), which
looks like an along-face bias, and a filter without it takes the pitch changes as separating the level from
the bias: its pitch comes out wrong by a_yz while it claims a fraction of that (seed001: 0.065 deg against 0.029).

Position errors are kept in metres east/north/up instead of 001's (longitude, latitude, height): the same state
through the diagonal matrix C of 001 eq. 7, and better conditioned. Dynamics (001 eqs. 13-15, with the Earth and
transport rates kept in full and the free-air gravity gradient on the vertical channel):

    d(dv)/dt  = f_n x phi - (2 w_ie + w_en) x dv + C_b^n (nabla + N(f_b) da) + w_a
    d(phi)/dt = -(w_ie + w_en) x phi - C_b^n eps + w_g
    d(dp)/dt  = dv,   d(eps)/dt = w_eps,   d(nabla)/dt = w_nabla,   d(dalpha)/dt = 0,   d(dk_D)/dt = 0

discretized per filter step T as Phi = I + F T + (F T)^2 / 2 (001 eq. 17) and Q_d = (Phi Q_c Phi^T + Q_c) T / 2.

Measurements, each a (z, H, R) block applied in sequence with the Joseph update (001 eq. 28):

* odometer + motion constraint (001 eqs. 18-20): z = C_b^m C_n^b v_n - [0, v_od, 0], with v_n the SINS mean
  velocity over the step (its displacement / T) and v_od the odometer distance over the step / T corrected by the
  estimated scale, H = [C_b^m C_n^b, -C_b^m C_n^b [v_n x], 0, 0, 0, -C_b^m [v_b x], -v_m] evaluated at the
  nominal motion v_b = [0, running-mean odometer speed, 0] (see the kernel: measured velocities there bias the
  scale and mounting estimates);
* zero-velocity update at a stand (004 eq. 2): z = v_n, H = [I 0 ...];
* zero-rate update at a stand: the mean gyro output minus the Earth rate resolved in b must be the residual gyro
  bias, z = w_ib_b - C_n^b w_ie = eps + C_n^b [w_ie x] phi. It makes the vertical gyro bias, and so the heading
  drift of a MEMS gyro, observable whenever the shearer stands;
* position fix (survey or CPOEM point, 001 eqs. 21-22) of the body reference point p = p_imu - C_b^n l:
  z = p_body' - p_fix (ENU m), H = [0, -[(C_b^n l) x], I, 0 ...]; a fix whose normalized innovation exceeds the
  gate is skipped and flagged.

After the updates the estimate is fed back into the mechanization, the sensor corrections and the odometer
calibration (closed loop), and the error state restarts at zero. The posterior update x+ (before the reset),
the covariances and Phi are stored for the RTS smoother (estimators.kalman.rts).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from estimators.io.logformat import (
    FLAG_COVARIANCE_REPAIRED,
    FLAG_POSITION,
    FLAG_SKIPPED,
    FLAG_VELOCITY,
    FLAG_ZUPT,
)
from estimators.kalman.update import gated_update, joseph_update
from estimators.nav.earth import gravity_nb, nav_rates, radii_nb
from estimators.nav.rotations import (
    cross3,
    mat_rotvec,
    qexp,
    qmul,
    qrot,
    quat_mat,
    rotvec_mat,
    skew3,
)

DV = slice(0, 3)
PHI = slice(3, 6)
DP = slice(6, 9)
GYRO_BIAS = slice(9, 12)
ACCEL_BIAS = slice(12, 15)
ODO_MOUNT = slice(15, 18)
ODO_SCALE = 18
ACCEL_NONORTH = slice(19, 22)
N_STATES = 22
_DV, _PHI, _DP, _BG, _BA, _AL, _NA = 0, 3, 6, 9, 12, 15, 19  # block starts, for the kernel

# Navigation vector of the kernel: geodetic position, ENU velocity, attitude q_nb.
LAT, LON, HGT = 0, 1, 2
VEL = slice(3, 6)
QUAT = slice(6, 10)
N_NAV = 10
# Calibration vector: gyro and accelerometer corrections (subtracted from the increments), odometer mounting as
# the rotation vector of C_m^b, odometer scale k (distance = nominal / (1 + k)).
CAL_GYRO = slice(0, 3)
CAL_ACCEL = slice(3, 6)
CAL_MOUNT = slice(6, 9)
CAL_SCALE = 9
CAL_NONORTH = slice(10, 13)  # (a_xy, a_xz, a_yz): dv_b <- dv_b - A dv_b
N_CAL = 13

N_NOMINAL = 8
"""Length of the kernels' running "nominal" vector: the odometer speed (0), the specific force's two low-pass
stages (1:4, 5:8) the models are linearized at (odometer_update, transition) and the last odometer speed (4)."""

# Indices of the kernel's parameter vector.
P_R_LATERAL, P_R_ALONG, P_R_VERTICAL, P_R_ZUPT, P_R_ZARU, P_TAU_FWD, P_TAU_FORCE, P_LEVER = range(8)
N_PARAMS = 11  # the lever arm takes 7..9, one spare


@nb.njit(cache=True)
def nonorth_matrix(v):
    """N(v) (3 x 3) with A v = N(v) (a_xy, a_xz, a_yz) for the symmetric zero-diagonal A."""
    n = np.zeros((3, 3))
    n[0, 0], n[0, 1] = v[1], v[2]
    n[1, 0], n[1, 2] = v[0], v[2]
    n[2, 1], n[2, 2] = v[0], v[1]
    return n


@nb.njit(cache=True)
def system_matrix(nav, f_n):
    """F (N_STATES x N_STATES) of the error dynamics at the navigation state `nav` with specific force f_n."""
    lat, h = nav[LAT], nav[HGT]
    v = nav[VEL]
    w_ie, w_en = nav_rates(lat, h, v)
    c_bn = quat_mat(nav[QUAT])
    f = np.zeros((N_STATES, N_STATES))
    f[_DV:_DV + 3, _DV:_DV + 3] = -skew3(2 * w_ie + w_en)
    f[_DV:_DV + 3, _PHI:_PHI + 3] = skew3(f_n)
    f[_DV:_DV + 3, _BA:_BA + 3] = c_bn
    f[_DV:_DV + 3, _NA:_NA + 3] = c_bn @ nonorth_matrix(c_bn.T @ f_n)
    r_m, r_n = radii_nb(lat)
    f[_DV + 2, _DP + 2] = 2 * gravity_nb(lat, h) / np.sqrt((r_m + h) * (r_n + h))
    f[_PHI:_PHI + 3, _PHI:_PHI + 3] = -skew3(w_ie + w_en)
    f[_PHI:_PHI + 3, _BG:_BG + 3] = -c_bn
    for i in range(3):
        f[_DP + i, _DV + i] = 1.0
    return f


@nb.njit(cache=True)
def discretize(f, q_psd, dt):
    """Phi = I + F T + (F T)^2 / 2 and Q_d = (Phi Q_c Phi^T + Q_c) T / 2 (001 eq. 17)."""
    ft = f * dt
    phi = np.eye(N_STATES) + ft + 0.5 * (ft @ ft)
    qc = np.diag(q_psd)
    return phi, 0.5 * (phi @ qc @ phi.T + qc) * dt




@nb.njit(cache=True)
def apply_correction(nav, cal, x):
    """Feed an error estimate back: corrected navigation state and calibration (in place)."""
    lat, h = nav[LAT], nav[HGT]
    r_m, r_n = radii_nb(lat)
    nav[LAT] -= x[_DP + 1] / (r_m + h)
    nav[LON] -= x[_DP] / ((r_n + h) * np.cos(lat))
    nav[HGT] -= x[_DP + 2]
    for i in range(3):
        nav[3 + i] -= x[_DV + i]
    q = qmul(qexp(x[_PHI:_PHI + 3]), nav[QUAT])
    nav[QUAT] = q / np.sqrt(np.sum(q * q))
    for i in range(3):
        cal[i] += x[_BG + i]
        cal[3 + i] += x[_BA + i]
        cal[CAL_NONORTH.start + i] += x[_NA + i]
    # C_b^m <- C_b^m (I - [dalpha x]), i.e. C_m^b <- (I + [dalpha x]) C_m^b, kept as a rotation vector.
    cal[6:9] = mat_rotvec(rotvec_mat(x[_AL:_AL + 3]) @ rotvec_mat(cal[6:9]))
    cal[CAL_SCALE] = (1 + cal[CAL_SCALE]) * (1 + x[ODO_SCALE]) - 1


@nb.njit(cache=True)
def _mech_step(nav, phi_b, dv_b, dt):
    """One strapdown update (estimators.sins.strapdown order); returns (dv_n specific-force increment, mean v)."""
    lat, h = nav[LAT], nav[HGT]
    v = nav[VEL].copy()
    w_ie, w_en = nav_rates(lat, h, v)
    zeta = (w_ie + w_en) * dt
    dv_n = qrot(nav[QUAT], dv_b)
    dv_n = dv_n - 0.5 * cross3(zeta, dv_n)
    g_n = np.array([0.0, 0.0, -gravity_nb(lat, h)])
    v_new = v + dv_n + (g_n - cross3(2.0 * w_ie + w_en, v)) * dt
    v_bar = 0.5 * (v + v_new)
    h_new = h + v_bar[2] * dt
    h_bar = 0.5 * (h + h_new)
    r_m, r_n = radii_nb(lat)
    lat_new = lat + v_bar[1] * dt / (r_m + h_bar)
    lat_bar = 0.5 * (lat + lat_new)
    r_m, r_n = radii_nb(lat_bar)
    nav[LON] += v_bar[0] * dt / ((r_n + h_bar) * np.cos(lat_bar))
    nav[LAT], nav[HGT] = lat_new, h_new
    nav[VEL] = v_new
    w_ie, w_en = nav_rates(lat_bar, h_bar, v_bar)
    q = qmul(qmul(qexp(-(w_ie + w_en) * dt), nav[QUAT]), qexp(phi_b))
    nav[QUAT] = q / np.sqrt(np.sum(q * q))
    return dv_n, v_bar


@nb.njit(cache=True)
def fix_measurement(nav, lever, fix_llh, n):
    """(z, H (3, n)) of a position fix (001 eqs. 21-22) of the body point: z = body-point position of the SINS
    minus the fix, ENU metres; H = [0, -[(C_b^n l) x], I, 0 ...]."""
    lat, hgt = nav[LAT], nav[HGT]
    r_m, r_n = radii_nb(lat)
    off = quat_mat(nav[QUAT]) @ lever
    z = np.array([(nav[LON] - fix_llh[1]) * (r_n + hgt) * np.cos(lat) - off[0],
                  (nav[LAT] - fix_llh[0]) * (r_m + hgt) - off[1],
                  nav[HGT] - fix_llh[2] - off[2]])
    h = np.zeros((3, n))
    h[:, _PHI:_PHI + 3] = -skew3(off)
    for i in range(3):
        h[i, _DP + i] = 1.0
    return z, h


@nb.njit(cache=True)
def mechanize_epoch(nav, cal, t_mech, phi_b, dv_b, u0, steps):
    """Mechanize steps u0 .. u0+steps-1 with the calibration's corrections (nav in place).

    Returns (t_span, f_sum: specific-force increment in n, disp: displacement in n, w_sum: corrected angle
    increment in b)."""
    t_span = t_mech[u0 + steps] - t_mech[u0]
    f_sum = np.zeros(3)
    disp = np.zeros(3)
    w_sum = np.zeros(3)
    for u in range(u0, u0 + steps):
        dt = t_mech[u + 1] - t_mech[u]
        ph = phi_b[u] - cal[CAL_GYRO] * dt
        dv = dv_b[u] - nonorth_matrix(dv_b[u]) @ cal[CAL_NONORTH] - cal[CAL_ACCEL] * dt
        dv_n, v_bar = _mech_step(nav, ph, dv, dt)
        f_sum += dv_n
        disp += v_bar * dt
        w_sum += ph
    return t_span, f_sum, disp, w_sum


@nb.njit(cache=True)
def transition(nav, nominal, f_sum, t_span, q_psd, tau_force):
    """(Phi, Q_d) over the epoch, F evaluated at the nominal specific force (updated here).

    F uses the specific force low-passed by two first-order stages of tau_force each (nominal[1:4], then
    nominal[5:8], which F takes), not this step's: the step's carries the machine's vibration, whose velocity is
    also in the innovations (errors in variables again: the vibration would "reveal" a heading error through
    f x phi that is not there). Two stages cut the drum tone by the square of one stage's factor at a delay of
    2 tau_force, so a speed change (a reversal) still reaches F within seconds, with its area kept."""
    f_now = f_sum / t_span
    if nominal[1] == 0.0 and nominal[2] == 0.0 and nominal[3] == 0.0:
        nominal[1:4] = f_now
        nominal[5:8] = f_now
    else:
        gain = min(1.0, t_span / tau_force)
        nominal[1:4] += (f_now - nominal[1:4]) * gain
        nominal[5:8] += (nominal[1:4] - nominal[5:8]) * gain
    return discretize(system_matrix(nav, nominal[5:8].copy()), q_psd, t_span)


@nb.njit(cache=True)
def odometer_update(x, p, nav, cal, disp, w_sum, lever, t_span, d_odo, nominal, r_vel, tau_fwd):
    """Odometer + motion-constraint velocity update (001 eqs. 18-20) of (x, P); returns the innovation (3,).

    d_odo is the odometer distance over the epoch, travel of the body reference point; disp is the IMU's
    displacement, so the IMU's turn about the lever arm, w_eb x l (w_sum the angle increment in b), is taken out
    of its velocity first (in the snake's bends it is 0.3 w_z along the face for a lever arm of 0.3 m across). 001 eq. 20 evaluates H at the true velocity. Measured
    velocities there (the odometer's quantization, the IMU's vibration) would put the same noise into H and z, and
    that correlation biases the scale and mounting estimates at every update (errors in variables). H uses the
    nominal motion instead: along the odometer axis at the odometer speed averaged up to two epochs back
    (nominal[0]; the quantization error of the last reading, nominal[4], is also in this one's, with the opposite
    sign)."""
    c_bn = quat_mat(nav[QUAT])
    c_nb = c_bn.T
    c_bm = rotvec_mat(cal[CAL_MOUNT]).T
    w_ie, _w_en = nav_rates(nav[LAT], nav[HGT], nav[VEL])
    v_b = c_nb @ (disp / t_span) - cross3(w_sum / t_span - c_nb @ w_ie, lever)
    v_od = d_odo / t_span / (1 + cal[CAL_SCALE])
    v_b_nom = np.array([0.0, nominal[0], 0.0])
    h = np.zeros((3, x.size))
    h[:, _DV:_DV + 3] = c_bm @ c_nb
    h[:, _PHI:_PHI + 3] = -c_bm @ c_nb @ skew3(c_bn @ v_b_nom)
    h[:, _AL:_AL + 3] = -c_bm @ skew3(v_b_nom)
    h[1, ODO_SCALE] = -(c_bm @ v_b_nom)[1]
    z = c_bm @ v_b - np.array([0.0, v_od, 0.0])
    nominal[0] += (nominal[4] - nominal[0]) * min(1.0, t_span / tau_fwd)
    nominal[4] = v_od
    innov = z - h @ x
    joseph_update(x, p, z, h, r_vel)
    return innov


@nb.njit(cache=True)
def stand_update(x, p, nav, disp, w_sum, t_span, nominal, r_zupt, r_zaru):
    """Zero-velocity (004 eq. 2) and zero-rate updates of (x, P) while the shearer stands (any state count >= 15).

    The zero velocity is that of the epoch's mean, disp / t_span (disp the IMU's displacement over the epoch), not
    of its last sample: a standing machine still shakes, and a tone whose period divides the epoch (a 30 Hz pick
    tone at 10 Hz updates) shows its velocity at the same phase at every epoch end. Taken as the velocity error,
    that sample holds the mechanized velocity off by it and moves the position steadily (1.4 mm/s, 0.4 m over
    seed004's 5 min alignment stand); over whole epochs the tone averages out."""
    nominal[0] = nominal[4] = 0.0
    n = x.size
    h = np.zeros((3, n))
    for i in range(3):
        h[i, _DV + i] = 1.0
    joseph_update(x, p, disp / t_span, h, np.eye(3) * r_zupt ** 2)
    c_nb = quat_mat(nav[QUAT]).T
    w_ie, _w_en = nav_rates(nav[LAT], nav[HGT], nav[VEL])
    h = np.zeros((3, n))
    h[:, _PHI:_PHI + 3] = c_nb @ skew3(w_ie)
    for i in range(3):
        h[i, _BG + i] = 1.0
    joseph_update(x, p, w_sum / t_span - c_nb @ w_ie, h, np.eye(3) * r_zaru ** 2)


@nb.njit(cache=True)
def keep_covariance(x, p, p_fallback):
    """Symmetrize P; if a variance is not positive and finite, restore p_fallback and drop the update x.
    Returns True when P had to be repaired."""
    p[:, :] = 0.5 * (p + p.T)
    for i in range(x.size):
        if not (p[i, i] > 0.0) or not np.isfinite(p[i, i]):
            p[:, :] = p_fallback
            x[:] = 0.0
            return True
    return False


@nb.njit(cache=True)
def run_filter(j0, j1, steps, t_mech, phi_b, dv_b, odo_dist, odo_mode, fix_epoch, fix_llh, fix_r, fix_gate, q_psd,
               params,
               nav, cal, p, nominal, out_nav, out_cal, x_post, p_post, p_pred, phi_store, flags, nis_out,
               vel_innov):
    """Filter epochs j0+1 .. j1 (epoch j ends mechanization step j * steps); state (nav, cal, p) in place.

    odo_mode[j]: 1 moving with a valid odometer over (j-1, j], 0 standing, -1 odometer missing (skipped).
    nominal (N_NOMINAL,): the running means of the odometer speed and of the specific force in n that H and F are
    evaluated at, and the last odometer speed (carried across calls).
    Fixes (fix_epoch sorted, fix_llh (F, 3) lat/lon/h, fix_r (F, 3, 3) ENU covariance, fix_gate (F,) the largest
    normalized innovation squared accepted) apply at their epoch.
    Stores per epoch: posterior navigation and calibration, covariance, the update x+ and Phi for the smoother,
    the velocity innovation in m (NaN where none) and, per fix, its normalized innovation squared.
    """
    lever = params[P_LEVER:P_LEVER + 3]
    r_vel = np.diag(np.array([params[P_R_LATERAL], params[P_R_ALONG], params[P_R_VERTICAL]]) ** 2)
    k_fix = np.searchsorted(fix_epoch, j0 + 1)
    x = np.zeros(N_STATES)
    for j in range(j0 + 1, j1 + 1):
        t_span, f_sum, disp, w_sum = mechanize_epoch(nav, cal, t_mech, phi_b, dv_b, (j - 1) * steps, steps)
        phi, qd = transition(nav, nominal, f_sum, t_span, q_psd, params[P_TAU_FORCE])
        p[:, :] = phi @ p @ phi.T + qd
        phi_store[j] = phi
        p_pred[j] = p
        x[:] = 0.0
        flag = 0
        if odo_mode[j] == 1:
            vel_innov[j] = odometer_update(x, p, nav, cal, disp, w_sum, lever, t_span, odo_dist[j] - odo_dist[j - 1], nominal,
                                           r_vel, params[P_TAU_FWD])
            flag |= FLAG_VELOCITY
        elif odo_mode[j] == 0:
            stand_update(x, p, nav, disp, w_sum, t_span, nominal, params[P_R_ZUPT], params[P_R_ZARU])
            flag |= FLAG_ZUPT
        else:
            flag |= FLAG_SKIPPED
        while k_fix < fix_epoch.size and fix_epoch[k_fix] == j:
            z, h = fix_measurement(nav, lever, fix_llh[k_fix], N_STATES)
            nis_out[k_fix], applied = gated_update(x, p, z, h, fix_r[k_fix], fix_gate[k_fix])
            flag |= FLAG_POSITION if applied else FLAG_SKIPPED
            k_fix += 1
        if keep_covariance(x, p, p_pred[j]):
            flag |= FLAG_COVARIANCE_REPAIRED
        apply_correction(nav, cal, x)
        x_post[j] = x
        p_post[j] = p
        out_nav[j] = nav
        out_cal[j] = cal
        flags[j] = flag
