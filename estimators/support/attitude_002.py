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
* the gradient-descent tuning of Q's rate variances (eq. 35, steps 1.1-1.4) with the objective per iteration;
* `support_batch`: a face's SUPPORT_IMU stream as (supports, samples, 3) arrays, units it cannot use left out
  with their reason, so that each filter runs once over all supports.

The scalar formulas are written once with numpy functions (numba's register_jitable) so that they serve both
numpy arrays (the API) and numba scalars (the kernels). The kernels allocate each filter's state and scratch
once (nothing in the sample loop), run the filters of a batch in parallel (prange) and use fast-math flags short
of assuming finite values (FASTMATH); a filter's result does not depend on the batch it runs in.

Rate-noise variances sigma_w^2 of Q (eq. 23) are in (rad/s)^2: Q_k = dt^2 / 4 Xi(q) diag(sigma_w^2) Xi(q)^T,
the covariance of the quaternion step driven by white rate deviations held over one sample.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
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
def accel_tilt_sincos(fx, fy, fz):
    """(sin, cos) of the accelerometer pitch and of its roll (eqs. 7-8), without trigonometric calls:
    sin(pitch) = f_y / |f|, cos(pitch) = sqrt(f_x^2 + f_z^2) / |f|, sin(roll) = -f_x / sqrt(f_x^2 + f_z^2),
    cos(roll) = f_z / sqrt(f_x^2 + f_z^2)."""
    rs = np.sqrt(fx * fx + fz * fz)
    n = np.sqrt(rs * rs + fy * fy)
    return fy / n, rs / n, -fx / rs, fz / rs


@register_jitable
def level_field(mx, my, mz, sp, cp, sr, cr):
    """Horizontal components (h_x, h_y) of the field m_b rotated to the level frame Rx(pitch) Ry(roll) m_b
    (002 eq. 4 in the project's convention), from the sines and cosines of pitch and roll."""
    return cr * mx + sr * mz, sp * sr * mx + cp * my - sp * cr * mz


@register_jitable
def mag_yaw(mx, my, mz, pitch, roll, declination):
    """True yaw [rad, counter-clockwise from north] from the magnetometer, tilt-compensated with the given pitch
    and roll (002 eqs. 3-6). The level field is B_h [sin(D + yaw), cos(D + yaw)]: the magnetic yaw is
    atan2(h_x, h_y) (eq. 5) and the true yaw subtracts the declination D (east positive; 002 eq. 6 adds it to
    its clockwise yaw)."""
    hx, hy = level_field(mx, my, mz, np.sin(pitch), np.cos(pitch), np.sin(roll), np.cos(roll))
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
def mag_yaw_variance(mx, my, mz, sp, cp, sr, cr, var_x, var_y, var_z):
    """Variance of the magnetic yaw for white magnetometer noise at fixed pitch and roll, given by their sines
    and cosines (002 eqs. 26-27)."""
    hx, hy = level_field(mx, my, mz, sp, cp, sr, cr)
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
def exp_half(ax, ay, az):
    """(c, s) with exp(a / 2) = [c, s a_x, s a_y, s a_z] for the rotation vector a [rad] (002 eq. 12:
    c = cos(|a|/2), s = sin(|a|/2) / |a|; Taylor series to 4th order below 0.01 rad, exact to 1e-17)."""
    a2 = ax * ax + ay * ay + az * az
    if a2 < 1e-4:
        return 1.0 - a2 / 8.0 + a2 * a2 / 384.0, 0.5 - a2 / 48.0 + a2 * a2 / 3840.0
    ang = np.sqrt(a2)
    return np.cos(0.5 * ang), np.sin(0.5 * ang) / ang


@register_jitable
def propagation_matrix(ax, ay, az, out):
    """A = cos(|a|/2) I + sin(|a|/2) / |a| Omega(a) for the angle increment a [rad] into out (4, 4) (002 eqs. 12,
    19): q_k = A q_{k-1} is q_{k-1} (x) exp(a / 2)."""
    c, s = exp_half(ax, ay, az)
    out[0, 0], out[0, 1], out[0, 2], out[0, 3] = c, -s * ax, -s * ay, -s * az
    out[1, 0], out[1, 1], out[1, 2], out[1, 3] = s * ax, c, s * az, -s * ay
    out[2, 0], out[2, 1], out[2, 2], out[2, 3] = s * ay, -s * az, c, s * ax
    out[3, 0], out[3, 1], out[3, 2], out[3, 3] = s * az, s * ay, -s * ax, c
    return out


@register_jitable
def process_noise(q, var_w, dt, out):
    """Q = dt^2 / 4 Xi(q) diag(var_w) Xi(q)^T into out (4, 4) (002 eqs. 22-23), var_w the rate-deviation
    variances [(rad/s)^2]; Xi(q) the 4x3 matrix of q (x) [0, w] = Xi(q) w."""
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    h = 0.25 * dt * dt
    v0, v1, v2 = h * var_w[0], h * var_w[1], h * var_w[2]
    xi = ((-q1, -q2, -q3), (q0, -q3, q2), (q3, q0, -q1), (-q2, q1, q0))
    for i in range(4):
        for j in range(i, 4):
            v = xi[i][0] * v0 * xi[j][0] + xi[i][1] * v1 * xi[j][1] + xi[i][2] * v2 * xi[j][2]
            out[i, j] = v
            out[j, i] = v
    return out


def propagate(q0, gyro, dt):
    """Attitude q_nb (K+1, 4) from q0 and gyro rates (K, 3) [rad/s] held over each step dt (002 eqs. 10-12)."""
    q = np.empty((gyro.shape[0] + 1, 4))
    q[0] = q0
    a = np.empty((4, 4))
    for k in range(gyro.shape[0]):
        q[k + 1] = propagation_matrix(*(gyro[k] * dt), a) @ q[k]
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
# Kernels: one numba call runs a batch of independent filters (prange over the filters); each filter's state and
# scratch are allocated once, nothing inside the sample loop allocates.

FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}
"""LLVM fast-math flags of the kernels: reassociation and contraction, no finite-math assumption (nnan, ninf)."""


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _chol4(a, out):
    """Lower Cholesky factor of a symmetric 4x4 matrix (its lower triangle is read) into out, which may be a;
    non-positive pivots are floored."""
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


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _measurement(acc, mg, declination, var_a, var_m, z, r):
    """z = (pitch, roll, yaw) from the accelerometer and magnetometer and its covariance R (eqs. 5-8, 24-28)."""
    z[0], z[1] = accel_pitch_roll(acc[0], acc[1], acc[2])
    sp, cp, sr, cr = accel_tilt_sincos(acc[0], acc[1], acc[2])
    hx, hy = level_field(mg[0], mg[1], mg[2], sp, cp, sr, cr)
    z[2] = wrap(np.arctan2(hx, hy) - declination)  # mag_yaw, eqs. 5-6
    vp, cpr, vr = accel_covariance(acc[0], acc[1], acc[2], var_a[0], var_a[1], var_a[2])
    r[0, 0], r[0, 1], r[0, 2] = vp, cpr, 0.0
    r[1, 0], r[1, 1], r[1, 2] = cpr, vr, 0.0
    r[2, 0], r[2, 1] = 0.0, 0.0
    r[2, 2] = mag_yaw_variance(mg[0], mg[1], mg[2], sp, cp, sr, cr, var_m[0], var_m[1], var_m[2])


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def body_rate(w, q, w_ie_n, out):
    """Gyro rate minus the Earth rate resolved in b (C_n^b w_ie^n with C from q)."""
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    ex, ey, ez = w_ie_n[0], w_ie_n[1], w_ie_n[2]
    # C_n^b v = q* v q: rows of C_b^n as columns
    out[0] = w[0] - ((1 - 2 * (q2 * q2 + q3 * q3)) * ex + 2 * (q1 * q2 + q0 * q3) * ey + 2 * (q1 * q3 - q0 * q2) * ez)
    out[1] = w[1] - (2 * (q1 * q2 - q0 * q3) * ex + (1 - 2 * (q1 * q1 + q3 * q3)) * ey + 2 * (q2 * q3 + q0 * q1) * ez)
    out[2] = w[2] - (2 * (q1 * q3 + q0 * q2) * ex + 2 * (q2 * q3 - q0 * q1) * ey + (1 - 2 * (q1 * q1 + q2 * q2)) * ez)


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _normalize_continuous(x, prev):
    """x normalised, its sign chosen on prev's side (q and -q are the same attitude)."""
    n = np.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3])
    if x[0] * prev[0] + x[1] * prev[1] + x[2] * prev[2] + x[3] * prev[3] < 0:
        n = -n
    for i in range(4):
        x[i] = x[i] / n


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _predict(x, p, a, pm, xm, ap):
    """x- = A x, P- = A P A^T + pm (pm holds Q on entry): the unscented transform of the linear process model
    (eqs. 18-19, 29-30) is exact, so no sigma points are needed for it."""
    for i in range(4):
        xm[i] = a[i, 0] * x[0] + a[i, 1] * x[1] + a[i, 2] * x[2] + a[i, 3] * x[3]
        for j in range(4):
            ap[i, j] = a[i, 0] * p[0, j] + a[i, 1] * p[1, j] + a[i, 2] * p[2, j] + a[i, 3] * p[3, j]
    for i in range(4):
        for j in range(i, 4):
            v = pm[i, j] + ap[i, 0] * a[j, 0] + ap[i, 1] * a[j, 1] + ap[i, 2] * a[j, 2] + ap[i, 3] * a[j, 3]
            pm[i, j] = v
            pm[j, i] = v


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _inv3(a, out):
    """Inverse of a 3x3 matrix (cofactors) into out."""
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
    for i in range(3):
        for j in range(3):
            out[i, j] /= det


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _ukf_kernel(gyro, accel, mag, dt, var_w, var_a, var_m, declination, w_ie_n, wm, wc, c, q0, p0, out_q):
    """002 section 3.5 steps 2.1-2.6 for each filter f over its samples; var_w (F, 3) per filter."""
    nf, nk = gyro.shape[0], gyro.shape[1]
    for f in nb.prange(nf):
        x = q0[f].copy()
        p = p0.copy()
        a, ap, pm, lo = np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4))
        sig, zs = np.empty((9, 4)), np.empty((9, 3))
        z, zm, y, w = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
        r, pzz, inv = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
        xm = np.empty(4)
        pxz, gain = np.empty((4, 3)), np.empty((4, 3))
        for k in range(nk):
            # Steps 2.1-2.2 (eqs. 18-19, 23, 29-30), Q at the previous estimate.
            body_rate(gyro[f, k], x, w_ie_n, w)
            propagation_matrix(w[0] * dt, w[1] * dt, w[2] * dt, a)
            process_noise(x, var_w[f], dt, pm)
            _predict(x, p, a, pm, xm, ap)
            # Step 2.3 (eqs. 16, 31): sigma points of the prediction, x- and x- -/+ the columns of chol(c P-).
            for i in range(4):
                for j in range(i + 1):
                    lo[i, j] = c * pm[i, j]
            _chol4(lo, lo)
            for j in range(4):
                sig[0, j] = xm[j]
                for i in range(4):
                    sig[1 + i, j] = xm[j] + lo[j, i]
                    sig[5 + i, j] = xm[j] - lo[j, i]
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
            _inv3(pzz, inv)
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


@register_jitable
def euler_quat_jacobian(q, yaw, out):
    """d q / d(pitch, roll, yaw) (4, 3) into out of q = euler_quat(pitch, roll, yaw) = qz qx qy: the columns are
    (0, cos(yaw), sin(yaw), 0) (x) q / 2, q (x) (0, 0, 1, 0) / 2 and (0, 0, 0, 1) (x) q / 2."""
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    cy, sy = 0.5 * np.cos(yaw), 0.5 * np.sin(yaw)
    out[0, 0], out[1, 0], out[2, 0], out[3, 0] = -cy * q1 - sy * q2, cy * q0 + sy * q3, sy * q0 - cy * q3, \
        cy * q2 - sy * q1
    out[0, 1], out[1, 1], out[2, 1], out[3, 1] = -0.5 * q2, -0.5 * q3, 0.5 * q0, 0.5 * q1
    out[0, 2], out[1, 2], out[2, 2], out[3, 2] = -0.5 * q3, -0.5 * q2, 0.5 * q1, 0.5 * q0
    return out


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _kf_kernel(gyro, accel, mag, dt, var_w, var_a, var_m, declination, w_ie_n, q0, p0, out_q):
    """Linear quaternion KF: x_k = A x_{k-1} + w (eqs. 18-19, Q of eq. 23), z = q(pitch, roll, yaw) from the
    accelerometer and magnetometer (eqs. 5-8) with H = I and R = J R_angles J^T (J = euler_quat_jacobian at z,
    R_angles of eqs. 24-28)."""
    nf, nk = gyro.shape[0], gyro.shape[1]
    for f in nb.prange(nf):
        x = q0[f].copy()
        p = p0.copy()
        a, ap, pm, s, gain = np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4))
        z, w = np.empty(3), np.empty(3)
        r = np.empty((3, 3))
        jac, jr = np.empty((4, 3)), np.empty((4, 3))
        zq, xm = np.empty(4), np.empty(4)
        for k in range(nk):
            body_rate(gyro[f, k], x, w_ie_n, w)
            propagation_matrix(w[0] * dt, w[1] * dt, w[2] * dt, a)
            process_noise(x, var_w[f], dt, pm)
            _predict(x, p, a, pm, xm, ap)
            _measurement(accel[f, k], mag[f, k], declination, var_a, var_m, z, r)
            zq[0], zq[1], zq[2], zq[3] = euler_quat(z[0], z[1], z[2])
            euler_quat_jacobian(zq, z[2], jac)
            if zq[0] * xm[0] + zq[1] * xm[1] + zq[2] * xm[2] + zq[3] * xm[3] < 0:
                for i in range(4):
                    zq[i] = -zq[i]
                    for j in range(3):
                        jac[i, j] = -jac[i, j]
            # S = P- + J R J^T (+ 1e-12 I: J R J^T has rank 3); K = P- S^-1 by Cholesky (S and P- symmetric).
            for i in range(4):
                for j in range(3):
                    jr[i, j] = jac[i, 0] * r[0, j] + jac[i, 1] * r[1, j] + jac[i, 2] * r[2, j]
            for i in range(4):
                for j in range(i + 1):
                    s[i, j] = pm[i, j] + jr[i, 0] * jac[j, 0] + jr[i, 1] * jac[j, 1] + jr[i, 2] * jac[j, 2]
                s[i, i] += 1e-12
            _chol4(s, s)
            for col in range(4):  # row col of K = (S^-1 P-[:, col])^T: forward then back substitution
                for i in range(4):
                    v = pm[i, col]
                    for m in range(i):
                        v -= s[i, m] * gain[col, m]
                    gain[col, i] = v / s[i, i]
                for i in range(3, -1, -1):
                    v = gain[col, i]
                    for m in range(i + 1, 4):
                        v -= s[m, i] * gain[col, m]
                    gain[col, i] = v / s[i, i]
            for i in range(4):
                x[i] = xm[i] + (gain[i, 0] * (zq[0] - xm[0]) + gain[i, 1] * (zq[1] - xm[1])
                                + gain[i, 2] * (zq[2] - xm[2]) + gain[i, 3] * (zq[3] - xm[3]))
            # P = (I - K) P-, symmetrised
            for i in range(4):
                for j in range(4):
                    ap[i, j] = pm[i, j] - (gain[i, 0] * pm[0, j] + gain[i, 1] * pm[1, j] + gain[i, 2] * pm[2, j]
                                           + gain[i, 3] * pm[3, j])
            for i in range(4):
                for j in range(i, 4):
                    v = 0.5 * (ap[i, j] + ap[j, i])
                    p[i, j] = v
                    p[j, i] = v
            _normalize_continuous(x, xm)
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


@dataclass(frozen=True)
class SupportBatch:
    """The SUPPORT_IMU stream of a face as arrays over supports and samples: one batched call per filter."""

    t: np.ndarray  # (K,) [s] the sample times every support kept shares
    supports: np.ndarray  # (N,) support index of each row of the arrays
    gyro: np.ndarray  # (N, K, 3) [rad/s] in the canopy frame c
    accel: np.ndarray  # (N, K, 3) [m/s^2] in c
    mag: np.ndarray  # (N, K, 3) [T] in c
    skipped: dict[int, str]  # support left out -> why (one line)
    dt: float  # [s] the sample interval


def support_batch(columns: Mapping[str, np.ndarray], expected: Iterable[int] = ()) -> SupportBatch:
    """SUPPORT_IMU columns (t, support, gyro_x .. mag_z: estimators.io.logformat) as (N, K, 3) arrays.

    Never passes on a non-finite value: a support is left out, with its reason in `skipped`, when it is in
    `expected` but has no rows, when one of its readings is NaN or infinite, or when its sample times are not the
    common ones (the times at least half of the other supports have). ValueError (one line) when no support is
    left or the common times are not uniformly spaced (the filters take one interval dt).
    """
    t = np.asarray(columns["t"], float)
    ids = np.asarray(columns["support"], np.int64)
    sensors = {name: np.stack([np.asarray(columns[f"{name}_{a}"], float) for a in "xyz"], axis=-1)
               for name in ("gyro", "accel", "mag")}
    finite = np.isfinite(t)
    for v in sensors.values():
        finite &= np.isfinite(v).all(axis=1)
    skipped: dict[int, str] = {int(j): "no rows in support_imu" for j in set(expected) - set(ids.tolist())}
    rows = {}
    for j in np.unique(ids):
        sel = np.flatnonzero(ids == j)
        bad = sel[~finite[sel]]
        if bad.size:
            skipped[int(j)] = f"{bad.size} of its {sel.size} rows have NaN or infinite values (first: row {bad[0]})"
        else:
            rows[int(j)] = sel[np.argsort(t[sel], kind="stable")]
    times, counts = np.unique(np.concatenate([t[r] for r in rows.values()] or [np.zeros(0)]), return_counts=True)
    grid = times[2 * counts >= len(rows)]
    for j, r in list(rows.items()):
        if r.size != grid.size or np.any(t[r] != grid):
            missing, extra = np.setdiff1d(grid, t[r]).size, r.size - np.intersect1d(grid, t[r]).size
            skipped[j] = f"{missing} of the {grid.size} common sample times missing, {extra} others"
            del rows[j]
    if not rows:
        reasons = "; ".join(f"support {j}: {why}" for j, why in sorted(skipped.items()))
        raise ValueError(f"support_imu: no support with usable readings ({reasons or 'the stream is empty'})")
    steps = np.diff(grid)
    dt = float(np.median(steps)) if steps.size else 0.0
    if not dt > 0 or np.any(np.abs(steps - dt) > 1e-6 * dt):
        at = int(np.argmax(np.abs(steps - dt))) if steps.size else 0
        raise ValueError(f"support_imu: the sample times are not uniform (step {steps[at] if steps.size else 0:g} s "
                         f"at t = {grid[at]:g} s, median {dt:g} s); the filters need one sample interval")
    order = np.array(sorted(rows))
    sel = np.stack([rows[j] for j in order])
    return SupportBatch(grid, order, *(np.ascontiguousarray(sensors[name][sel]) for name in ("gyro", "accel", "mag")),
                        dict(sorted(skipped.items())), dt)


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
