"""002's filters of a canopy unit's attitude (002_5cc0b59ad045ffaa.txt section 3), each a numba kernel over a batch
of independent filters (supports, or the Q candidates of the tuning, estimators.support.tuning):

* the quaternion UKF (state q, process eqs. 18-19 with Q of eq. 23, measurement eqs. 20-21, sigma points and
  weights eqs. 16-17 from filterpy's MerweScaledSigmaPoints, recursion eqs. 29-34);
* the linear quaternion KF baseline (same state and process; the accelerometer/magnetometer quaternion as a
  linear measurement).

The models are estimators.support.unit_model's. The kernels allocate each filter's state and scratch once
(nothing in the sample loop), run the filters of a batch in parallel (prange) and use fast-math flags short of
reassociating or assuming finite values (kernel_math.FASTMATH); a filter's result does not depend on the batch
it runs in, nor on whether the kernel was compiled in the process or loaded from numba's cache.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints

from estimators.nav.rotations_scalar import (
    euler_quat,
    normalize_continuous,
    quat_euler,
    sub_rotated_back,
)
from estimators.support.batch import batch_inputs
from estimators.support.kernel_math import FASTMATH, chol4, inv3
from estimators.support.unit_model import (
    UnitModel,
    euler_quat_jacobian,
    measurement,
    process_noise,
    propagation_matrix,
    start_attitude,
    wrap,
)


@dataclass(frozen=True)
class SigmaSettings:
    """Merwe scaled sigma points (002 eqs. 16-17): alpha, beta, kappa."""

    alpha: float = 0.5
    beta: float = 2.0
    kappa: float = 0.0

    def weights(self, n: int = 4) -> tuple[np.ndarray, np.ndarray, float]:
        """(Wm, Wc, n + lambda) from filterpy's MerweScaledSigmaPoints."""
        pts = MerweScaledSigmaPoints(n, alpha=self.alpha, beta=self.beta, kappa=self.kappa)
        return np.asarray(pts.Wm, float), np.asarray(pts.Wc, float), self.alpha ** 2 * (n + self.kappa)


SIGMA_002 = SigmaSettings()
"""The filters' default sigma points (alpha 0.5, beta 2, kappa 0)."""


# --------------------------------------------------------------------------------------------------------------
# Kernels


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _predict(gyro_b, x, p, dt, var_w, w_ie_n, w, a, pm, xm, ap):
    """x- = A x, P- = A P A^T + Q into xm, pm (002 steps 2.1-2.2, eqs. 18-19, 23, 29-30): A from the body rate w
    (the gyro minus C_n^b w_ie), Q at the previous estimate x; w, a, ap scratch. The unscented transform of the
    linear process model is exact, so no sigma points are needed for it."""
    sub_rotated_back(gyro_b, x, w_ie_n, w)
    propagation_matrix(w[0] * dt, w[1] * dt, w[2] * dt, a)
    process_noise(x, var_w, dt, pm)
    for i in range(4):
        xm[i] = a[i, 0] * x[0] + a[i, 1] * x[1] + a[i, 2] * x[2] + a[i, 3] * x[3]
        for j in range(4):
            ap[i, j] = a[i, 0] * p[0, j] + a[i, 1] * p[1, j] + a[i, 2] * p[2, j] + a[i, 3] * p[3, j]
    for i in range(4):
        for j in range(i, 4):
            v = pm[i, j] + ap[i, 0] * a[j, 0] + ap[i, 1] * a[j, 1] + ap[i, 2] * a[j, 2] + ap[i, 3] * a[j, 3]
            pm[i, j] = v
            pm[j, i] = v


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _ukf_kernel(gyro, accel, mag, dt, var_w, var_a, var_m, declination, w_ie_n, wm, wc, c, q0, p0, out_q):
    """002 section 3.5 steps 2.1-2.6 for each filter f over its samples; var_w (F, 3) per filter."""
    nf, nk = gyro.shape[0], gyro.shape[1]
    for f in nb.prange(nf):
        x = q0[f].copy()
        p = p0.copy()
        a, ap, pm, lo = np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4))
        sig, zs = np.empty((9, 4)), np.empty((9, 3))
        z, zm, y, w = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
        r, pzz, inv = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
        xm = np.empty(4)
        pxz, gain = np.empty((4, 3)), np.empty((4, 3))
        for k in range(nk):
            _predict(gyro[f, k], x, p, dt, var_w[f], w_ie_n, w, a, pm, xm, ap)  # steps 2.1-2.2
            # Step 2.3 (eqs. 16, 31): sigma points of the prediction, x- and x- -/+ the columns of chol(c P-).
            for i in range(4):
                for j in range(i + 1):
                    lo[i, j] = c * pm[i, j]
            chol4(lo, lo)
            for j in range(4):
                sig[0, j] = xm[j]
                for i in range(4):
                    sig[1 + i, j] = xm[j] + lo[j, i]
                    sig[5 + i, j] = xm[j] - lo[j, i]
            # Step 2.4 (eqs. 20-21, 32): output sigma points, yaw unwrapped around the central one.
            zm[:] = 0.0
            for i in range(9):
                zs[i, 0], zs[i, 1], zs[i, 2] = quat_euler(sig[i, 0], sig[i, 1], sig[i, 2], sig[i, 3])
                if i > 0:
                    zs[i, 2] = zs[0, 2] + wrap(zs[i, 2] - zs[0, 2])
                for j in range(3):
                    zm[j] += wm[i] * zs[i, j]
            measurement(accel[f, k], mag[f, k], declination, var_a, var_m, z, r)
            pzz[:, :] = r
            pxz[:, :] = 0.0
            for i in range(9):
                for j in range(3):
                    dz = wc[i] * (zs[i, j] - zm[j])
                    for m in range(3):
                        pzz[j, m] += dz * (zs[i, m] - zm[m])
                    for m in range(4):
                        pxz[m, j] += dz * (sig[i, m] - xm[m])
            # Steps 2.5-2.6 (eqs. 33-34).
            inv3(pzz, inv)
            for j in range(3):
                y[j] = z[j] - zm[j]
            y[2] = wrap(y[2])
            for i in range(4):
                for j in range(3):
                    gain[i, j] = pxz[i, 0] * inv[0, j] + pxz[i, 1] * inv[1, j] + pxz[i, 2] * inv[2, j]
                x[i] = xm[i] + gain[i, 0] * y[0] + gain[i, 1] * y[1] + gain[i, 2] * y[2]
            # P = P- - K Pzz K^T = P- - K Pxz^T
            for i in range(4):
                for j in range(i, 4):
                    v = pm[i, j] - (gain[i, 0] * pxz[j, 0] + gain[i, 1] * pxz[j, 1] + gain[i, 2] * pxz[j, 2])
                    p[i, j] = v
                    p[j, i] = v
            normalize_continuous(x, out_q[f, k - 1] if k > 0 else q0[f])
            out_q[f, k] = x


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _kf_kernel(gyro, accel, mag, dt, var_w, var_a, var_m, declination, w_ie_n, q0, p0, out_q):
    """Linear quaternion KF: x_k = A x_{k-1} + w (eqs. 18-19, Q of eq. 23), z = q(pitch, roll, yaw) from the
    accelerometer and magnetometer (eqs. 5-8) with H = I and R = J R_angles J^T (J = euler_quat_jacobian at z,
    R_angles of eqs. 24-28)."""
    nf, nk = gyro.shape[0], gyro.shape[1]
    for f in nb.prange(nf):
        x = q0[f].copy()
        p = p0.copy()
        a, ap, pm, s, gain = np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4))
        z, w = np.empty(3), np.empty(3)
        r = np.empty((3, 3))
        jac, jr = np.empty((4, 3)), np.empty((4, 3))
        zq, xm = np.empty(4), np.empty(4)
        for k in range(nk):
            _predict(gyro[f, k], x, p, dt, var_w[f], w_ie_n, w, a, pm, xm, ap)
            measurement(accel[f, k], mag[f, k], declination, var_a, var_m, z, r)
            zq[0], zq[1], zq[2], zq[3] = euler_quat(z[0], z[1], z[2])
            euler_quat_jacobian(zq, z[2], jac)
            if zq[0] * xm[0] + zq[1] * xm[1] + zq[2] * xm[2] + zq[3] * xm[3] < 0:
                for i in range(4):
                    zq[i] = -zq[i]
                    for j in range(3):
                        jac[i, j] = -jac[i, j]
            # S = P- + J R J^T (+ 1e-12 I: J R J^T has rank 3); K = P- S^-1 by Cholesky (S and P- symmetric).
            for i in range(4):
                for j in range(3):
                    jr[i, j] = jac[i, 0] * r[0, j] + jac[i, 1] * r[1, j] + jac[i, 2] * r[2, j]
            for i in range(4):
                for j in range(i + 1):
                    s[i, j] = pm[i, j] + jr[i, 0] * jac[j, 0] + jr[i, 1] * jac[j, 1] + jr[i, 2] * jac[j, 2]
                s[i, i] += 1e-12
            chol4(s, s)
            for col in range(4):  # row col of K = (S^-1 P-[:, col])^T: forward then back substitution
                for i in range(4):
                    v = pm[i, col]
                    for m in range(i):
                        v -= s[i, m] * gain[col, m]
                    gain[col, i] = v / s[i, i]
                for i in range(3, -1, -1):
                    v = gain[col, i]
                    for m in range(i + 1, 4):
                        v -= s[m, i] * gain[col, m]
                    gain[col, i] = v / s[i, i]
            for i in range(4):
                x[i] = xm[i] + (gain[i, 0] * (zq[0] - xm[0]) + gain[i, 1] * (zq[1] - xm[1])
                                + gain[i, 2] * (zq[2] - xm[2]) + gain[i, 3] * (zq[3] - xm[3]))
            # P = (I - K) P-, symmetrised
            for i in range(4):
                for j in range(4):
                    ap[i, j] = pm[i, j] - (gain[i, 0] * pm[0, j] + gain[i, 1] * pm[1, j] + gain[i, 2] * pm[2, j]
                                           + gain[i, 3] * pm[3, j])
            for i in range(4):
                for j in range(i, 4):
                    v = 0.5 * (ap[i, j] + ap[j, i])
                    p[i, j] = v
                    p[j, i] = v
            normalize_continuous(x, xm)
            out_q[f, k] = x


# --------------------------------------------------------------------------------------------------------------
# API


def _var_w(var_w, n: int) -> np.ndarray:
    v = np.asarray(var_w, float)
    v = np.broadcast_to(v if v.ndim == 2 else v[None], (n, 3))
    if np.any(v < 0) or not np.all(np.isfinite(v)):
        raise ValueError(f"rate-noise variances must be finite and >= 0, got {var_w!r}")
    return np.ascontiguousarray(v)


def _kernel_args(gyro, accel, mag, dt, model, var_w, q0, p0_sigma):
    """What both kernels take: the checked inputs and the model (gyro .. w_ie_n), the start (q0, p0) and the output
    q_nb (N, K, 4)."""
    gyro, accel, mag = batch_inputs(gyro, accel, mag)
    inputs = (gyro, accel, mag, float(dt), _var_w(var_w, gyro.shape[0]), np.asarray(model.var_accel, float),
              np.asarray(model.var_mag, float), model.declination, np.asarray(model.earth_rate_n, float))
    start = (start_attitude(q0, accel, mag, model), np.eye(4) * p0_sigma ** 2)
    return inputs, start, np.empty(gyro.shape[:2] + (4,))


def ukf(gyro, accel, mag, dt: float, model: UnitModel, var_w, q0=None, p0_sigma: float = 0.01,
        sigma: SigmaSettings = SIGMA_002) -> np.ndarray:
    """The quaternion UKF of 002 section 3 on a batch: q_nb (N, K, 4) after each sample.

    gyro [rad/s], accel [m/s^2], mag [T]: (K, 3) or (N, K, 3), one row per sample interval of dt [s]; var_w
    the rate-noise variances of Q [(rad/s)^2], (3,) or (N, 3) per filter; q0 the start (default: from the first
    accelerometer and magnetometer samples); p0_sigma the start's sigma per quaternion component.
    """
    inputs, start, out = _kernel_args(gyro, accel, mag, dt, model, var_w, q0, p0_sigma)
    _ukf_kernel(*inputs, *sigma.weights(4), *start, out)
    return out


def kf(gyro, accel, mag, dt: float, model: UnitModel, var_w, q0=None, p0_sigma: float = 0.01) -> np.ndarray:
    """The linear quaternion KF baseline (see `_kf_kernel`) on a batch: q_nb (N, K, 4); arguments as `ukf`."""
    inputs, start, out = _kernel_args(gyro, accel, mag, dt, model, var_w, q0, p0_sigma)
    _kf_kernel(*inputs, *start, out)
    return out
