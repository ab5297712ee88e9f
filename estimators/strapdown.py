"""Strapdown mechanization in the local-level ENU frame from IMU increments (000 eqs. 3-5).

Per interval, in the fixed order velocity, position, attitude, each with mid-interval quantities:

* attitude increment of the body: the rotation vector phi = dtheta_k + (1/12) dtheta_{k-1} x dtheta_k
  (two-sample coning correction with the previous interval);
* velocity increment in the body frame with rotation and sculling corrections:
  dv_b = dv_k + 1/2 dtheta_k x dv_k + 1/12 (dtheta_{k-1} x dv_k + dv_{k-1} x dtheta_k);
* velocity: v_k = v_{k-1} + (I - 1/2 [zeta x]) C_nb(k-1) dv_b + (g_n - (2 w_ie + w_en) x v) h,
  zeta = (w_ie + w_en) h the rotation of n over the interval;
* position: latitude, longitude, height from the mean velocity;
* attitude: q_nb(k) = Exp(-zeta) (x) q_nb(k-1) (x) Exp(phi).

The kernel is numba; `mechanize` validates input and converts between arrays and the kernel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from estimators import earth

_radii = nb.njit(cache=True)(earth.radii)
_gravity = nb.njit(cache=True)(earth.normal_gravity_kernel)
_OMEGA = earth.OMEGA_IE


@dataclass
class NavState:
    """Navigation solution at each time: geodetic position, ENU velocity, attitude q_nb."""

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    v_n: np.ndarray  # (K, 3)
    q_nb: np.ndarray  # (K, 4)


@nb.njit(cache=True)
def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@nb.njit(cache=True)
def _qmul(p, q):
    return np.array([
        p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
        p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2],
        p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1],
        p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0]])


@nb.njit(cache=True)
def _qexp(phi):
    """Unit quaternion of the rotation vector phi (series below 1e-8 rad)."""
    theta = np.sqrt(phi[0] ** 2 + phi[1] ** 2 + phi[2] ** 2)
    if theta < 1e-8:
        c, s = 1.0 - theta * theta / 8, 0.5 - theta * theta / 48
    else:
        c, s = np.cos(0.5 * theta), np.sin(0.5 * theta) / theta
    return np.array([c, s * phi[0], s * phi[1], s * phi[2]])


@nb.njit(cache=True)
def _qrot(q, v):
    u = q[1:]
    t = 2.0 * _cross(u, v)
    return v + q[0] * t + _cross(u, t)


@nb.njit(cache=True)
def _rates(lat, h, v):
    """w_ie^n and w_en^n (ENU) at (lat, h) with velocity v."""
    r_m, r_n = _radii(lat)
    w_ie = np.array([0.0, _OMEGA * np.cos(lat), _OMEGA * np.sin(lat)])
    w_en = np.array([-v[1] / (r_m + h), v[0] / (r_n + h), v[0] * np.tan(lat) / (r_n + h)])
    return w_ie, w_en


@nb.njit(cache=True)
def _mechanize_kernel(t, dtheta, dv, lat, lon, hgt, vel, quat, coning):
    for k in range(1, t.size):
        dt = t[k] - t[k - 1]
        phi = dtheta[k].copy()
        dv_b = dv[k] + 0.5 * _cross(dtheta[k], dv[k])
        if coning and k >= 2:
            phi += _cross(dtheta[k - 1], dtheta[k]) / 12.0
            dv_b += (_cross(dtheta[k - 1], dv[k]) + _cross(dv[k - 1], dtheta[k])) / 12.0
        # Mid-interval position and velocity, extrapolated from the last two epochs.
        if k >= 2:
            lat_m = lat[k - 1] + 0.5 * (lat[k - 1] - lat[k - 2])
            h_m = hgt[k - 1] + 0.5 * (hgt[k - 1] - hgt[k - 2])
            v_m = vel[k - 1] + 0.5 * (vel[k - 1] - vel[k - 2])
        else:
            lat_m, h_m, v_m = lat[0], hgt[0], vel[0].copy()
        w_ie, w_en = _rates(lat_m, h_m, v_m)
        zeta = (w_ie + w_en) * dt
        dv_n = _qrot(quat[k - 1], dv_b)
        dv_n = dv_n - 0.5 * _cross(zeta, dv_n)
        g_n = np.array([0.0, 0.0, -_gravity(lat_m, h_m)])
        vel[k] = vel[k - 1] + dv_n + (g_n - _cross(2.0 * w_ie + w_en, v_m)) * dt
        v_bar = 0.5 * (vel[k] + vel[k - 1])
        hgt[k] = hgt[k - 1] + v_bar[2] * dt
        h_bar = 0.5 * (hgt[k] + hgt[k - 1])
        r_m, r_n = _radii(lat[k - 1])
        lat[k] = lat[k - 1] + v_bar[1] * dt / (r_m + h_bar)
        lat_bar = 0.5 * (lat[k] + lat[k - 1])
        r_m, r_n = _radii(lat_bar)
        lon[k] = lon[k - 1] + v_bar[0] * dt / ((r_n + h_bar) * np.cos(lat_bar))
        # Attitude with the n-frame rotation re-evaluated at the new mid-interval state.
        w_ie, w_en = _rates(lat_bar, h_bar, v_bar)
        q = _qmul(_qmul(_qexp(-(w_ie + w_en) * dt), quat[k - 1]), _qexp(phi))
        quat[k] = q / np.sqrt(np.sum(q * q))


def mechanize(t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, lat0: float, lon0: float, h0: float,
              v0_n: np.ndarray, q0_nb: np.ndarray, coning: bool = True) -> NavState:
    """Integrate increments (row k over (t[k-1], t[k]]; row 0 unused) from the state at t[0]."""
    t = np.ascontiguousarray(t, float)
    dtheta = np.ascontiguousarray(dtheta, float)
    dv = np.ascontiguousarray(dv, float)
    if dtheta.shape != (t.size, 3) or dv.shape != (t.size, 3):
        raise ValueError(f"increments must be ({t.size}, 3) like t; got {dtheta.shape} and {dv.shape}")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        raise ValueError(f"time must increase; row {int(np.argmin(np.diff(t) > 0)) + 1} does not")
    for name, arr in (("dtheta", dtheta), ("dv", dv)):
        bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
        if bad.size:
            raise ValueError(f"{name} row {bad[0]} is not finite")
    earth.check_latitude(lat0)
    n = t.size
    lat, lon, hgt = np.empty(n), np.empty(n), np.empty(n)
    vel, quat = np.empty((n, 3)), np.empty((n, 4))
    lat[0], lon[0], hgt[0], vel[0] = lat0, lon0, h0, v0_n
    quat[0] = np.asarray(q0_nb, float) / np.linalg.norm(q0_nb)
    _mechanize_kernel(t, dtheta, dv, lat, lon, hgt, vel, quat, coning)
    return NavState(t, lat, lon, hgt, vel, quat)
