"""Stationary fine alignment of a standing shearer: the 10-state model of 000 section 5.2 run by an EKF, a UKF
and the "optimized UKF", all sharing one model, one measurement and one loop.

State (000 eq. 19, same order and meaning):

    x = [dV_E, dV_N, phi_E, phi_N, phi_U, eps_ax, eps_ay, eps_wx, eps_wy, eps_wz]

dV_E, dV_N: east/north velocity error of the computed solution (the truth stands still); phi: attitude error of
the computed navigation frame n', as large-azimuth error angles C_n'^n = E(phi) = Rz(phi_U) Rx(phi_E) Ry(phi_N)
(C_b^n = E(phi) C_b^n'; to first order E = I + [phi x], the psi-angle convention of estimators.sins.error_model and
C_n^n' ~ I - [phi x] of 000 eq. 10). phi_U is the heading error at any size and the tilt E^T e_U does not depend
on it, so a heading uncertainty of tens of degrees does not leak into the level (a rotation-vector state does).
eps_a (x, y) and eps_w (x, y, z): accelerometer and gyro biases in the body frame, reported = true + eps, random
constants (000 eq. 16) or random walks (`gyro_bias_psd`, `accel_bias_psd`).

Model. 000 eqs. 15 and 20-22 are the small-angle linearization; to handle the 3, 3, 5 deg initial errors the
filter propagates the exact nonlinear error of a stationary IMU instead (derived from the mechanization
C_b^n'(k+1) = Exp(-w_ie T) C_b^n'(k) Exp(dtheta), v(k+1) = v(k) + C_b^n' dv + g T - 2 w_ie x v T, and the truth
C_b^n constant up to the Earth rotation, v = 0):

    E(phi_{k+1}) = R E(phi_k) R^T Exp(-C_b^n'(k+1) eps_w T),        R = Exp(-[w_ie x] T)        (000 eq. 15, 18)
    dV_{k+1} = dV_k + [(E(phi_mid)^T - I) f^n + C_b^n' [eps_ax, eps_ay, 0]]_EN T - [2 w_ie x dV]_EN T  (eq. 15, 17)

with f^n = [0, 0, gamma]; linearized at phi = 0 this is A of 000 eqs. 20-22 (with the full psi-angle Earth-rate
coupling -[w_ie x] phi and the gyro drift mapped by the full C_b^n', eq. 22). Process noise W of 000 eq. 19 on
the velocity (VRW^2) and attitude (ARW^2) states; discretized as 000 eqs. 24, 26, 27, 29 (transition
Phi = I + A T + A^2 T^2/2 + A^3 T^3/6, Gamma = T (I + A T/2 + A^2 T^2/6), Q_k = q / T, so Q_d = Gamma Q_k Gamma^T).

Measurements, one linear (z, H, R) per update (000 eqs. 23, 25, 28, 30 and one addition):

* zero velocity (000 eq. 23): z = computed (v_E, v_N) = [I_2 0] x + V, R = velocity_sigma^2 I;
* zero vertical rate (not in 000; ``zero_rate=True``): the standing shearer turns only with the Earth, so the
  gyro output over the block resolved on the computed vertical minus the Earth rate's vertical component is the
  vertical gyro bias: z = [C_b^n' dtheta]_U - w_U T = -w_N T phi_E + T [C_b^n' eps_w]_U + ARW noise,
  R = ARW^2 T. Without it the vertical bias of a MEMS gyro (hundreds of deg/h) turns the computed heading by
  tens of degrees during the alignment: the heading sigma grows to match (measured ~55 deg after 300 s on the
  MTi-G-700, honest, but the start heading is lost); with it the heading keeps its start value and sigma. The
  horizontal gyro outputs are left to the velocity channel (their Earth-rate part depends on the unknown
  heading, the gyrocompassing 000 relies on), so nothing is counted twice there.

Loop: increments are summed over blocks of `update_rate` (default 10 Hz); per block the nominal solution
(C_b^n', v') is mechanized, the filter predicts and updates, and the estimated phi and dV are fed back into the
nominal (error-state reset: C_b^n' <- E(phi) C_b^n', v' <- v' - dV, phi = dV = 0; biases stay in the state),
and the covariance follows the reset, P <- G P G^T with G the Jacobian of the remaining error E(phi) E(phi_hat)^T
in phi (a heading correction turns the tilt axes). Without it the tilt covariance stays in the old axes while
the body-fixed accelerometer bias is mapped through the corrected nominal, and the filter takes that bias for
partly observable: measured, a level sigma of 0.66 accel bias / g on nav-004, and on the MTi-G-700, whose
heading sigma is tens of degrees without the zero-rate update, a level 0.8 deg off with a sigma of 0.05 deg.
The measurements are linear, so all three filters share the exact linear (Kalman, Joseph form) update; they
differ in the time update only:

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

Bad input. The zero-velocity and zero-rate innovations of a standing IMU are white with the covariance the
filter predicts; their normalized squares (NIS) averaged over MOTION_WINDOW_S windows are tested against the
chi-square bound of false-alarm rate MOTION_FALSE_ALARM. A shearer that moves (starts hauling, cuts, turns)
fails the test: `fine_align` raises AlignmentError naming the time, or with on_motion="flag" returns the result
with `motion_t` set.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, unscented_transform
from scipy.stats import chi2

from estimators.kalman.update import joseph_update
from estimators.nav import earth
from estimators.nav.rotations import (
    mat_to_euler,
    mat_to_quat,
    quat_to_euler,
    quat_to_mat,
    rotvec_mat,
)
from estimators.sins.coarse_alignment import AlignmentError, heading_limit, level_limit

DV = slice(0, 2)
PHI = slice(2, 5)
EPS_A = slice(5, 7)
EPS_W = slice(7, 10)
N_STATES = 10
_DVE, _DVN, _PE, _PN, _PU, _AX, _AY, _WX = 0, 1, 2, 3, 4, 5, 6, 7  # indices for the kernels
METHODS = ("ekf", "ukf", "optimized_ukf")

MOTION_WINDOW_S = 10.0
"""Length of the windows [s] over which the normalized innovations are averaged for the motion test."""
MOTION_FALSE_ALARM = 1e-6
"""False-alarm probability per window of the motion test (chi-square of a standing, consistent filter)."""
MOTION_SETTLE_S = 20.0
"""The first seconds, while the 3-5 deg start errors are being removed, are not tested."""


@dataclass
class FineAlignment:
    """Estimates at each update: t [s] (end of block), q_nb (K, 4), sigma (K, 10) state sigmas after the update
    (attitude sigmas = uncertainty of the attitude), bias (K, 5) the bias estimates (phi, dV are reset to 0),
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
# Kernels (numba): shared by the EKF loop and the UKF steps.


@nb.njit(cache=True)
def _err_mat(pe, pn, pu):
    """E(phi) = Rz(phi_U) Rx(phi_E) Ry(phi_N) (estimators.nav.rotations euler_to_mat order)."""
    sp, cp = math.sin(pe), math.cos(pe)
    sr, cr = math.sin(pn), math.cos(pn)
    sy, cy = math.sin(pu), math.cos(pu)
    return np.array([[cy * cr - sy * sp * sr, -sy * cp, cy * sr + sy * sp * cr],
                     [sy * cr + cy * sp * sr, cy * cp, sy * sr - cy * sp * cr],
                     [-cp * sr, sp, cp * cr]])


@nb.njit(cache=True)
def _err_angles(c):
    """Inverse of _err_mat (estimators.nav.rotations mat_to_euler): (phi_E, phi_N, phi_U)."""
    cp = math.hypot(c[2, 0], c[2, 2])
    pe = math.atan2(c[2, 1], cp)
    pn = 0.0 if cp < 1e-12 else math.atan2(-c[2, 0], c[2, 2])
    sr, cr = math.sin(pn), math.cos(pn)
    return pe, pn, math.atan2(c[1, 0] * cr + c[1, 2] * sr, c[0, 0] * cr + c[0, 2] * sr)


@nb.njit(cache=True)
def _propagate(x, c1, r_ie, w_u, gamma, T):
    """The nonlinear error model over one block (module docstring) for one state x."""
    e0 = _err_mat(x[_PE], x[_PN], x[_PU])
    e1 = r_ie @ e0 @ r_ie.T @ rotvec_mat(-(c1 @ x[_WX:_WX + 3]) * T)
    pe, pn, pu = _err_angles(e1)
    mid = _err_mat(0.5 * (x[_PE] + pe), 0.5 * (x[_PN] + pn), 0.5 * (x[_PU] + pu))
    acc_e = gamma * mid[2, 0] + c1[0, 0] * x[_AX] + c1[0, 1] * x[_AY] + 2 * w_u * x[_DVN]  # minus [2 w x dV]
    acc_n = gamma * mid[2, 1] + c1[1, 0] * x[_AX] + c1[1, 1] * x[_AY] - 2 * w_u * x[_DVE]
    out = x.copy()
    out[_DVE] += acc_e * T
    out[_DVN] += acc_n * T
    out[_PE], out[_PN], out[_PU] = pe, pn, pu
    return out


@nb.njit(cache=True)
def _propagate_rows(xs, c1, r_ie, w_u, gamma, T):
    out = np.empty_like(xs)
    for i in range(xs.shape[0]):
        out[i] = _propagate(xs[i], c1, r_ie, w_u, gamma, T)
    return out


@nb.njit(cache=True)
def _transition(c1, w, gamma, T, q_psd):
    """A (000 eqs. 20-22) at phi = 0, then Phi (eq. 26) and Q_d = Gamma Q_k Gamma^T (eqs. 27, 29), third order."""
    a = np.zeros((N_STATES, N_STATES))
    a[_DVE, _DVN], a[_DVN, _DVE] = 2 * w[2], -2 * w[2]
    a[_DVE, _PN], a[_DVN, _PE] = -gamma, gamma  # [f^n x] rows E, N
    a[_DVE:_DVN + 1, _AX:_AY + 1] = c1[:2, :2]
    wx = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    a[_PE:_PU + 1, _PE:_PU + 1] = -wx
    a[_PE:_PU + 1, _WX:_WX + 3] = -c1
    at = a * T
    at2 = at @ at
    eye = np.eye(N_STATES)
    phi = eye + at + at2 / 2 + at2 @ at / 6
    gam = T * (eye + at / 2 + at2 / 6)
    qd = (gam * (q_psd / T)) @ gam.T
    return phi, 0.5 * (qd + qd.T)


@nb.njit(cache=True)
def _mechanize(c, v, dth, dvb, r_ie, g_n, w_u, T):
    """Nominal C_b^n' and (v_E, v_N) over one block (stationary: no transport rate; coning negligible)."""
    c1 = r_ie @ c @ rotvec_mat(dth)
    c1 = 1.5 * c1 - 0.5 * (c1 @ c1.T @ c1)  # keep it orthonormal
    dvn = 0.5 * (c + c1) @ dvb
    v1 = np.array([v[0] + dvn[0] + g_n[0] * T + 2 * w_u * v[1] * T,
                   v[1] + dvn[1] + g_n[1] * T - 2 * w_u * v[0] * T])
    return c1, v1


@nb.njit(cache=True)
def _measurement(c0, c1, v, dth, w, T, r_vel, r_rate, zero_rate):
    """(z, H, R) of the standing IMU: zero velocity, and with zero_rate the vertical rate (module docstring)."""
    m = 3 if zero_rate else 2
    z = np.zeros(m)
    hm = np.zeros((m, N_STATES))
    r = np.zeros((m, m))
    z[0], z[1] = v[0], v[1]
    hm[0, _DVE] = hm[1, _DVN] = 1.0
    r[0, 0] = r[1, 1] = r_vel
    if zero_rate:
        c_mid = 0.5 * (c0 + c1)
        z[2] = c_mid[2, 0] * dth[0] + c_mid[2, 1] * dth[1] + c_mid[2, 2] * dth[2] - w[2] * T
        hm[2, _PE] = -w[1] * T
        hm[2, _WX:_WX + 3] = c_mid[2] * T
        r[2, 2] = r_rate
    return z, hm, r




@nb.njit(cache=True)
def _reset(c, v, x, p):
    """Feed phi and dV into the nominal and zero them (the biases stay in the state); P <- G P G^T with G the
    Jacobian (central differences) of the remaining error E(phi) E(phi_hat)^T in phi at phi_hat (module
    docstring, "Loop")."""
    e_hat = _err_mat(x[_PE], x[_PN], x[_PU])
    g = np.zeros((3, 3))
    step = 1e-5
    for j in range(3):
        lo, hi = x[_PE:_PU + 1].copy(), x[_PE:_PU + 1].copy()
        lo[j] -= step
        hi[j] += step
        a = _err_angles(_err_mat(hi[0], hi[1], hi[2]) @ e_hat.T)
        b = _err_angles(_err_mat(lo[0], lo[1], lo[2]) @ e_hat.T)
        for i in range(3):
            g[i, j] = (a[i] - b[i]) / (2 * step)
    p[_PE:_PU + 1, :] = g @ np.ascontiguousarray(p[_PE:_PU + 1, :])
    p[:, _PE:_PU + 1] = np.ascontiguousarray(p[:, _PE:_PU + 1]) @ g.T
    c1 = e_hat @ c
    v1 = np.array([v[0] - x[_DVE], v[1] - x[_DVN]])
    x[:_PU + 1] = 0.0
    return c1, v1


@nb.njit(cache=True)
def _correct(k, c0, c, v, x, p, dth, w, T, r_vel, r_rate, zero_rate, c_out, s_out, b_out, nis_out):
    """Measurement update, reset and outputs of block k (shared by both loops); returns the nominal (c, v)."""
    z, hm, r = _measurement(c0, c, v, dth, w, T, r_vel, r_rate, zero_rate)
    nis_out[k] = joseph_update(x, p, z, hm, r)
    c, v = _reset(c, v, x, p)
    c_out[k] = c
    for i in range(N_STATES):
        s_out[k, i] = math.sqrt(p[i, i])
    b_out[k] = x[_AX:]
    return c, v


@nb.njit(cache=True)
def _ekf_kernel(dth_b, dv_b, c, v, x, T, w, r_ie, g_n, gamma, q_psd, p, r_vel, r_rate, zero_rate, c_out, s_out,
                b_out, nis_out):
    """The EKF loop over all blocks from the nominal (c, v) and state (x, p); outputs into c_out (K, 3, 3),
    s_out (K, 10), b_out (K, 5), nis_out (K,); returns the final P."""
    for k in range(dth_b.shape[0]):
        c0 = c
        c, v = _mechanize(c, v, dth_b[k], dv_b[k], r_ie, g_n, w[2], T)
        phi, qd = _transition(c, w, gamma, T, q_psd)
        x = _propagate(x, c, r_ie, w[2], gamma, T)
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
        c, v = _mechanize(c, v, dth_b[k], dv_b[k], r_ie, g_n, w[2], T)
        _, qd = _transition(c, w, gamma, T, q_psd)
        for name in names:
            sp = pts[name]
            x_new, P_new = unscented_transform(_propagate_rows(sp.sigma_points(x, P), c, r_ie, w[2], gamma, T),
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


def motion_test(nis: np.ndarray, dof: int, T: float) -> float | None:
    """Start [s] of the first MOTION_WINDOW_S window (after MOTION_SETTLE_S) whose summed normalized innovation
    squared exceeds the chi-square bound of MOTION_FALSE_ALARM, or None."""
    n = max(1, round(MOTION_WINDOW_S / T))
    start = round(MOTION_SETTLE_S / T)
    k = (nis.size - start) // n
    if k < 1:
        return None
    sums = nis[start: start + k * n].reshape(k, n).sum(axis=1)
    bad = np.flatnonzero(sums > chi2.isf(MOTION_FALSE_ALARM, dof * n))
    return None if bad.size == 0 else float((start + bad[0] * n) * T)


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
    q_psd[EPS_A] = accel_bias_psd
    q_psd[EPS_W] = gyro_bias_psd
    s0 = np.asarray(initial_sigma_rad, float)
    P = np.diag(np.concatenate([[velocity_sigma ** 2] * 2, s0 ** 2, [max(accel_bias_sigma, tiny) ** 2] * 2,
                                [max(gyro_bias_sigma, 1e-12) ** 2] * 3]))
    w = earth.earth_rate_n(lat)
    gamma = float(earth.normal_gravity(lat, h))
    g_n = earth.gravity_n(lat, h)
    r_vel, r_rate = velocity_sigma ** 2, max(arw, 1e-9) ** 2 * T + (rate_sigma * T) ** 2
    c = quat_to_mat(np.asarray(q0_nb, float) / np.linalg.norm(q0_nb))

    c_out = np.empty((n_upd, 3, 3))
    s_out = np.empty((n_upd, N_STATES))
    b_out = np.empty((n_upd, 5))
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
