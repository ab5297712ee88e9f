"""Fine alignment (000 section 5.2): EKF / UKF / optimized UKF from 3, 3, 5 deg off on a standing shearer.

Floors (estimators.sins.fine_alignment `alignment_floors`, per axis and signed, of the biases actually drawn, with the
accelerometer non-orthogonality times gravity counted as bias): phi_N = east accel bias / g, phi_U = the
gyrocompassing floor east gyro bias / (w_ie cos L) plus tan L phi_N, phi_E = the information-weighted mean of
-north accel bias / g and the north and up gyros' verdicts (a navigation-grade gyro measures the Earth-rate
direction well enough to take a sixth of the weight; for MEMS gyros it is -north accel bias / g); every angle also
weighs the start error (the filter's prior), so a MEMS heading floor is its start error.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from estimators.nav import earth
from estimators.nav.rotations import (
    euler_to_quat,
    quat_conj,
    quat_mul,
    quat_rotate,
    quat_to_mat,
    rotvec_to_quat,
)
from estimators.sins.coarse_alignment import AlignmentError, heading_limit
from estimators.sins.fine_alignment import METHODS, alignment_floors, fine_align
from twin.config.imu_grades import grade
from twin.sensors.imu_errors import apply_imu_errors

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

LAT = np.radians(34.27)
RATE = 200.0
YAW = np.radians(-90.0)  # 000 section 5.3: heading 270 deg
ERR0 = np.radians([3.0, 3.0, 5.0])  # phi_E, phi_N, phi_U of the start attitude
GAMMA = earth.normal_gravity(LAT, 0.0)
WINDOW = 10.0  # [s] the result is the mean attitude over the last 10 s (FineAlignment.attitude)


def stationary(grade_name: str, seconds: float, seed: int):
    """Increments of an IMU standing at pitch = roll = 0, yaw 270 deg, with the grade's errors."""
    q_nb = euler_to_quat(0.0, 0.0, YAW)
    n = int(seconds * RATE)
    w_b = quat_rotate(quat_conj(q_nb), earth.earth_rate_n(LAT))
    f_b = quat_rotate(quat_conj(q_nb), np.array([0.0, 0.0, GAMMA]))
    g = grade(grade_name)
    dtheta, dv, info = apply_imu_errors(np.tile(w_b / RATE, (n, 1)), np.tile(f_b / RATE, (n, 1)), 1 / RATE, g,
                                        np.random.default_rng(seed))
    q0 = quat_mul(rotvec_to_quat(-ERR0), q_nb)  # truth C_b^n = Exp(phi) C_b^n' with phi = ERR0
    return dtheta, dv, q_nb, q0, info, g


def accel_sigma(g) -> float:
    """Per-axis sigma of the horizontal accelerometer error at rest: turn-on bias and non-orthogonality x g."""
    return float(np.hypot(g.accel_bias, GAMMA * g.accel_nonorth))


def run(grade_name, seconds, seed, method, **kw):
    dtheta, dv, q_true, q0, info, g = stationary(grade_name, seconds, seed)
    gp = 2 * g.gyro_bias_instability ** 2 / g.gyro_bias_tau if g.gyro_bias_instability else 0.0
    ap = 2 * g.accel_bias_instability ** 2 / g.accel_bias_tau if g.accel_bias_instability else 0.0
    res = fine_align(dtheta, dv, 1 / RATE, LAT, q0, (g.gyro_arw, g.accel_vrw), ERR0, method,
                     gyro_bias_sigma=g.gyro_bias, accel_bias_sigma=accel_sigma(g), gyro_bias_psd=gp,
                     accel_bias_psd=ap, **kw)
    return res, q_true, info, g


def floors(res, q_true, info, g, seconds):
    """(floors, classical) of the draw (alignment_floors: the tilt in the axes of the estimate, the gyro ARW
    averaged over the run, the start error at one sigma as the filter's prior)."""
    c = quat_to_mat(q_true)
    acc = info.accel_bias + (info.accel_matrix - np.eye(3)) @ (c.T @ [0.0, 0.0, GAMMA])
    gyr = info.gyro_bias + (info.gyro_matrix - np.eye(3)) @ (c.T @ earth.earth_rate_n(LAT))
    return alignment_floors(quat_to_mat(res.attitude(WINDOW)), acc, gyr, LAT, accel_sigma(g), g.gyro_bias,
                            arw=g.gyro_arw, seconds=seconds, start_error=ERR0, start_sigma=ERR0)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_nav_grade_reaches_the_floors(seed):
    """Navigation grade of 004 after 1800 s (EKF): the level within 10 % of its floor plus 3 sigma of the gyro
    ARW in the gyros' share of it (a sixth; the heading's ARW allowance), phi_N within 10 % of east accel bias /
    g, the heading within 10 % of the gyrocompassing floor plus 3 ARW sigma (8 seeds: level 0.7-9.6 %, phi_N
    0.1-2.6 %, heading inside the allowance, which is 0.2-1 times the floor at 1800 s)."""
    seconds = 1800.0
    res, q_true, info, g = run("nav-004", seconds, seed, "ekf")
    _, phi = res.errors(q_true, window_s=WINDOW)
    fl, classical = floors(res, q_true, info, g, seconds)
    arw_angle = g.gyro_arw / np.sqrt(seconds) / (earth.OMEGA_IE * np.cos(LAT))
    assert np.hypot(*(phi[:2] - fl[:2])) <= 0.1 * np.hypot(*fl[:2]) + 0.2 * 3 * arw_angle
    assert abs(phi[1] - classical[1]) <= 0.1 * abs(classical[1])
    assert abs(phi[2] - fl[2]) <= 0.1 * abs(fl[2]) + 3 * arw_angle
    assert np.all(np.abs(phi) < 3 * res.attitude_sigma[-1])


@pytest.mark.parametrize("method", ["ukf", "optimized_ukf"])
def test_nav_grade_unscented_filters_reach_the_level(method):
    res, q_true, info, g = run("nav-004", 600.0, 0, method)
    d, phi = res.errors(q_true, window_s=WINDOW)
    fl, _ = floors(res, q_true, info, g, 600.0)
    assert np.hypot(*(phi[:2] - fl[:2])) <= 0.1 * np.hypot(*fl[:2])
    assert np.all(np.abs(np.degrees(d)) < 0.02)  # from 3, 3, 5 deg
    assert np.all(res.attitude_sigma[-1] < ERR0 / 100)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_mti_g_700_levels_honestly_and_keeps_its_heading(seed):
    """720 deg/h gyro bias: no gyrocompassing (floor tens of degrees), so the heading keeps its 5 deg start
    error and its 5 deg sigma instead of turning with the vertical gyro bias; the level reaches its floor
    (accel bias and non-orthogonality / g, 0.1-0.3 deg) within 10 % (12 seeds: 0.8-7.1 %) with a sigma that is
    the prior accel sigma / g."""
    res, q_true, info, g = run("mti-g-700", 300.0, seed, "ekf")
    _, phi = res.errors(q_true, window_s=WINDOW)
    fl, _ = floors(res, q_true, info, g, 300.0)
    sig = res.attitude_sigma[-1]
    assert abs(heading_limit(g.gyro_bias, LAT)) > np.radians(10.0)
    assert sig[2] >= 0.99 * ERR0[2]
    assert abs(phi[2] - fl[2]) <= 0.1 * abs(fl[2])
    assert np.all(sig[:2] > 0.95 * accel_sigma(g) / GAMMA)
    assert np.all(np.abs(phi) < 3 * sig)
    assert np.hypot(*(phi[:2] - fl[:2])) <= 0.1 * np.hypot(*fl[:2])


def test_mti_g_700_without_the_zero_rate_update_says_the_heading_is_unknown():
    """Without the vertical zero-rate update the 720 deg/h vertical bias turns the computed heading: the heading
    sigma must grow to tens of degrees and cover the error, and the level must stay honest."""
    for seed in (0, 1):
        res, q_true, _, g = run("mti-g-700", 300.0, seed, "ekf", zero_rate=False)
        _, phi = res.errors(q_true, window_s=WINDOW)
        sig = res.attitude_sigma[-1]
        assert sig[2] > np.radians(20.0)
        assert np.all(np.abs(phi) < 3 * sig)
        assert np.all(sig[:2] > 0.95 * accel_sigma(g) / GAMMA)


@pytest.mark.parametrize("grade_name", ["nav-004", "mti-g-700"])
def test_nees_is_chi_square(grade_name):
    """Normalized attitude error squared (filter covariance) summed over seeds within the 99 % chi-square band
    of 3 x seeds degrees of freedom."""
    seeds = range(8)
    total = 0.0
    for seed in seeds:
        res, q_true, _, _ = run(grade_name, 300.0, 100 + seed, "ekf")
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


def test_the_bias_estimates_are_read_by_name():
    """An error-free IMU but for a vertical gyro bias of 20 deg/h: the zero-rate update finds it, in gyro_bias's z
    (the accelerometer estimates, accel_bias, stay near zero: at rest they mimic a tilt)."""
    dtheta, dv, _, q0, _, _ = stationary("ideal", 60.0, 0)
    eps = np.radians(20.0 / 3600)
    dtheta[:, 2] += eps / RATE
    res = fine_align(dtheta, dv, 1 / RATE, LAT, q0, (0.0, 0.0), ERR0, "ekf", gyro_bias_sigma=np.radians(100 / 3600),
                     accel_bias_sigma=1e-3)
    assert res.gyro_bias.shape == (600, 3) and res.accel_bias.shape == (600, 2)
    assert res.gyro_bias[-1, 2] == pytest.approx(eps, rel=1e-3)
    assert np.all(np.abs(res.gyro_bias[-1, :2]) < 0.05 * eps) and np.all(np.abs(res.accel_bias[-1]) < 1e-4)


def test_ekf_kernel_and_ukf_agree():
    """The numba EKF loop and the Python UKF loop share the model: same answer where the model is linear."""
    a, q_true, _, _ = run("nav-004", 120.0, 5, "ekf")
    b, _, _, _ = run("nav-004", 120.0, 5, "ukf")
    assert np.allclose(a.errors(q_true)[1], b.errors(q_true)[1], atol=np.radians(2e-4))
    assert np.allclose(a.attitude_sigma[-1], b.attitude_sigma[-1], rtol=0.05)


def test_a_moving_shearer_is_refused_or_flagged():
    """The shearer starts hauling at 60 s (0.05 m/s^2 along the face for 3 s, then 0.15 m/s): the zero-velocity
    innovations give it away; the standing record passes."""
    dtheta, dv, _, q0, _, g = stationary("mti-g-700", 120.0, 0)
    args = (1 / RATE, LAT, q0, (g.gyro_arw, g.accel_vrw), ERR0, "ekf")
    kw = {"gyro_bias_sigma": g.gyro_bias, "accel_bias_sigma": accel_sigma(g)}
    assert fine_align(dtheta, dv, *args, **kw).motion_t is None
    moving = dv.copy()
    moving[int(60 * RATE):int(63 * RATE), 1] += 0.05 / RATE
    with pytest.raises(AlignmentError, match="moves"):
        fine_align(dtheta, moving, *args, **kw)
    res = fine_align(dtheta, moving, *args, on_motion="flag", **kw)
    assert 50.0 <= res.motion_t <= 63.0


def test_a_rocking_standing_machine_aligns_with_its_vibration_in_the_zero_rate_noise():
    """A navigation-grade IMU on an idling machine that rocks 0.001 deg at the drum's 0.6 Hz: taken with the gyro's
    random walk alone the zero-rate innovations look like motion (flagged at the first tested window, the
    attitude 0.04-0.08 deg off); with the machine's rate noise (rate_sigma, 5e-4 rad/s) the stand passes and
    gyrocompasses to within the claimed 3 sigma (0.003 deg level, 0.0015 deg heading here)."""
    dtheta, dv, q_true, q0, _, g = stationary("nav-004", 600.0, 0)
    t = np.arange(dtheta.shape[0] + 1) / RATE
    rocking = dtheta + np.diff(np.radians(0.001) * np.sin(2 * np.pi * 0.6 * t[:, None] + [0.3, 1.1, 2.0]), axis=0)
    args = (rocking, dv, 1 / RATE, LAT, q0, (g.gyro_arw, g.accel_vrw), ERR0, "ekf")
    kw = {"gyro_bias_sigma": g.gyro_bias, "accel_bias_sigma": accel_sigma(g), "on_motion": "flag"}
    assert fine_align(*args, **kw).motion_t is not None
    res = fine_align(*args, rate_sigma=5e-4, **kw)
    assert res.motion_t is None
    _, phi = res.errors(q_true, window_s=WINDOW)
    assert np.all(np.abs(phi) < 3 * res.attitude_sigma[-1])


def test_bad_input_is_refused():
    dtheta, dv, _, q0, _, _ = stationary("ideal", 1.0, 0)
    with pytest.raises(ValueError, match="unknown method"):
        fine_align(dtheta, dv, 1 / RATE, LAT, q0, (0.0, 0.0), ERR0, "pf")
    with pytest.raises(ValueError, match="on_motion"):
        fine_align(dtheta, dv, 1 / RATE, LAT, q0, (0.0, 0.0), ERR0, "ekf", on_motion="ignore")
    bad = dtheta.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        fine_align(bad, dv, 1 / RATE, LAT, q0, (0.0, 0.0), ERR0, "ukf")
