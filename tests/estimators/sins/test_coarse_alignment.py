"""Coarse alignment: exact on error-free data, at the physical limits with biases, refuses a moving IMU."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.nav import earth
from estimators.nav.rotations import euler_to_quat, quat_conj, quat_rotate
from estimators.sins.coarse_alignment import (
    AlignmentError,
    coarse_align,
    heading_limit,
    level_limit,
)

LAT = np.radians(34.27)
RATE = 200.0


def stationary(pitch, roll, yaw, seconds=60.0, gyro_bias_b=np.zeros(3), accel_bias_b=np.zeros(3)):
    q_nb = euler_to_quat(pitch, roll, yaw)
    n = int(seconds * RATE)
    w_b = quat_rotate(quat_conj(q_nb), earth.earth_rate_n(LAT)) + gyro_bias_b
    f_b = quat_rotate(quat_conj(q_nb), np.array([0.0, 0.0, earth.normal_gravity(LAT, 0.0)])) + accel_bias_b
    return np.tile(w_b / RATE, (n, 1)), np.tile(f_b / RATE, (n, 1)), q_nb


def test_error_free_alignment_is_exact():
    dtheta, dv, _ = stationary(np.radians(2.0), np.radians(-1.0), np.radians(30.0))
    a = coarse_align(dtheta, dv, 1 / RATE, LAT)
    assert np.allclose([a.pitch, a.roll, a.yaw], np.radians([2.0, -1.0, 30.0]), atol=1e-9)


def test_biases_set_the_level_and_heading_errors():
    """An east-pointing gyro bias and a north accelerometer bias (body = n at zero angles) give heading and
    level errors equal to the gyrocompassing and bias/g limits."""
    gyro_bias, accel_bias = np.radians(0.001) / 3600, 30e-6 * 9.80665  # the navigation grade of 004
    dtheta, dv, _ = stationary(0.0, 0.0, 0.0, gyro_bias_b=np.array([gyro_bias, 0, 0]),
                               accel_bias_b=np.array([0, accel_bias, 0]))
    a = coarse_align(dtheta, dv, 1 / RATE, LAT)
    assert abs(a.pitch) == pytest.approx(level_limit(accel_bias, LAT), rel=0.01)
    assert abs(a.yaw) == pytest.approx(heading_limit(gyro_bias, LAT), rel=0.01)


def test_a_moving_imu_is_refused():
    dtheta, dv, _ = stationary(0.0, 0.0, 0.0)
    dv[:, 1] += 0.3 * np.sin(np.arange(dv.shape[0]) / RATE * 2 * np.pi * 0.2) / RATE  # the shearer hauling
    with pytest.raises(AlignmentError, match="moves"):
        coarse_align(dtheta, dv, 1 / RATE, LAT)
    dtheta, dv, _ = stationary(0.0, 0.0, 0.0)
    dv[:, 2] += 0.5 / RATE  # a steady push along the vertical changes |f| (a steady horizontal one looks like a tilt)
    with pytest.raises(AlignmentError, match="not gravity"):
        coarse_align(dtheta, dv, 1 / RATE, LAT)
    bad = dtheta.copy()
    bad[5, 0] = np.nan
    with pytest.raises(AlignmentError, match="row 5"):
        coarse_align(bad, dv, 1 / RATE, LAT)
