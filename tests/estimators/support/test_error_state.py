"""Support attitude after 002 (estimators.support.attitude_002, estimators.support.error_state).

Exact data: a unit turning at a constant body rate, so the gyro's rotation over each step is exact and the
accelerometer and magnetometer see gravity and the field without error.
"""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

from estimators.nav.rotations import (
    euler_to_quat,
    quat_conj,
    quat_mul,
    quat_rotate,
    quat_to_euler,
    rotvec_to_quat,
)
from estimators.support import attitude_002 as sa
from estimators.support.error_state import (
    FLAG_DIP,
    FLAG_GATE,
    FLAG_NORM,
    FLAG_STATIC,
    OursSettings,
    ours,
)

G = np.array([0.0, 0.0, 9.79])
B_N = np.array([-1.5e-6, 2.9e-5, -4.3e-5])  # ENU, declination about -3 deg
DT = 0.01


def exact_unit(k: int = 2000, w_b=(0.02, -0.03, 0.025), start=(0.1, 0.3, -0.2)):
    q0 = euler_to_quat(*start)
    t = np.arange(1, k + 1) * DT
    q = quat_mul(q0, rotvec_to_quat(np.asarray(w_b) * t[:, None]))
    q_bn = quat_conj(q)
    return q0, q, np.tile(w_b, (k, 1)), quat_rotate(q_bn, G), quat_rotate(q_bn, B_N)


def model(var_a=1e-8, var_m=1e-20):
    return sa.UnitModel(np.full(3, var_a), np.full(3, var_m), B_N, np.zeros(3))


def test_accel_angles_round_trip():
    """002 eqs. 7-8: the specific force of a resting unit gives back its pitch and roll."""
    rng = np.random.default_rng(1)
    pitch, roll, yaw = rng.uniform(-1.2, 1.2, 200), rng.uniform(-2.5, 2.5, 200), rng.uniform(-3, 3, 200)
    f_b = quat_rotate(quat_conj(euler_to_quat(pitch, roll, yaw)), G)
    p, r = sa.accel_pitch_roll(*f_b.T)
    np.testing.assert_allclose(p, pitch, atol=1e-12)
    np.testing.assert_allclose(r, roll, atol=1e-12)


def test_mag_yaw_round_trip_with_declination():
    """002 eqs. 3-6: the tilt-compensated field minus the declination gives the true yaw."""
    rng = np.random.default_rng(2)
    pitch, roll, yaw = rng.uniform(-1.2, 1.2, 200), rng.uniform(-2.5, 2.5, 200), rng.uniform(-3, 3, 200)
    m_b = quat_rotate(quat_conj(euler_to_quat(pitch, roll, yaw)), B_N)
    got = sa.mag_yaw(*m_b.T, pitch, roll, model().declination)
    np.testing.assert_allclose(sa.wrap(got - yaw), 0.0, atol=1e-12)
    assert model().declination == pytest.approx(np.arctan2(B_N[0], B_N[1]))


def test_euler_output_and_propagation():
    """Eq. 21 in the project's convention matches estimators.nav.rotations; eq. 12 integrates a constant rate exactly."""
    q0, q, w, _, _ = exact_unit(500)
    np.testing.assert_allclose(np.stack(sa.quat_euler(*q.T), -1), np.stack(quat_to_euler(q), -1), atol=1e-12)
    np.testing.assert_allclose(sa.propagate(q0, w, DT)[1:], q, atol=1e-12)


def test_measurement_covariance_matches_finite_differences():
    """Eqs. 24-27: the angle variances from the sensor variances equal the linearized propagation."""
    f = np.array([1.2, -2.0, 9.4])
    m = np.array([2e-5, 1e-5, -4e-5])
    var_f, var_m = np.array([1e-4, 2e-4, 3e-4]), np.array([1e-14, 2e-14, 3e-14])
    jac_f = np.empty((2, 3))
    jac_m = np.empty(3)
    p, r = sa.accel_pitch_roll(*f)
    for i in range(3):
        d = np.zeros(3)
        d[i] = 1e-7
        jac_f[:, i] = (np.array(sa.accel_pitch_roll(*(f + d))) - np.array(sa.accel_pitch_roll(*(f - d)))) / 2e-7
        d *= 1e-4
        jac_m[i] = (sa.mag_yaw(*(m + d), p, r, 0.0) - sa.mag_yaw(*(m - d), p, r, 0.0)) / 2e-11
    cov = jac_f @ np.diag(var_f) @ jac_f.T
    vp, cpr, vr = sa.accel_covariance(*f, *var_f)
    np.testing.assert_allclose([vp, cpr, vr], [cov[0, 0], cov[0, 1], cov[1, 1]], rtol=1e-6)
    sincos = (np.sin(p), np.cos(p), np.sin(r), np.cos(r))
    np.testing.assert_allclose(sincos, sa.accel_tilt_sincos(*f), rtol=1e-14)
    assert sa.mag_yaw_variance(*m, *sincos, *var_m) == pytest.approx(jac_m @ np.diag(var_m) @ jac_m, rel=1e-6)


def test_ukf_tracks_noise_free_truth():
    q0, q, w, f, m = exact_unit()
    est = sa.ukf(w, f, m, DT, model(), [1e-8] * 3, q0=q0, p0_sigma=1e-4)[0]
    assert np.abs(sa.euler_errors(q, est)).max() < 1e-6
    est = sa.kf(w, f, m, DT, model(), [1e-8] * 3, q0=q0, p0_sigma=1e-4)[0]
    assert np.abs(sa.euler_errors(q, est)).max() < 1e-6


def test_euler_quat_jacobian_and_the_kf_on_noisy_readings():
    """The KF's measurement Jacobian matches finite differences, and on noisy readings the KF stays within the
    noise of the accelerometer and magnetometer angles."""
    rng = np.random.default_rng(7)
    for z in rng.uniform(-1.2, 1.2, (5, 3)):
        jac = sa.euler_quat_jacobian(np.array(sa.euler_quat(*z)), z[2], np.empty((4, 3)))
        fd = np.column_stack([(np.array(sa.euler_quat(*(z + d))) - np.array(sa.euler_quat(*(z - d)))) / 2e-7
                              for d in np.eye(3) * 1e-7])
        np.testing.assert_allclose(jac, fd, atol=1e-8)
    _q0, q, w, f, m = exact_unit(3000)
    f = f + rng.normal(0, 0.01, f.shape)
    m = m + rng.normal(0, 1e-7, m.shape)
    est = sa.kf(w, f, m, DT, model(1e-4, 1e-14), [1e-6] * 3)[0]
    assert np.abs(sa.euler_errors(q, est)[100:]).max() < np.radians(0.5)


def test_ukf_kernel_matches_filterpy():
    """The numba kernel is 002's recursion: filterpy's UnscentedKalmanFilter with the same sigma points, the
    sigma points redrawn after the prediction (eq. 31) and Q of eq. 23 at the previous estimate."""
    rng = np.random.default_rng(3)
    q0, _q, w, f, m = exact_unit(200)
    f = f + rng.normal(0, 0.02, f.shape)
    m = m + rng.normal(0, 2e-7, m.shape)
    mod = model(4e-4, 4e-14)
    var_w = np.array([1e-3, 2e-3, 5e-4])
    ours_q = sa.ukf(w, f, m, DT, mod, var_w, q0=q0, p0_sigma=0.01)[0]

    pts = MerweScaledSigmaPoints(4, alpha=0.5, beta=2.0, kappa=0.0, subtract=np.subtract)
    step = {"a": np.eye(4)}

    def hx(x):
        return np.array(sa.quat_euler(*x))

    def z_mean(sigmas, wm):
        ref = sigmas[0, 2]
        out = wm @ sigmas
        out[2] = wm @ (ref + sa.wrap(sigmas[:, 2] - ref))
        return out

    def residual_z(a, b):
        d = a - b
        d[2] = sa.wrap(d[2])
        return d

    filt = UnscentedKalmanFilter(4, 3, DT, hx, lambda x, dt: step["a"] @ x, pts, z_mean_fn=z_mean,
                                 residual_z=residual_z)
    filt.x, filt.P = q0.copy(), np.eye(4) * 1e-4
    for k in range(200):
        step["a"] = sa.propagation_matrix(*(w[k] * DT), np.empty((4, 4)))
        filt.Q = sa.process_noise(filt.x, var_w, DT, np.empty((4, 4)))
        filt.predict()
        filt.sigmas_f = pts.sigma_points(filt.x, filt.P)
        z, r = np.empty(3), np.empty((3, 3))
        sa._measurement(f[k], m[k], mod.declination, mod.var_accel, mod.var_mag, z, r)
        filt.update(z, R=r)
        filt.x = filt.x / np.linalg.norm(filt.x)
        np.testing.assert_allclose(filt.x, ours_q[k], atol=1e-9)


def test_gradient_descent_objective_decreases():
    rng = np.random.default_rng(4)
    _q0, q, w, f, m = exact_unit(1500)
    bias = np.array([0.004, -0.003, 0.002])
    f = f + rng.normal(0, 0.01, f.shape)
    m = m + rng.normal(0, 1e-7, m.shape)
    tuning = sa.tune_q(w + bias, f, m, DT, model(1e-4, 1e-14), q, [1e-8] * 3, iterations=8)
    obj = np.asarray(tuning.objective)
    assert obj.size >= 3
    assert np.all(np.diff(obj) < 0)
    assert obj[-1] < 0.5 * obj[0]


def test_ours_flags_disturbed_field_and_keeps_yaw():
    """A field disturbance on the magnetometer for 20 s: flagged, and the yaw holds; the gyro bias is estimated."""
    rng = np.random.default_rng(5)
    k = 6000
    _q0, q, w, f, m = exact_unit(k, w_b=(0.0, 0.0, 0.01))
    bias = np.array([0.003, -0.002, 0.004])
    f = f + rng.normal(0, 0.007, f.shape)
    m = m + rng.normal(0, 1e-7, m.shape)
    t = np.arange(1, k + 1) * DT
    hit = (t > 30) & (t < 50)
    m_dist = m.copy()
    m_dist[hit] += quat_rotate(quat_conj(q[hit]), np.array([4e-6, -3e-6, 2e-6]))
    res = ours(w + bias, f, m_dist, DT, model(5e-5, 1e-14), OursSettings(gyro_bias_sigma0=0.01))
    ts = t[res.sample]
    flagged = (res.flags[0] & (FLAG_NORM | FLAG_DIP | FLAG_GATE)) > 0
    inside = (ts > 30.5) & (ts < 49.5)
    assert flagged[inside].all()
    assert not flagged[(ts > 10) & ~((ts > 29) & (ts < 52))].any()
    err = sa.euler_errors(q[res.sample], res.q_nb[0])
    assert np.abs(err[ts > 10]).max() < np.radians(0.1)
    np.testing.assert_allclose(res.gyro_bias[0, -1], bias, atol=2e-4)


def test_ours_zero_rate_updates_hold_the_yaw_of_a_static_unit_through_a_long_disturbance():
    """A canopy unit switched on next to a standing shearer: the field is disturbed for the first 40 s and the
    uncalibrated gyro's z bias is 0.5 deg/s. The zero-rate updates learn the bias, so the yaw holds its start
    error instead of drifting 20 deg; once the field is clean the yaw comes back."""
    rng = np.random.default_rng(6)
    k = 6000
    _q0, q, w, f, m = exact_unit(k, w_b=(0.0, 0.0, 0.0))
    bias = np.array([0.003, -0.002, np.radians(0.5)])
    f = f + rng.normal(0, 0.007, f.shape)
    t = np.arange(1, k + 1) * DT
    m = m + rng.normal(0, 1e-7, m.shape) + np.where(t[:, None] < 40, quat_rotate(quat_conj(q), [3e-6, -2e-6, 2e-6]), 0)
    runs = {gate: ours(w + bias + rng.normal(0, 1e-3, w.shape), f, m, DT, model(5e-5, 1e-14),
                       OursSettings(gyro_bias_sigma0=0.02, relock_updates=30, zaru_gate=gate))
            for gate in (16.27, 0.0)}
    res = runs[16.27]
    ts = t[res.sample]
    yaw = np.degrees(sa.euler_errors(q[res.sample], res.q_nb[0])[:, 2])
    during = (ts > 5) & (ts < 39)
    assert (res.flags[0][during] & FLAG_STATIC).all()
    assert np.ptp(yaw[during]) < 0.3
    assert np.abs(yaw[ts > 48]).max() < 0.2
    assert res.gyro_bias[0, np.searchsorted(ts, 30.0), 2] == pytest.approx(bias[2], abs=2e-4)
    without = np.degrees(sa.euler_errors(q[res.sample], runs[0.0].q_nb[0])[:, 2])
    assert np.ptp(without[during]) > 10
