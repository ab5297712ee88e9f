"""The SINS/odometer error Kalman filter of 001 section 3 (19 states) plus the accelerometer triad's
non-orthogonality (3 states) as one sequential numba kernel.

Error state: estimators.kalman.error_state (001 eq. 12's order, then the non-orthogonality da).

The non-orthogonality is not in 001. A symmetric A in f~ = (I + A) f + nabla is, while the body stays level, one
more bias (A [0, 0, g]); but as the pitch follows the floor the z accelerometer reads a_yz g sin(theta), which
looks like an along-face bias, and a filter without it takes the pitch changes as separating the level from
the bias: its pitch comes out wrong by a_yz while it claims a fraction of that (seed001: 0.065 deg against 0.029).

Dynamics (001 eqs. 13-15, with the Earth and transport rates kept in full and the free-air gravity gradient on
the vertical channel; position errors dp in ENU metres):

    d(dv)/dt  = f_n x phi - (2 w_ie + w_en) x dv + C_b^n (nabla + N(f_b) da) + w_a
    d(phi)/dt = -(w_ie + w_en) x phi - C_b^n eps + w_g
    d(dp)/dt  = dv,   d(eps)/dt = w_eps,   d(nabla)/dt = w_nabla,   d(dalpha)/dt = 0,   d(dk_D)/dt = 0

discretized per filter step T as Phi = I + F T + (F T)^2 / 2 (001 eq. 17) and Q_d = (Phi Q_c Phi^T + Q_c) T / 2.

Measurements (estimators.kalman.measurements, each a (z, H, R) applied in sequence with the Joseph update of
estimators.kalman.update, 001 eq. 28): odometer + motion constraint while moving (001 eqs. 18-20), zero velocity
(004 eq. 2) and zero rate at a stand, position fixes (001 eqs. 21-22) gated on their normalized innovation.

After the updates the estimate is fed back into the mechanization, the sensor corrections and the odometer
calibration (closed loop), and the error state restarts at zero. The posterior update x+ (before the reset),
the covariances and Phi are stored for the RTS smoother (estimators.kalman.rts).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from estimators.arrays import add, put
from estimators.io.logformat import (
    FLAG_COVARIANCE_REPAIRED,
    FLAG_POSITION,
    FLAG_SKIPPED,
    FLAG_VELOCITY,
    FLAG_ZUPT,
)
from estimators.kalman.error_state import (
    ACCEL_BIAS,
    ACCEL_NONORTH,
    CAL_ACCEL,
    CAL_GYRO,
    CAL_MOUNT,
    CAL_NONORTH,
    CAL_SCALE,
    DV,
    GYRO_BIAS,
    HGT,
    LAT,
    LON,
    N_STATES,
    NOM_FORCE_1,
    NOM_FORCE_2,
    ODO_MOUNT,
    ODO_SCALE,
    QUAT,
    VEL,
)
from estimators.kalman.measurements import (
    odometer_velocity,
    position_fix,
    zero_rate,
    zero_velocity,
)
from estimators.kalman.update import gated_update, joseph_update
from estimators.nav.rotations import mat_rotvec, quat_mat, rotvec_mat
from estimators.sins.error_model import (
    bias_blocks,
    feed_back_navigation,
    navigation_block,
)
from estimators.sins.strapdown import strapdown_step

# The odometer channel of an epoch (t[j-1], t[j]] (estimators.shearer.prepare decides it from the odometer).
MODE_NO_DATA = -1
"""The odometer is missing (outside its log or in a dropout): no update, flagged skipped."""
MODE_STANDING = 0
"""The machine stands: zero velocity and zero rate."""
MODE_MOVING = 1
"""The machine moves: odometer velocity with the motion constraints."""
MODE_SETTLING = 2
"""The odometer has stopped counting but the machine may still coast (Config.stand_settle_s): no update."""

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


@nb.njit(cache=True, inline="always")
def system_matrix(nav, f_n):
    """F (N_STATES x N_STATES) of the error dynamics at the navigation state `nav` with specific force f_n: the
    navigation and bias blocks of estimators.sins.error_model (without the Earth-rate partials), and the
    non-orthogonality's."""
    c_nb = quat_mat(nav[QUAT])
    f = np.zeros((N_STATES, N_STATES))
    navigation_block(f, nav, f_n)
    bias_blocks(f, c_nb)
    put(f[DV, ACCEL_NONORTH], c_nb @ nonorth_matrix(c_nb.T @ f_n))
    return f


@nb.njit(cache=True, inline="always")
def discretize(f, q_psd, dt):
    """Phi = I + F T + (F T)^2 / 2 and Q_d = (Phi Q_c Phi^T + Q_c) T / 2 (001 eq. 17)."""
    ft = f * dt
    phi = np.eye(N_STATES) + ft + 0.5 * (ft @ ft)
    # Phi Q_c as Phi's columns scaled (Q_c is diagonal): the product's every element, one fewer matrix product.
    return phi, 0.5 * ((phi * q_psd) @ phi.T + np.diag(q_psd)) * dt


@nb.njit(cache=True, inline="always")
def apply_correction(nav, cal, x):
    """Feed an error estimate back: corrected navigation state and calibration (in place)."""
    feed_back_navigation(nav, x)
    add(cal[CAL_GYRO], x[GYRO_BIAS])
    add(cal[CAL_ACCEL], x[ACCEL_BIAS])
    add(cal[CAL_NONORTH], x[ACCEL_NONORTH])
    # C_b^m <- C_b^m (I - [dalpha x]), i.e. C_m^b <- (I + [dalpha x]) C_m^b, kept as a rotation vector.
    put(cal[CAL_MOUNT], mat_rotvec(rotvec_mat(x[ODO_MOUNT]) @ rotvec_mat(cal[CAL_MOUNT])))
    cal[CAL_SCALE] = (1 + cal[CAL_SCALE]) * (1 + x[ODO_SCALE]) - 1


@nb.njit(cache=True, inline="always")
def mechanize_epoch(nav, cal, t_mech, phi_b, dv_b, u0, steps):
    """Mechanize steps u0 .. u0+steps-1 with the calibration's corrections (nav in place; estimators.sins.strapdown's
    step with the Earth and transport rates at each interval's start).

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
        nav[LAT], nav[LON], nav[HGT], vel, quat, dv_n, v_bar = strapdown_step(
            nav[LAT], nav[LON], nav[HGT], nav[VEL], nav[QUAT], ph, dv, dt, nav[LAT], nav[HGT], nav[VEL], False)
        put(nav[VEL], vel)
        put(nav[QUAT], quat)
        f_sum += dv_n
        disp += v_bar * dt
        w_sum += ph
    return t_span, f_sum, disp, w_sum


@nb.njit(cache=True, inline="always")
def transition(nav, nominal, f_sum, t_span, q_psd, tau_force):
    """(Phi, Q_d) over the epoch, F evaluated at the nominal specific force (updated here).

    F uses the specific force low-passed by two first-order stages of tau_force each (nominal[NOM_FORCE_1], then
    nominal[NOM_FORCE_2], which F takes), not this step's: the step's carries the machine's vibration, whose
    velocity is also in the innovations (errors in variables again: the vibration would "reveal" a heading error
    through f x phi that is not there). Two stages cut the drum tone by the square of one stage's factor at a
    delay of 2 tau_force, so a speed change (a reversal) still reaches F within seconds, with its area kept."""
    f_now = f_sum / t_span
    if np.all(nominal[NOM_FORCE_1] == 0.0):
        put(nominal[NOM_FORCE_1], f_now)
        put(nominal[NOM_FORCE_2], f_now)
    else:
        gain = min(1.0, t_span / tau_force)
        add(nominal[NOM_FORCE_1], (f_now - nominal[NOM_FORCE_1]) * gain)
        add(nominal[NOM_FORCE_2], (nominal[NOM_FORCE_1] - nominal[NOM_FORCE_2]) * gain)
    return discretize(system_matrix(nav, nominal[NOM_FORCE_2].copy()), q_psd, t_span)


@nb.njit(cache=True, inline="always")
def odometer_aiding(x, p, mode, nav, cal, disp, w_sum, lever, t_span, d_odo, nominal, r_vel, params):
    """The epoch's odometer-channel updates of (x, P) (estimators.kalman.measurements, Joseph form) by mode
    (run_filter's odo_mode, MODE_*): the odometer velocity while moving, zero velocity and zero rate at a stand,
    none while settling or without data (then flagged skipped). Returns (flag bits, velocity innovation (3,),
    NaN unless moving)."""
    innov = np.full(3, np.nan)
    if mode == MODE_MOVING:
        z, h, r = odometer_velocity(nav, cal, disp, w_sum, lever, t_span, d_odo, nominal, r_vel,
                                    params[P_TAU_FWD], x.size)
        innov = z - h @ x
        joseph_update(x, p, z, h, r)
        return FLAG_VELOCITY, innov
    if mode == MODE_STANDING:
        z, h, r = zero_velocity(disp, t_span, nominal, params[P_R_ZUPT], x.size)
        joseph_update(x, p, z, h, r)
        z, h, r = zero_rate(nav, w_sum, t_span, params[P_R_ZARU], x.size)
        joseph_update(x, p, z, h, r)
        return FLAG_ZUPT, innov
    if mode == MODE_SETTLING:
        return 0, innov
    return FLAG_SKIPPED, innov


@nb.njit(cache=True, inline="always")
def keep_covariance(x, p, p_fallback):
    """Symmetrize P; if a variance is not positive and finite, restore p_fallback and drop the update x.
    Returns True when P had to be repaired."""
    put(p, 0.5 * (p + p.T))
    for i in range(x.size):
        if not (p[i, i] > 0.0) or not np.isfinite(p[i, i]):
            put(p, p_fallback)
            x[:] = 0.0
            return True
    return False


@nb.njit(cache=True)
def run_filter(j0, j1, row0, steps, t_mech, phi_b, dv_b, odo_dist, odo_mode, fix_epoch, fix_llh, fix_r, fix_gate, q_psd,
               params,
               nav, cal, p, nominal, out_nav, out_cal, x_post, p_post, p_pred, phi_store, flags, nis_out,
               vel_innov):
    """Filter epochs j0+1 .. j1 (epoch j ends mechanization step j * steps); state (nav, cal, p) in place.

    odo_mode[j]: the odometer channel over (j-1, j], MODE_*.
    nominal (N_NOMINAL,): the running means of the odometer speed and of the specific force in n that H and F are
    evaluated at, and the last odometer speed (carried across calls).
    Fixes (fix_epoch sorted, fix_llh (F, 3) lat/lon/h, fix_r (F, 3, 3) ENU covariance, fix_gate (F,) the largest
    normalized innovation squared accepted) apply at their epoch.
    Stores per epoch j: posterior navigation and calibration, the update x+, flags and the velocity innovation in m
    (NaN where none) in row j; the covariances P_j, P_{j,j-1} and Phi_{j,j-1} for the smoother in row j - row0 of
    p_post, p_pred and phi_store (a block of a pass: its caller keeps them on disk, estimators.kalman.rts); per fix,
    its normalized innovation squared. p_pred and phi_store of one row are scratch (a pass nothing smooths keeps
    neither: 2 x 441 floats an epoch).
    """
    lever = params[P_LEVER:P_LEVER + 3]
    r_vel = np.diag(np.array([params[P_R_LATERAL], params[P_R_ALONG], params[P_R_VERTICAL]]) ** 2)
    k_fix = np.searchsorted(fix_epoch, j0 + 1)
    x = np.zeros(N_STATES)
    smoothed = p_pred.shape[0] > 1
    for j in range(j0 + 1, j1 + 1):
        t_span, f_sum, disp, w_sum = mechanize_epoch(nav, cal, t_mech, phi_b, dv_b, (j - 1) * steps, steps)
        phi, qd = transition(nav, nominal, f_sum, t_span, q_psd, params[P_TAU_FORCE])
        put(p, phi @ p @ phi.T + qd)
        k = j - row0 if smoothed else 0
        put(phi_store[k], phi)
        put(p_pred[k], p)
        x[:] = 0.0
        flag, innov = odometer_aiding(x, p, odo_mode[j], nav, cal, disp, w_sum, lever, t_span,
                                      odo_dist[j] - odo_dist[j - 1], nominal, r_vel, params)
        if flag & FLAG_VELOCITY:
            put(vel_innov[j], innov)
        while k_fix < fix_epoch.size and fix_epoch[k_fix] == j:
            z, h, r = position_fix(nav, lever, fix_llh[k_fix], fix_r[k_fix], N_STATES)
            nis_out[k_fix], applied = gated_update(x, p, z, h, r, fix_gate[k_fix])
            flag |= FLAG_POSITION if applied else FLAG_SKIPPED
            k_fix += 1
        if keep_covariance(x, p, p_pred[k]):
            flag |= FLAG_COVARIANCE_REPAIRED
        apply_correction(nav, cal, x)
        put(x_post[j], x)
        put(p_post[j - row0], p)
        put(out_nav[j], nav)
        put(out_cal[j], cal)
        flags[j] = flag
