"""Published shearer truth: smooth splines through the ride samples, carried into the geodetic frame.

Position in the tangent plane t is a quintic interpolating spline through the sampled body positions, so
velocity and acceleration are its exact derivatives. Attitude is q_tb = q_tf (x) Exp(r(t)) with r a
quintic spline through the sampled rotation vectors relative to the face frame; the body rate is the exact
derivative, w_tb^b = J_r(r) dr/dt (J_r the right Jacobian of SO(3)). t is Earth-fixed, so

    v_n  = C_n^t v_t,                    q_nb = q_nt (x) q_tb,
    w_ib^b = w_tb^b + C_b^t w_ie^t,      w_nb^b = w_ib^b - C_b^n (w_ie^n + w_en^n),
    f^b  = C_b^t (a_t + 2 w_ie^t x v_t) - C_b^n g^n,

which is the navigation equation dv_n/dt = C_n^b f^b - (2 w_ie^n + w_en^n) x v_n + g^n written in the
Earth-fixed frame t, so an exact mechanization fed these rates and forces reproduces this trajectory.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import make_interp_spline

from estimators import earth
from estimators.rotations import (mat_to_quat, quat_conj, quat_mul, quat_to_mat, quat_to_rotvec,
                                  rotvec_to_quat, skew)


@dataclass
class ShearerTruth:
    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    p_t: np.ndarray  # (K, 3)
    v_n: np.ndarray
    q_nb: np.ndarray  # (K, 4)
    w_ib_b: np.ndarray
    w_nb_b: np.ndarray
    f_b: np.ndarray


def right_jacobian(r: np.ndarray) -> np.ndarray:
    """J_r(r) of SO(3) (..., 3, 3): w_b = J_r(r) dr/dt for R = R0 Exp(r)."""
    theta = np.linalg.norm(r, axis=-1)[..., None, None]
    small = theta < 1e-6
    th = np.where(small, 1.0, theta)
    a = np.where(small, 0.5 - theta ** 2 / 24, (1 - np.cos(th)) / th ** 2)
    b = np.where(small, 1.0 / 6 - theta ** 2 / 120, (th - np.sin(th)) / th ** 3)
    k = skew(r)
    return np.eye(3) - a * k + b * (k @ k)


def shearer_truth(t: np.ndarray, p_t: np.ndarray, q_tb: np.ndarray, q_tf: np.ndarray,
                  lat0: float, lon0: float, h0: float) -> ShearerTruth:
    """Truth at the sample times from body samples in t (positions and attitudes)."""
    pos = make_interp_spline(t, p_t, k=5)
    v_t, a_t = pos(t, 1), pos(t, 2)
    r = quat_to_rotvec(quat_mul(quat_conj(q_tf), q_tb))
    rot = make_interp_spline(t, r, k=5)
    w_tb_b = np.einsum("kij,kj->ki", right_jacobian(r), rot(t, 1))
    q_tb_s = quat_mul(q_tf, rotvec_to_quat(r))

    lat, lon, h = earth.enu_to_lla(p_t, lat0, lon0, h0)
    mat_nt = earth.mat_nt(lat, lon, lat0, lon0)
    mat_tb = quat_to_mat(q_tb_s)
    mat_bt = np.swapaxes(mat_tb, -1, -2)
    mat_bn = mat_bt @ np.swapaxes(mat_nt, -1, -2)
    w_ie_t = earth.earth_rate_n(lat0)  # t is the local-level frame at the reference point
    v_n = np.einsum("kij,kj->ki", mat_nt, v_t)
    q_nb = mat_to_quat(mat_nt @ mat_tb)
    w_ib_b = w_tb_b + np.einsum("kij,j->ki", mat_bt, w_ie_t)
    w_in_n = earth.earth_rate_n(lat) + earth.transport_rate_n(lat, h, v_n)
    w_nb_b = w_ib_b - np.einsum("kij,kj->ki", mat_bn, w_in_n)
    f_b = (np.einsum("kij,kj->ki", mat_bt, a_t + np.cross(2 * w_ie_t, v_t))
           - np.einsum("kij,kj->ki", mat_bn, earth.gravity_n(lat, h)))
    return ShearerTruth(t, lat, lon, h, p_t, v_n, q_nb, w_ib_b, w_nb_b, f_b)
