"""Stationary fine alignment of a standing shearer: the 10-state model of 000 section 5.2 run by an EKF, a UKF
and the "optimized UKF", all sharing one model and one loop.

State (000 eq. 19, same order and meaning):

    x = [dV_E, dV_N, phi_E, phi_N, phi_U, eps_ax, eps_ay, eps_wx, eps_wy, eps_wz]

dV_E, dV_N: east/north velocity error of the computed solution (the truth stands still); phi: attitude error of
the computed navigation frame n', as large-azimuth error angles C_n'^n = E(phi) = Rz(phi_U) Rx(phi_E) Ry(phi_N)
(C_b^n = E(phi) C_b^n'; to first order E = I + [phi x], the psi-angle convention of estimators.error_model and
C_n^n' ~ I - [phi x] of 000 eq. 10). phi_U is the heading error at any size and the tilt E^T e_U does not depend
on it, so a heading uncertainty of tens of degrees does not leak into the level (a rotation-vector state does:
a UKF on it shrank the heading sigma of a MEMS IMU below its true error). eps_a (x, y) and eps_w (x, y, z): accelerometer and gyro biases in the body
frame, reported = true + eps, random constants (000 eq. 16).

Model. 000 eqs. 15 and 20-22 are the small-angle linearization; to handle the 3, 3, 5 deg initial errors the
filter propagates the exact nonlinear error of a stationary IMU instead (derived from the mechanization
q_nb(k+1) = Exp(-w_ie T) q_nb(k) Exp(dtheta), v(k+1) = v(k) + C_b^n' dv + g T - 2 w_ie x v T, and the truth
C_b^n constant up to the Earth rotation, v = 0):

    E(phi_{k+1}) = R E(phi_k) R^T Exp(-C_b^n'(k+1) eps_w T),        R = Exp(-[w_ie x] T)        (000 eq. 15, 18)
    dV_{k+1} = dV_k + [(E(phi_mid)^T - I) f^n + C_b^n' [eps_ax, eps_ay, 0]]_EN T - [2 w_ie x dV]_EN T  (eq. 15, 17)

with f^n = [0, 0, gamma]; linearized at phi = 0 this is A of 000 eqs. 20-22 (with the full psi-angle Earth-rate
coupling -[w_ie x] phi and the gyro drift mapped by the full C_b^n', eq. 22). Process noise W of 000 eq. 19 on
the velocity (VRW^2) and attitude (ARW^2) states; discretized as 000 eqs. 24, 26, 27, 29 (transition
Phi = I + A T + A^2 T^2/2 + A^3 T^3/6, Gamma = T (I + A T/2 + A^2 T^2/6), Q_k = q / T, so Q_d = Gamma Q_k Gamma^T).
Measurement (000 eqs. 23, 25, 28): z = computed (v_E, v_N) = H x + V, H = [I_2 0_{2x8}], R_k = r^2 I (eq. 30).

Loop: increments are summed over blocks of `update_rate` (default 10 Hz); per block the nominal solution
(q_nb', v') is mechanized, the filter predicts and updates, and the estimated phi and dV are fed back into the
nominal (error-state reset: C_b^n' <- E(phi) C_b^n', v' <- v' - dV, phi = dV = 0; biases stay in the state).
The measurement is linear, so all three filters share the exact linear (Kalman) update; they differ in the time
update only:

* ``ekf``: x <- f(x), P <- Phi P Phi^T + Q_d (Phi from the Jacobian A at the current estimate, eq. 26).
* ``ukf``: the unscented transform of the nonlinear f, filterpy ``MerweScaledSigmaPoints`` with the usual
  scaled-UT parameters alpha = 1e-3, beta = 2, kappa = 0 and filterpy ``unscented_transform``.
* ``optimized_ukf``: 000 section 5.2 names an "optimized UKF" but gives no equation of the optimization (its
  only equations, 15-30, are the model and its discretization, which all three filters here use). What is
  implemented is an explicit, stated choice, not the paper's (unknown) algorithm: the unscented transform with
  the spread chosen for Gaussian priors (Julier-Uhlmann: n + lambda = 3 matches the fourth moment, i.e. alpha =
  1, beta = 2, kappa = 3 - n), so the sigma points sample the attitude error at +-sqrt(3) sigma where the
  nonlinearity acts, instead of the near-linearization of alpha = 1e-3. If the propagated covariance loses
  positive definiteness (the centre weight is negative) the step falls back to the ukf transform.

Limits. Level and heading cannot be separated from the horizontal accelerometer bias and the east gyro drift at
rest: they settle at the floors accel bias / g and east gyro bias / (w_ie cos L) (estimators.alignment
`level_limit`, `heading_limit`), and the covariance says so when the bias priors are given (gyro_bias_sigma,
accel_bias_sigma, e.g. the grade's turn-on bias). Known defect: with a MEMS gyro bias of hundreds of deg/h
(MTi-G-700) the uncompensated vertical drift turns the computed frame by tens of degrees, the (first-order)
covariance treats the accelerometer bias as observable from that turning, and the level settles at 2-5 times
accel bias / g with a level sigma (~0.05 deg) that is too small; the heading sigma stays honest (tens of deg).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, unscented_transform

from estimators import earth
from estimators.rotations import (
    euler_to_mat,
    mat_to_euler,
    mat_to_quat,
    quat_mul,
    quat_normalize,
    quat_to_euler,
    quat_to_mat,
    rotvec_to_quat,
    skew,
)

DV = slice(0, 2)
PHI = slice(2, 5)
EPS_A = slice(5, 7)
EPS_W = slice(7, 10)
N_STATES = 10
METHODS = ("ekf", "ukf", "optimized_ukf")


@dataclass
class FineAlignment:
    """Estimates at each update: t [s] (end of block), q_nb (K, 4), sigma (K, 10) state sigmas after the update
    (attitude sigmas = uncertainty of the attitude), x (K, 10) the bias estimates (phi, dV are reset to 0),
    and the final covariance P."""

    method: str
    t: np.ndarray
    q_nb: np.ndarray
    sigma: np.ndarray
    bias: np.ndarray
    P: np.ndarray

    @property
    def attitude_sigma(self) -> np.ndarray:
        """(K, 3) one-sigma attitude error [rad] in n: east, north, up (up = heading)."""
        return self.sigma[:, PHI]

    def errors(self, q_true: np.ndarray, k: int = -1) -> tuple[np.ndarray, np.ndarray]:
        """Errors against the truth at update k: (estimate - truth of pitch, roll, yaw [rad]; the error angles
        phi [rad] of the filter's state, C_b^n_true = Rz(phi_U) Rx(phi_E) Ry(phi_N) C_b^n_estimated)."""
        q_est = self.q_nb[k]
        e_est, e_true = np.array(quat_to_euler(q_est)), np.array(quat_to_euler(q_true))
        d = (e_est - e_true + np.pi) % (2 * np.pi) - np.pi
        phi = np.array(mat_to_euler(quat_to_mat(q_true) @ quat_to_mat(q_est).T))
        return d, phi

    def nees(self, q_true: np.ndarray) -> float:
        """Normalized attitude error squared phi^T P_phi^-1 phi at the end (the full P is kept for it)."""
        _, phi = self.errors(q_true)
        return float(phi @ np.linalg.solve(self.P[PHI, PHI], phi))


class _Model:
    """The shared nonlinear error model over one block of length T (see the module docstring)."""

    def __init__(self, lat: float, h: float, T: float, q_psd: np.ndarray):
        self.T = T
        self.w = earth.earth_rate_n(lat)
        self.gamma = float(earth.normal_gravity(lat, h))
        self.f_n = np.array([0.0, 0.0, self.gamma])
        self.R = quat_to_mat(rotvec_to_quat(-self.w * T))
        self.q_psd = q_psd  # continuous PSD of W (diagonal, 10)
        self.c_nb = np.eye(3)

    def f(self, X: np.ndarray) -> np.ndarray:
        """Propagate rows of states X (S, 10) over one block with the nominal C_b^n' of the block end."""
        T, c = self.T, self.c_nb
        e0 = _err_mat(X[:, PHI])
        theta = -(X[:, EPS_W] @ c.T) * T
        e1 = self.R @ e0 @ self.R.T @ quat_to_mat(rotvec_to_quat(theta))
        phi1 = np.stack(mat_to_euler(e1), axis=-1)
        mid = _err_mat(0.5 * (X[:, PHI] + phi1))
        acc = (np.swapaxes(mid, -1, -2) @ self.f_n)[:, :2]  # (E^T f^n)_EN; E^T e_U does not depend on the heading
        acc += X[:, EPS_A] @ c[:2, :2].T
        dv = X[:, DV]
        cor = 2 * np.stack([-self.w[2] * dv[:, 1], self.w[2] * dv[:, 0]], axis=1)  # [2 w x (dvE, dvN, 0)]_EN
        out = X.copy()
        out[:, DV] = dv + (acc - cor) * T
        out[:, PHI] = phi1
        return out

    def jacobian(self) -> np.ndarray:
        """A (000 eq. 20) of the continuous error dynamics at phi = 0."""
        a = np.zeros((N_STATES, N_STATES))
        wu = self.w[2]
        a[DV, DV] = [[0.0, 2 * wu], [-2 * wu, 0.0]]
        a[DV, PHI] = skew(self.f_n)[:2]
        a[DV, EPS_A] = self.c_nb[:2, :2]
        a[PHI, PHI] = -skew(self.w)
        a[PHI, EPS_W] = -self.c_nb
        return a

    def discretize(self) -> tuple[np.ndarray, np.ndarray]:
        """Phi (000 eq. 26) and Q_d = Gamma Q_k Gamma^T (eqs. 27, 29) to third order."""
        a, T = self.jacobian(), self.T
        at = a * T
        at2 = at @ at
        phi = np.eye(N_STATES) + at + at2 / 2 + at2 @ at / 6
        gamma = T * (np.eye(N_STATES) + at / 2 + at2 / 6)
        qd = gamma @ np.diag(self.q_psd / T) @ gamma.T
        return phi, 0.5 * (qd + qd.T)


def _err_mat(phi: np.ndarray) -> np.ndarray:
    """C_n'^n of attitude-error angles phi = (phi_E, phi_N, phi_U) (..., 3): Rz(phi_U) Rx(phi_E) Ry(phi_N)."""
    return euler_to_mat(phi[..., 0], phi[..., 1], phi[..., 2])


def _block_sums(a: np.ndarray, m: int) -> np.ndarray:
    k = a.shape[0] // m
    return a[: k * m].reshape(k, m, 3).sum(axis=1)


def fine_align(dtheta, dv, dt: float, lat: float, q0_nb, grade_noise: tuple[float, float], initial_sigma_rad,
               method: str = "ukf", *, h: float = 0.0, gyro_bias_sigma: float = 0.0, accel_bias_sigma: float = 0.0,
               velocity_sigma: float = 1e-3, update_rate: float = 10.0, gyro_bias_psd: float = 0.0,
               accel_bias_psd: float = 0.0) -> FineAlignment:
    """Fine alignment of a stationary IMU from increments (rows over equal intervals dt [s]).

    lat [rad], h [m]: the known position; q0_nb: the (coarse) start attitude; grade_noise = (arw [rad/sqrt(s)],
    vrw [m/s/sqrt(s)]); initial_sigma_rad: (3,) sigma of the initial attitude errors phi_E, phi_N, phi_U [rad];
    method: 'ekf', 'ukf' or 'optimized_ukf'. gyro_bias_sigma [rad/s] and accel_bias_sigma [m/s^2]: priors of the
    bias states (the grade's turn-on bias; 0 keeps them at zero). velocity_sigma [m/s]: the measurement noise of
    the zero-velocity observation (vibration of the standing machine). gyro_bias_psd [rad^2/s^3] and
    accel_bias_psd [m^2/s^5]: random-walk PSD of the bias states for an in-run bias instability (000 eq. 16 takes
    them as random constants, the default 0; a Gauss-Markov bias of sigma s and time tau gives 2 s^2 / tau).
    Returns a FineAlignment.
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; use one of {', '.join(METHODS)}")
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
    model = _Model(lat, h, T, q_psd)

    s0 = np.asarray(initial_sigma_rad, float)
    P = np.diag(np.concatenate([[velocity_sigma ** 2] * 2, s0 ** 2, [max(accel_bias_sigma, tiny) ** 2] * 2,
                                [max(gyro_bias_sigma, 1e-12) ** 2] * 3]))
    x = np.zeros(N_STATES)
    H = np.zeros((2, N_STATES))
    H[0, 0] = H[1, 1] = 1.0
    Rm = velocity_sigma ** 2 * np.eye(2)

    pts = {"ukf": MerweScaledSigmaPoints(N_STATES, alpha=1e-3, beta=2.0, kappa=0.0),
           "optimized_ukf": MerweScaledSigmaPoints(N_STATES, alpha=1.0, beta=2.0, kappa=3.0 - N_STATES)}
    q = quat_normalize(np.asarray(q0_nb, float))
    v = np.zeros(2)
    q_ie = rotvec_to_quat(-model.w * T)
    w_u = model.w[2]
    g_n = earth.gravity_n(lat, h)

    t_out = np.arange(1, n_upd + 1) * T
    q_out = np.empty((n_upd, 4))
    s_out = np.empty((n_upd, N_STATES))
    b_out = np.empty((n_upd, 5))
    for k in range(n_upd):
        # Nominal mechanization over the block (stationary: no transport rate, coning negligible).
        c0 = quat_to_mat(q)
        q = quat_normalize(quat_mul(q_ie, quat_mul(q, rotvec_to_quat(dth_b[k]))))
        c1 = quat_to_mat(q)
        dvn = 0.5 * (c0 + c1) @ dv_b[k] + g_n * T
        v = v + dvn[:2] - 2 * np.array([-w_u * v[1], w_u * v[0]]) * T
        model.c_nb = c1
        phi_m, qd = model.discretize()
        # Time update.
        if method == "ekf":
            x = model.f(x[None])[0]
            P = phi_m @ P @ phi_m.T + qd
        else:
            done = False
            for name in ((method, "ukf") if method == "optimized_ukf" else ("ukf",)):
                sp = pts[name]
                sig = model.f(sp.sigma_points(x, P))
                x_new, P_new = unscented_transform(sig, sp.Wm, sp.Wc, qd)
                P_new = 0.5 * (P_new + P_new.T)
                try:
                    np.linalg.cholesky(P_new)
                except np.linalg.LinAlgError:
                    continue
                x, P, done = x_new, P_new, True
                break
            if not done:
                raise np.linalg.LinAlgError("the propagated covariance is not positive definite")
        # Measurement update: z = computed v_EN.
        s = H @ P @ H.T + Rm
        kg = np.linalg.solve(s, H @ P).T
        x = x + kg @ (v - H @ x)
        ikh = np.eye(N_STATES) - kg @ H
        P = ikh @ P @ ikh.T + kg @ Rm @ kg.T
        # Error-state reset into the nominal.
        q = quat_normalize(mat_to_quat(_err_mat(x[PHI]) @ quat_to_mat(q)))
        v = v - x[DV]
        x[DV] = 0.0
        x[PHI] = 0.0
        q_out[k] = q
        s_out[k] = np.sqrt(np.diag(P))
        b_out[k] = x[5:]
    return FineAlignment(method, t_out, q_out, s_out, b_out, P)
