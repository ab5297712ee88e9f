"""Rotation algebra (vectorised over leading dimensions).

Conventions
-----------
* Quaternions are scalar-first ``[w, x, y, z]`` with the Hamilton product
  (MuJoCo order; scipy is scalar-last -- reorder when comparing).
* ``q_nb`` / ``C_b^n`` rotate body-frame (b) components into the
  navigation frame (n, ENU): ``v_n = C_b^n v_b = q_nb v_b q_nb*``.
* Euler angles (project design): pitch about x, roll about y, yaw about z,
  ``C_b^n = Rz(yaw) @ Rx(pitch) @ Ry(roll)`` with right-handed active
  elementary rotations.  At zero angles b coincides with n, so the body
  y axis points North; yaw is positive counter-clockwise seen from Up.
* Rotation vectors ``phi`` (axis * angle) map to ``exp(phi/2)``.

Vectors have shape ``(...,3)``, quaternions ``(...,4)``, matrices
``(...,3,3)``; Euler angles are arrays of shape ``(...)``.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = [
    "skew",
    "quat_mul",
    "quat_conj",
    "quat_normalize",
    "quat_rotate",
    "quat_to_mat",
    "mat_to_quat",
    "rotvec_to_quat",
    "quat_to_rotvec",
    "euler_to_mat",
    "mat_to_euler",
    "euler_to_quat",
    "quat_to_euler",
    "heading_deg_cw_from_north",
    "cross3",
    "qmul",
    "qexp",
    "qrot",
    "skew3",
    "quat_mat",
    "rotvec_mat",
    "mat_rotvec",
]

# Below this angle [rad] the series of sin(x/2)/x resp. atan(x)/x are used;
# with the terms kept the truncation error is < 1e-19 relative.
_SMALL_ANGLE = 1e-3


def skew(v):
    """Cross-product matrix ``[v]x`` with ``skew(v) @ u == cross(v, u)``."""
    v = np.asarray(v, dtype=float)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    o = np.zeros_like(x)
    return np.stack(
        [
            np.stack([o, -z, y], axis=-1),
            np.stack([z, o, -x], axis=-1),
            np.stack([-y, x, o], axis=-1),
        ],
        axis=-2,
    )


def quat_mul(p, q):
    """Hamilton product ``p * q``; ``q_ac = quat_mul(q_ab, q_bc)``."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    pw, pv = p[..., :1], p[..., 1:]
    qw, qv = q[..., :1], q[..., 1:]
    w = pw * qw - np.sum(pv * qv, axis=-1, keepdims=True)
    v = pw * qv + qw * pv + np.cross(pv, qv)
    return np.concatenate([w, v], axis=-1)


def quat_conj(q):
    """Conjugate ``[w, -x, -y, -z]`` (the inverse of a unit quaternion)."""
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_normalize(q):
    """Scale ``q`` to unit norm."""
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_rotate(q, v):
    """Rotate vector ``v`` by unit quaternion ``q``: ``v' = q v q*``.

    With ``q = q_nb`` this maps b components to n components.
    """
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, dtype=float)
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_to_mat(q):
    """Direction cosine matrix of unit quaternion ``q`` (``q_nb -> C_b^n``)."""
    q = np.asarray(q, dtype=float)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return np.stack(
        [
            np.stack([1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)], axis=-1),
            np.stack([2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx)], axis=-1),
            np.stack([2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)], axis=-1),
        ],
        axis=-2,
    )


def mat_to_quat(C):
    """Unit quaternion of rotation matrix ``C`` (``C_b^n -> q_nb``), ``w >= 0``.

    Shepperd's method: of the four expressions ``4 q_i q`` the one with the
    largest ``|q_i|`` (largest of trace, C00, C11, C22) is normalised, so
    no small pivot is ever divided by.
    """
    C = np.asarray(C, dtype=float)
    c00, c01, c02 = C[..., 0, 0], C[..., 0, 1], C[..., 0, 2]
    c10, c11, c12 = C[..., 1, 0], C[..., 1, 1], C[..., 1, 2]
    c20, c21, c22 = C[..., 2, 0], C[..., 2, 1], C[..., 2, 2]
    tr = c00 + c11 + c22
    # Row i equals 4 q_i * [w, x, y, z] (for i = w, x, y, z).
    cand = np.stack(
        [
            np.stack([1 + tr, c21 - c12, c02 - c20, c10 - c01], axis=-1),
            np.stack([c21 - c12, 1 + 2 * c00 - tr, c01 + c10, c02 + c20], axis=-1),
            np.stack([c02 - c20, c01 + c10, 1 + 2 * c11 - tr, c12 + c21], axis=-1),
            np.stack([c10 - c01, c02 + c20, c12 + c21, 1 + 2 * c22 - tr], axis=-1),
        ],
        axis=-2,
    )
    pivot = np.argmax(np.stack([tr, c00, c11, c22], axis=-1), axis=-1)
    q = np.take_along_axis(cand, pivot[..., None, None], axis=-2)[..., 0, :]
    q = quat_normalize(q)
    return np.where(q[..., :1] < 0, -q, q)


def rotvec_to_quat(phi):
    """Quaternion ``exp(phi/2) = [cos(|phi|/2), sin(|phi|/2) phi/|phi|]``.

    Exact; ``sin(x/2)/x`` uses its Taylor series below 1e-3 rad, so the
    result is accurate to rounding for any small angle including 0.
    """
    phi = np.asarray(phi, dtype=float)
    ang = np.linalg.norm(phi, axis=-1, keepdims=True)
    small = ang < _SMALL_ANGLE
    a2 = ang * ang
    safe = np.where(small, 1.0, ang)
    k = np.where(
        small,
        0.5 - a2 / 48.0 + a2 * a2 / 3840.0,
        np.sin(0.5 * safe) / safe,
    )
    return np.concatenate([np.cos(0.5 * ang), k * phi], axis=-1)


def quat_to_rotvec(q):
    """Rotation vector (axis * angle, angle in [0, pi]) of quaternion ``q``.

    ``q`` is normalised and its sign chosen with ``w >= 0`` first; a series
    for ``atan(x)/x`` keeps small angles accurate.
    """
    q = quat_normalize(q)
    q = np.where(q[..., :1] < 0, -q, q)
    w, v = q[..., :1], q[..., 1:]
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    small = n < _SMALL_ANGLE  # then w > 0.9999995
    safe_n = np.where(small, 1.0, n)
    safe_w = np.where(small, w, 1.0)
    r2 = (n / safe_w) ** 2  # tan^2(angle/2); used only where small
    k = np.where(
        small,
        2.0 / safe_w * (1.0 - r2 / 3.0 + r2 * r2 / 5.0),
        2.0 * np.arctan2(safe_n, w) / safe_n,
    )
    return k * v


def euler_to_mat(pitch, roll, yaw):
    """``C_b^n = Rz(yaw) Rx(pitch) Ry(roll)``."""
    pitch, roll, yaw = np.broadcast_arrays(
        np.asarray(pitch, float), np.asarray(roll, float), np.asarray(yaw, float)
    )
    sp, cp = np.sin(pitch), np.cos(pitch)
    sr, cr = np.sin(roll), np.cos(roll)
    sy, cy = np.sin(yaw), np.cos(yaw)
    return np.stack(
        [
            np.stack([cy * cr - sy * sp * sr, -sy * cp, cy * sr + sy * sp * cr], axis=-1),
            np.stack([sy * cr + cy * sp * sr, cy * cp, sy * sr - cy * sp * cr], axis=-1),
            np.stack([-cp * sr, sp, cp * cr], axis=-1),
        ],
        axis=-2,
    )


def mat_to_euler(C):
    """Inverse of :func:`euler_to_mat`: ``(pitch, roll, yaw)``.

    pitch in [-pi/2, pi/2], roll and yaw in [-pi, pi].  Yaw is taken from
    ``C @ Ry(roll)^T = Rz(yaw) Rx(pitch)``, which keeps the angles consistent
    with ``C`` near gimbal lock (|pitch| = pi/2, where only yaw + roll or
    yaw - roll is observable); exactly at the lock roll is set to 0.
    """
    C = np.asarray(C, dtype=float)
    c20, c21, c22 = C[..., 2, 0], C[..., 2, 1], C[..., 2, 2]
    cp = np.hypot(c20, c22)
    pitch = np.arctan2(c21, cp)
    roll = np.where(cp < 1e-12, 0.0, np.arctan2(-c20, c22))
    sr, cr = np.sin(roll), np.cos(roll)
    yaw = np.arctan2(
        C[..., 1, 0] * cr + C[..., 1, 2] * sr, C[..., 0, 0] * cr + C[..., 0, 2] * sr
    )
    return pitch, roll, yaw


def euler_to_quat(pitch, roll, yaw):
    """``q_nb = qz(yaw) * qx(pitch) * qy(roll)``, sign chosen with ``w >= 0``."""
    pitch, roll, yaw = np.broadcast_arrays(
        np.asarray(pitch, float), np.asarray(roll, float), np.asarray(yaw, float)
    )
    o = np.zeros_like(pitch)
    hp, hr, hy = 0.5 * pitch, 0.5 * roll, 0.5 * yaw
    qx = np.stack([np.cos(hp), np.sin(hp), o, o], axis=-1)
    qy = np.stack([np.cos(hr), o, np.sin(hr), o], axis=-1)
    qz = np.stack([np.cos(hy), o, o, np.sin(hy)], axis=-1)
    q = quat_mul(quat_mul(qz, qx), qy)
    return np.where(q[..., :1] < 0, -q, q)


def quat_to_euler(q):
    """``(pitch, roll, yaw)`` of unit quaternion ``q_nb``."""
    return mat_to_euler(quat_to_mat(q))


def heading_deg_cw_from_north(yaw):
    """Compass heading [deg, 0..360) clockwise from North for ENU ``yaw``.

    ``yaw`` is counter-clockwise about Up with yaw 0 meaning the body y axis
    points North, so heading = -yaw (in degrees) wrapped to [0, 360).
    """
    hdg = np.mod(-np.rad2deg(yaw), 360.0)
    return (np.where(hdg >= 360.0, 0.0, hdg) + 0.0)[()]


# ------------------------------------------------------------------------------------------------------------
# Kernel helpers: the same algebra on single vectors, compiled with numba for the sequential kernels
# (mechanization, filters). One set, used by every kernel of the package.


@nb.njit(cache=True)
def cross3(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@nb.njit(cache=True)
def qmul(p, q):
    return np.array([
        p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
        p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2],
        p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1],
        p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0]])


@nb.njit(cache=True)
def qexp(phi):
    """Unit quaternion of the rotation vector phi (series below 1e-8 rad)."""
    theta = np.sqrt(phi[0] ** 2 + phi[1] ** 2 + phi[2] ** 2)
    if theta < 1e-8:
        c, s = 1.0 - theta * theta / 8, 0.5 - theta * theta / 48
    else:
        c, s = np.cos(0.5 * theta), np.sin(0.5 * theta) / theta
    return np.array([c, s * phi[0], s * phi[1], s * phi[2]])


@nb.njit(cache=True)
def qrot(q, v):
    u = q[1:]
    t = 2.0 * cross3(u, v)
    return v + q[0] * t + cross3(u, t)


@nb.njit(cache=True)
def skew3(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@nb.njit(cache=True)
def quat_mat(q):
    """C_b^n of q_nb."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


@nb.njit(cache=True)
def rotvec_mat(r):
    """Rotation matrix of the rotation vector r (Rodrigues; series for tiny angles)."""
    a2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
    if a2 < 1e-16:
        s, c = 1.0 - a2 / 6.0, 0.5 - a2 / 24.0
    else:
        a = np.sqrt(a2)
        s, c = np.sin(a) / a, (1.0 - np.cos(a)) / a2
    k = skew3(r)
    return np.eye(3) + s * k + c * (k @ k)


@nb.njit(cache=True)
def mat_rotvec(c):
    """Rotation vector of a rotation matrix (angles below pi)."""
    cos_a = min(1.0, max(-1.0, 0.5 * (c[0, 0] + c[1, 1] + c[2, 2] - 1)))
    a = np.arccos(cos_a)
    v = np.array([c[2, 1] - c[1, 2], c[0, 2] - c[2, 0], c[1, 0] - c[0, 1]])
    return 0.5 * v if a < 1e-9 else a / (2 * np.sin(a)) * v
