"""The closed-loop fine alignment at rest of 000 section 6.4 (estimators.sins.lever_arm_filter)."""

from __future__ import annotations

import numpy as np

from estimators.nav import earth
from estimators.nav.rotations import (
    euler_to_quat,
    quat_conj,
    quat_mul,
    quat_rotate,
    quat_to_rotvec,
    rotvec_to_quat,
)
from estimators.sins.lever_arm_filter import AtRestSettings, align_at_rest


def test_a_standing_sensor_levels_from_the_paper_errors():
    """Exact increments of a tilted, standing IMU from 000 section 6.4's initial errors (0.1, 0.1, 0.5 deg): after
    120 s the level errors are a hundredth of a degree and the heading error has shrunk (gyrocompassing)."""
    lat, lon, h, rate = np.radians(34.27), np.radians(117.18), 36.0, 100.0
    t = np.arange(round(120.0 * rate) + 1) / rate
    q_true = euler_to_quat(np.radians(2.0), np.radians(-1.0), np.radians(30.0))
    w_b = quat_rotate(quat_conj(q_true), earth.earth_rate_n(lat))
    f_b = quat_rotate(quat_conj(q_true), np.array([0.0, 0.0, earth.normal_gravity(lat, h)]))
    dtheta, dv = np.tile(w_b / rate, (t.size, 1)), np.tile(f_b / rate, (t.size, 1))
    dtheta[0] = dv[0] = 0.0
    phi0 = np.radians([0.1, 0.1, 0.5])
    g0 = 9.80665
    settings = AtRestSettings(attitude_sigma=phi0, gyro_bias_sigma=np.radians(0.01) / 3600,
                              gyro_noise=np.radians(0.005) / 3600, accel_bias_sigma=1e-4 * g0, accel_noise=1e-5 * g0,
                              update_hz=10.0, velocity_sigma=0.05)
    k, q_nb = align_at_rest(t, dtheta, dv, quat_mul(rotvec_to_quat(-phi0), q_true), lat, lon, h, settings)
    np.testing.assert_array_equal(k, np.arange(10, t.size, 10))
    err = np.degrees(quat_to_rotvec(quat_mul(q_true, quat_conj(q_nb))))  # C_true = Exp(phi) C_est
    assert np.all(np.abs(err[-1, :2]) < 0.01), err[-1]
    assert abs(err[-1, 2]) < 0.45, err[-1]
