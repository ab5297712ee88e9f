"""The 10-state stationary alignment model of 000 section 5.2 (estimators.sins.fine_alignment runs it): state,
nonlinear error propagation and its transition, the nominal mechanization, the measurement and the error-state
reset, numba kernels shared by the EKF loop and the UKF steps.

State: the ten states of the shared error-state layout (estimators.kalman.error_state) a stand observes, in its
order, with its names and signs (errors estimate - truth), i.e. 000 eq. 19's states with the gyro biases before the
accelerometer biases; SHARED_INDEX[i] is state i's index in the shared layout:

    x = [dv_E, dv_N, phi_E, phi_N, phi_U, eps_x, eps_y, eps_z, nabla_x, nabla_y]

dv_E, dv_N: east/north velocity error of the computed solution (the truth stands still); eps (x, y, z) and
nabla (x, y): gyro and accelerometer biases in the body frame, reported - true (as the shared filters subtract
them from the increments), random constants (000 eq. 16) or random walks (`gyro_bias_psd`, `accel_bias_psd`).
The one exception to the shared meaning: phi, the attitude error of the computed navigation frame n', is here
the large-azimuth error angles C_n'^n = E(phi) = Rz(phi_U) Rx(phi_E) Ry(phi_N) (C_b^n = E(phi) C_b^n'), equal to
the shared rotation vector (C_b^n' = (I - [phi x]) C_b^n; the psi angle of estimators.sins.error_model, 000
eq. 10) to first order, E = I + [phi x]. phi_U is the heading error at any size and the tilt E^T e_U does not
depend on it, so a heading uncertainty of tens of degrees does not leak into the level (a rotation-vector state
does).

Model. 000 eqs. 15 and 20-22 are the small-angle linearization; to handle the 3, 3, 5 deg initial errors the
filter propagates the exact nonlinear error of a stationary IMU instead (derived from the mechanization
C_b^n'(k+1) = Exp(-w_ie T) C_b^n'(k) Exp(dtheta), v(k+1) = v(k) + C_b^n' dv + g T - 2 w_ie x v T, and the truth
C_b^n constant up to the Earth rotation, v = 0):

    E(phi_{k+1}) = R E(phi_k) R^T Exp(-C_b^n'(k+1) eps T),          R = Exp(-[w_ie x] T)        (000 eq. 15, 18)
    dv_{k+1} = dv_k + [(E(phi_mid)^T - I) f^n + C_b^n' [nabla_x, nabla_y, 0]]_EN T - [2 w_ie x dv]_EN T (eq. 15, 17)

with f^n = [0, 0, gamma]; linearized at phi = 0 this is A of 000 eqs. 20-22 (with the full psi-angle Earth-rate
coupling -[w_ie x] phi and the gyro drift mapped by the full C_b^n', eq. 22). Process noise W of 000 eq. 19 on
the velocity (VRW^2) and attitude (ARW^2) states; discretized as 000 eqs. 24, 26, 27, 29 (transition
Phi = I + A T + A^2 T^2/2 + A^3 T^3/6, Gamma = T (I + A T/2 + A^2 T^2/6), Q_k = q / T, so Q_d = Gamma Q_k Gamma^T).

Measurements, one linear (z, H, R) per update (000 eqs. 23, 25, 28, 30 and one addition):

* zero velocity (000 eq. 23): z = computed (v_E, v_N) = [I_2 0] x + V, R = velocity_sigma^2 I;
* zero vertical rate (not in 000; ``zero_rate=True``): the standing shearer turns only with the Earth, so the
  gyro output over the block resolved on the computed vertical minus the Earth rate's vertical component is the
  vertical gyro bias: z = [C_b^n' dtheta]_U - w_U T = -w_N T phi_E + T [C_b^n' eps]_U + ARW noise,
  R = ARW^2 T. Without it the vertical bias of a MEMS gyro (hundreds of deg/h) turns the computed heading by
  tens of degrees during the alignment: the heading sigma grows to match (measured ~55 deg after 300 s on the
  MTi-G-700, honest, but the start heading is lost); with it the heading keeps its start value and sigma. The
  horizontal gyro outputs are left to the velocity channel (their Earth-rate part depends on the unknown
  heading, the gyrocompassing 000 relies on), so nothing is counted twice there.

Reset: after each update the estimated phi and dv are fed back into the nominal (error-state reset:
C_b^n' <- E(phi) C_b^n', v' <- v' - dv, phi = dv = 0; biases stay in the state), and the covariance follows it, P <- G P G^T with G the Jacobian of the remaining error E(phi) E(phi_hat)^T
in phi (a heading correction turns the tilt axes). Without it the tilt covariance stays in the old axes while
the body-fixed accelerometer bias is mapped through the corrected nominal, and the filter takes that bias for
partly observable: measured, a level sigma of 0.66 accel bias / g on nav-004, and on the MTi-G-700, whose
heading sigma is tens of degrees without the zero-rate update, a level 0.8 deg off with a sigma of 0.05 deg.

The kernels the EKF loop calls are inlined into it (numba inline="always"; the UKF calls them from Python): numba
compiles a called kernel on its own and then optimizes its code again in every caller, and the loop compiled 15 %
faster as one function, bit for bit the same.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from estimators.arrays import put
from estimators.kalman import error_state as es
from estimators.nav.rotation_kernels import euler_mat, mat_euler, rotvec_mat

DV = slice(0, 2)  # dv_E, dv_N
PHI = slice(DV.stop, DV.stop + 3)
GYRO_BIAS = slice(PHI.stop, PHI.stop + 3)
ACCEL_BIAS = slice(GYRO_BIAS.stop, GYRO_BIAS.stop + 2)  # nabla_x, nabla_y
N_STATES = ACCEL_BIAS.stop
BIASES = slice(GYRO_BIAS.start, N_STATES)  # the states the reset keeps (FineAlignment.bias)


def _shared_index(blocks) -> np.ndarray:
    """For (own block, shared block) pairs: each own state's index in the shared layout, the own block taking the
    leading states of the shared one; read-only."""
    index = np.empty(N_STATES, dtype=np.int64)
    for own, shared in blocks:
        index[own] = np.arange(shared.start, shared.start + own.stop - own.start)
    index.setflags(write=False)
    return index


SHARED_INDEX = _shared_index(((DV, es.DV), (PHI, es.PHI), (GYRO_BIAS, es.GYRO_BIAS), (ACCEL_BIAS, es.ACCEL_BIAS)))
"""Index in the shared layout (estimators.kalman.error_state) of each alignment state."""
_DVE, _DVN = DV.start, DV.start + 1  # scalar indices for the kernels
_PE, _PN, _PU = PHI.start, PHI.start + 1, PHI.start + 2
_AX, _AY = ACCEL_BIAS.start, ACCEL_BIAS.start + 1


@nb.njit(cache=True, inline="always")
def propagate(x, c1, r_ie, w_u, gamma, T):
    """The nonlinear error model over one block (module docstring) for one state x."""
    e0 = euler_mat(x[_PE], x[_PN], x[_PU])
    e1 = r_ie @ e0 @ r_ie.T @ rotvec_mat(-(c1 @ x[GYRO_BIAS]) * T)
    pe, pn, pu = mat_euler(e1)
    mid = euler_mat(0.5 * (x[_PE] + pe), 0.5 * (x[_PN] + pn), 0.5 * (x[_PU] + pu))
    acc_e = gamma * mid[2, 0] + c1[0, 0] * x[_AX] + c1[0, 1] * x[_AY] + 2 * w_u * x[_DVN]  # minus [2 w x dv]
    acc_n = gamma * mid[2, 1] + c1[1, 0] * x[_AX] + c1[1, 1] * x[_AY] - 2 * w_u * x[_DVE]
    out = x.copy()
    out[_DVE] += acc_e * T
    out[_DVN] += acc_n * T
    out[_PE], out[_PN], out[_PU] = pe, pn, pu
    return out


@nb.njit(cache=True)
def propagate_rows(xs, c1, r_ie, w_u, gamma, T):
    """propagate for each row of xs (the UKF's sigma points)."""
    out = np.empty_like(xs)
    for i in range(xs.shape[0]):
        put(out[i], propagate(xs[i], c1, r_ie, w_u, gamma, T))
    return out


@nb.njit(cache=True, inline="always")
def transition(c1, w, gamma, T, q_psd):
    """A (000 eqs. 20-22) at phi = 0, then Phi (eq. 26) and Q_d = Gamma Q_k Gamma^T (eqs. 27, 29), third order."""
    a = np.zeros((N_STATES, N_STATES))
    a[_DVE, _DVN], a[_DVN, _DVE] = 2 * w[2], -2 * w[2]
    a[_DVE, _PN], a[_DVN, _PE] = -gamma, gamma  # [f^n x] rows E, N
    put(a[DV, ACCEL_BIAS], c1[:2, :2])
    wx = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    put(a[PHI, PHI], -wx)
    put(a[PHI, GYRO_BIAS], -c1)
    at = a * T
    at2 = at @ at
    eye = np.eye(N_STATES)
    phi = eye + at + at2 / 2 + at2 @ at / 6
    gam = T * (eye + at / 2 + at2 / 6)
    qd = (gam * (q_psd / T)) @ gam.T
    return phi, 0.5 * (qd + qd.T)


@nb.njit(cache=True, inline="always")
def mechanize_nominal(c, v, dth, dvb, r_ie, g_n, w_u, T):
    """Nominal C_b^n' and (v_E, v_N) over one block (stationary: no transport rate; coning negligible).

    Kept apart from estimators.sins.strapdown.strapdown_step: the model above is derived from this DCM recursion at a fixed
    position (the step's quaternion and geodetic update would change the numbers)."""
    c1 = r_ie @ c @ rotvec_mat(dth)
    c1 = 1.5 * c1 - 0.5 * (c1 @ c1.T @ c1)  # keep it orthonormal
    dvn = 0.5 * (c + c1) @ dvb
    v1 = np.array([v[0] + dvn[0] + g_n[0] * T + 2 * w_u * v[1] * T,
                   v[1] + dvn[1] + g_n[1] * T - 2 * w_u * v[0] * T])
    return c1, v1


@nb.njit(cache=True, inline="always")
def measurement(c0, c1, v, dth, w, T, r_vel, r_rate, zero_rate):
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
        put(hm[2, GYRO_BIAS], c_mid[2] * T)
        r[2, 2] = r_rate
    return z, hm, r


@nb.njit(cache=True, inline="always")
def reset(c, v, x, p):
    """Feed phi and dv into the nominal and zero them (the biases stay in the state); P <- G P G^T with G the
    Jacobian (central differences) of the remaining error E(phi) E(phi_hat)^T in phi at phi_hat (module
    docstring, "Reset")."""
    e_hat = euler_mat(x[_PE], x[_PN], x[_PU])
    g = np.zeros((3, 3))
    step = 1e-5
    for j in range(3):
        lo, hi = x[PHI].copy(), x[PHI].copy()
        lo[j] -= step
        hi[j] += step
        a = mat_euler(euler_mat(hi[0], hi[1], hi[2]) @ e_hat.T)
        b = mat_euler(euler_mat(lo[0], lo[1], lo[2]) @ e_hat.T)
        for i in range(3):
            g[i, j] = (a[i] - b[i]) / (2 * step)
    put(p[PHI, :], g @ np.ascontiguousarray(p[PHI, :]))
    put(p[:, PHI], np.ascontiguousarray(p[:, PHI]) @ g.T)
    c1 = e_hat @ c
    v1 = np.array([v[0] - x[_DVE], v[1] - x[_DVN]])
    x[DV] = 0.0
    x[PHI] = 0.0
    return c1, v1
