"""Canopy attitude that keeps its yaw under magnetic disturbance: an error-state filter with gyro-bias states
and disturbed-magnetometer detection (issue 8, item 4; the baseline is 002_5cc0b59ad045ffaa.txt's GD-UKF).

Where 002's UKF takes every magnetometer sample as a yaw measurement (so the shearer's field goes straight into
the yaw) and trusts the gyro without a bias, this filter

* propagates q_nb with the gyro minus its estimated bias and minus the Earth rate (per sample, 002 eq. 12);
* keeps the error state x = [dtheta (body-frame attitude error, C_true = C_est (I + [dtheta x])), db_g];
* every `samples_per_update` samples updates with the mean specific-force direction and the mean magnetometer
  heading of the interval (each sample rotated by the gyro to the interval's end frame before averaging);
* rejects a magnetometer update when the field is disturbed: its norm differs from the geomagnetic model's by
  more than `norm_tol`, its dip (from the current attitude) by more than `dip_tol`, or its heading innovation
  fails the chi-square gate `gate`. After `relock_updates` consecutive rejections by the gate alone (norm and
  dip fine) the update is taken with its innovation variance as R, so a yaw that drifted cannot lock it out.
  An accelerometer update is skipped when |f| differs from g by more than `accel_gate` (the unit accelerates).

Measurement models (H on x, derived in the docstrings of the kernel helpers):
    gravity direction u_b = f / |f|:     u_b = C_est^T e_up + [C_est^T e_up x] dtheta + v
    magnetic heading a = atan2(m_E, m_N) of m_n = C_est m_b:
        a - atan2(B_E, B_N) = g^T [B_n x] C_est dtheta + v,   g = [B_N, -B_E, 0] / (B_E^2 + B_N^2)
The declination is in B_n (the geomagnetic model's field in ENU), so no separate correction is needed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from estimators.support_attitude import (
    UnitModel,
    _inputs,
    body_rate,
    initial_attitude,
    wrap,
)

FLAG_NORM = 1
"""Magnetometer sample rejected: its norm differs from the model's."""
FLAG_DIP = 2
"""Rejected: its dip differs from the model's inclination."""
FLAG_GATE = 4
"""Rejected: its heading innovation failed the chi-square gate."""
FLAG_ACCEL = 8
"""Accelerometer update skipped: the unit accelerates."""


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


@nb.njit(cache=True, inline="always")
def _rot(q, v, out):
    """out = C(q) v (q scalar first, Hamilton)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    tx = 2.0 * (y * v[2] - z * v[1])
    ty = 2.0 * (z * v[0] - x * v[2])
    tz = 2.0 * (x * v[1] - y * v[0])
    out[0] = v[0] + w * tx + (y * tz - z * ty)
    out[1] = v[1] + w * ty + (z * tx - x * tz)
    out[2] = v[2] + w * tz + (x * ty - y * tx)


@nb.njit(cache=True, inline="always")
def _mul_exp(q, a, out):
    """out = q (x) exp(a / 2), normalised (002 eq. 12 for the increment a [rad])."""
    ang = np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    c = np.cos(0.5 * ang)
    s = 0.5 - ang * ang / 48.0 if ang < 1e-4 else np.sin(0.5 * ang) / ang
    r0, r1, r2, r3 = c, s * a[0], s * a[1], s * a[2]
    w, x, y, z = q[0], q[1], q[2], q[3]
    o0 = w * r0 - x * r1 - y * r2 - z * r3
    o1 = w * r1 + x * r0 + y * r3 - z * r2
    o2 = w * r2 - x * r3 + y * r0 + z * r1
    o3 = w * r3 + x * r2 - y * r1 + z * r0
    n = np.sqrt(o0 * o0 + o1 * o1 + o2 * o2 + o3 * o3)
    out[0], out[1], out[2], out[3] = o0 / n, o1 / n, o2 / n, o3 / n


@nb.njit(cache=True, inline="always")
def _mat(q, c):
    """C_b^n of q into c (3x3)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    c[0, 0], c[0, 1], c[0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    c[1, 0], c[1, 1], c[1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    c[2, 0], c[2, 1], c[2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)


@nb.njit(cache=True, inline="always")
def _update(p, x, h, y, r, m):
    """Kalman update of the 6-state x, P with m rows of h (m x 6), innovation y, diagonal R r (m,)."""
    hp = h[:m] @ p
    s = hp @ h[:m].T
    for i in range(m):
        s[i, i] += r[i]
    gain = np.linalg.solve(s, hp).T
    x += gain @ y[:m]
    p -= gain @ hp
    for i in range(6):
        for j in range(i):
            v = 0.5 * (p[i, j] + p[j, i])
            p[i, j] = v
            p[j, i] = v


@nb.njit(cache=True, parallel=True)
def _ours_kernel(gyro, accel, mag, dt, m_upd, q0, p0, qd, field_n, w_ie_n, g_norm, var_acc, var_mag_angle_t2,
                 accel_gate, norm_tol, dip_tol, gate, relock, out_q, out_b, out_flag, out_sigma):
    nf, nk = gyro.shape[0], gyro.shape[1]
    bn = np.sqrt(field_n[0] ** 2 + field_n[1] ** 2 + field_n[2] ** 2)
    bh2 = field_n[0] ** 2 + field_n[1] ** 2
    a_ref = np.arctan2(field_n[0], field_n[1])
    dip_ref = np.arctan2(-field_n[2], np.sqrt(bh2))
    sk_b = np.zeros((3, 3))
    sk_b[0, 1], sk_b[0, 2], sk_b[1, 0] = -field_n[2], field_n[1], field_n[2]
    sk_b[1, 2], sk_b[2, 0], sk_b[2, 1] = -field_n[0], -field_n[1], field_n[0]
    gv = np.array([field_n[1], -field_n[0], 0.0]) / bh2
    hmag_n = gv @ sk_b  # (3,): heading sensitivity to the n-frame error
    for f in nb.prange(nf):
        q = q0[f].copy()
        qn = np.empty(4)
        b = np.zeros(3)
        p = p0.copy()
        w = np.empty(3)
        a = np.empty(3)
        qrel = np.array([1.0, 0.0, 0.0, 0.0])
        sf = np.zeros(3)
        sm = np.zeros(3)
        v = np.empty(3)
        c = np.empty((3, 3))
        crel = np.empty((3, 3))
        h = np.zeros((3, 6))
        y = np.empty(3)
        r = np.empty(3)
        dx = np.zeros(6)
        rejected = 0
        u = 0
        for k in range(nk):
            # Per sample: propagate with the bias-corrected rate; accumulate f and m in the interval's start frame.
            body_rate(gyro[f, k], q, w_ie_n, w)
            for i in range(3):
                a[i] = (w[i] - b[i]) * dt
            _mul_exp(q, a, qn)
            q[:] = qn
            _mul_exp(qrel, a, qn)
            qrel[:] = qn
            _rot(qrel, accel[f, k], v)
            sf += v
            _rot(qrel, mag[f, k], v)
            sm += v
            if (k + 1) % m_upd != 0:
                continue
            # Covariance over the interval T: dtheta_end = C_rel^T dtheta_start - T db (small rotation in T).
            t_int = m_upd * dt
            _mat(qrel, crel)
            fmat = np.eye(6)
            fmat[:3, :3] = crel.T
            for i in range(3):
                fmat[i, 3 + i] = -t_int
            p[:, :] = fmat @ p @ fmat.T + qd
            flag = 0
            fb = crel.T @ sf / m_upd
            mb = crel.T @ sm / m_upd
            _mat(q, c)
            dx[:] = 0.0
            # Gravity direction.
            fn = np.sqrt(fb[0] ** 2 + fb[1] ** 2 + fb[2] ** 2)
            if abs(fn - g_norm) > accel_gate:
                flag |= FLAG_ACCEL
            else:
                up = c[2]  # C^T e_up: the third row of C_b^n
                h[:, :] = 0.0
                h[0, 1], h[0, 2], h[1, 0] = -up[2], up[1], up[2]
                h[1, 2], h[2, 0], h[2, 1] = -up[0], -up[1], up[0]
                for i in range(3):
                    y[i] = fb[i] / fn - up[i]
                    r[i] = var_acc / (fn * fn * m_upd)
                _update(p, dx, h, y, r, 3)
            # Magnetic heading, with the disturbance tests.
            mn = c @ mb
            mnorm = np.sqrt(mb[0] ** 2 + mb[1] ** 2 + mb[2] ** 2)
            if abs(mnorm - bn) > norm_tol:
                flag |= FLAG_NORM
            if abs(np.arctan2(-mn[2], np.sqrt(mn[0] ** 2 + mn[1] ** 2)) - dip_ref) > dip_tol:
                flag |= FLAG_DIP
            h[:, :] = 0.0
            hrow = hmag_n @ c
            h[0, 0], h[0, 1], h[0, 2] = hrow[0], hrow[1], hrow[2]
            y[0] = wrap(np.arctan2(mn[0], mn[1]) - a_ref)
            # innovation relative to the state correction already made by the gravity update
            y[0] -= hrow[0] * dx[0] + hrow[1] * dx[1] + hrow[2] * dx[2]
            r[0] = var_mag_angle_t2 / (bh2 * m_upd)
            s = r[0]
            for i in range(3):
                for j in range(3):
                    s += hrow[i] * p[i, j] * hrow[j]
            if flag & (FLAG_NORM | FLAG_DIP) == 0:
                if y[0] * y[0] > gate * s:
                    rejected += 1
                    if rejected > relock:
                        r[0] = y[0] * y[0]
                        rejected = 0
                        _update(p, dx, h, y, r, 1)
                    else:
                        flag |= FLAG_GATE
                else:
                    rejected = 0
                    _update(p, dx, h, y, r, 1)
            # Reset: fold the error into q and b.
            _mul_exp(q, dx[:3], qn)
            q[:] = qn
            b += dx[3:]
            out_q[f, u] = q
            out_b[f, u] = b
            out_flag[f, u] = flag
            for i in range(6):
                out_sigma[f, u, i] = np.sqrt(p[i, i])
            u += 1
            qrel[:] = 0.0
            qrel[0] = 1.0
            sf[:] = 0.0
            sm[:] = 0.0


@dataclass
class OursResult:
    """Outputs at the update samples (every samples_per_update-th sample, index `sample`)."""

    sample: np.ndarray  # (U,) index of the input sample each row follows
    q_nb: np.ndarray  # (N, U, 4)
    gyro_bias: np.ndarray  # (N, U, 3) [rad/s]
    flags: np.ndarray  # (N, U) FLAG_* bits
    sigma: np.ndarray  # (N, U, 6) one-sigma of dtheta [rad] and the bias [rad/s]


def ours(gyro, accel, mag, dt: float, model: UnitModel, settings: OursSettings = OursSettings(),
         q0=None) -> OursResult:
    """Run the filter on a batch of units: gyro [rad/s], accel [m/s^2], mag [T] of shape (K, 3) or (N, K, 3)."""
    gyro, accel, mag = _inputs(gyro, accel, mag)
    s = settings
    n, k = gyro.shape[:2]
    m = int(s.samples_per_update)
    if m < 1:
        raise ValueError(f"samples_per_update must be >= 1, got {m}")
    q0 = initial_attitude(accel, mag, model) if q0 is None else np.broadcast_to(np.asarray(q0, float), (n, 4))
    p0 = np.diag([s.attitude_sigma0 ** 2] * 3 + [s.gyro_bias_sigma0 ** 2] * 3)
    t_int = m * dt
    qd = np.diag([s.gyro_arw ** 2 * t_int] * 3 + [s.gyro_bias_walk ** 2 * t_int] * 3)
    g_norm = float(np.median(np.linalg.norm(accel[:, :: max(1, k // 1000)], axis=-1)))  # |g| at the site
    u = k // m
    out_q, out_b = np.empty((n, u, 4)), np.empty((n, u, 3))
    out_flag, out_sigma = np.empty((n, u), np.int8), np.empty((n, u, 6))
    _ours_kernel(gyro, accel, mag, float(dt), m, np.ascontiguousarray(q0), p0, qd,
                 np.asarray(model.field_n, float), np.asarray(model.earth_rate_n, float), g_norm,
                 float(s.accel_sigma ** 2), float(s.mag_sigma ** 2), float(s.accel_gate), float(s.norm_tol),
                 float(s.dip_tol), float(s.gate), int(s.relock_updates), out_q, out_b, out_flag, out_sigma)
    return OursResult(np.arange(1, u + 1) * m - 1, out_q, out_b, out_flag, out_sigma)


__all__ = ["FLAG_ACCEL", "FLAG_DIP", "FLAG_GATE", "FLAG_NORM", "OursResult", "OursSettings", "ours", "wrap"]
