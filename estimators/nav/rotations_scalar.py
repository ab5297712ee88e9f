"""Rotation algebra in scalar form, for the batched (prange) support filters' kernels.

Conventions are estimators.nav.rotation_kernels' (scalar-first Hamilton q_nb, C_b^n = Rz(yaw) Rx(pitch) Ry(roll)).
Its array forms (qmul, qexp, qrot, quat_mat, ...) take and return arrays, a new one per call; these take quaternion
components as scalars or write into arrays the caller allocated once, so a kernel's sample loop allocates nothing.
`euler_quat` and `quat_mat_into` are the kernels' own, re-exported here for the support filters. Where one repeats
an array-form helper it is kept for speed, measured on our support filter's kernel (estimators.support.error_state,
200 units, 60 s at 100 Hz, per core on the 2-core development machine): 490-555x real time with these, 370-375x
with quat_mat in place of `quat_mat_into` (the same numbers), 180-190x with qrot in place of `add_rotated` (and
4e-16 apart). Where the formulas differ (qexp's series against `exp_half`'s, rotation_kernels.mat_euler's yaw and
gimbal-lock case against `quat_euler`'s) the scalar form is the one the support filters' numbers come from.

The njit helpers are inlined into the calling kernel (inline="always") and so compiled with its fast-math flags
(the support kernels': estimators.support.kernel_math.FASTMATH); the register_jitable ones also serve NumPy arrays.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numba.extending import register_jitable

from estimators.nav.rotation_kernels import euler_quat, quat_mat_into

__all__ = [
    "add_rotated",
    "euler_quat",
    "exp_half",
    "mul_exp",
    "normalize_continuous",
    "quat_euler",
    "quat_mat_into",
    "sub_rotated_back",
]


@register_jitable
def quat_euler(q0, q1, q2, q3):
    """(pitch, roll, yaw) of a quaternion q_nb, normalised first: pitch = asin(C_21), roll = atan2(-C_20, C_22),
    yaw = atan2(-C_01, C_11) of C_b^n (002 eqs. 14, 21 in the project's convention). Unlike
    rotation_kernels.mat_euler, no special case at gimbal lock."""
    n2 = q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3
    c20 = 2.0 * (q1 * q3 - q0 * q2) / n2
    c21 = 2.0 * (q2 * q3 + q0 * q1) / n2
    c22 = 1.0 - 2.0 * (q1 * q1 + q2 * q2) / n2
    c01 = 2.0 * (q1 * q2 - q0 * q3) / n2
    c11 = 1.0 - 2.0 * (q1 * q1 + q3 * q3) / n2
    return np.arctan2(c21, np.sqrt(c20 * c20 + c22 * c22)), np.arctan2(-c20, c22), np.arctan2(-c01, c11)


@register_jitable
def exp_half(ax, ay, az):
    """(c, s) with exp(a / 2) = [c, s a_x, s a_y, s a_z] for the rotation vector a [rad] (002 eq. 12:
    c = cos(|a|/2), s = sin(|a|/2) / |a|; Taylor series to 4th order below 0.01 rad, exact to 1e-17, where
    rotation_kernels.qexp switches at 1e-8 rad)."""
    a2 = ax * ax + ay * ay + az * az
    if a2 < 1e-4:
        return 1.0 - a2 / 8.0 + a2 * a2 / 384.0, 0.5 - a2 / 48.0 + a2 * a2 / 3840.0
    ang = np.sqrt(a2)
    return np.cos(0.5 * ang), np.sin(0.5 * ang) / ang


@nb.njit(cache=True, inline="always")
def mul_exp(q, a0, a1, a2):
    """q <- q (x) exp(a / 2) in place, unnormalised (002 eq. 12 for the increment a [rad], `exp_half`)."""
    c, s = exp_half(a0, a1, a2)
    r1, r2, r3 = s * a0, s * a1, s * a2
    w, x, y, z = q[0], q[1], q[2], q[3]
    q[0] = w * c - x * r1 - y * r2 - z * r3
    q[1] = w * r1 + x * c + y * r3 - z * r2
    q[2] = w * r2 - x * r3 + y * c + z * r1
    q[3] = w * r3 + x * r2 - y * r1 + z * c


@nb.njit(cache=True, inline="always")
def add_rotated(q, v, acc):
    """acc += C_b^n(q) v for a unit q: rotation_kernels.qrot added into acc without its three new arrays (2.7x faster in
    the support kernel, see the module docstring)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    tx = 2.0 * (y * v[2] - z * v[1])
    ty = 2.0 * (z * v[0] - x * v[2])
    tz = 2.0 * (x * v[1] - y * v[0])
    acc[0] += v[0] + w * tx + (y * tz - z * ty)
    acc[1] += v[1] + w * ty + (z * tx - x * tz)
    acc[2] += v[2] + w * tz + (x * ty - y * tx)


@nb.njit(cache=True, inline="always")
def sub_rotated_back(u, q, v, out):
    """out = u - C_n^b(q) v = u - C_b^n(q)^T v for a unit q (the rows of C_b^n as columns)."""
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    ex, ey, ez = v[0], v[1], v[2]
    out[0] = u[0] - ((1 - 2 * (q2 * q2 + q3 * q3)) * ex + 2 * (q1 * q2 + q0 * q3) * ey + 2 * (q1 * q3 - q0 * q2) * ez)
    out[1] = u[1] - (2 * (q1 * q2 - q0 * q3) * ex + (1 - 2 * (q1 * q1 + q3 * q3)) * ey + 2 * (q2 * q3 + q0 * q1) * ez)
    out[2] = u[2] - (2 * (q1 * q3 + q0 * q2) * ex + 2 * (q2 * q3 - q0 * q1) * ey + (1 - 2 * (q1 * q1 + q2 * q2)) * ez)


@nb.njit(cache=True, inline="always")
def normalize_continuous(q, prev):
    """q normalised in place, its sign chosen on prev's side (q and -q are the same attitude); prev may be q."""
    n = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if q[0] * prev[0] + q[1] * prev[1] + q[2] * prev[2] + q[3] * prev[3] < 0:
        n = -n
    for i in range(4):
        q[i] = q[i] / n

