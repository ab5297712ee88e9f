"""Canopy attitude of a hydraulic support from a 9-axis unit after 002_5cc0b59ad045ffaa.txt.

Conventions are the project's, not 002's (002 uses NED, X forward, Z down, yaw clockwise): frames b (x right,
y forward, z up) and n (ENU), C_b^n = Rz(yaw) Rx(pitch) Ry(roll), yaw counter-clockwise from north. 002's
pitch (nose up) is our pitch about x, its roll (left side up) our roll about y, its yaw our -yaw. Every
equation below is 002's rewritten in this convention; the docstrings say which one.

Contents
--------
* accelerometer pitch and roll (002 eqs. 7-8), tilt-compensated magnetic yaw with declination (eqs. 3-6),
  quaternion propagation by the gyro (eqs. 10-12), the measurement covariance from the sensor variances
  (eqs. 24-28) and the Euler output function of a quaternion (eq. 21);
* the quaternion UKF of 002 section 3 (state q, process eqs. 18-19 with Q of eq. 23, measurement eqs. 20-21,
  sigma points and weights eqs. 16-17 from filterpy's MerweScaledSigmaPoints, recursion eqs. 29-34), as a
  numba kernel over a batch of independent filters (supports, or Q candidates of the tuning);
* the linear quaternion KF baseline (same state and process; the accelerometer/magnetometer quaternion as
  a linear measurement);
* the gradient-descent tuning of Q's rate variances (eq. 35, steps 1.1-1.4) with the objective per iteration.

The scalar formulas are written once with numpy functions (numba's register_jitable) so that they serve both
numpy arrays (the API) and numba scalars (the kernels).

Rate-noise variances sigma_w^2 of Q (eq. 23) are in (rad/s)^2: Q_k = dt^2 / 4 Xi(q) diag(sigma_w^2) Xi(q)^T,
the covariance of the quaternion step driven by white rate deviations held over one sample.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba as nb
import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints
from numba.extending import register_jitable

# --------------------------------------------------------------------------------------------------------------
# Attitude from single sensors (002 section 2.3)


@register_jitable
def accel_pitch_roll(fx, fy, fz):
    """Pitch and roll [rad] from the specific force in b (002 eqs. 7-8 in the project's convention).

    At rest f_b = C_n^b [0, 0, g] = g [-cos(pitch) sin(roll), sin(pitch), cos(pitch) cos(roll)], so
    pitch = atan2(f_y, sqrt(f_x^2 + f_z^2)) and roll = atan2(-f_x, f_z).
    """
    return np.arctan2(fy, np.sqrt(fx * fx + fz * fz)), np.arctan2(-fx, fz)


@register_jitable
def level_field(mx, my, mz, pitch, roll):
    """Horizontal components (h_x, h_y) of the field m_b rotated to the level frame Rx(pitch) Ry(roll) m_b
    (002 eq. 4 in the project's convention)."""
    sp, cp, sr, cr = np.sin(pitch), np.cos(pitch), np.sin(roll), np.cos(roll)
    return cr * mx + sr * mz, sp * sr * mx + cp * my - sp * cr * mz


@register_jitable
def mag_yaw(mx, my, mz, pitch, roll, declination):
    """True yaw [rad, counter-clockwise from north] from the magnetometer, tilt-compensated with the given pitch
    and roll (002 eqs. 3-6). The level field is B_h [sin(D + yaw), cos(D + yaw)]: the magnetic yaw is
    atan2(h_x, h_y) (eq. 5) and the true yaw subtracts the declination D (east positive; 002 eq. 6 adds it to
    its clockwise yaw)."""
    hx, hy = level_field(mx, my, mz, pitch, roll)
    return wrap(np.arctan2(hx, hy) - declination)


@register_jitable
def wrap(a):
    """Angle wrapped to [-pi, pi)."""
    return (a + np.pi) % (2.0 * np.pi) - np.pi


@register_jitable
def accel_covariance(fx, fy, fz, var_x, var_y, var_z):
    """Covariance (var_pitch, cov_pitch_roll, var_roll) of the accelerometer angles (002 eqs. 24-25): the
    Jacobian of `accel_pitch_roll` times diag(var) times its transpose."""
    s = fx * fx + fz * fz
    f2 = s + fy * fy
    rs = np.sqrt(s)
    jp0, jp1, jp2 = -fy * fx / (rs * f2), rs / f2, -fy * fz / (rs * f2)
    jr0, jr2 = -fz / s, fx / s
    return (jp0 * jp0 * var_x + jp1 * jp1 * var_y + jp2 * jp2 * var_z, jp0 * jr0 * var_x + jp2 * jr2 * var_z,
            jr0 * jr0 * var_x + jr2 * jr2 * var_z)


@register_jitable
def mag_yaw_variance(mx, my, mz, pitch, roll, var_x, var_y, var_z):
    """Variance of the magnetic yaw for white magnetometer noise at fixed pitch and roll (002 eqs. 26-27)."""
    sp, cp, sr, cr = np.sin(pitch), np.cos(pitch), np.sin(roll), np.cos(roll)
    hx, hy = level_field(mx, my, mz, pitch, roll)
    h2 = hx * hx + hy * hy
    j0 = (hy * cr - hx * sp * sr) / h2
    j1 = -hx * cp / h2
    j2 = (hy * sr + hx * sp * cr) / h2
    return j0 * j0 * var_x + j1 * j1 * var_y + j2 * j2 * var_z


@register_jitable
def quat_euler(q0, q1, q2, q3):
    """(pitch, roll, yaw) of a quaternion q_nb, normalised first (002 eq. 21 / eq. 14 in the project's
    convention: pitch = asin(C_21), roll = atan2(-C_20, C_22), yaw = atan2(-C_01, C_11))."""
    n2 = q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3
    c20 = 2.0 * (q1 * q3 - q0 * q2) / n2
    c21 = 2.0 * (q2 * q3 + q0 * q1) / n2
    c22 = 1.0 - 2.0 * (q1 * q1 + q2 * q2) / n2
    c01 = 2.0 * (q1 * q2 - q0 * q3) / n2
    c11 = 1.0 - 2.0 * (q1 * q1 + q3 * q3) / n2
    return np.arctan2(c21, np.sqrt(c20 * c20 + c22 * c22)), np.arctan2(-c20, c22), np.arctan2(-c01, c11)


@register_jitable
def euler_quat(pitch, roll, yaw):
    """q_nb = qz(yaw) qx(pitch) qy(roll) as four components (w >= 0 not enforced)."""
    cp, sp = np.cos(0.5 * pitch), np.sin(0.5 * pitch)
    cr, sr = np.cos(0.5 * roll), np.sin(0.5 * roll)
    cy, sy = np.cos(0.5 * yaw), np.sin(0.5 * yaw)
    return (cy * cp * cr - sy * sp * sr, cy * sp * cr - sy * cp * sr, cy * cp * sr + sy * sp * cr,
            cy * sp * sr + sy * cp * cr)


@register_jitable
def propagation_matrix(ax, ay, az):
    """A = cos(|a|/2) I + sin(|a|/2) / |a| Omega(a) for the angle increment a [rad] (002 eqs. 12, 19):
    q_k = A q_{k-1} is q_{k-1} (x) exp(a / 2). Returns the 4x4 matrix (numba and numpy scalars)."""
    ang = np.sqrt(ax * ax + ay * ay + az * az)
    c = np.cos(0.5 * ang)
    s = 0.5 - ang * ang / 48.0 if ang < 1e-4 else np.sin(0.5 * ang) / ang
    a = np.empty((4, 4))
    a[0, 0], a[0, 1], a[0, 2], a[0, 3] = c, -s * ax, -s * ay, -s * az
    a[1, 0], a[1, 1], a[1, 2], a[1, 3] = s * ax, c, s * az, -s * ay
    a[2, 0], a[2, 1], a[2, 2], a[2, 3] = s * ay, -s * az, c, s * ax
    a[3, 0], a[3, 1], a[3, 2], a[3, 3] = s * az, s * ay, -s * ax, c
    return a


@register_jitable
def process_noise(q, var_w, dt):
    """Q = dt^2 / 4 Xi(q) diag(var_w) Xi(q)^T (002 eqs. 22-23), var_w the rate-deviation variances."""
    xi = np.empty((4, 3))
    xi[0, 0], xi[0, 1], xi[0, 2] = -q[1], -q[2], -q[3]
    xi[1, 0], xi[1, 1], xi[1, 2] = q[0], -q[3], q[2]
    xi[2, 0], xi[2, 1], xi[2, 2] = q[3], q[0], -q[1]
    xi[3, 0], xi[3, 1], xi[3, 2] = -q[2], q[1], q[0]
    out = np.empty((4, 4))
    for i in range(4):
        for j in range(4):
            acc = 0.0
            for m in range(3):
                acc += xi[i, m] * var_w[m] * xi[j, m]
            out[i, j] = 0.25 * dt * dt * acc
    return out


def propagate(q0, gyro, dt):
    """Attitude q_nb (K+1, 4) from q0 and gyro rates (K, 3) [rad/s] held over each step dt (002 eqs. 10-12)."""
    q = np.empty((gyro.shape[0] + 1, 4))
    q[0] = q0
    for k in range(gyro.shape[0]):
        q[k + 1] = propagation_matrix(*(gyro[k] * dt)) @ q[k]
    return q




# --------------------------------------------------------------------------------------------------------------
# Inputs shared by the filters


@dataclass(frozen=True)
class UnitModel:
    """What the filters know of the unit and the site (SI).

    var_accel, var_mag: white-noise variances per axis of one accelerometer [(m/s^2)^2] and magnetometer [T^2]
    sample (002 eqs. 25, 27); field_n: the geomagnetic field in n (ENU) [T] from the geomagnetic model, which
    also gives the declination; earth_rate_n: Earth rate in n [rad/s], removed from the gyro (zeros to ignore it,
    as 002 does).
    """

    var_accel: np.ndarray
    var_mag: np.ndarray
    field_n: np.ndarray
    earth_rate_n: np.ndarray

    @property
    def declination(self) -> float:
        """Declination [rad], east positive, of field_n."""
        return float(np.arctan2(self.field_n[0], self.field_n[1]))


@dataclass(frozen=True)
class SigmaSettings:
    """Merwe scaled sigma points (002 eqs. 16-17): alpha, beta, kappa."""

    alpha: float = 0.5
    beta: float = 2.0
    kappa: float = 0.0

    def weights(self, n: int = 4) -> tuple[np.ndarray, np.ndarray, float]:
        """(Wm, Wc, n + lambda) from filterpy's MerweScaledSigmaPoints."""
        pts = MerweScaledSigmaPoints(n, alpha=self.alpha, beta=self.beta, kappa=self.kappa)
        return np.asarray(pts.Wm, float), np.asarray(pts.Wc, float), self.alpha ** 2 * (n + self.kappa)


def initial_attitude(accel: np.ndarray, mag: np.ndarray, model: UnitModel) -> np.ndarray:
    """q_nb (N, 4) of each unit from its first accelerometer and magnetometer samples (eqs. 8, 5-6)."""
    pitch, roll = accel_pitch_roll(accel[:, 0, 0], accel[:, 0, 1], accel[:, 0, 2])
    yaw = mag_yaw(mag[:, 0, 0], mag[:, 0, 1], mag[:, 0, 2], pitch, roll, model.declination)
    return np.stack(euler_quat(pitch, roll, yaw), axis=-1)


def _batch(a: np.ndarray, name: str) -> np.ndarray:
    a = np.asarray(a, float)
    if a.ndim == 2:
        a = a[None]
    if a.ndim != 3 or a.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (K, 3) or (N, K, 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} has NaN or infinite samples")
    return np.ascontiguousarray(a)


def _inputs(gyro, accel, mag):
    gyro, accel, mag = _batch(gyro, "gyro"), _batch(accel, "accel"), _batch(mag, "mag")
    if not gyro.shape == accel.shape == mag.shape:
        raise ValueError(f"gyro, accel and mag differ in shape: {gyro.shape}, {accel.shape}, {mag.shape}")
    return gyro, accel, mag


# --------------------------------------------------------------------------------------------------------------
# Kernels


@nb.njit(cache=True, inline="always")
def _chol4(a, out):
    """Lower Cholesky factor of a symmetric 4x4 matrix into out; non-positive pivots are floored."""
    for j in range(4):
        s = a[j, j]
        for m in range(j):
            s -= out[j, m] * out[j, m]
        d = np.sqrt(s) if s > 1e-30 else 1e-15
        out[j, j] = d
        for i in range(j + 1, 4):
            s = a[i, j]
            for m in range(j):
                s -= out[i, m] * out[j, m]
            out[i, j] = s / d
        for i in range(j):
            out[i, j] = 0.0


@nb.njit(cache=True, inline="always")
def _measurement(acc, mg, declination, var_a, var_m, z, r):
    """z = (pitch, roll, yaw) from the accelerometer and magnetometer and its covariance R (eqs. 5-8, 24-28)."""
    p, rl = accel_pitch_roll(acc[0], acc[1], acc[2])
    z[0], z[1] = p, rl
    z[2] = mag_yaw(mg[0], mg[1], mg[2], p, rl, declination)
    vp, cpr, vr = accel_covariance(acc[0], acc[1], acc[2], var_a[0], var_a[1], var_a[2])
    r[:, :] = 0.0
    r[0, 0], r[0, 1], r[1, 0], r[1, 1] = vp, cpr, cpr, vr
    r[2, 2] = mag_yaw_variance(mg[0], mg[1], mg[2], p, rl, var_m[0], var_m[1], var_m[2])


@nb.njit(cache=True, inline="always")
def body_rate(w, q, w_ie_n, out):
    """Gyro rate minus the Earth rate resolved in b (C_n^b w_ie^n with C from q)."""
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    ex, ey, ez = w_ie_n[0], w_ie_n[1], w_ie_n[2]
    # C_n^b v = q* v q: rows of C_b^n as columns
    out[0] = w[0] - ((1 - 2 * (q2 * q2 + q3 * q3)) * ex + 2 * (q1 * q2 + q0 * q3) * ey + 2 * (q1 * q3 - q0 * q2) * ez)
    out[1] = w[1] - (2 * (q1 * q2 - q0 * q3) * ex + (1 - 2 * (q1 * q1 + q3 * q3)) * ey + 2 * (q2 * q3 + q0 * q1) * ez)
    out[2] = w[2] - (2 * (q1 * q3 + q0 * q2) * ex + 2 * (q2 * q3 - q0 * q1) * ey + (1 - 2 * (q1 * q1 + q2 * q2)) * ez)


@nb.njit(cache=True, inline="always")
def _normalize_continuous(x, prev):
    n = np.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3])
    sgn = 1.0 if x[0] * prev[0] + x[1] * prev[1] + x[2] * prev[2] + x[3] * prev[3] >= 0 else -1.0
    for i in range(4):
        x[i] = sgn * x[i] / n


@nb.njit(cache=True, inline="always")
def _sigma_points(x, p, c, lo, sig):
    """2n + 1 sigma points (eq. 16) of (x, P): x and x -/+ the columns of chol(c P), c = n + lambda."""
    for i in range(4):
        for j in range(4):
            lo[i, j] = c * p[i, j]
    _chol4(lo.copy(), lo)
    for j in range(4):
        sig[0, j] = x[j]
        for i in range(4):
            sig[1 + i, j] = x[j] + lo[j, i]
            sig[5 + i, j] = x[j] - lo[j, i]


@nb.njit(cache=True, parallel=True)
def _ukf_kernel(gyro, accel, mag, dt, var_w, var_a, var_m, declination, w_ie_n, wm, wc, c, q0, p0, out_q):
    """002 section 3.5 steps 2.1-2.6 for each filter f over its samples; var_w (F, 3) per filter."""
    nf, nk = gyro.shape[0], gyro.shape[1]
    for f in nb.prange(nf):
        x = q0[f].copy()
        p = p0.copy()
        lo = np.empty((4, 4))
        sig = np.empty((9, 4))
        prop = np.empty((9, 4))
        zs = np.empty((9, 3))
        z = np.empty(3)
        r = np.empty((3, 3))
        w = np.empty(3)
        xm = np.empty(4)
        zm = np.empty(3)
        pm = np.empty((4, 4))
        pzz = np.empty((3, 3))
        pxz = np.empty((4, 3))
        gain = np.empty((4, 3))
        y = np.empty(3)
        for k in range(nk):
            # Step 2.1-2.2 (eqs. 18-19, 23, 29-30): sigma points of x_{k-1}, through A_{k-1}, plus Q.
            body_rate(gyro[f, k], x, w_ie_n, w)
            a = propagation_matrix(w[0] * dt, w[1] * dt, w[2] * dt)
            pm[:, :] = process_noise(x, var_w[f], dt)
            _sigma_points(x, p, c, lo, sig)
            xm[:] = 0.0
            for i in range(9):
                for j in range(4):
                    prop[i, j] = a[j, 0] * sig[i, 0] + a[j, 1] * sig[i, 1] + a[j, 2] * sig[i, 2] + a[j, 3] * sig[i, 3]
                    xm[j] += wm[i] * prop[i, j]
            for i in range(9):
                for j in range(4):
                    dj = wc[i] * (prop[i, j] - xm[j])
                    for m in range(4):
                        pm[j, m] += dj * (prop[i, m] - xm[m])
            # Step 2.3 (eq. 31): new sigma points of the prediction.
            _sigma_points(xm, pm, c, lo, sig)
            # Step 2.4 (eqs. 20-21, 32): output sigma points, yaw unwrapped around the central one.
            zm[:] = 0.0
            for i in range(9):
                zs[i, 0], zs[i, 1], zs[i, 2] = quat_euler(sig[i, 0], sig[i, 1], sig[i, 2], sig[i, 3])
                if i > 0:
                    zs[i, 2] = zs[0, 2] + wrap(zs[i, 2] - zs[0, 2])
                for j in range(3):
                    zm[j] += wm[i] * zs[i, j]
            _measurement(accel[f, k], mag[f, k], declination, var_a, var_m, z, r)
            pzz[:, :] = r
            pxz[:, :] = 0.0
            for i in range(9):
                for j in range(3):
                    dz = wc[i] * (zs[i, j] - zm[j])
                    for m in range(3):
                        pzz[j, m] += dz * (zs[i, m] - zm[m])
                    for m in range(4):
                        pxz[m, j] += dz * (sig[i, m] - xm[m])
            # Steps 2.5-2.6 (eqs. 33-34).
            inv = _inv3(pzz)
            for j in range(3):
                y[j] = z[j] - zm[j]
            y[2] = wrap(y[2])
            for i in range(4):
                for j in range(3):
                    gain[i, j] = pxz[i, 0] * inv[0, j] + pxz[i, 1] * inv[1, j] + pxz[i, 2] * inv[2, j]
                x[i] = xm[i] + gain[i, 0] * y[0] + gain[i, 1] * y[1] + gain[i, 2] * y[2]
            # P = P- - K Pzz K^T = P- - K Pxz^T
            for i in range(4):
                for j in range(i, 4):
                    v = pm[i, j] - (gain[i, 0] * pxz[j, 0] + gain[i, 1] * pxz[j, 1] + gain[i, 2] * pxz[j, 2])
                    p[i, j] = v
                    p[j, i] = v
            _normalize_continuous(x, out_q[f, k - 1] if k > 0 else q0[f])
            out_q[f, k] = x


@nb.njit(cache=True, inline="always")
def _inv3(a):
    """Inverse of a 3x3 matrix (cofactors)."""
    out = np.empty((3, 3))
    out[0, 0] = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    out[0, 1] = a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]
    out[0, 2] = a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]
    out[1, 0] = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    out[1, 1] = a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]
    out[1, 2] = a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]
    out[2, 0] = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    out[2, 1] = a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]
    out[2, 2] = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    det = a[0, 0] * out[0, 0] + a[0, 1] * out[1, 0] + a[0, 2] * out[2, 0]
    return out / det


@nb.njit(cache=True, parallel=True)
def _kf_kernel(gyro, accel, mag, dt, var_w, var_a, var_m, declination, w_ie_n, q0, p0, out_q):
    """Linear quaternion KF: x_k = A x_{k-1} + w (eqs. 18-19, Q of eq. 23), z = q(pitch, roll, yaw) from the
    accelerometer and magnetometer (eqs. 5-8) with H = I and R = J R_angles J^T (J the Jacobian of the Euler to
    quaternion map at z, R_angles of eqs. 24-28)."""
    nf, nk = gyro.shape[0], gyro.shape[1]
    eye = np.eye(4)
    for f in nb.prange(nf):
        x = q0[f].copy()
        p = p0.copy()
        z = np.empty(3)
        r = np.empty((3, 3))
        w = np.empty(3)
        jac = np.empty((4, 3))
        zq = np.empty(4)
        for k in range(nk):
            body_rate(gyro[f, k], x, w_ie_n, w)
            a = propagation_matrix(w[0] * dt, w[1] * dt, w[2] * dt)
            xm = a @ x
            pm = a @ p @ a.T + process_noise(x, var_w[f], dt)
            _measurement(accel[f, k], mag[f, k], declination, var_a, var_m, z, r)
            zq[0], zq[1], zq[2], zq[3] = euler_quat(z[0], z[1], z[2])
            h = 1e-6
            for m in range(3):
                zp = z.copy()
                zp[m] += h
                a0, a1, a2, a3 = euler_quat(zp[0], zp[1], zp[2])
                jac[0, m], jac[1, m] = (a0 - zq[0]) / h, (a1 - zq[1]) / h
                jac[2, m], jac[3, m] = (a2 - zq[2]) / h, (a3 - zq[3]) / h
            if zq[0] * xm[0] + zq[1] * xm[1] + zq[2] * xm[2] + zq[3] * xm[3] < 0:
                zq = -zq
                jac = -jac
            rq = jac @ r @ jac.T + 1e-12 * eye
            gain = pm @ np.linalg.inv(pm + rq)
            xn = xm + gain @ (zq - xm)
            p = (eye - gain) @ pm
            p = 0.5 * (p + p.T)
            _normalize_continuous(xn, x)
            x = xn
            out_q[f, k] = x


# --------------------------------------------------------------------------------------------------------------
# API


def _var_w(var_w, n: int) -> np.ndarray:
    v = np.asarray(var_w, float)
    v = np.broadcast_to(v if v.ndim == 2 else v[None], (n, 3))
    if np.any(v < 0) or not np.all(np.isfinite(v)):
        raise ValueError(f"rate-noise variances must be finite and >= 0, got {var_w!r}")
    return np.ascontiguousarray(v)


def _start(q0, accel, mag, model, p0_sigma):
    q0 = initial_attitude(accel, mag, model) if q0 is None else np.broadcast_to(np.asarray(q0, float),
                                                                               (accel.shape[0], 4))
    return np.ascontiguousarray(q0), np.eye(4) * p0_sigma ** 2


def ukf(gyro, accel, mag, dt: float, model: UnitModel, var_w, q0=None, p0_sigma: float = 0.01,
        sigma: SigmaSettings = SigmaSettings()) -> np.ndarray:
    """The quaternion UKF of 002 section 3 on a batch: q_nb (N, K, 4) after each sample.

    gyro [rad/s], accel [m/s^2], mag [T]: (K, 3) or (N, K, 3), one row per sample interval of dt [s]; var_w
    the rate-noise variances of Q [(rad/s)^2], (3,) or (N, 3) per filter; q0 the start (default: from the first
    accelerometer and magnetometer samples); p0_sigma the start's sigma per quaternion component.
    """
    gyro, accel, mag = _inputs(gyro, accel, mag)
    q0, p0 = _start(q0, accel, mag, model, p0_sigma)
    wm, wc, c = sigma.weights(4)
    out = np.empty(gyro.shape[:2] + (4,))
    _ukf_kernel(gyro, accel, mag, float(dt), _var_w(var_w, gyro.shape[0]), np.asarray(model.var_accel, float),
                np.asarray(model.var_mag, float), model.declination, np.asarray(model.earth_rate_n, float),
                wm, wc, c, q0, p0, out)
    return out


def kf(gyro, accel, mag, dt: float, model: UnitModel, var_w, q0=None, p0_sigma: float = 0.01) -> np.ndarray:
    """The linear quaternion KF baseline (see `_kf_kernel`) on a batch: q_nb (N, K, 4); arguments as `ukf`."""
    gyro, accel, mag = _inputs(gyro, accel, mag)
    q0, p0 = _start(q0, accel, mag, model, p0_sigma)
    out = np.empty(gyro.shape[:2] + (4,))
    _kf_kernel(gyro, accel, mag, float(dt), _var_w(var_w, gyro.shape[0]), np.asarray(model.var_accel, float),
               np.asarray(model.var_mag, float), model.declination, np.asarray(model.earth_rate_n, float),
               q0, p0, out)
    return out


def euler_errors(q_true: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    """Pitch, roll, yaw errors (..., 3) [rad] of q_est against q_true (yaw wrapped)."""
    et = np.stack(quat_euler(*np.moveaxis(q_true, -1, 0)), axis=-1)
    ee = np.stack(quat_euler(*np.moveaxis(q_est, -1, 0)), axis=-1)
    return wrap(ee - et)


# --------------------------------------------------------------------------------------------------------------
# Gradient-descent tuning of Q (002 section 3.1, eq. 35)


@dataclass
class Tuning:
    """Result of `tune_q`: the tuned variances [(rad/s)^2], the objective [rad] and variances per iteration."""

    var_w: np.ndarray
    objective: list[float] = field(default_factory=list)
    history: list[np.ndarray] = field(default_factory=list)
    converged: bool = False


def objective(q_true: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    """002 eq. 35: RMSE of the estimate against the truth, here over pitch, roll and yaw together [rad];
    per filter of the batch (leading axis)."""
    e = euler_errors(q_true, q_est)
    return np.sqrt(np.mean(e ** 2, axis=tuple(range(1, e.ndim))))


def tune_q(gyro, accel, mag, dt: float, model: UnitModel, q_true: np.ndarray, var_w0, q0=None,
           sigma: SigmaSettings = SigmaSettings(), iterations: int = 30, tol: float = 1e-4,
           step: float = 0.1, line: np.ndarray | None = None) -> Tuning:
    """Gradient descent on the variances of Q against a reference segment with truth q_true (K, 4), 002 steps
    1.1-1.4: the gradient by central differences in log(var) (step `step`), a line search over the factors
    `line` (default 2^1 .. 2^-6 of the unit step along -g/|g|, the best kept), stop when |g| < tol f, when the
    best does not lower f by a relative `tol`, or after `iterations`. Each batch of Q candidates is one call of the UKF kernel.
    f never rises: a step is taken only if it lowers f.
    """
    gyro, accel, mag = _inputs(gyro, accel, mag)
    if gyro.shape[0] != 1:
        raise ValueError("tune_q works on one unit's reference segment")
    line = 2.0 ** -np.arange(-1, 7) if line is None else np.asarray(line, float)
    if q0 is None:
        q0 = initial_attitude(accel, mag, model)[0]
    theta = np.log(np.asarray(var_w0, float))

    def run(thetas: np.ndarray) -> np.ndarray:
        n = thetas.shape[0]
        est = ukf(np.broadcast_to(gyro, (n,) + gyro.shape[1:]), np.broadcast_to(accel, (n,) + gyro.shape[1:]),
                  np.broadcast_to(mag, (n,) + gyro.shape[1:]), dt, model, np.exp(thetas), q0=q0, sigma=sigma)
        return objective(np.broadcast_to(q_true, est.shape), est)

    f = float(run(theta[None])[0])
    out = Tuning(np.exp(theta), [f], [np.exp(theta)])
    for _ in range(iterations):
        probes = theta + step * np.concatenate([np.eye(3), -np.eye(3)])
        fp = run(probes)
        g = (fp[:3] - fp[3:]) / (2 * step)
        gn = float(np.linalg.norm(g))
        if gn < tol * f:
            out.converged = True
            break
        cands = theta - line[:, None] * (g / gn)
        fc = run(cands)
        best = int(np.argmin(fc))
        if not fc[best] < f * (1 - tol):
            out.converged = True
            break
        theta, f = cands[best], float(fc[best])
        out.objective.append(f)
        out.history.append(np.exp(theta))
    out.var_w = np.exp(theta)
    return out
