"""Fine alignment (000 section 5.2): EKF / UKF / optimized UKF from 3, 3, 5 deg off on a standing shearer.

Floors (the errors no stationary alignment can beat, because at rest the biases and the attitude errors are not
separable): level = horizontal accelerometer bias / g, heading = east gyro bias / (w_ie cos L) plus the level
coupling tan L * (east accelerometer bias / g) (phi_U' = phi_E Omega_N - ... steady state of 000 eq. 15).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from estimators import earth
from estimators.alignment import heading_limit, level_limit
from estimators.fine_alignment import METHODS, fine_align
from estimators.rotations import (
    euler_to_quat,
    quat_conj,
    quat_mul,
    quat_rotate,
    quat_to_mat,
    rotvec_to_quat,
)
from twin.imu_errors import apply_imu_errors
from twin.imu_grades import grade

LAT = np.radians(34.27)
RATE = 200.0
YAW = np.radians(-90.0)  # 000 section 5.3: heading 270 deg
ERR0 = np.radians([3.0, 3.0, 5.0])  # phi_E, phi_N, phi_U of the start attitude


def stationary(grade_name: str, seconds: float, seed: int):
    """Increments of an IMU standing at pitch = roll = 0, yaw 270 deg, with the grade's errors."""
    q_nb = euler_to_quat(0.0, 0.0, YAW)
    n = int(seconds * RATE)
    w_b = quat_rotate(quat_conj(q_nb), earth.earth_rate_n(LAT))
    f_b = quat_rotate(quat_conj(q_nb), np.array([0.0, 0.0, earth.normal_gravity(LAT, 0.0)]))
    g = grade(grade_name)
    dtheta, dv, info = apply_imu_errors(np.tile(w_b / RATE, (n, 1)), np.tile(f_b / RATE, (n, 1)), 1 / RATE, g,
                                        np.random.default_rng(seed))
    q0 = quat_mul(rotvec_to_quat(-ERR0), q_nb)  # truth C_b^n = Exp(phi) C_b^n' with phi = ERR0
    return dtheta, dv, q_nb, q0, info, g


def run(grade_name, seconds, seed, method, update_rate=2.0):
    dtheta, dv, q_true, q0, info, g = stationary(grade_name, seconds, seed)
    res = fine_align(dtheta, dv, 1 / RATE, LAT, q0, (g.gyro_arw, g.accel_vrw), ERR0, method,
                     gyro_bias_sigma=g.gyro_bias, accel_bias_sigma=g.accel_bias, update_rate=update_rate,
                     **bias_psd(g))
    return res, q_true, info, g


def bias_psd(g):
    """Random-walk PSD of the bias states matching the grade's Gauss-Markov in-run bias (2 sigma^2 / tau)."""
    gp = 2 * g.gyro_bias_instability ** 2 / g.gyro_bias_tau if g.gyro_bias_instability else 0.0
    ap = 2 * g.accel_bias_instability ** 2 / g.accel_bias_tau if g.accel_bias_instability else 0.0
    return {"gyro_bias_psd": gp, "accel_bias_psd": ap}


def floors(q_true, info):
    """(level floor, heading floor) [rad] of the drawn biases."""
    c = quat_to_mat(q_true)
    acc_n, gyro_n = c @ info.accel_bias, c @ info.gyro_bias
    level = level_limit(float(np.hypot(acc_n[0], acc_n[1])), LAT)
    heading = abs(heading_limit(float(gyro_n[0]), LAT)) + np.tan(LAT) * abs(level_limit(float(acc_n[0]), LAT))
    return level, heading


@pytest.mark.parametrize("seed", [0, 1])
def test_nav_grade_ukf_reaches_the_floors(seed):
    """Navigation grade of 004 after 1800 s (the east-gyro floor needs the gyro ARW averaged down: 0.0001
    deg/sqrt(h) against 0.001 deg/h): heading within 10 % of the gyrocompassing floor (plus the 3-sigma ARW
    noise of the averaged east rate); level within 35 % of accel bias / g, not 10 %: the north gyro bias
    (prior 0.001 deg/h = 1.2e-4 rad of level through Omega_U, eq. 15) is still being separated from the north
    accelerometer bias at 1800 s (8 seeds: level / floor 0.83 .. 1.33, heading / floor 0.10 .. 1.49 with the ARW allowance)."""
    seconds = 1800.0
    res, q_true, info, g = run("nav-004", seconds, seed, "ukf")
    _, phi = res.errors(q_true)
    level, heading = floors(q_true, info)
    arw_noise = g.gyro_arw / np.sqrt(seconds) / (earth.OMEGA_IE * np.cos(LAT))
    assert np.hypot(phi[0], phi[1]) <= 1.35 * level
    assert abs(phi[2]) <= 1.1 * heading + 3 * arw_noise
    assert np.all(np.abs(phi) < np.radians(0.02))


@pytest.mark.parametrize("method", ["ekf", "optimized_ukf"])
def test_nav_grade_other_filters_converge(method):
    res, q_true, info, _ = run("nav-004", 600.0, 0, method)
    d, phi = res.errors(q_true)
    level, _ = floors(q_true, info)
    assert np.hypot(phi[0], phi[1]) <= 1.5 * level
    assert np.all(np.abs(np.degrees(d)) < 0.02)  # from 3, 3, 5 deg
    assert np.all(res.attitude_sigma[-1] < ERR0 / 100)


def test_mti_g_700_heading_sigma_admits_no_gyrocompassing():
    """720 deg/h gyro bias: the gyrocompassing floor is tens of degrees; the filter must report a heading sigma
    of that order (growing beyond the 5 deg start, as the vertical gyro bias turns the computed frame) instead
    of claiming accuracy, and the true heading error must lie within it."""
    for seed in (0, 1):
        res, q_true, _, _ = run("mti-g-700", 300.0, seed, "ukf")
        _, phi = res.errors(q_true)
        assert abs(heading_limit(grade("mti-g-700").gyro_bias, LAT)) > np.radians(10.0)
        assert res.attitude_sigma[-1, 2] > np.radians(20.0)
        assert abs(phi[2]) < 3 * res.attitude_sigma[-1, 2]
        assert np.hypot(phi[0], phi[1]) < np.radians(2.0)  # levelled (see the report: not to the 0.2 deg floor)


def test_nav_grade_nees_is_chi_square():
    """Normalized attitude error squared (filter covariance) summed over seeds within the 99 % chi-square band
    of 3 x seeds degrees of freedom."""
    seeds = range(6)
    total = 0.0
    for seed in seeds:
        res, q_true, _, _ = run("nav-004", 300.0, 100 + seed, "ukf")
        total += res.nees(q_true)
    dof = 3 * len(seeds)
    lo, hi = chi2.ppf([0.005, 0.995], dof)
    assert lo <= total <= hi, (total, lo, hi)


@pytest.mark.parametrize("method", METHODS)
def test_error_free_imu_converges_for_every_method(method):
    dtheta, dv, q_true, q0, _, _ = stationary("ideal", 120.0, 0)
    res = fine_align(dtheta, dv, 1 / RATE, LAT, q0, (0.0, 0.0), ERR0, method, gyro_bias_sigma=1e-9,
                     accel_bias_sigma=1e-4, update_rate=10.0)
    d, _ = res.errors(q_true)
    assert np.all(np.abs(np.degrees(d)) < 0.05)
    assert res.t[-1] == pytest.approx(120.0)
    assert res.q_nb.shape == (1200, 4) and res.sigma.shape == (1200, 10)


def test_bad_input_is_refused():
    dtheta, dv, _, q0, _, _ = stationary("ideal", 1.0, 0)
    with pytest.raises(ValueError, match="unknown method"):
        fine_align(dtheta, dv, 1 / RATE, LAT, q0, (0.0, 0.0), ERR0, "pf")
    bad = dtheta.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        fine_align(bad, dv, 1 / RATE, LAT, q0, (0.0, 0.0), ERR0, "ukf")
