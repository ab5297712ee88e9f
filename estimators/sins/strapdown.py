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

from estimators.nav import earth
from estimators.nav.earth import gravity_nb, nav_rate_parts, radii_nb
from estimators.nav.rotation_kernels import cross_parts, qexp_parts, qmul_parts, qrot_into
from estimators.nav.rotations import qexp, qmul
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
    phi, dv_b = np.empty((u, 3)), np.empty((u, 3))
    _compensate_kernel(np.ascontiguousarray(dtheta, float), np.ascontiguousarray(dv, float), coefficients(n_samples),
                       phi, dv_b)
    return phi, dv_b


@nb.njit(cache=True)
def _compensate_kernel(dtheta, dv, k, phi, dv_b):
    """`compensate` into phi, dv_b (U, 3) in one pass over the increments, each sum and product in the order of
    NumPy's vector form (the same numbers bit for bit: tests/estimators/sins/test_strapdown.py)."""
    n = k.size + 1
    for u in range(phi.shape[0]):
        r = 1 + u * n
        last = r + n - 1
        s_th = (dtheta[r, 0], dtheta[r, 1], dtheta[r, 2])
        s_v = (dv[r, 0], dv[r, 1], dv[r, 2])
        for i in range(1, n):
            s_th = (s_th[0] + dtheta[r + i, 0], s_th[1] + dtheta[r + i, 1], s_th[2] + dtheta[r + i, 2])
            s_v = (s_v[0] + dv[r + i, 0], s_v[1] + dv[r + i, 1], s_v[2] + dv[r + i, 2])
        c = (0.0, 0.0, 0.0)
        d = (0.0, 0.0, 0.0)
        for i in range(n - 1):
            c = (c[0] + k[i] * dtheta[r + i, 0], c[1] + k[i] * dtheta[r + i, 1], c[2] + k[i] * dtheta[r + i, 2])
            d = (d[0] + k[i] * dv[r + i, 0], d[1] + k[i] * dv[r + i, 1], d[2] + k[i] * dv[r + i, 2])
        th_n = (dtheta[last, 0], dtheta[last, 1], dtheta[last, 2])
        v_n = (dv[last, 0], dv[last, 1], dv[last, 2])
        coning = cross_parts(c, th_n)
        rotation = cross_parts(s_th, s_v)
        sculling_c = cross_parts(c, v_n)
        sculling_d = cross_parts(d, th_n)
        for j in range(3):
            phi[u, j] = s_th[j] + coning[j]
            dv_b[u, j] = s_v[j] + 0.5 * rotation[j] + sculling_c[j] + sculling_d[j]


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
    velocity over the interval (`step_into` with new arrays)."""
    v_new, q_new, dv_n, v_bar = np.empty(3), np.empty(4), np.empty(3), np.empty(3)
    lat_new, lon_new, h_new = step_into(lat, lon, h, v, q, phi, dv_b, dt, lat_e, h_e, v_e, hold_height, v_new, q_new,
                                        dv_n, v_bar)
    return lat_new, lon_new, h_new, v_new, q_new, dv_n, v_bar


@nb.njit(cache=True, inline="always")
def step_into(lat, lon, h, v, q, phi, dv_b, dt, lat_e, h_e, v_e, hold_height, v_new, q_new, dv_n, v_bar):
    """`strapdown_step` into the caller's arrays v_new, q_new, dv_n, v_bar (none of them an input); returns
    (lat, lon, h). Written in scalars (no array for a term), each the operations of the vector form in its order, so
    the numbers are the vector form's bit for bit (tests/estimators/sins/test_strapdown.py)."""
    # dv_n = C_b^n dv_b (rotation_kernels.qrot), less half the n-frame rotation zeta = (w_ie + w_en) dt across it.
    ie1, ie2, en0, en1, en2 = nav_rate_parts(lat_e, h_e, v_e[0], v_e[1])
    z0, z1, z2 = (0.0 + en0) * dt, (ie1 + en1) * dt, (ie2 + en2) * dt
    qrot_into(q, dv_b, dv_n)
    r0, r1, r2 = dv_n[0], dv_n[1], dv_n[2]
    dv_n[0] = r0 - 0.5 * (z1 * r2 - z2 * r1)
    dv_n[1] = r1 - 0.5 * (z2 * r0 - z0 * r2)
    dv_n[2] = r2 - 0.5 * (z0 * r1 - z1 * r0)
    # v_new = v + dv_n + (g_n - (2 w_ie + w_en) x v_e) dt
    c0, c1, c2 = 2.0 * 0.0 + en0, 2.0 * ie1 + en1, 2.0 * ie2 + en2
    g = -gravity_nb(lat_e, h_e)
    v_new[0] = v[0] + dv_n[0] + (0.0 - (c1 * v_e[2] - c2 * v_e[1])) * dt
    v_new[1] = v[1] + dv_n[1] + (0.0 - (c2 * v_e[0] - c0 * v_e[2])) * dt
    v_new[2] = v[2] + dv_n[2] + (g - (c0 * v_e[1] - c1 * v_e[0])) * dt
    if hold_height:  # the vertical channel held (an altitude aid or a known floor): no vertical motion
        v_new[2] = 0.0
    for i in range(3):
        v_bar[i] = 0.5 * (v[i] + v_new[i])
    h_new = h + v_bar[2] * dt
    h_bar = 0.5 * (h + h_new)
    r_m, r_n = radii_nb(lat)
    lat_new = lat + v_bar[1] * dt / (r_m + h_bar)
    lat_bar = 0.5 * (lat + lat_new)
    r_m, r_n = radii_nb(lat_bar)
    lon_new = lon + v_bar[0] * dt / ((r_n + h_bar) * np.cos(lat_bar))
    # Attitude with the n-frame rotation re-evaluated at the new mid-interval state:
    # q_new = Exp(-(w_ie + w_en) dt) (x) q (x) Exp(phi), normalised.
    ie1, ie2, en0, en1, en2 = nav_rate_parts(lat_bar, h_bar, v_bar[0], v_bar[1])
    e0, e1, e2, e3 = qexp_parts(-(0.0 + en0) * dt, -(ie1 + en1) * dt, -(ie2 + en2) * dt)
    p0, p1, p2, p3 = qmul_parts(e0, e1, e2, e3, q[0], q[1], q[2], q[3])
    f0, f1, f2, f3 = qexp_parts(phi[0], phi[1], phi[2])
    p0, p1, p2, p3 = qmul_parts(p0, p1, p2, p3, f0, f1, f2, f3)
    norm = np.sqrt(0.0 + p0 * p0 + p1 * p1 + p2 * p2 + p3 * p3)
    q_new[0], q_new[1], q_new[2], q_new[3] = p0 / norm, p1 / norm, p2 / norm, p3 / norm
    return lat_new, lon_new, h_new


@nb.njit(cache=True)
def _mechanize_kernel(t_upd, phi, dv_b, lat, lon, hgt, vel, quat, hold_height, u_first):
    """Update u (over (t_upd[u-1], t_upd[u]]) with the compensated phi[u-1], dv_b[u-1]; outputs at index u, from
    u_first (1; 2 where rows 0 and 1 are the last two updates of an earlier block)."""
    v_m, dv_n, v_bar = np.empty(3), np.empty(3), np.empty(3)
    for u in range(u_first, lat.size):
        # Mid-interval position and velocity, extrapolated from the last two epochs.
        if u >= 2:
            lat_m = lat[u - 1] + 0.5 * (lat[u - 1] - lat[u - 2])
            h_m = hgt[u - 1] + 0.5 * (hgt[u - 1] - hgt[u - 2])
            for i in range(3):
                v_m[i] = vel[u - 1, i] + 0.5 * (vel[u - 1, i] - vel[u - 2, i])
        else:
            lat_m, h_m = lat[0], hgt[0]
            for i in range(3):
                v_m[i] = vel[0, i]
        lat[u], lon[u], hgt[u] = step_into(lat[u - 1], lon[u - 1], hgt[u - 1], vel[u - 1], quat[u - 1], phi[u - 1],
                                           dv_b[u - 1], t_upd[u] - t_upd[u - 1], lat_m, h_m, v_m, hold_height,
                                           vel[u], quat[u], dv_n, v_bar)


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
