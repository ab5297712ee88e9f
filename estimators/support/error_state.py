"""Canopy attitude that keeps its yaw under magnetic disturbance: an error-state filter with gyro-bias states
and disturbed-magnetometer detection (issue 8, item 4; the baseline is 002_5cc0b59ad045ffaa.txt's GD-UKF).

Where 002's UKF takes every magnetometer sample as a yaw measurement (so the shearer's field goes straight into
the yaw) and trusts the gyro without a bias, this filter

* propagates q_nb with the gyro minus its estimated bias and minus the Earth rate (per sample, 002 eq. 12);
* keeps the error state x = [dtheta (body-frame attitude error, C_true = C_est (I + [dtheta x])), db_g];
* every `samples_per_update` samples updates with the mean specific-force direction and the mean magnetometer
  heading of the interval (each sample rotated by the gyro to the interval's end frame before averaging);
* with `zaru_gate` > 0, for a unit that is static but for brief motions (a support canopy), takes the interval's
  mean rate as a zero-rate update of the bias when the unit is static: the mean of gyro - C_n^b w_ie minus the
  bias estimate passes the chi-square gate `zaru_gate` (3 degrees of freedom) and the unit does not accelerate.
  So the bias, the yaw's included, is learnt without the magnetometer, and the yaw holds through a long
  disturbance (a unit switched on next to a standing shearer, with an uncalibrated gyro's turn-on bias of a
  fraction of a deg/s). A unit turning slowly and steadily about the vertical (a turntable) would have its turn
  taken for a bias: off by default;
* rejects a magnetometer update when the field is disturbed: its norm differs from the geomagnetic model's by
  more than `norm_tol`, its dip (from the current attitude) by more than `dip_tol`, or its heading innovation
  fails the chi-square gate `gate`. After `relock_updates` consecutive rejections by the gate alone (norm and
  dip fine) the update is taken with its innovation variance as R, so a yaw that drifted cannot lock it out.
  An accelerometer update is skipped when |f| differs from g by more than `accel_gate` (the unit accelerates);
* keeps the gravity update's gain off the rotation about the vertical (`_tilt_update`), so that the yaw moves
  only with the gyro, the magnetometer and the bias, never with the accelerometer's noise.

Measurement models (H on x, derived in the docstrings of the kernel helpers):
    zero rate, static unit:              mean(gyro - C_n^b w_ie) - b_est = db_g + v,  var(v) = arw^2 / T
    gravity direction u_b = f / |f|:     u_b = C_est^T e_up + [C_est^T e_up x] dtheta + v
    magnetic heading a = atan2(m_E, m_N) of m_n = C_est m_b:
        a - atan2(B_E, B_N) = g^T [B_n x] C_est dtheta + v,   g = [B_N, -B_E, 0] / (B_E^2 + B_N^2)
The declination is in B_n (the geomagnetic model's field in ENU), so no separate correction is needed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from estimators.nav.rotations_scalar import (
    add_rotated,
    mul_exp,
    normalize_continuous,
    quat_mat_into,
    sub_rotated_back,
)
from estimators.support.batch import batch_inputs
from estimators.support.kernel_math import FASTMATH, inv3
from estimators.support.unit_model import UnitModel, start_attitude, wrap

THETA = 0
"""Error state: dtheta, the body-frame attitude error [rad] (3), C_true = C_est (I + [dtheta x])."""
BIAS = 3
"""Error state: db_g, the gyro bias error [rad/s] (3)."""
N_ERR = 6
"""Size of the error state."""

FLAG_NORM = 1
"""Magnetometer sample rejected: its norm differs from the model's."""
FLAG_DIP = 2
"""Rejected: its dip differs from the model's inclination."""
FLAG_GATE = 4
"""Rejected: its heading innovation failed the chi-square gate."""
FLAG_ACCEL = 8
"""Accelerometer update skipped: the unit accelerates."""
FLAG_STATIC = 16
"""Zero-rate update applied: the unit was static over the interval."""


@dataclass(frozen=True)
class OursSettings:
    """Tuning of the filter (SI). Noise densities are one-sigma; tolerances are absolute."""

    samples_per_update: int = 10
    gyro_arw: float = 1e-3  # [rad/sqrt(s)] angle random walk of the gyro (plus unmodelled rate errors)
    gyro_bias_walk: float = 1e-5  # [rad/s/sqrt(s)] random walk of the gyro bias
    attitude_sigma0: float = 0.05  # [rad] the start's attitude uncertainty
    gyro_bias_sigma0: float = 0.01  # [rad/s] the start's bias uncertainty (the grade's turn-on bias)
    accel_sigma: float = 2e-3  # [m/s^2] per sample, plus what the unit's vibration adds
    accel_gate: float = 0.5  # [m/s^2]
    mag_sigma: float = 2e-7  # [T] per sample, plus the unmodelled field (environment)
    norm_tol: float = 1.0e-6  # [T]
    dip_tol: float = 0.02  # [rad]
    gate: float = 10.83  # chi-square, 1 degree of freedom, 0.999
    relock_updates: int = 300
    zaru_gate: float = 0.0  # chi-square, 3 degrees of freedom (16.27: 0.999); 0: no zero-rate updates


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _propagate_covariance(p, crel, t_int, qd, fp):
    """P <- F P F^T + diag(qd) for F = [[C_rel^T, -T I], [0, I]]: dtheta_end = C_rel^T dtheta_start - T db."""
    for j in range(N_ERR):
        for i in range(3):
            fp[THETA + i, j] = (crel[0, i] * p[THETA, j] + crel[1, i] * p[THETA + 1, j] + crel[2, i] * p[THETA + 2, j]
                                - t_int * p[BIAS + i, j])
        for i in range(BIAS, BIAS + 3):
            fp[i, j] = p[i, j]
    for i in range(N_ERR):
        for j in range(3):
            p[i, THETA + j] = (fp[i, THETA] * crel[0, j] + fp[i, THETA + 1] * crel[1, j] + fp[i, THETA + 2] * crel[2, j]
                               - t_int * fp[i, BIAS + j])
        for j in range(BIAS, BIAS + 3):
            p[i, j] = fp[i, j]
    for i in range(N_ERR):
        p[i, i] += qd[i]
        for j in range(i):
            v = 0.5 * (p[i, j] + p[j, i])
            p[i, j] = v
            p[j, i] = v


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _innovation(p, dx, h, y, ph):
    """(innovation y - h dx against the correction dx made so far, h P h^T) of a scalar measurement row h (N_ERR,);
    fills ph = P h^T."""
    hph, innov = 0.0, y
    for i in range(N_ERR):
        v = 0.0
        for j in range(N_ERR):
            v += p[i, j] * h[j]
        ph[i] = v
        hph += h[i] * v
        innov -= h[i] * dx[i]
    return innov, hph


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _scalar_update(p, dx, ph, innov, s):
    """Kalman update of the error state dx and P by one scalar measurement: K = P h^T / s, s = h P h^T + r."""
    for i in range(N_ERR):
        dx[i] += ph[i] / s * innov
    for i in range(N_ERR):
        for j in range(i + 1):
            v = p[i, j] - ph[i] * ph[j] / s
            p[i, j] = v
            p[j, i] = v


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _tilt_update(p, dx, ph, innov, s, up, k):
    """`_scalar_update` for a gravity-direction row, its gain stripped of the components along the body's up vector
    `up` (attitude and bias): gravity says nothing of a rotation about the vertical, and without the magnetometer
    the yaw's variance grows large, so a null space of H moved by the last correction would leak noise into the
    yaw (the EKF's spurious observability). Joseph form, the gain being suboptimal."""
    for i in range(N_ERR):
        k[i] = ph[i] / s
    for blk in (THETA, BIAS):
        along = k[blk] * up[0] + k[blk + 1] * up[1] + k[blk + 2] * up[2]
        for i in range(3):
            k[blk + i] -= along * up[i]
    for i in range(N_ERR):
        dx[i] += k[i] * innov
    for i in range(N_ERR):
        for j in range(i + 1):
            v = p[i, j] - k[i] * ph[j] - ph[i] * k[j] + k[i] * k[j] * s
            p[i, j] = v
            p[j, i] = v


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _ours_kernel(gyro, accel, mag, dt, m_upd, q0, p0, qd, field_n, w_ie_n, g_norm, var_acc, var_mag_angle_t2,
                 accel_gate, norm_tol, dip_tol, gate, relock, zaru_gate, var_zaru, out_q, out_b, out_flag, out_sigma):
    """The module's filter for each unit f (prange): per sample the propagation, every m_upd samples the updates
    and the reset, whose results go to row u of the outputs."""
    nf, nk = gyro.shape[0], gyro.shape[1]
    bn = np.sqrt(field_n[0] ** 2 + field_n[1] ** 2 + field_n[2] ** 2)
    bh2 = field_n[0] ** 2 + field_n[1] ** 2
    a_ref = np.arctan2(field_n[0], field_n[1])
    dip_ref = np.arctan2(-field_n[2], np.sqrt(bh2))
    # Heading sensitivity to the n-frame attitude error: g^T [B_n x], g = [B_N, -B_E, 0] / (B_E^2 + B_N^2).
    g0, g1 = field_n[1] / bh2, -field_n[0] / bh2
    hmag_n = np.array([g1 * field_n[2], -g0 * field_n[2], g0 * field_n[1] - g1 * field_n[0]])
    t_int = m_upd * dt
    for f in nb.prange(nf):
        q = q0[f].copy()
        b = np.zeros(3)
        p = p0.copy()
        fp = np.empty((N_ERR, N_ERR))
        w = np.empty(3)
        qrel = np.empty(4)
        sf, sm, sw = np.zeros(3), np.zeros(3), np.zeros(3)
        c, crel, s3, s3i = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
        yw = np.empty(3)
        fb, mb, mn = np.empty(3), np.empty(3), np.empty(3)
        h, ph, dx, gain = np.zeros(N_ERR), np.empty(N_ERR), np.zeros(N_ERR), np.empty(N_ERR)
        rejected = 0
        u = 0
        qrel[0], qrel[1], qrel[2], qrel[3] = 1.0, 0.0, 0.0, 0.0
        for k in range(nk):
            # Per sample: propagate with the bias-corrected rate; accumulate f and m in the interval's start frame.
            sub_rotated_back(gyro[f, k], q, w_ie_n, w)  # gyro minus C_n^b w_ie
            for i in range(3):
                sw[i] += w[i]
            a0, a1, a2 = (w[0] - b[0]) * dt, (w[1] - b[1]) * dt, (w[2] - b[2]) * dt
            mul_exp(q, a0, a1, a2)
            mul_exp(qrel, a0, a1, a2)
            add_rotated(qrel, accel[f, k], sf)
            add_rotated(qrel, mag[f, k], sm)
            if (k + 1) % m_upd != 0:
                continue
            normalize_continuous(q, q)
            normalize_continuous(qrel, qrel)
            quat_mat_into(qrel, crel)
            _propagate_covariance(p, crel, t_int, qd, fp)
            for i in range(3):  # interval means in the end frame: C_rel^T s / m
                fb[i] = (crel[0, i] * sf[0] + crel[1, i] * sf[1] + crel[2, i] * sf[2]) / m_upd
                mb[i] = (crel[0, i] * sm[0] + crel[1, i] * sm[1] + crel[2, i] * sm[2]) / m_upd
            quat_mat_into(q, c)
            flag = 0
            dx[:] = 0.0
            fn = np.sqrt(fb[0] ** 2 + fb[1] ** 2 + fb[2] ** 2)
            if abs(fn - g_norm[f]) > accel_gate:
                flag |= FLAG_ACCEL
            elif zaru_gate > 0:
                # Zero rate: y = mean(gyro - C_n^b w_ie) - b, S = P_bb + R; static when y^T S^-1 y passes the gate.
                for i in range(3):
                    yw[i] = sw[i] / m_upd - b[i]
                    for j in range(3):
                        s3[i, j] = p[BIAS + i, BIAS + j]
                    s3[i, i] += var_zaru
                inv3(s3, s3i)
                chi2 = 0.0
                for i in range(3):
                    chi2 += yw[i] * (s3i[i, 0] * yw[0] + s3i[i, 1] * yw[1] + s3i[i, 2] * yw[2])
                if chi2 <= zaru_gate:
                    flag |= FLAG_STATIC
                    for i in range(3):
                        h[:] = 0.0
                        h[BIAS + i] = 1.0
                        innov, hph = _innovation(p, dx, h, yw[i], ph)
                        _scalar_update(p, dx, ph, innov, hph + var_zaru)
            h[:] = 0.0
            if flag & FLAG_ACCEL == 0:
                # Gravity direction u_b = C^T e_up + [C^T e_up x] dtheta, three scalar updates (R diagonal).
                r_acc = var_acc / (fn * fn * m_upd)
                up = c[2]  # C^T e_up: the third row of C_b^n
                up0, up1, up2 = up[0], up[1], up[2]
                for i in range(3):
                    if i == 0:
                        h[THETA], h[THETA + 1], h[THETA + 2] = 0.0, -up2, up1
                    elif i == 1:
                        h[THETA], h[THETA + 1], h[THETA + 2] = up2, 0.0, -up0
                    else:
                        h[THETA], h[THETA + 1], h[THETA + 2] = -up1, up0, 0.0
                    innov, hph = _innovation(p, dx, h, fb[i] / fn - c[2, i], ph)
                    _tilt_update(p, dx, ph, innov, hph + r_acc, up, gain)
            # Magnetic heading, with the disturbance tests.
            for i in range(3):
                mn[i] = c[i, 0] * mb[0] + c[i, 1] * mb[1] + c[i, 2] * mb[2]
            if abs(np.sqrt(mb[0] ** 2 + mb[1] ** 2 + mb[2] ** 2) - bn) > norm_tol:
                flag |= FLAG_NORM
            if abs(np.arctan2(-mn[2], np.sqrt(mn[0] ** 2 + mn[1] ** 2)) - dip_ref) > dip_tol:
                flag |= FLAG_DIP
            if flag & (FLAG_NORM | FLAG_DIP) == 0:
                for j in range(3):
                    h[THETA + j] = hmag_n[0] * c[0, j] + hmag_n[1] * c[1, j] + hmag_n[2] * c[2, j]
                innov, hph = _innovation(p, dx, h, wrap(np.arctan2(mn[0], mn[1]) - a_ref), ph)
                r_mag = var_mag_angle_t2 / (bh2 * m_upd)
                if innov * innov <= gate * (hph + r_mag):
                    rejected = 0
                    _scalar_update(p, dx, ph, innov, hph + r_mag)
                elif rejected + 1 > relock:  # gate-only rejections this long: take it, its innovation as R
                    rejected = 0
                    _scalar_update(p, dx, ph, innov, hph + innov * innov)
                else:
                    rejected += 1
                    flag |= FLAG_GATE
            # Reset: fold the error into q and b.
            mul_exp(q, dx[THETA], dx[THETA + 1], dx[THETA + 2])
            normalize_continuous(q, q)
            for i in range(3):
                b[i] += dx[BIAS + i]
            out_q[f, u] = q
            out_b[f, u] = b
            out_flag[f, u] = flag
            for i in range(N_ERR):
                out_sigma[f, u, i] = np.sqrt(p[i, i])
            u += 1
            qrel[0], qrel[1], qrel[2], qrel[3] = 1.0, 0.0, 0.0, 0.0
            sf[:] = 0.0
            sm[:] = 0.0
            sw[:] = 0.0


@dataclass
class OursResult:
    """Outputs at the update samples (every samples_per_update-th sample, index `sample`)."""

    sample: np.ndarray  # (U,) index of the input sample each row follows
    q_nb: np.ndarray  # (N, U, 4)
    gyro_bias: np.ndarray  # (N, U, 3) [rad/s]
    flags: np.ndarray  # (N, U) FLAG_* bits
    sigma: np.ndarray  # (N, U, N_ERR) one-sigma of dtheta [rad] and the bias [rad/s]


def ours(gyro, accel, mag, dt: float, model: UnitModel, settings: OursSettings = OursSettings(),
         q0=None) -> OursResult:
    """Run the filter on a batch of units: gyro [rad/s], accel [m/s^2], mag [T] of shape (K, 3) or (N, K, 3)."""
    gyro, accel, mag = batch_inputs(gyro, accel, mag)
    s = settings
    n, k = gyro.shape[:2]
    m = int(s.samples_per_update)
    if m < 1:
        raise ValueError(f"samples_per_update must be >= 1, got {m}")
    p0 = np.diag([s.attitude_sigma0 ** 2] * 3 + [s.gyro_bias_sigma0 ** 2] * 3)
    t_int = m * dt
    qd = np.array([s.gyro_arw ** 2 * t_int] * 3 + [s.gyro_bias_walk ** 2 * t_int] * 3)
    g_norm = np.median(np.linalg.norm(accel[:, :: max(1, k // 1000)], axis=-1), axis=1)  # |g| each unit reads
    u = k // m
    out_q, out_b = np.empty((n, u, 4)), np.empty((n, u, 3))
    out_flag, out_sigma = np.empty((n, u), np.int8), np.empty((n, u, N_ERR))
    _ours_kernel(gyro, accel, mag, float(dt), m, start_attitude(q0, accel, mag, model), p0, qd,
                 np.asarray(model.field_n, float), np.asarray(model.earth_rate_n, float), g_norm,
                 float(s.accel_sigma ** 2), float(s.mag_sigma ** 2), float(s.accel_gate), float(s.norm_tol),
                 float(s.dip_tol), float(s.gate), int(s.relock_updates), float(s.zaru_gate),
                 float(s.gyro_arw ** 2 / t_int), out_q, out_b, out_flag, out_sigma)
    return OursResult(np.arange(1, u + 1) * m - 1, out_q, out_b, out_flag, out_sigma)


__all__ = ["BIAS", "FLAG_ACCEL", "FLAG_DIP", "FLAG_GATE", "FLAG_NORM", "FLAG_STATIC", "N_ERR", "THETA", "OursResult",
           "OursSettings", "ours"]
