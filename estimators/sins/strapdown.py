"""Strapdown mechanization in the local-level ENU frame from IMU increments (000 eqs. 3-5).

Per interval, in the fixed order velocity, position, attitude, each with mid-interval quantities:

* attitude increment of the body over N sub-samples: the rotation vector
  phi = sum theta_i + (sum_{i<N} k_i theta_i) x theta_N (N-sample coning compensation, estimators.sins.coning);
* velocity increment in the body frame with rotation and sculling corrections:
  dv_b = sum v_i + 1/2 (sum theta_i) x (sum v_i) + sum_{i<N} k_i (theta_i x v_N + v_i x theta_N);
* velocity: v_k = v_{k-1} + (I - 1/2 [zeta x]) C_nb(k-1) dv_b + (g_n - (2 w_ie + w_en) x v) h,
  zeta = (w_ie + w_en) h the rotation of n over the interval;
* position: latitude, longitude, height from the mean velocity;
* attitude: q_nb(k) = Exp(-zeta) (x) q_nb(k-1) (x) Exp(phi).

One step kernel (`strapdown_step`, numba) takes the point the Earth and transport rates, gravity and Coriolis
are evaluated at from its caller: `mechanize` extrapolates the mid-interval state from the last two epochs, the
odometer filter (estimators.shearer.odometer_filter) takes the interval's start. `mechanize` validates input and
converts between arrays and the kernel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from estimators.arrays import put
from estimators.nav import earth
from estimators.nav.earth import gravity_nb, nav_rates, radii_nb
from estimators.nav.rotations import cross3, qexp, qmul, qrot
from estimators.sins.coning import coefficients


@dataclass
class NavState:
    """Navigation solution at each time: geodetic position, ENU velocity, attitude q_nb."""

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    v_n: np.ndarray  # (K, 3)
    q_nb: np.ndarray  # (K, 4)


def compensate(dtheta: np.ndarray, dv: np.ndarray, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Per update of N increments (rows 1.., grouped by N): the rotation vector with coning compensation and
    the body velocity increment with rotation and sculling compensation (000 eqs. 60-61, 68-69), (U, 3) each.

    phi = sum theta_i + c x theta_N,  dv_b = sum v_i + 1/2 (sum theta_i) x (sum v_i) + c x v_N + d x theta_N,
    with c = sum_{i<N} k_i theta_i and d = sum_{i<N} k_i v_i (estimators.sins.coning)."""
    u = (dtheta.shape[0] - 1) // n_samples
    th = dtheta[1:1 + u * n_samples].reshape(u, n_samples, 3)
    v = dv[1:1 + u * n_samples].reshape(u, n_samples, 3)
    k = coefficients(n_samples)
    sum_th, sum_v = th.sum(axis=1), v.sum(axis=1)
    c = np.einsum("i,uij->uj", k, th[:, :-1])
    d = np.einsum("i,uij->uj", k, v[:, :-1])
    phi = sum_th + np.cross(c, th[:, -1])
    dv_b = sum_v + 0.5 * np.cross(sum_th, sum_v) + np.cross(c, v[:, -1]) + np.cross(d, th[:, -1])
    return phi, dv_b


@nb.njit(cache=True)
def body_attitude(q0: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Attitude of the body relative to a non-rotating frame after each update: q_u = q_{u-1} (x) Exp(phi_u)."""
    out = np.empty((phi.shape[0] + 1, 4))
    out[0] = q0
    for u in range(phi.shape[0]):
        q = qmul(out[u], qexp(phi[u]))
        out[u + 1] = q / np.sqrt(np.sum(q * q))
    return out


@nb.njit(cache=True)
def strapdown_step(lat, lon, h, v, q, phi, dv_b, dt, lat_e, h_e, v_e, hold_height):
    """One update over dt (000 eqs. 3-5) of the state (lat, lon, h, v_n, q_nb) with the compensated increments phi,
    dv_b; the Earth and transport rates, gravity and Coriolis of the velocity update evaluated at the caller's
    point (lat_e, h_e, v_e) (`_mechanize_kernel`: the extrapolated mid-interval state; the odometer filter's
    epochs: the interval's start). hold_height zeroes the new vertical velocity.

    Returns (lat, lon, h, v_n, q_nb) after the update, the specific-force increment in n (dv_n) and the mean
    velocity over the interval."""
    w_ie, w_en = nav_rates(lat_e, h_e, v_e)
    zeta = (w_ie + w_en) * dt
    dv_n = qrot(q, dv_b)
    dv_n = dv_n - 0.5 * cross3(zeta, dv_n)
    g_n = np.array([0.0, 0.0, -gravity_nb(lat_e, h_e)])
    v_new = v + dv_n + (g_n - cross3(2.0 * w_ie + w_en, v_e)) * dt
    if hold_height:  # the vertical channel held (an altitude aid or a known floor): no vertical motion
        v_new[2] = 0.0
    v_bar = 0.5 * (v + v_new)
    h_new = h + v_bar[2] * dt
    h_bar = 0.5 * (h + h_new)
    r_m, r_n = radii_nb(lat)
    lat_new = lat + v_bar[1] * dt / (r_m + h_bar)
    lat_bar = 0.5 * (lat + lat_new)
    r_m, r_n = radii_nb(lat_bar)
    lon_new = lon + v_bar[0] * dt / ((r_n + h_bar) * np.cos(lat_bar))
    # Attitude with the n-frame rotation re-evaluated at the new mid-interval state.
    w_ie, w_en = nav_rates(lat_bar, h_bar, v_bar)
    q_new = qmul(qmul(qexp(-(w_ie + w_en) * dt), q), qexp(phi))
    return lat_new, lon_new, h_new, v_new, q_new / np.sqrt(np.sum(q_new * q_new)), dv_n, v_bar


@nb.njit(cache=True)
def _mechanize_kernel(t_upd, phi, dv_b, lat, lon, hgt, vel, quat, hold_height, u_first):
    """Update u (over (t_upd[u-1], t_upd[u]]) with the compensated phi[u-1], dv_b[u-1]; outputs at index u, from
    u_first (1; 2 where rows 0 and 1 are the last two updates of an earlier block)."""
    for u in range(u_first, lat.size):
        # Mid-interval position and velocity, extrapolated from the last two epochs.
        if u >= 2:
            lat_m = lat[u - 1] + 0.5 * (lat[u - 1] - lat[u - 2])
            h_m = hgt[u - 1] + 0.5 * (hgt[u - 1] - hgt[u - 2])
            v_m = vel[u - 1] + 0.5 * (vel[u - 1] - vel[u - 2])
        else:
            lat_m, h_m, v_m = lat[0], hgt[0], vel[0].copy()
        lat[u], lon[u], hgt[u], v_n, q_nb, _dv_n, _v_bar = strapdown_step(
            lat[u - 1], lon[u - 1], hgt[u - 1], vel[u - 1], quat[u - 1], phi[u - 1], dv_b[u - 1],
            t_upd[u] - t_upd[u - 1], lat_m, h_m, v_m, hold_height)
        put(vel[u], v_n)
        put(quat[u], q_nb)


def compensated_increments(t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, n_samples: int,
                           first_row: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Check a log of increments (row k over (t[k-1], t[k]]; row 0 unused) and compensate it per update of
    `n_samples` increments: (update times t[0], t[N], ... ; rotation vectors; body velocity increments).

    Raises ValueError with one line naming the first bad row (numbered from `first_row`, the number of row 0 in a
    longer log): shapes, time order, a sample-rate change (a gap or a mixed-rate log), non-finite values."""
    t = np.ascontiguousarray(t, float)
    dtheta = np.ascontiguousarray(dtheta, float)
    dv = np.ascontiguousarray(dv, float)
    if dtheta.shape != (t.size, 3) or dv.shape != (t.size, 3):
        raise ValueError(f"increments must be ({t.size}, 3) like t; got {dtheta.shape} and {dv.shape}")
    step = np.diff(t)
    if t.size > 1 and not np.all(step > 0):
        raise ValueError(f"time must increase; row {first_row + int(np.argmin(step > 0)) + 1} does not")
    if t.size > 2:
        median = np.median(step)
        odd = np.flatnonzero(np.abs(step - median) > 0.5 * median)
        if odd.size:
            raise ValueError(f"sample interval at row {first_row + odd[0] + 1} is {step[odd[0]]:.6g} s, the median is "
                             f"{median:.6g} s: resample or split the log at the gap")
    for name, arr in (("dtheta", dtheta), ("dv", dv)):
        bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
        if bad.size:
            raise ValueError(f"{name} row {first_row + bad[0]} is not finite")
    phi, dv_b = compensate(dtheta, dv, n_samples)
    t_upd = np.ascontiguousarray(t[: phi.shape[0] * n_samples + 1: n_samples])
    return t_upd, phi, dv_b


def mechanize(t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, lat0: float, lon0: float, h0: float,
              v0_n: np.ndarray, q0_nb: np.ndarray, n_samples: int = 4, hold_height: bool = False) -> NavState:
    """Integrate increments (row k over (t[k-1], t[k]]; row 0 unused) from the state at t[0].

    Attitude and velocity are updated every `n_samples` increments with N-sample coning and sculling
    compensation (estimators.sins.coning; N = 1 is none); the solution is at t[0], t[N], t[2N], ...
    `hold_height` keeps the height and zeroes the vertical velocity (the unstable vertical channel held).
    """
    t_upd, phi, dv_b = compensated_increments(t, dtheta, dv, n_samples)
    earth.check_latitude(lat0)
    n = phi.shape[0] + 1
    lat, lon, hgt = np.empty(n), np.empty(n), np.empty(n)
    vel, quat = np.empty((n, 3)), np.empty((n, 4))
    lat[0], lon[0], hgt[0], vel[0] = lat0, lon0, h0, v0_n
    quat[0] = np.asarray(q0_nb, float) / np.linalg.norm(q0_nb)
    _mechanize_kernel(t_upd, phi, dv_b, lat, lon, hgt, vel, quat, hold_height, 1)
    return NavState(t_upd, lat, lon, hgt, vel, quat)


class Mechanization:
    """`mechanize` over consecutive blocks of increments, carrying the state from block to block: the rows are,
    bit for bit, those of one call over the whole log. Each block (t, dtheta, dv) starts at the last block's end
    (row 0 unused, t[0] the end time) and holds a whole number of updates of n_samples increments."""

    def __init__(self, lat0: float, lon0: float, h0: float, v0_n: np.ndarray, q0_nb: np.ndarray, n_samples: int = 4,
                 hold_height: bool = False):
        earth.check_latitude(lat0)
        self.n_samples, self.hold_height = n_samples, hold_height
        self._last = NavState(np.zeros(1), np.array([lat0]), np.array([lon0]), np.array([h0]),
                              np.asarray(v0_n, float).reshape(1, 3),
                              (np.asarray(q0_nb, float) / np.linalg.norm(q0_nb)).reshape(1, 4))

    def run(self, t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, first_row: int = 0) -> NavState:
        """The solution at the block's update times (t[0], t[N], ...; row 0 the state the block starts from);
        `first_row` numbers the block's rows in a ValueError (compensated_increments)."""
        t_upd, phi, dv_b = compensated_increments(t, dtheta, dv, self.n_samples, first_row)
        k = self._last.lat.size  # rows of history: 1 at the start, then the last two updates
        n = phi.shape[0] + k
        lat, lon, hgt = np.empty(n), np.empty(n), np.empty(n)
        vel, quat = np.empty((n, 3)), np.empty((n, 4))
        last = self._last
        lat[:k], lon[:k], hgt[:k], vel[:k], quat[:k] = last.lat, last.lon, last.h, last.v_n, last.q_nb
        pad = np.zeros((k - 1, 3))
        _mechanize_kernel(np.concatenate([np.zeros(k - 1), t_upd]), np.concatenate([pad, phi]),
                          np.concatenate([pad, dv_b]), lat, lon, hgt, vel, quat, self.hold_height, k)
        rows = slice(n - 2, n) if n >= 2 else slice(0, n)
        self._last = NavState(t_upd[-2:], lat[rows], lon[rows], hgt[rows], vel[rows], quat[rows])
        out = slice(k - 1, n)
        return NavState(t_upd, lat[out], lon[out], hgt[out], vel[out], quat[out])
