"""Stationary fine alignment of a standing shearer: the 10-state model of 000 section 5.2 run by an EKF, a UKF
and the "optimized UKF", all sharing one model, one measurement and one loop.

Model, measurements and reset: estimators.sins.alignment_model (the states of 000 eq. 19 as a selection of the
shared error-state layout: dv_E, dv_N, phi_E, phi_N, phi_U, gyro and accelerometer biases; phi the large-azimuth
error angles C_b^n = E(phi) C_b^n').

Loop: increments are summed over blocks of `update_rate` (default 10 Hz); per block the nominal solution
(C_b^n', v') is mechanized, the filter predicts and updates, and the estimated phi and dv are fed back into the
nominal, the covariance following (estimators.sins.alignment_model `reset`). The measurements are linear, so all
three filters share the exact linear (Kalman, Joseph form) update; they differ in the time update only:

* ``ekf``: x <- f(x), P <- Phi P Phi^T + Q_d (Phi from the Jacobian A at the current estimate, eq. 26); the whole
  loop is one numba kernel.
* ``ukf``: the unscented transform of the nonlinear f, filterpy ``MerweScaledSigmaPoints`` with the usual
  scaled-UT parameters alpha = 1e-3, beta = 2, kappa = 0 and filterpy ``unscented_transform``.
* ``optimized_ukf``: 000 section 5.2 names an "optimized UKF" but gives no equation of the optimization (its
  only equations, 15-30, are the model and its discretization, which all three filters here use). What is
  implemented is an explicit, stated choice, not the paper's (unknown) algorithm: the unscented transform with
  the spread chosen for Gaussian priors (Julier-Uhlmann: n + lambda = 3 matches the fourth moment, i.e. alpha =
  1, beta = 2, kappa = 3 - n), so the sigma points sample the attitude error at +-sqrt(3) sigma where the
  nonlinearity acts, instead of the near-linearization of alpha = 1e-3. If the propagated covariance loses
  positive definiteness (the centre weight is negative) the step falls back to the ukf transform.

Limits (`alignment_floors`). At rest an attitude error is invisible when the biases mimic it: a tilt phi_E
changes the north specific force by gamma phi_E and the gyros by the Earth rate turned by phi_E (north by
-w_U phi_E, up by w_N phi_E); phi_N changes the east specific force and, with the heading phi_U, the east gyro.
So phi_N settles at accel bias / g (east), phi_U at the gyrocompassing floor (east gyro bias) / (w_ie cos L)
plus tan L phi_N, and phi_E at the information-weighted mean of what the north accelerometer and the north and
up gyros each say: -nabla_N / g where the accelerometer prior is the tighter reference (every MEMS grade: the
Earth rate is far below the gyro bias), while a navigation-grade gyro (004: 0.001 deg/h against 30 ug) takes
about a sixth of the weight (less the ARW that is not yet averaged down). The start attitude's prior
(initial_sigma_rad) is a source too: with the 3 deg start errors at one sigma it pulls the MEMS level by
(accel sigma / g) / 3 deg = 6 % of accel sigma / g towards the start; and a gyro whose heading floor exceeds the
initial heading uncertainty leaves the heading where it started, with its sigma. The covariance says all this
when the bias priors are given (gyro_bias_sigma, accel_bias_sigma, e.g. the grade's turn-on bias).

Bad input: a shearer that moves fails the test of the innovations (estimators.sins.motion_test); `fine_align`
raises AlignmentError naming the time, or with on_motion="flag" returns the result with `motion_t` set.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, unscented_transform

from estimators.arrays import put
from estimators.kalman.update import joseph_update
from estimators.nav import earth
from estimators.nav.rotations import (
    mat_to_euler,
    mat_to_quat,
    quat_to_euler,
    quat_to_mat,
    rotvec_mat,
)
from estimators.sins.alignment_model import (
    ACCEL_BIAS,
    BIASES,
    DV,
    GYRO_BIAS,
    N_STATES,
    PHI,
    measurement,
    mechanize_nominal,
    propagate,
    propagate_rows,
    reset,
    transition,
)
from estimators.sins.coarse_alignment import AlignmentError, heading_limit, level_limit
from estimators.sins.motion_test import motion_test

METHODS = ("ekf", "ukf", "optimized_ukf")


@dataclass
class FineAlignment:
    """Estimates at each update: t [s] (end of block), q_nb (K, 4), sigma (K, 10) state sigmas after the update
    (attitude sigmas = uncertainty of the attitude), bias (K, 5) the bias states' estimates (alignment_model
    BIASES: gyro x, y, z, then accelerometer x, y; read by name as gyro_bias, accel_bias; phi, dv are reset to 0),
    nis (K,) normalized innovation squared of each update (dof = number of measurements: 3 with the zero-rate
    update, else 2), the final covariance P, and motion_t: the start [s] of the first window that failed the
    motion test (None: the data look stationary)."""

    method: str
    t: np.ndarray
    q_nb: np.ndarray
    sigma: np.ndarray
    bias: np.ndarray
    P: np.ndarray
    nis: np.ndarray
    motion_t: float | None = None

    @property
    def gyro_bias(self) -> np.ndarray:
        """(K, 3) gyro bias estimates [rad/s] in b (reported - true)."""
        return self.bias[:, GYRO_BIAS.start - BIASES.start:GYRO_BIAS.stop - BIASES.start]

    @property
    def accel_bias(self) -> np.ndarray:
        """(K, 2) accelerometer bias estimates [m/s^2] in b, x and y (reported - true)."""
        return self.bias[:, ACCEL_BIAS.start - BIASES.start:ACCEL_BIAS.stop - BIASES.start]

    @property
    def attitude_sigma(self) -> np.ndarray:
        """(K, 3) one-sigma attitude error [rad] in n: east, north, up (up = heading)."""
        return self.sigma[:, PHI]

    def attitude(self, window_s: float = 0.0, k: int = -1) -> np.ndarray:
        """q_nb at update k, or with window_s > 0 the mean of the estimates over the window_s before it: the
        standing IMU has one attitude, and the mean removes the update-to-update tracking noise of the filter
        (gyro ARW against accelerometer VRW: ~8 mdeg per axis for the MTi-G-700) that a single update carries.
        The sigma stays the filter's (conservative for the mean)."""
        k = k % self.t.size
        if window_s <= 0.0:
            return self.q_nb[k]
        q = self.q_nb[np.searchsorted(self.t, self.t[k] - window_s, side="right"): k + 1]
        q = q * np.sign(q @ q[-1])[:, None]  # one hemisphere; then the chordal mean
        return q.mean(axis=0) / np.linalg.norm(q.mean(axis=0))

    def errors(self, q_true: np.ndarray, k: int = -1, window_s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Errors against the truth of `attitude(window_s, k)`: (estimate - truth of pitch, roll, yaw [rad]; the
        error angles phi [rad] of the filter's state, C_b^n_true = Rz(phi_U) Rx(phi_E) Ry(phi_N) C_b^n_est)."""
        q_est = self.attitude(window_s, k)
        e_est, e_true = np.array(quat_to_euler(q_est)), np.array(quat_to_euler(q_true))
        d = (e_est - e_true + np.pi) % (2 * np.pi) - np.pi
        phi = np.array(mat_to_euler(quat_to_mat(q_true) @ quat_to_mat(q_est).T))
        return d, phi

    def nees(self, q_true: np.ndarray) -> float:
        """Normalized attitude error squared phi^T P_phi^-1 phi at the end (the full P is kept for it)."""
        _, phi = self.errors(q_true)
        return float(phi @ np.linalg.solve(self.P[PHI, PHI], phi))


def alignment_floors(c_nb, accel_bias_b, gyro_bias_b, lat: float, accel_sigma: float, gyro_sigma: float,
                     h: float = 0.0, *, arw: float = 0.0, seconds: float = np.inf, start_error=None,
                     start_sigma=None) -> tuple[np.ndarray, np.ndarray]:
    """Final attitude errors phi = (phi_E, phi_N, phi_U) [rad] of an ideal stationary alignment, for the attitude
    c_nb (C_b^n; the tilt is about the axes of the estimate once its heading error is taken out, so pass the
    estimate's) and effective biases in b (reported - true, whatever their cause: turn-on bias, non-orthogonality
    times the sensed gravity, in-run drift).

    Returns (floors, classical). classical = (-nabla_N / g, nabla_E / g, tan L phi_N - eps_E / (w_ie cos L)):
    the accelerometer and gyrocompassing floors (estimators.sins.coarse_alignment `level_limit`, `heading_limit`). floors:
    each angle the information-weighted mean of every source's verdict on it (module docstring, "Limits"):
    phi_E of the north accelerometer (weight gamma^2 / accel_sigma^2), the north gyro (w_U^2 / s_g^2) and the up
    gyro (w_N^2 / s_g^2); phi_N of the east accelerometer; phi_U of the gyrocompass (w_N^2 / s_g^2); with
    s_g^2 = gyro_sigma^2 + arw^2 / seconds (the ARW [rad/sqrt(s)] averaged over the alignment). With the start
    attitude's error and sigma (3,) [rad] (the filter's prior) each angle also weighs the start's verdict
    (start_error, weight 1 / start_sigma^2): a gyro that cannot gyrocompass leaves the heading at its start."""
    acc_n = np.asarray(c_nb) @ np.asarray(accel_bias_b, float)
    gyr_n = np.asarray(c_nb) @ np.asarray(gyro_bias_b, float)
    w = earth.earth_rate_n(lat)
    phi_n = level_limit(acc_n[0], lat, h)
    classical = np.array([-level_limit(acc_n[1], lat, h), phi_n,
                          np.tan(lat) * phi_n - heading_limit(gyr_n[0], lat)])
    gamma = float(earth.normal_gravity(lat, h))
    s_g2 = max(gyro_sigma ** 2 + arw ** 2 / seconds, 1e-60)
    i_acc = gamma ** 2 / max(accel_sigma, 1e-30) ** 2
    verdicts = [[classical[0], -gyr_n[1] / w[2], gyr_n[2] / w[1]], [classical[1]], [classical[2]]]
    info = [[i_acc, w[2] ** 2 / s_g2, w[1] ** 2 / s_g2], [i_acc], [w[1] ** 2 / s_g2]]
    floors = np.empty(3)
    for i in range(3):
        v, wt = verdicts[i], info[i]
        if start_error is not None:
            v, wt = v + [start_error[i]], wt + [1.0 / start_sigma[i] ** 2]
        floors[i] = np.dot(wt, v) / np.sum(wt)
    return floors, classical


# ------------------------------------------------------------------------------------------------------------
# The loops: the EKF as one numba kernel; the UKF steps the same kernels around the unscented transform.


@nb.njit(cache=True, inline="always")
def _correct(k, c0, c, v, x, p, dth, w, T, r_vel, r_rate, zero_rate, c_out, s_out, b_out, nis_out):
    """Measurement update, reset and outputs of block k (shared by both loops); returns the nominal (c, v)."""
    z, hm, r = measurement(c0, c, v, dth, w, T, r_vel, r_rate, zero_rate)
    nis_out[k] = joseph_update(x, p, z, hm, r)
    c, v = reset(c, v, x, p)
    put(c_out[k], c)
    for i in range(N_STATES):
        s_out[k, i] = math.sqrt(p[i, i])
    put(b_out[k], x[BIASES])
    return c, v


@nb.njit(cache=True)
def _ekf_kernel(dth_b, dv_b, c, v, x, T, w, r_ie, g_n, gamma, q_psd, p, r_vel, r_rate, zero_rate, c_out, s_out,
                b_out, nis_out):
    """The EKF loop over all blocks from the nominal (c, v) and state (x, p); outputs into c_out (K, 3, 3),
    s_out (K, 10), b_out (K, 5), nis_out (K,); returns the final P."""
    for k in range(dth_b.shape[0]):
        c0 = c
        c, v = mechanize_nominal(c, v, dth_b[k], dv_b[k], r_ie, g_n, w[2], T)
        phi, qd = transition(c, w, gamma, T, q_psd)
        x = propagate(x, c, r_ie, w[2], gamma, T)
        p = phi @ p @ phi.T + qd
        c, v = _correct(k, c0, c, v, x, p, dth_b[k], w, T, r_vel, r_rate, zero_rate, c_out, s_out, b_out, nis_out)
    return p


# ------------------------------------------------------------------------------------------------------------
# API


def _block_sums(a: np.ndarray, m: int) -> np.ndarray:
    k = a.shape[0] // m
    return np.ascontiguousarray(a[: k * m].reshape(k, m, 3).sum(axis=1))


def _ukf_loop(method, dth_b, dv_b, c, v, x, T, w, r_ie, g_n, gamma, q_psd, P, r_vel, r_rate, zero_rate, c_out,
              s_out, b_out, nis_out):
    """The UKF loop (arguments as _ekf_kernel): the unscented time update (filterpy) between the shared kernels."""
    pts = {"ukf": MerweScaledSigmaPoints(N_STATES, alpha=1e-3, beta=2.0, kappa=0.0),
           "optimized_ukf": MerweScaledSigmaPoints(N_STATES, alpha=1.0, beta=2.0, kappa=3.0 - N_STATES)}
    names = (method, "ukf") if method == "optimized_ukf" else ("ukf",)
    for k in range(dth_b.shape[0]):
        c0 = c
        c, v = mechanize_nominal(c, v, dth_b[k], dv_b[k], r_ie, g_n, w[2], T)
        _, qd = transition(c, w, gamma, T, q_psd)
        for name in names:
            sp = pts[name]
            x_new, P_new = unscented_transform(propagate_rows(sp.sigma_points(x, P), c, r_ie, w[2], gamma, T),
                                               sp.Wm, sp.Wc, qd)
            P_new = 0.5 * (P_new + P_new.T)
            try:
                np.linalg.cholesky(P_new)
            except np.linalg.LinAlgError:
                continue
            x, P = x_new, P_new
            break
        else:
            raise np.linalg.LinAlgError("the propagated covariance is not positive definite")
        c, v = _correct(k, c0, c, v, x, P, dth_b[k], w, T, r_vel, r_rate, zero_rate, c_out, s_out, b_out, nis_out)
    return P


def fine_align(dtheta, dv, dt: float, lat: float, q0_nb, grade_noise: tuple[float, float], initial_sigma_rad,
               method: str = "ukf", *, h: float = 0.0, gyro_bias_sigma: float = 0.0, accel_bias_sigma: float = 0.0,
               velocity_sigma: float = 1e-3, rate_sigma: float = 0.0, update_rate: float = 10.0, gyro_bias_psd: float = 0.0,
               accel_bias_psd: float = 0.0, zero_rate: bool = True, on_motion: str = "raise") -> FineAlignment:
    """Fine alignment of a stationary IMU from increments (rows over equal intervals dt [s]).

    lat [rad], h [m]: the known position; q0_nb: the (coarse) start attitude; grade_noise = (arw [rad/sqrt(s)],
    vrw [m/s/sqrt(s)]); initial_sigma_rad: (3,) sigma of the initial attitude errors phi_E, phi_N, phi_U [rad];
    method: 'ekf', 'ukf' or 'optimized_ukf'. gyro_bias_sigma [rad/s] and accel_bias_sigma [m/s^2]: priors of the
    bias states (the grade's turn-on bias; 0 keeps them at zero). velocity_sigma [m/s]: the measurement noise of
    the zero-velocity observation (vibration of the standing machine). rate_sigma [rad/s]: the same machine's
    vibration in the zero-rate observation, as noise of the mean rate over an update block, added to the gyro's
    random walk (a navigation-grade gyro's walk is far below a standing shearer's rocking). gyro_bias_psd [rad^2/s^3] and
    accel_bias_psd [m^2/s^5]: random-walk PSD of the bias states for an in-run bias instability (000 eq. 16 takes
    them as random constants, the default 0; a Gauss-Markov bias of sigma s and time tau gives 2 s^2 / tau).
    zero_rate: use the vertical zero-rate measurement (module docstring). on_motion: 'raise' (AlignmentError) or
    'flag' (FineAlignment.motion_t) when the data fail the standing test.
    Returns a FineAlignment.
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; use one of {', '.join(METHODS)}")
    if on_motion not in ("raise", "flag"):
        raise ValueError(f"on_motion must be 'raise' or 'flag', got {on_motion!r}")
    dtheta, dv = np.asarray(dtheta, float), np.asarray(dv, float)
    if dtheta.shape != dv.shape or dtheta.ndim != 2 or dtheta.shape[1] != 3:
        raise ValueError(f"increments must be two (N, 3) arrays; got {dtheta.shape} and {dv.shape}")
    if not (np.isfinite(dtheta).all() and np.isfinite(dv).all()):
        raise ValueError("increments contain NaN or infinite values")
    earth.check_latitude(lat)
    m = max(1, round(1.0 / (update_rate * dt)))
    if dtheta.shape[0] < m:
        raise ValueError(f"{dtheta.shape[0]} samples are shorter than one update block of {m}")
    T = m * dt
    dth_b, dv_b = _block_sums(dtheta, m), _block_sums(dv, m)
    n_upd = dth_b.shape[0]

    arw, vrw = grade_noise
    tiny = 1e-14  # keeps P positive definite for the unscented transforms where a noise is zero
    q_psd = np.zeros(N_STATES)
    q_psd[DV] = max(vrw, 1e-6) ** 2
    q_psd[PHI] = max(arw, 1e-9) ** 2
    q_psd[GYRO_BIAS] = gyro_bias_psd
    q_psd[ACCEL_BIAS] = accel_bias_psd
    var0 = np.zeros(N_STATES)
    var0[DV] = velocity_sigma ** 2
    var0[PHI] = np.asarray(initial_sigma_rad, float) ** 2
    var0[GYRO_BIAS] = max(gyro_bias_sigma, 1e-12) ** 2
    var0[ACCEL_BIAS] = max(accel_bias_sigma, tiny) ** 2
    P = np.diag(var0)
    w = earth.earth_rate_n(lat)
    gamma = float(earth.normal_gravity(lat, h))
    g_n = earth.gravity_n(lat, h)
    r_vel, r_rate = velocity_sigma ** 2, max(arw, 1e-9) ** 2 * T + (rate_sigma * T) ** 2
    c = quat_to_mat(np.asarray(q0_nb, float) / np.linalg.norm(q0_nb))

    c_out = np.empty((n_upd, 3, 3))
    s_out = np.empty((n_upd, N_STATES))
    b_out = np.empty((n_upd, BIASES.stop - BIASES.start))
    nis = np.empty(n_upd)
    args = (dth_b, dv_b, c, np.zeros(2), np.zeros(N_STATES), T, w, rotvec_mat(-w * T), g_n, gamma, q_psd, P, r_vel, r_rate, zero_rate, c_out, s_out, b_out, nis)
    P = _ekf_kernel(*args) if method == "ekf" else _ukf_loop(method, *args)
    t_out = np.arange(1, n_upd + 1) * T
    res = FineAlignment(method, t_out, mat_to_quat(c_out), s_out, b_out, P, nis,
                        motion_test(nis, 3 if zero_rate else 2, T))
    if res.motion_t is not None and on_motion == "raise":
        raise AlignmentError(f"the zero-velocity/zero-rate innovations from t = {res.motion_t:.1f} s are not those "
                             f"of a standing IMU: the shearer moves; align while it stands")
    return res
