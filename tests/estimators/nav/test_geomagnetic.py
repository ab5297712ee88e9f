"""Magnetic heading building blocks (estimators.nav.geomagnetic): geomagnetic reference, tilt-compensated yaw against
002 eqs. 4-6 in 002's own frames, the yaw closing error and its H row on phi against finite differences, the
yaw noise variance, the disturbance test, and the ellipsoid calibration."""

from __future__ import annotations

import datetime

import numpy as np
import pytest
from pygeomag import GeoMag, decimal_year_from_date

from estimators.nav.geomagnetic import (
    apply_calibration,
    field_check,
    fit_ellipsoid,
    geomagnetic_reference,
    tilt_compensated_yaw,
    wrap_angle,
    yaw_closing_error,
    yaw_closing_error_nb,
    yaw_h_phi,
    yaw_measurement,
    yaw_noise_variance,
)
from estimators.nav.rotations import (
    euler_to_mat,
    mat_to_euler,
    quat_normalize,
    quat_to_mat,
    rotvec_to_quat,
    skew,
)
from tests.conftest import simulated
from twin.face.haulage import CUTTING
from twin.sensors.magnetometer import shearer_attitude_at
from twin.sensors.streams import imu_truth, sensor_streams

SITE_DEG = (36.67, 117.06, 50.0)  # Jinan (003's authors, Shandong University)
DATE = "2020-09-01"
REF = geomagnetic_reference(np.radians(SITE_DEG[0]), np.radians(SITE_DEG[1]), SITE_DEG[2], DATE)
SOFT_IRON = np.array([[1.02, 0.01, 0.0], [0.01, 0.98, 0.0], [0.0, 0.0, 1.0]])  # the twin's default
HARD_IRON = np.array([2.0e-6, -1.0e-6, 0.5e-6])


def random_attitudes(rng, k, max_tilt=1.2):
    pitch = rng.uniform(-max_tilt, max_tilt, k)
    roll = rng.uniform(-max_tilt, max_tilt, k)
    yaw = rng.uniform(-np.pi, np.pi, k)
    return pitch, roll, yaw, euler_to_mat(pitch, roll, yaw)


def body_field(mat_nb):
    return np.einsum("...ji,j->...i", mat_nb, REF.field_n)


def test_reference_is_pygeomags_wmm_field_in_enu():
    day = datetime.date.fromisoformat(DATE)
    wmm = GeoMag(base_year=2020).calculate(glat=SITE_DEG[0], glon=SITE_DEG[1], alt=SITE_DEG[2] / 1000,
                                           time=decimal_year_from_date(day))
    assert REF.declination == pytest.approx(np.radians(wmm.d), abs=1e-12)
    assert REF.inclination == pytest.approx(np.radians(wmm.i), abs=1e-12)
    assert REF.intensity == pytest.approx(wmm.f * 1e-9, rel=1e-12)
    assert REF.field_n == pytest.approx(np.array([wmm.y, wmm.x, -wmm.z]) * 1e-9, rel=1e-12)
    # Elements consistent with the vector: |B| = F, dip and declination from the components.
    b_e, b_n, b_u = REF.field_n
    assert np.linalg.norm(REF.field_n) == pytest.approx(REF.intensity, rel=1e-5)  # WMM rounds to 0.1 nT
    assert np.arctan2(-b_u, REF.horizontal) == pytest.approx(REF.inclination, abs=1e-5)
    assert np.arctan2(b_e, b_n) == pytest.approx(REF.declination, abs=1e-5)
    with pytest.raises(ValueError, match="not a date"):
        geomagnetic_reference(0.6, 2.0, 0.0, "June 2020")


def test_tilt_compensated_yaw_recovers_the_true_yaw():
    rng = np.random.default_rng(1)
    pitch, roll, yaw, mat = random_attitudes(rng, 5000)
    got = tilt_compensated_yaw(body_field(mat), pitch, roll, REF.declination)
    assert np.abs(wrap_angle(got - yaw)).max() < 1e-12
    assert np.all((got > -np.pi) & (got <= np.pi))
    assert isinstance(tilt_compensated_yaw(body_field(mat[0]), pitch[0], roll[0], REF.declination), float)


def test_tilt_compensated_yaw_is_002_eqs_4_to_6_in_002s_frames():
    """002: NED, body forward-right-down, psi clockwise: psi = -yaw, theta = pitch, phi = roll, m = (b_y, b_x, -b_z)."""
    rng = np.random.default_rng(2)
    pitch, roll, _, mat = random_attitudes(rng, 2000)
    b = body_field(mat)
    m_x, m_y, m_z = b[:, 1], b[:, 0], -b[:, 2]
    theta, phi = pitch, roll
    mn_cos = m_z * np.cos(phi) * np.sin(theta) + m_y * np.sin(phi) * np.sin(theta) + m_x * np.cos(theta)  # eq. 4
    mn_sin = m_z * np.sin(phi) - m_y * np.cos(phi)
    psi_m = np.arctan2(mn_sin, mn_cos)  # eq. 5, quadrant-correct
    psi_mag = psi_m + REF.declination  # eq. 6
    assert np.abs(wrap_angle(-psi_mag - tilt_compensated_yaw(b, pitch, roll, REF.declination))).max() < 1e-12
    # And 002 eq. 3: the body field of NED components (M_N, 0, M_D) at magnetic heading psi_m.
    m_n, m_d = REF.horizontal, -REF.field_n[2]
    eq3_x = m_n * np.cos(theta) * np.cos(psi_m) - m_d * np.sin(theta)
    assert np.abs(eq3_x - m_x).max() < 1e-6 * REF.intensity


def test_yaw_closing_error_and_its_h_row_match_finite_differences():
    rng = np.random.default_rng(3)
    _, _, _, mat = random_attitudes(rng, 500, max_tilt=0.5)
    b = body_field(mat)
    assert np.abs(yaw_closing_error(b, mat, REF.declination)).max() < 1e-12
    h_phi = yaw_h_phi(REF.field_n)
    tan_i = np.tan(REF.inclination)
    assert h_phi == pytest.approx([-np.sin(REF.declination) * tan_i, -np.cos(REF.declination) * tan_i, -1.0])
    for scale in (1e-4, 1e-3):
        phi = rng.normal(0.0, scale, (500, 3))
        mat_est = quat_to_mat(rotvec_to_quat(-phi)) @ mat  # C' = exp(-[phi x]) C = (I - [phi x]) C + O(phi^2)
        z = yaw_closing_error(b, mat_est, REF.declination)
        remainder = np.abs(z - phi @ h_phi) / np.sum(phi ** 2, axis=1)
        assert remainder.max() < 5.0  # second order in |phi|: the row is the Jacobian
    # The SINS yaw alone has a different row: the levelling by the SINS tilt is what makes z attitude-free.
    pitch, _, yaw = mat_to_euler(mat[0])
    phi = np.array([1e-5, 0.0, 0.0])
    mat_est = (np.eye(3) - skew(phi)) @ mat[0]
    dyaw_sins = wrap_angle(mat_to_euler(mat_est)[2] - yaw)
    assert dyaw_sins == pytest.approx(-np.sin(yaw) * np.tan(pitch) * 1e-5, abs=1e-9)


def test_numba_closing_error_equals_numpy():
    rng = np.random.default_rng(4)
    _, _, _, mat = random_attitudes(rng, 50)
    b = body_field(mat) + rng.normal(0.0, 2e-6, (50, 3))
    mat_est = quat_to_mat(quat_normalize(rotvec_to_quat(rng.normal(0, 0.02, (50, 3))))) @ mat
    ref = yaw_closing_error(b, mat_est, REF.declination)
    got = np.array([yaw_closing_error_nb(b[k], mat_est[k], REF.declination) for k in range(50)])
    assert np.abs(got - ref).max() < 1e-13


def test_yaw_noise_variance_matches_monte_carlo():
    """002 eqs. 26-27: sigma_yaw = sigma_m / H for isotropic noise, whatever the tilt."""
    rng = np.random.default_rng(5)
    noise = 0.5e-6
    pitch, roll, yaw, mat = random_attitudes(rng, 1, max_tilt=0.6)
    b = body_field(mat[0]) + rng.normal(0.0, noise, (40000, 3))
    err = wrap_angle(tilt_compensated_yaw(b, pitch[0], roll[0], REF.declination) - yaw[0])
    var = yaw_noise_variance(REF, noise)
    assert np.var(err) == pytest.approx(var, rel=0.03)  # 4 sigma of a 40000-sample variance is 2.8 %
    meas = yaw_measurement(b[:10], np.broadcast_to(mat[0], (10, 3, 3)), REF, noise, extra_sigma=0.01)
    assert meas.z.shape == (10,) and meas.r == pytest.approx(var + 1e-4)
    assert np.array_equal(meas.h_phi, yaw_h_phi(REF.field_n))


def test_field_check_flags_disturbed_nan_and_saturated_readings():
    rng = np.random.default_rng(6)
    pitch, roll, _, mat = random_attitudes(rng, 1000, max_tilt=0.5)
    b = body_field(mat) + rng.normal(0.0, 1e-7, (1000, 3))
    clean = field_check(b, pitch, roll, REF)
    assert clean.ok.all()
    assert np.abs(clean.norm_error).max() < 0.01 and np.abs(clean.dip_error).max() < np.radians(0.5)
    u = rng.normal(size=(1000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    heavy = field_check(b + 15e-6 * u, pitch, roll, REF)  # the interference of scenarios/seed003_interference
    # Blind spot: a disturbance that turns the field about the vertical keeps norm and dip (and moves the yaw);
    # a random direction lands near it rarely.
    assert heavy.ok.mean() < 0.01
    bad = b[:3].copy()
    bad[0, 1] = np.nan
    bad[1, 2] = 60e-6
    flags = field_check(bad, pitch[:3], roll[:3], REF, saturation_t=60e-6).ok
    assert flags.tolist() == [False, False, True]


def test_ellipsoid_fit_recovers_hard_and_soft_iron_within_one_percent_of_the_field():
    rng = np.random.default_rng(7)
    _, _, _, mat = random_attitudes(rng, 3000, max_tilt=np.pi / 2)
    true_b = body_field(mat)
    raw = true_b @ SOFT_IRON.T + HARD_IRON
    cal = fit_ellipsoid(raw + rng.normal(0.0, 1e-7, raw.shape), REF.intensity)
    f = REF.intensity
    assert np.abs(cal.hard_iron_t - HARD_IRON).max() < 0.01 * f
    assert np.abs(cal.soft_iron - SOFT_IRON).max() < 0.01
    assert np.abs(cal.correction @ cal.soft_iron - np.eye(3)).max() < 1e-12
    assert np.linalg.norm(apply_calibration(raw, cal) - true_b, axis=1).max() < 0.01 * f
    assert cal.residual_rms < 2e-7  # the noise, not a misfit
    # Yaw from calibrated readings: raw readings are off by degrees, calibrated ones by < 0.2 deg.
    pitch, roll, yaw = mat_to_euler(mat)
    level = np.cos(pitch) > 0.5
    yaw_raw = tilt_compensated_yaw(raw, pitch, roll, REF.declination)
    yaw_cal = tilt_compensated_yaw(apply_calibration(raw, cal), pitch, roll, REF.declination)
    assert np.degrees(np.abs(wrap_angle(yaw_raw - yaw))[level].max()) > 2.0
    assert np.degrees(np.abs(wrap_angle(yaw_cal - yaw))[level].max()) < 0.2


def test_ellipsoid_fit_refuses_data_from_a_shearer_on_its_face():
    rng = np.random.default_rng(8)
    k = 2000
    mat = euler_to_mat(rng.normal(0, 0.03, k), rng.normal(0, 0.03, k), np.radians(-124.5) + rng.normal(0, 0.05, k))
    raw = body_field(mat) @ SOFT_IRON.T + HARD_IRON + rng.normal(0.0, 1e-7, (k, 3))
    with pytest.raises(ValueError, match="too few attitudes"):
        fit_ellipsoid(raw, REF.intensity)
    with pytest.raises(ValueError, match="shape"):
        fit_ellipsoid(raw[:, :2], REF.intensity)


def test_seed003_interference_disturbs_the_straight_cut_and_is_caught():
    """scenarios/seed003_interference.toml: the 10-30 s window lies in the straight cut; there the magnetic yaw
    is off by tens of degrees and the disturbance test flags every reading, elsewhere none."""
    scn, res = simulated("seed003_interference")
    shearer = res.tables["truth_shearer"]
    mag = sensor_streams(scn, res.tables, imu_truth(scn, shearer))["mag"]
    ref = geomagnetic_reference(np.radians(scn.site.lat_deg), np.radians(scn.site.lon_deg), scn.site.height_m,
                                scn.sensors.mag.date)
    t = mag["t"]
    b = np.column_stack([mag["b_x"], mag["b_y"], mag["b_z"]])
    pitch, roll, yaw = mat_to_euler(quat_to_mat(shearer_attitude_at(shearer, t)))
    err = np.degrees(np.abs(wrap_angle(tilt_compensated_yaw(b, pitch, roll, ref.declination) - yaw)))
    inside = (t >= 10.0) & (t < 30.0)
    phase = np.asarray(shearer["phase"])[np.searchsorted(shearer["t"], t[inside])]
    assert np.all(phase == CUTTING)
    assert err[inside].min() > 10.0 and err[~inside].max() < 2.0
    ok = field_check(b, pitch, roll, ref).ok
    assert not ok[inside].any() and ok[~inside].all()
