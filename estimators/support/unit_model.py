"""002's models of a 9-axis canopy unit (002_5cc0b59ad045ffaa.txt section 2): what the support filters know of it.

Conventions are the project's, not 002's (002 uses NED, X forward, Z down, yaw clockwise): frames b (x right,
y forward, z up) and n (ENU), C_b^n = Rz(yaw) Rx(pitch) Ry(roll), yaw counter-clockwise from north. 002's
pitch (nose up) is our pitch about x, its roll (left side up) our roll about y, its yaw our -yaw. Every
equation below is 002's rewritten in this convention; the docstrings say which one.

* measurement: accelerometer pitch and roll (eqs. 7-8), tilt-compensated magnetic yaw with declination
  (eqs. 3-6), their covariance from the sensor variances (eqs. 24-28), the quaternion of the angles and its
  Jacobian (the KF's linear measurement);
* process: quaternion propagation by the gyro (eqs. 10-12, 19) and its noise Q (eqs. 22-23);
* `UnitModel`, the unit's noise and the site's field, and the start attitude from the first samples.

The scalar formulas are written once with numpy functions (numba's register_jitable) so that they serve both
numpy arrays (the API) and numba scalars (the kernels). Rate-noise variances sigma_w^2 of Q (eq. 23) are in
(rad/s)^2: Q_k = dt^2 / 4 Xi(q) diag(sigma_w^2) Xi(q)^T, the covariance of the quaternion step driven by white
rate deviations held over one sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np
from numba.extending import register_jitable

from estimators.nav.rotations_scalar import euler_quat, exp_half, quat_euler
from estimators.support.kernel_math import FASTMATH

# --------------------------------------------------------------------------------------------------------------
# Measurement: attitude from single sensors (002 section 2.3) and its covariance


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


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def measurement(acc, mg, declination, var_a, var_m, z, r):
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


def euler_errors(q_true: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    """Pitch, roll, yaw errors (..., 3) [rad] of q_est against q_true (yaw wrapped)."""
    et = np.stack(quat_euler(*np.moveaxis(q_true, -1, 0)), axis=-1)
    ee = np.stack(quat_euler(*np.moveaxis(q_est, -1, 0)), axis=-1)
    return wrap(ee - et)


# --------------------------------------------------------------------------------------------------------------
# Process: quaternion propagation by the gyro (002 section 2.4)


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
# The unit and its start


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


def initial_attitude(accel: np.ndarray, mag: np.ndarray, model: UnitModel) -> np.ndarray:
    """q_nb (N, 4) of each unit from its first accelerometer and magnetometer samples (eqs. 8, 5-6)."""
    pitch, roll = accel_pitch_roll(accel[:, 0, 0], accel[:, 0, 1], accel[:, 0, 2])
    yaw = mag_yaw(mag[:, 0, 0], mag[:, 0, 1], mag[:, 0, 2], pitch, roll, model.declination)
    return np.stack(euler_quat(pitch, roll, yaw), axis=-1)


def start_attitude(q0, accel: np.ndarray, mag: np.ndarray, model: UnitModel) -> np.ndarray:
    """q_nb (N, 4), contiguous, a filter starts each of the N units from: q0 (4,) or (N, 4), or when None
    `initial_attitude`."""
    q0 = initial_attitude(accel, mag, model) if q0 is None else np.broadcast_to(np.asarray(q0, float),
                                                                               (accel.shape[0], 4))
    return np.ascontiguousarray(q0)
