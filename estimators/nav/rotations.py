"""Rotation algebra on NumPy arrays, vectorised over leading dimensions: estimators.nav.rotation_kernels' numba
kernels (the one definition) run over the rows of the broadcast arguments.

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
``(...,3,3)``; Euler angles are arrays of shape ``(...)``.  Inputs may be
lists or arrays of any real dtype; results are float64 arrays (floats for
scalar Euler angles).  The kernels' names (qmul, qexp, ...) are re-exported
for the sequential kernels.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from estimators.nav import rotation_kernels as K
from estimators.nav.rotation_kernels import (
    cross3,
    mat_rotvec,
    qexp,
    qmul,
    qrot,
    quat_mat,
    rotvec_mat,
    skew3,
)

__all__ = [
    "cross3",
    "euler_to_mat",
    "euler_to_quat",
    "heading_deg_cw_from_north",
    "mat_rotvec",
    "mat_to_euler",
    "mat_to_quat",
    "qexp",
    "qmul",
    "qrot",
    "quat_conj",
    "quat_mat",
    "quat_mul",
    "quat_normalize",
    "quat_rotate",
    "quat_to_euler",
    "quat_to_mat",
    "quat_to_rotvec",
    "rotvec_mat",
    "rotvec_to_quat",
    "skew",
    "skew3",
]

_VEC, _QUAT, _MAT, _ANGLE = (3,), (4,), (3, 3), ()


def _rows(kernel, out_core, *args):
    """``kernel(*rows, out)`` over the rows of ``args`` = (value, core shape) pairs, their leading dimensions
    broadcast by NumPy's rules; the result has shape ``leading + out_core``."""
    arrays, leads = [], []
    for value, core in args:
        a = np.asarray(value, dtype=np.float64)
        k = a.ndim - len(core)
        if k < 0 or a.shape[k:] != core:
            raise ValueError(f"expected an array of shape (..., {', '.join(map(str, core))}), got {a.shape}")
        arrays.append(a)
        leads.append(a.shape[:k])
    lead = leads[0] if leads.count(leads[0]) == len(leads) else np.broadcast_shapes(*leads)
    rows = [
        np.ascontiguousarray(a if a_lead == lead else np.broadcast_to(a, lead + core)).reshape((-1, *core))
        for a, a_lead, (_, core) in zip(arrays, leads, args)
    ]
    out = np.empty((rows[0].shape[0], *out_core))
    kernel(*rows, out)
    return out.reshape(lead + out_core)


@nb.njit(cache=True)
def _skew_rows(v, out):
    for i in range(out.shape[0]):
        out[i] = skew3(v[i])


@nb.njit(cache=True)
def _quat_mul_rows(p, q, out):
    for i in range(out.shape[0]):
        K.qmul_into(p[i], q[i], out[i])


@nb.njit(cache=True, error_model="numpy")
def _quat_normalize_rows(q, out):
    for i in range(out.shape[0]):
        K.qnormalize_into(q[i], out[i])


@nb.njit(cache=True)
def _quat_rotate_rows(q, v, out):
    for i in range(out.shape[0]):
        K.qrot_into(q[i], v[i], out[i])


@nb.njit(cache=True)
def _quat_to_mat_rows(q, out):
    for i in range(out.shape[0]):
        K.quat_mat_into(q[i], out[i])


@nb.njit(cache=True, error_model="numpy")
def _mat_to_quat_rows(c, out):
    for i in range(out.shape[0]):
        K.mat_quat_into(c[i], out[i])


@nb.njit(cache=True)
def _rotvec_to_quat_rows(phi, out):
    for i in range(out.shape[0]):
        K.qexp_into(phi[i], out[i])


@nb.njit(cache=True, error_model="numpy")
def _quat_to_rotvec_rows(q, out):
    for i in range(out.shape[0]):
        K.quat_rotvec_into(q[i], out[i])


@nb.njit(cache=True)
def _euler_to_mat_rows(pitch, roll, yaw, out):
    for i in range(out.shape[0]):
        K.euler_mat_into(pitch[i], roll[i], yaw[i], out[i])


@nb.njit(cache=True)
def _euler_to_quat_rows(pitch, roll, yaw, out):
    for i in range(out.shape[0]):
        K.euler_quat_into(pitch[i], roll[i], yaw[i], out[i])


@nb.njit(cache=True)
def _mat_to_euler_rows(c, out):
    for i in range(out.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = K.mat_euler(c[i])


@nb.njit(cache=True)
def _quat_to_euler_rows(q, out):
    c = np.empty((3, 3))
    for i in range(out.shape[0]):
        K.quat_mat_into(q[i], c)
        out[i, 0], out[i, 1], out[i, 2] = K.mat_euler(c)


def skew(v):
    """Cross-product matrix ``[v]x`` with ``skew(v) @ u == cross(v, u)``."""
    return _rows(_skew_rows, _MAT, (v, _VEC))


def quat_mul(p, q):
    """Hamilton product ``p * q``; ``q_ac = quat_mul(q_ab, q_bc)``."""
    return _rows(_quat_mul_rows, _QUAT, (p, _QUAT), (q, _QUAT))


def quat_conj(q):
    """Conjugate ``[w, -x, -y, -z]`` (the inverse of a unit quaternion)."""
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_normalize(q):
    """Scale ``q`` to unit norm."""
    return _rows(_quat_normalize_rows, _QUAT, (q, _QUAT))


def quat_rotate(q, v):
    """Rotate vector ``v`` by unit quaternion ``q``: ``v' = q v q*``.

    With ``q = q_nb`` this maps b components to n components.
    """
    return _rows(_quat_rotate_rows, _VEC, (q, _QUAT), (v, _VEC))


def quat_to_mat(q):
    """Direction cosine matrix of unit quaternion ``q`` (``q_nb -> C_b^n``)."""
    return _rows(_quat_to_mat_rows, _MAT, (q, _QUAT))


def mat_to_quat(C):
    """Unit quaternion of rotation matrix ``C`` (``C_b^n -> q_nb``), ``w >= 0``.

    Shepperd's method: of the four expressions ``4 q_i q`` the one with the
    largest ``|q_i|`` (largest of trace, C00, C11, C22) is normalised, so
    no small pivot is ever divided by.
    """
    return _rows(_mat_to_quat_rows, _QUAT, (C, _MAT))


def rotvec_to_quat(phi):
    """Quaternion ``exp(phi/2) = [cos(|phi|/2), sin(|phi|/2) phi/|phi|]``.

    Exact; below 1e-8 rad the series of ``cos(x/2)`` and ``sin(x/2)/x``
    (equal to them in double precision there) avoids 0/0.
    """
    return _rows(_rotvec_to_quat_rows, _QUAT, (phi, _VEC))


def quat_to_rotvec(q):
    """Rotation vector (axis * angle, angle in [0, pi]) of quaternion ``q``.

    ``q`` is normalised and its sign chosen with ``w >= 0`` first; a series
    for ``atan(x)/x`` keeps small angles accurate.
    """
    return _rows(_quat_to_rotvec_rows, _VEC, (q, _QUAT))


def euler_to_mat(pitch, roll, yaw):
    """``C_b^n = Rz(yaw) Rx(pitch) Ry(roll)``."""
    return _rows(_euler_to_mat_rows, _MAT, (pitch, _ANGLE), (roll, _ANGLE), (yaw, _ANGLE))


def _angles(rows):
    """(pitch, roll, yaw) of an array ``(..., 3)`` of them, each ``(...)`` (a float for one)."""
    return rows[..., 0][()], rows[..., 1][()], rows[..., 2][()]


def mat_to_euler(C):
    """Inverse of :func:`euler_to_mat`: ``(pitch, roll, yaw)``.

    pitch in [-pi/2, pi/2], roll and yaw in [-pi, pi].  Yaw is taken from
    ``C @ Ry(roll)^T = Rz(yaw) Rx(pitch)``, which keeps the angles consistent
    with ``C`` near gimbal lock (|pitch| = pi/2, where only yaw + roll or
    yaw - roll is observable); exactly at the lock roll is set to 0.
    """
    return _angles(_rows(_mat_to_euler_rows, _VEC, (C, _MAT)))


def euler_to_quat(pitch, roll, yaw):
    """``q_nb = qz(yaw) * qx(pitch) * qy(roll)``, sign chosen with ``w >= 0``."""
    return _rows(_euler_to_quat_rows, _QUAT, (pitch, _ANGLE), (roll, _ANGLE), (yaw, _ANGLE))


def quat_to_euler(q):
    """``(pitch, roll, yaw)`` of unit quaternion ``q_nb``."""
    return _angles(_rows(_quat_to_euler_rows, _VEC, (q, _QUAT)))


def heading_deg_cw_from_north(yaw):
    """Compass heading [deg, 0..360) clockwise from North for ENU ``yaw``.

    ``yaw`` is counter-clockwise about Up with yaw 0 meaning the body y axis
    points North, so heading = -yaw (in degrees) wrapped to [0, 360).
    """
    hdg = np.mod(-np.rad2deg(yaw), 360.0)
    return (np.where(hdg >= 360.0, 0.0, hdg) + 0.0)[()]
