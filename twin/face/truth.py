"""Published shearer truth: smooth splines through the ride samples, carried into the geodetic frame.

Position in the tangent plane t is an interpolating spline (degree SPLINE_DEGREE) through the sampled body positions, so
velocity and acceleration are its exact derivatives. Attitude is q_tb = q_tf (x) Exp(r(t)) with r a
spline through the sampled rotation vectors relative to the face frame; the body rate is the exact
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

from estimators.nav import earth
from estimators.nav.rotations import (
    quat_conj,
    quat_mul,
    quat_rotate,
    quat_to_rotvec,
    rotvec_to_quat,
)

SPLINE_DEGREE = 5
"""Degree of the truth splines: quintic, so acceleration (specific force) is smooth to its third derivative."""


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


def right_jacobian_times(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """J_r(r) v for SO(3) (vectors (..., 3)): the body rate w_b = J_r(r) dr/dt of R = R0 Exp(r).

    J_r(r) = I - a [r]x + b [r]x^2 with a = (1 - cos t) / t^2, b = (t - sin t) / t^3, t = |r|.
    """
    theta = np.linalg.norm(r, axis=-1, keepdims=True)
    small = theta < 1e-4
    th = np.where(small, 1.0, theta)
    a = np.where(small, 0.5 - theta ** 2 / 24, (1 - np.cos(th)) / th ** 2)
    b = np.where(small, 1.0 / 6 - theta ** 2 / 120, (th - np.sin(th)) / th ** 3)
    r_x_v = np.cross(r, v)
    return v - a * r_x_v + b * np.cross(r, r_x_v)


def shearer_truth(t_ride: np.ndarray, p_ride: np.ndarray, q_ride: np.ndarray, t: np.ndarray, q_tf: np.ndarray,
                  lat0: float, lon0: float, h0: float) -> ShearerTruth:
    """Truth at times t from the ride's body samples in the tangent plane (positions and q_tb)."""
    pos = make_interp_spline(t_ride, p_ride, k=SPLINE_DEGREE)
    p_t, v_t, a_t = pos(t), pos(t, 1), pos(t, 2)
    del pos
    r_ride = quat_to_rotvec(quat_mul(np.broadcast_to(quat_conj(q_tf), q_ride.shape), q_ride))
    rot = make_interp_spline(t_ride, r_ride, k=SPLINE_DEGREE)
    r = rot(t)
    w_tb_b = right_jacobian_times(r, rot(t, 1))
    del rot
    q_tb = quat_mul(np.broadcast_to(q_tf, (t.size, 4)), rotvec_to_quat(r))
    del r

    lat, lon, h = earth.enu_to_lla(p_t, lat0, lon0, h0)
    q_nt = quat_mul(quat_conj(earth.quat_en(lat, lon)), np.broadcast_to(earth.quat_en(lat0, lon0), (t.size, 4)))
    q_nb = quat_mul(q_nt, q_tb)
    q_bt, q_bn = quat_conj(q_tb), quat_conj(q_nb)
    w_ie_t = np.broadcast_to(earth.earth_rate_n(lat0), v_t.shape)  # t is level at the reference point
    v_n = quat_rotate(q_nt, v_t)
    w_ib_b = w_tb_b + quat_rotate(q_bt, w_ie_t)
    w_in_n = earth.earth_rate_n(lat) + earth.transport_rate_n(lat, h, v_n)
    w_nb_b = w_ib_b - quat_rotate(q_bn, w_in_n)
    f_b = quat_rotate(q_bt, a_t + np.cross(2 * w_ie_t, v_t)) - quat_rotate(q_bn, earth.gravity_n(lat, h))
    return ShearerTruth(t, lat, lon, h, p_t, v_n, q_nb, w_ib_b, w_nb_b, f_b)
