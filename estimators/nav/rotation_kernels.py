"""Rotation algebra on single vectors, compiled with numba: the one definition of the package's rotations.

The sequential kernels (mechanization, filters) call these directly; estimators.nav.rotations runs them over the
rows of NumPy arrays. Conventions are DESIGN.md's: scalar-first Hamilton quaternions, q_nb and C_b^n take body
(b) components to navigation (n) components, C_b^n = Rz(yaw) Rx(pitch) Ry(roll) with (pitch, roll, yaw) about
(x, y, z). A ``*_into`` form writes its result into an array the caller allocated (it may not alias an input
unless said); the form without the suffix returns a new array. The ``*_into`` forms are inlined into the caller
(inline="always"), so they take the caller's fast-math flags; the array forms are compiled without them.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from numba.extending import register_jitable

# Below this |v| of a unit quaternion's vector part (about its angle / 2) quat_rotvec_into uses the series of
# atan(x) / x; with the terms kept the truncation error is < 1e-19 relative.
SMALL_ANGLE = 1e-3


@nb.njit(cache=True, inline="always")
def cross_parts(a, b):
    """a x b of two 3-vectors (arrays or tuples) as three scalars."""
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


@nb.njit(cache=True)
def cross3(a, b):
    x, y, z = cross_parts(a, b)
    return np.array([x, y, z])


@nb.njit(cache=True)
def skew3(v):
    """Cross-product matrix [v]x, skew3(v) @ u = v x u."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@nb.njit(cache=True, inline="always")
def qmul_into(p, q, out):
    """out = p (x) q, the Hamilton product (q_ac = q_ab (x) q_bc); out may be p or q."""
    out[0], out[1], out[2], out[3] = qmul_parts(p[0], p[1], p[2], p[3], q[0], q[1], q[2], q[3])


@nb.njit(cache=True, inline="always")
def qmul_parts(p0, p1, p2, p3, q0, q1, q2, q3):
    """The Hamilton product p (x) q of quaternions given as scalars, as four scalars."""
    return (p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3, p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1, p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0)


@nb.njit(cache=True)
def qmul(p, q):
    out = np.empty(4)
    qmul_into(p, q, out)
    return out


@nb.njit(cache=True, inline="always", error_model="numpy")
def qnormalize_into(q, out):
    """out = q / |q|; out may be q."""
    n = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    for i in range(4):
        out[i] = q[i] / n


@nb.njit(cache=True, inline="always")
def qexp_into(phi, out):
    """out = exp(phi / 2) = [cos(|phi|/2), sin(|phi|/2) phi / |phi|], the unit quaternion of the rotation vector
    phi (axis * angle); series below 1e-8 rad."""
    out[0], out[1], out[2], out[3] = qexp_parts(phi[0], phi[1], phi[2])


@nb.njit(cache=True, inline="always")
def qexp_parts(a0, a1, a2):
    """`qexp_into` of the rotation vector (a0, a1, a2), as four scalars."""
    theta = np.sqrt(a0 ** 2 + a1 ** 2 + a2 ** 2)
    if theta < 1e-8:
        c, s = 1.0 - theta * theta / 8, 0.5 - theta * theta / 48
    else:
        c, s = np.cos(0.5 * theta), np.sin(0.5 * theta) / theta
    return c, s * a0, s * a1, s * a2


@nb.njit(cache=True)
def qexp(phi):
    out = np.empty(4)
    qexp_into(phi, out)
    return out


@nb.njit(cache=True, inline="always", error_model="numpy")
def quat_rotvec_into(q, out):
    """out = the rotation vector (angle in [0, pi]) of q, normalised and taken with w >= 0 first; the series of
    atan(x) / x below SMALL_ANGLE keeps small angles accurate."""
    n = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if q[0] < 0:
        n = -n
    w, x, y, z = q[0] / n, q[1] / n, q[2] / n, q[3] / n
    nv = np.sqrt(x * x + y * y + z * z)
    if nv < SMALL_ANGLE:  # then w > 0.9999995
        r = nv / w
        r2 = r * r  # tan^2(angle / 2)
        k = 2.0 / w * (1.0 - r2 / 3.0 + r2 * r2 / 5.0)
    else:
        k = 2.0 * math.atan2(nv, w) / nv
    out[0], out[1], out[2] = k * x, k * y, k * z


@nb.njit(cache=True, inline="always")
def qrot_parts(w, x, y, z, v0, v1, v2):
    """q v q* = C_b^n(q) v for a unit q = (w, x, y, z), in scalars: v + w t + u x t with t = 2 u x v, u = (x, y, z)."""
    tx = 2.0 * (y * v2 - z * v1)
    ty = 2.0 * (z * v0 - x * v2)
    tz = 2.0 * (x * v1 - y * v0)
    return v0 + w * tx + (y * tz - z * ty), v1 + w * ty + (z * tx - x * tz), v2 + w * tz + (x * ty - y * tx)


@nb.njit(cache=True, inline="always")
def qrot_into(q, v, out):
    """out = q v q* (qrot_parts)."""
    out[0], out[1], out[2] = qrot_parts(q[0], q[1], q[2], q[3], v[0], v[1], v[2])


@nb.njit(cache=True)
def qrot(q, v):
    out = np.empty(3)
    qrot_into(q, v, out)
    return out


@nb.njit(cache=True, inline="always")
def quat_mat_into(q, c_nb):
    """C_b^n of the unit quaternion q_nb into c_nb (3, 3)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    c_nb[0, 0], c_nb[0, 1], c_nb[0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    c_nb[1, 0], c_nb[1, 1], c_nb[1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    c_nb[2, 0], c_nb[2, 1], c_nb[2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)


@nb.njit(cache=True)
def quat_mat(q):
    """C_b^n of q_nb."""
    c_nb = np.empty((3, 3))
    quat_mat_into(q, c_nb)
    return c_nb


@nb.njit(cache=True, inline="always", error_model="numpy")
def mat_quat_into(c, out):
    """out = the unit quaternion of the rotation matrix c (C_b^n -> q_nb), w >= 0. Shepperd's method: of the
    four expressions 4 q_i q the one with the largest |q_i| (largest of trace, c00, c11, c22, the first on a tie)
    is normalised, so no small pivot is divided by."""
    tr = c[0, 0] + c[1, 1] + c[2, 2]
    pivot, best = 0, tr
    for i in range(3):
        if c[i, i] > best:
            pivot, best = i + 1, c[i, i]
    if pivot == 0:
        out[0], out[1], out[2], out[3] = 1 + tr, c[2, 1] - c[1, 2], c[0, 2] - c[2, 0], c[1, 0] - c[0, 1]
    elif pivot == 1:
        out[0], out[1], out[2], out[3] = c[2, 1] - c[1, 2], 1 + 2 * c[0, 0] - tr, c[0, 1] + c[1, 0], c[0, 2] + c[2, 0]
    elif pivot == 2:
        out[0], out[1], out[2], out[3] = c[0, 2] - c[2, 0], c[0, 1] + c[1, 0], 1 + 2 * c[1, 1] - tr, c[1, 2] + c[2, 1]
    else:
        out[0], out[1], out[2], out[3] = c[1, 0] - c[0, 1], c[0, 2] + c[2, 0], c[1, 2] + c[2, 1], 1 + 2 * c[2, 2] - tr
    qnormalize_into(out, out)
    if out[0] < 0:
        for i in range(4):
            out[i] = -out[i]


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


@nb.njit(cache=True, inline="always")
def euler_mat_into(pitch, roll, yaw, c):
    """c = Rz(yaw) Rx(pitch) Ry(roll) (3, 3) of scalar angles."""
    sp, cp = math.sin(pitch), math.cos(pitch)
    sr, cr = math.sin(roll), math.cos(roll)
    sy, cy = math.sin(yaw), math.cos(yaw)
    c[0, 0], c[0, 1], c[0, 2] = cy * cr - sy * sp * sr, -sy * cp, cy * sr + sy * sp * cr
    c[1, 0], c[1, 1], c[1, 2] = sy * cr + cy * sp * sr, cy * cp, sy * sr - cy * sp * cr
    c[2, 0], c[2, 1], c[2, 2] = -cp * sr, sp, cp * cr


@nb.njit(cache=True)
def euler_mat(pitch, roll, yaw):
    """C = Rz(yaw) Rx(pitch) Ry(roll); fine alignment's large-azimuth error matrix E(phi) with
    (phi_E, phi_N, phi_U)."""
    c = np.empty((3, 3))
    euler_mat_into(pitch, roll, yaw, c)
    return c


@nb.njit(cache=True)
def mat_euler(c):
    """Inverse of euler_mat: (pitch, roll, yaw), pitch in [-pi/2, pi/2], roll and yaw in [-pi, pi]. Yaw is taken
    from c Ry(roll)^T = Rz(yaw) Rx(pitch), which keeps the angles consistent with c near gimbal lock (|pitch| =
    pi/2, where only yaw + roll or yaw - roll is observable); exactly at the lock roll is set to 0."""
    cp = math.hypot(c[2, 0], c[2, 2])
    pitch = math.atan2(c[2, 1], cp)
    roll = 0.0 if cp < 1e-12 else math.atan2(-c[2, 0], c[2, 2])
    sr, cr = math.sin(roll), math.cos(roll)
    return pitch, roll, math.atan2(c[1, 0] * cr + c[1, 2] * sr, c[0, 0] * cr + c[0, 2] * sr)


@register_jitable
def euler_quat(pitch, roll, yaw):
    """q_nb = qz(yaw) qx(pitch) qy(roll) as four components, its sign as the product gives it."""
    cp, sp = np.cos(0.5 * pitch), np.sin(0.5 * pitch)
    cr, sr = np.cos(0.5 * roll), np.sin(0.5 * roll)
    cy, sy = np.cos(0.5 * yaw), np.sin(0.5 * yaw)
    return (cy * cp * cr - sy * sp * sr, cy * sp * cr - sy * cp * sr, cy * cp * sr + sy * sp * cr,
            cy * sp * sr + sy * cp * cr)


# euler_quat inlined into the caller's IR, so it takes the caller's flags: the register_jitable form is compiled
# once per process, with the flags of the kernel that compiles it first (the support filters' fast math).
_euler_quat_inlined = nb.njit(inline="always")(euler_quat)


@nb.njit(cache=True, inline="always")
def euler_quat_into(pitch, roll, yaw, out):
    """out = euler_quat(pitch, roll, yaw) with its sign chosen for w >= 0."""
    w, x, y, z = _euler_quat_inlined(pitch, roll, yaw)
    if w < 0:
        w, x, y, z = -w, -x, -y, -z
    out[0], out[1], out[2], out[3] = w, x, y, z
