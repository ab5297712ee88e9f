"""Installation errors (000 section 6): static mounting calibration and lever-arm compensation.

The lever-arm checks use the sway of 000 eq. 54 (pitch, roll, yaw 10 deg amplitude, periods 6, 8, 10 s) of a
body whose reference point is fixed on the Earth at the paper's site; the sensor increments at the lever arm
come from the twin's exact IMU model (twin.sensors.imu.sensor_increments, no vibration).
"""

from __future__ import annotations

import numpy as np
import pytest

from estimators.nav import earth
from estimators.nav.rotations import euler_to_mat, mat_to_quat, quat_to_mat
from estimators.sins.installation import (
    compensate_lever_arm,
    estimate_lever_arm,
    lever_arm_acceleration,
    lever_arm_dv_two_sample,
    mounting_calibration,
    mounting_error_specific_force,
    tilt_from_specific_force,
)
from estimators.sins.strapdown import mechanize
from twin.papers.motions import sway as experiment_sway

LAT, LON, H = np.radians(34.27), np.radians(117.18), 36.0  # 000 section 5.3's site
AMP = np.radians(10.0)
PERIODS = np.array([6.0, 8.0, 10.0])  # pitch, roll, yaw (eq. 54)
RATE_HZ = 200.0
DURATION = 400.0
# Tables 2-3: maximum attitude errors [deg] (E, N, U) without / with compensation, per lever arm.
PAPER = {
    (1.0, 1.0, 1.0): ((0.45, 0.25, 0.35), (0.12, 0.10, 0.05), (73.3, 60.0, 85.7)),
    (1.5, 1.5, 1.0): ((0.90, 0.70, 0.70), (0.20, 0.15, 0.08), (77.8, 78.6, 88.6)),
}


def sway(t):
    """Eq. 54 motion at a fixed point (twin.papers.motions.sway with this file's amplitudes, periods and site)."""
    return experiment_sway(t, [AMP] * 3, PERIODS, LAT, H)


def sway_rate_derivative(t, step=1e-4):
    """d w_ib^b / dt of `sway` by central differences (accurate to ~1e-9 rad/s^2)."""
    return (sway(np.asarray(t) + step)[1] - sway(np.asarray(t) - step)[1]) / (2 * step)


def no_vibration():
    from twin.sensors.imu import VibrationTones
    return VibrationTones(freq_hz=np.ones((1, 1)), ang_amp=np.zeros((1, 1, 3)), lin_amp=np.zeros((1, 1, 3)),
                          phase_ang=np.zeros((3, 1)), phase_lin=np.zeros((3, 1)))


def sensor_increments(t, lever_arm_b, mat_bs=None):
    """Exact increments of a sensor at lever_arm_b on the swaying body (twin IMU model, no vibration)."""
    from twin.sensors.imu import sensor_increments as twin_increments
    _, w, f = sway(t)
    return twin_increments(t, w, f, np.zeros((t.size, 1)), no_vibration(), np.asarray(lever_arm_b, float),
                           np.eye(3) if mat_bs is None else mat_bs)


def attitude_errors(c_true, q_nb):
    """Small-angle attitude errors phi (E, N, U) [rad] with C_est = (I - [phi x]) C_true, (K, 3)."""
    e = np.einsum("kij,klj->kil", quat_to_mat(q_nb), c_true)
    return 0.5 * np.stack([e[:, 1, 2] - e[:, 2, 1], e[:, 2, 0] - e[:, 0, 2], e[:, 0, 1] - e[:, 1, 0]], axis=-1)


def lever_arm_case(r_p, duration=DURATION):
    """Max attitude and velocity errors of a 400 s mechanization (2-sample updates) of the sensor's
    increments, uncompensated and compensated (eq. 53): dict of (3,) arrays [rad], [m/s]."""
    t = np.arange(round(duration * RATE_HZ) + 1) / RATE_HZ
    c, _, _ = sway(t)
    dtheta, dv = sensor_increments(t, r_p)
    q0 = mat_to_quat(c[0])
    out = {}
    for label, dv_used in (("uncompensated", dv), ("compensated", compensate_lever_arm(dtheta, dv, r_p, t=t))):
        nav = mechanize(t, dtheta, dv_used, LAT, LON, H, np.zeros(3), q0, n_samples=2, hold_height=True)
        out[label] = np.abs(attitude_errors(c[::2], nav.q_nb)).max(axis=0)
        out[label + "_vel"] = np.abs(nav.v_n).max(axis=0)
    return out


# ------------------------------------------------------------------------------------------- mounting


def test_level_mounting_closed_form_exact():
    gam = earth.normal_gravity(LAT, H)
    for pitch, roll in ((0.01, -0.02), (-0.05, 0.03), (0.2, 0.3)):
        m = euler_to_mat(pitch, roll, 0.004)  # the heading deviation does not matter when level
        f_s = gam * m.T @ np.array([0.0, 0.0, 1.0])
        est = mounting_calibration(f_s)
        assert abs(est["pitch"] - pitch) < 1e-12 and abs(est["roll"] - roll) < 1e-12
        p, r = tilt_from_specific_force(f_s)
        assert abs(p - pitch) < 1e-12 and abs(r - roll) < 1e-12


def test_mounting_from_twin_static_increments():
    """Twin sensor with mounting C_s^b = twin.sensors.imu.mounting_matrix at rest in two known attitudes."""
    from twin.sensors.imu import mounting_matrix
    from twin.sensors.imu import sensor_increments as twin_increments
    mis_deg = np.array([0.8, -1.3, 0.0])
    t = np.arange(201) / RATE_HZ
    attitudes = [euler_to_mat(0.0, 0.0, 0.3), euler_to_mat(np.radians(6.0), np.radians(-4.0), 1.2)]
    means = []
    for c in attitudes:
        w = np.broadcast_to(c.T @ earth.earth_rate_n(LAT), (t.size, 3)).copy()
        f = np.broadcast_to(earth.normal_gravity(LAT, H) * c[2], (t.size, 3)).copy()
        _, dv = twin_increments(t, w, f, np.zeros((t.size, 1)), no_vibration(), np.zeros(3),
                                mounting_matrix(mis_deg))
        means.append(dv[1:].sum(axis=0) / (t[-1] - t[0]))
    est = mounting_calibration(np.array(means), np.array(attitudes), gamma=earth.normal_gravity(LAT, H))
    assert abs(est["pitch"] - np.radians(mis_deg[0])) < 1e-6
    assert abs(est["roll"] - np.radians(mis_deg[1])) < 1e-6
    assert np.abs(est["residual"]).max() < 1e-6


def test_mounting_with_yaw_and_bias():
    gam = earth.normal_gravity(LAT, H)
    ang = np.array([0.012, -0.021, 0.017])
    m = euler_to_mat(*ang)
    bias = np.array([8e-4, -1.0e-3, 6e-4])  # ~1e-4 g, the paper's accelerometer bias
    attitudes = np.array([euler_to_mat(*e) for e in
                          np.radians([[0, 0, 0], [15, 0, 40], [0, 15, -70], [-12, -10, 120]])])
    clean = gam * np.einsum("kj,ji->ki", attitudes[:, 2, :], m)  # gamma M^T C_n^b e_z
    # Error-free, several attitudes: the heading deviation is observable too.
    est = mounting_calibration(clean, attitudes, gamma=gam, fit_yaw=True)
    assert np.allclose([est["pitch"], est["roll"], est["yaw"]], ang, atol=1e-9)
    # With bias, not fitted: the tilt errs by at most the bias-limited |b_h| / g.
    level = mounting_calibration(clean[0] + bias, gamma=gam)
    limit = np.hypot(bias[0], bias[1]) / gam
    err = np.hypot(level["pitch"] - ang[0], level["roll"] - ang[1])
    assert 0.5 * limit < err < 1.05 * limit + 1e-9
    # Fitted with the bias from >= 3 distinct attitudes: recovered.
    est = mounting_calibration(clean + bias, attitudes, gamma=gam, fit_yaw=True, fit_bias=True)
    assert np.allclose([est["pitch"], est["roll"], est["yaw"]], ang, atol=1e-9)
    assert np.allclose(est["bias"], bias, atol=1e-9)
    with pytest.raises(ValueError, match="observable"):
        mounting_calibration(clean[0] + bias, gamma=gam, fit_bias=True)


def test_mounting_sensing_error_eq32():
    m = euler_to_mat(0.01, -0.02, 0.0)
    f_b = np.array([0.3, -0.2, 9.8])
    df = mounting_error_specific_force(m, f_b)
    assert np.allclose(df, f_b - m.T @ f_b, atol=1e-15)
    c_sn = euler_to_mat(0.1, 0.2, 0.3)
    assert np.allclose(mounting_error_specific_force(m, f_b, c_sn), c_sn @ df)


# ------------------------------------------------------------------------------------------- lever arm


def test_two_sample_increment_matches_exact_integral():
    """For a rate exactly linear in time the two-sample form (eqs. 48-52) is the exact integral."""
    a, b2 = np.array([0.1, -0.2, 0.05]), np.array([0.3, 0.1, -0.4])
    r, h = np.array([1.0, 1.5, -0.5]), 0.005
    tau = np.linspace(0, 2 * h, 20001)
    w = a + np.outer(tau, b2)
    integrand = lever_arm_acceleration(w, np.broadcast_to(b2, w.shape), r)
    exact = np.trapezoid(integrand, tau, axis=0)
    th1, th2 = a * h + b2 * h * h / 2, a * h + 3 * b2 * h * h / 2
    assert np.allclose(lever_arm_dv_two_sample(th1, th2, r, h)[0], exact, rtol=1e-8, atol=1e-15)


@pytest.mark.parametrize("r_p", list(PAPER))
def test_lever_arm_compensation_400s(r_p):
    res = lever_arm_case(np.array(r_p))
    reduction = 100 * (1 - res["compensated"] / res["uncompensated"])
    assert np.all(reduction >= np.array(PAPER[r_p][2])), reduction
    assert np.all(res["uncompensated"] > 1e-7)  # the lever arm does disturb the attitude
    assert np.all(res["compensated_vel"] < 1e-3) and np.all(res["uncompensated_vel"][:2] > 0.1)


def test_compensated_increments_match_reference_point():
    t = np.arange(2001) / RATE_HZ
    r_p = np.array([1.5, 1.5, 1.0])
    dtheta, dv = sensor_increments(t, r_p)
    _, dv0 = sensor_increments(t, np.zeros(3))
    lever = np.abs(dv - dv0)[1:].max()
    resid = compensate_lever_arm(dtheta, dv, r_p, h=1 / RATE_HZ) - dv0
    # Over each pair (the two-sample interval T of eq. 52) the fit is accurate to O(T^2); its split over the
    # two samples only to O(w h) relative (the rate derivative is taken constant over the pair).
    assert lever > 1e-4
    assert np.abs(resid[1:].reshape(-1, 2, 3).sum(axis=1)).max() < 1e-5 * lever
    assert np.abs(resid[1:]).max() < 5e-3 * lever
    # An odd number of increments: the last one is compensated from its pair with the one before.
    resid_odd = compensate_lever_arm(dtheta[:-1], dv[:-1], r_p, h=1 / RATE_HZ) - dv0[:-1]
    assert np.abs(resid_odd[1:]).max() < 5e-3 * lever


@pytest.mark.parametrize("r_p", list(PAPER))
def test_lever_arm_from_two_epochs(r_p):
    r_p = np.array(r_p)
    t12 = np.array([1.3, 3.7])
    c, w, f = sway(t12)
    w_dot = sway_rate_derivative(t12)
    a_b = f + lever_arm_acceleration(w, w_dot, r_p)
    assert np.allclose(estimate_lever_arm(c, a_b, w, w_dot), r_p, atol=1e-6)
    # From the sensor's increments: means over 10 ms around each epoch, the rate derivative from the
    # neighbouring gyro increments, the attitude known (truth; in use the SINS's).
    t = np.arange(int(6 * RATE_HZ) + 1) / RATE_HZ
    dtheta, dv = sensor_increments(t, r_p)
    rows = [round(e * RATE_HZ) for e in t12]
    mid = np.array([t[k] for k in rows])
    a_m = np.array([(dv[k] + dv[k + 1]) * RATE_HZ / 2 for k in rows])
    w_m = np.array([(dtheta[k] + dtheta[k + 1]) * RATE_HZ / 2 for k in rows])
    wd_m = np.array([(dtheta[k + 1] - dtheta[k]) * RATE_HZ ** 2 for k in rows])
    est = estimate_lever_arm(sway(mid)[0], a_m, w_m, wd_m)
    assert np.allclose(est, r_p, atol=0.01), est
    # Many epochs by least squares: closer.
    rows = np.arange(10, t.size - 2, 7)
    a_m = (dv[rows] + dv[rows + 1]) * RATE_HZ / 2
    w_m = (dtheta[rows] + dtheta[rows + 1]) * RATE_HZ / 2
    wd_m = (dtheta[rows + 1] - dtheta[rows]) * RATE_HZ ** 2
    est = estimate_lever_arm(sway(t[rows])[0], a_m, w_m, wd_m)
    assert np.allclose(est, r_p, atol=0.01), est
    with pytest.raises(ValueError):
        estimate_lever_arm(c[:1], a_b[:1], w[:1], w_dot[:1])
