"""002's KF and UKF kernels (estimators.support.filters_002) on exact and noisy data."""

from __future__ import annotations

import pytest
import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

from estimators.nav.rotations_scalar import euler_quat, quat_euler
from estimators.support.filters_002 import kf, ukf
from estimators.support.unit_model import (
    euler_errors,
    euler_quat_jacobian,
    measurement,
    process_noise,
    propagation_matrix,
    wrap,
)
from tests.estimators.support.conftest import DT, exact_unit, model

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")


def test_ukf_tracks_noise_free_truth():
    q0, q, w, f, m = exact_unit()
    est = ukf(w, f, m, DT, model(), [1e-8] * 3, q0=q0, p0_sigma=1e-4)[0]
    assert np.abs(euler_errors(q, est)).max() < 1e-6
    est = kf(w, f, m, DT, model(), [1e-8] * 3, q0=q0, p0_sigma=1e-4)[0]
    assert np.abs(euler_errors(q, est)).max() < 1e-6


def test_euler_quat_jacobian_and_the_kf_on_noisy_readings():
    """The KF's measurement Jacobian matches finite differences, and on noisy readings the KF stays within the
    noise of the accelerometer and magnetometer angles."""
    rng = np.random.default_rng(7)
    for z in rng.uniform(-1.2, 1.2, (5, 3)):
        jac = euler_quat_jacobian(np.array(euler_quat(*z)), z[2], np.empty((4, 3)))
        fd = np.column_stack([(np.array(euler_quat(*(z + d))) - np.array(euler_quat(*(z - d)))) / 2e-7
                              for d in np.eye(3) * 1e-7])
        np.testing.assert_allclose(jac, fd, atol=1e-8)
    _q0, q, w, f, m = exact_unit(3000)
    f = f + rng.normal(0, 0.01, f.shape)
    m = m + rng.normal(0, 1e-7, m.shape)
    est = kf(w, f, m, DT, model(1e-4, 1e-14), [1e-6] * 3)[0]
    assert np.abs(euler_errors(q, est)[100:]).max() < np.radians(0.5)


def test_ukf_kernel_matches_filterpy():
    """The numba kernel is 002's recursion: filterpy's UnscentedKalmanFilter with the same sigma points, the
    sigma points redrawn after the prediction (eq. 31) and Q of eq. 23 at the previous estimate."""
    rng = np.random.default_rng(3)
    q0, _q, w, f, m = exact_unit(200)
    f = f + rng.normal(0, 0.02, f.shape)
    m = m + rng.normal(0, 2e-7, m.shape)
    mod = model(4e-4, 4e-14)
    var_w = np.array([1e-3, 2e-3, 5e-4])
    ours_q = ukf(w, f, m, DT, mod, var_w, q0=q0, p0_sigma=0.01)[0]

    pts = MerweScaledSigmaPoints(4, alpha=0.5, beta=2.0, kappa=0.0, subtract=np.subtract)
    step = {"a": np.eye(4)}

    def hx(x):
        return np.array(quat_euler(*x))

    def z_mean(sigmas, wm):
        ref = sigmas[0, 2]
        out = wm @ sigmas
        out[2] = wm @ (ref + wrap(sigmas[:, 2] - ref))
        return out

    def residual_z(a, b):
        d = a - b
        d[2] = wrap(d[2])
        return d

    filt = UnscentedKalmanFilter(4, 3, DT, hx, lambda x, dt: step["a"] @ x, pts, z_mean_fn=z_mean,
                                 residual_z=residual_z)
    filt.x, filt.P = q0.copy(), np.eye(4) * 1e-4
    for k in range(200):
        step["a"] = propagation_matrix(*(w[k] * DT), np.empty((4, 4)))
        filt.Q = process_noise(filt.x, var_w, DT, np.empty((4, 4)))
        filt.predict()
        filt.sigmas_f = pts.sigma_points(filt.x, filt.P)
        z, r = np.empty(3), np.empty((3, 3))
        measurement(f[k], m[k], mod.declination, mod.var_accel, mod.var_mag, z, r)
        filt.update(z, R=r)
        filt.x = filt.x / np.linalg.norm(filt.x)
        np.testing.assert_allclose(filt.x, ours_q[k], atol=1e-9)
