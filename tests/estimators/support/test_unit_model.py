"""002's unit models (estimators.support.unit_model) on exact data (tests.estimators.support.conftest)."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.nav.rotations import (
    euler_to_quat,
    quat_conj,
    quat_rotate,
    quat_to_euler,
)
from estimators.nav.rotations_scalar import quat_euler
from estimators.support import unit_model as um
from tests.estimators.support.conftest import B_N, DT, G, exact_unit, model


def test_accel_angles_round_trip():
    """002 eqs. 7-8: the specific force of a resting unit gives back its pitch and roll."""
    rng = np.random.default_rng(1)
    pitch, roll, yaw = rng.uniform(-1.2, 1.2, 200), rng.uniform(-2.5, 2.5, 200), rng.uniform(-3, 3, 200)
    f_b = quat_rotate(quat_conj(euler_to_quat(pitch, roll, yaw)), G)
    p, r = um.accel_pitch_roll(*f_b.T)
    np.testing.assert_allclose(p, pitch, atol=1e-12)
    np.testing.assert_allclose(r, roll, atol=1e-12)


def test_mag_yaw_round_trip_with_declination():
    """002 eqs. 3-6: the tilt-compensated field minus the declination gives the true yaw."""
    rng = np.random.default_rng(2)
    pitch, roll, yaw = rng.uniform(-1.2, 1.2, 200), rng.uniform(-2.5, 2.5, 200), rng.uniform(-3, 3, 200)
    m_b = quat_rotate(quat_conj(euler_to_quat(pitch, roll, yaw)), B_N)
    got = um.mag_yaw(*m_b.T, pitch, roll, model().declination)
    np.testing.assert_allclose(um.wrap(got - yaw), 0.0, atol=1e-12)
    assert model().declination == pytest.approx(np.arctan2(B_N[0], B_N[1]))


def test_euler_output_and_propagation():
    """Eq. 21 in the project's convention matches estimators.nav.rotations; eq. 12 integrates a constant rate exactly."""
    q0, q, w, _, _ = exact_unit(500)
    np.testing.assert_allclose(np.stack(quat_euler(*q.T), -1), np.stack(quat_to_euler(q), -1), atol=1e-12)
    np.testing.assert_allclose(um.propagate(q0, w, DT)[1:], q, atol=1e-12)


def test_measurement_covariance_matches_finite_differences():
    """Eqs. 24-27: the angle variances from the sensor variances equal the linearized propagation."""
    f = np.array([1.2, -2.0, 9.4])
    m = np.array([2e-5, 1e-5, -4e-5])
    var_f, var_m = np.array([1e-4, 2e-4, 3e-4]), np.array([1e-14, 2e-14, 3e-14])
    jac_f = np.empty((2, 3))
    jac_m = np.empty(3)
    p, r = um.accel_pitch_roll(*f)
    for i in range(3):
        d = np.zeros(3)
        d[i] = 1e-7
        jac_f[:, i] = (np.array(um.accel_pitch_roll(*(f + d))) - np.array(um.accel_pitch_roll(*(f - d)))) / 2e-7
        d *= 1e-4
        jac_m[i] = (um.mag_yaw(*(m + d), p, r, 0.0) - um.mag_yaw(*(m - d), p, r, 0.0)) / 2e-11
    cov = jac_f @ np.diag(var_f) @ jac_f.T
    vp, cpr, vr = um.accel_covariance(*f, *var_f)
    np.testing.assert_allclose([vp, cpr, vr], [cov[0, 0], cov[0, 1], cov[1, 1]], rtol=1e-6)
    sincos = (np.sin(p), np.cos(p), np.sin(r), np.cos(r))
    np.testing.assert_allclose(sincos, um.accel_tilt_sincos(*f), rtol=1e-14)
    assert um.mag_yaw_variance(*m, *sincos, *var_m) == pytest.approx(jac_m @ np.diag(var_m) @ jac_m, rel=1e-6)
