"""Shearer magnetometer (twin.sensors.magnetometer) and support canopy units (twin.sensors.support_imu) on synthetic truth."""

from __future__ import annotations

import datetime

import numpy as np
import pytest
from pygeomag import GeoMag, decimal_year_from_date

from estimators.io.logformat import MAG, SUPPORT_IMU, check_table, make_table
from estimators.nav import earth
from estimators.nav.rotations import (
    euler_to_mat,
    euler_to_quat,
    quat_conj,
    quat_rotate,
    quat_to_mat,
)
from tests.conftest import simulated
from tests.twin.sensors.test_survey_chunks import joined, random_starts, same
from twin.config.scenario import parse_scenario
from twin.face.layout import FaceFrame
from twin.sensors.chunks import halo_rows, split_truth
from twin.sensors.magnetometer import (
    Magnetometer,
    earth_field_n,
    field_elements,
    mag_stream,
    site_field_elements,
    site_field_n,
    tilt_compensated_heading,
)
from twin.sensors.support_imu import (
    DISTURBANCE_RANGE_PANS,
    canopy_attitude_n,
    canopy_motion,
    canopy_rows,
    support_imu_stream,
)

SITE = (34.27, 117.18, 36.0)
DATE = "2026-06-01"
QUIET_MAG = {"noise_t": 0.0, "hard_iron_t": [0.0, 0.0, 0.0], "soft_iron": np.eye(3).tolist(),
             "motor_disturbance_t": [0.0, 0.0, 0.0]}


def scenario(mag=None, support_imu=None, faults=()):
    sensors = {"mag": {"date": DATE, **(mag or {})}}
    if support_imu is not None:
        sensors["support_imu"] = support_imu
    return parse_scenario({"name": "mag-test", "sensors": sensors, "faults": list(faults)})


def shearer_truth(duration=120.0, rate=200.0, v_cut=8.0 / 60, v_ret=18.0 / 60):
    """Synthetic truth_shearer columns: wobbling attitude; stopped, cutting, returning, stopped again."""
    t = np.arange(round(duration * rate) + 1) / rate
    q = euler_to_quat(0.03 * np.sin(0.1 * t), 0.02 * np.cos(0.07 * t), -0.5 + 0.05 * np.sin(0.05 * t))
    phase = np.select([t < 20, t < 60, t < 90], [0, 1, 2], 0).astype(np.int8)
    speed = np.select([phase == 1, phase == 2], [v_cut, v_ret], 1e-4)  # suspension jitter while stopped
    v = speed[:, None] * np.array([0.6, 0.8, 0.0])
    truth = {"t": t, "phase": phase, "s": np.cumsum(speed) / rate}
    truth.update({f"q_nb_{a}": q[:, k] for k, a in enumerate("wxyz")})
    truth.update({f"v_n_{a}": v[:, k] for k, a in enumerate("enu")})
    return truth


def columns(stream, name):
    return np.column_stack([stream[f"{name}_{a}"] for a in "xyz"])


def attitude(truth, t):
    idx = np.searchsorted(truth["t"], t)
    assert np.allclose(truth["t"][idx], t, atol=1e-12, rtol=0)
    return np.column_stack([truth[f"q_nb_{a}"][idx] for a in "wxyz"]), idx


# ---------------------------------------------------------------------------------------------- Earth field


def test_wmm_field_at_reference_site_is_plausible_and_pygeomag_s():
    el = field_elements(*SITE, DATE)
    assert -10.0 < np.degrees(el.declination) < -2.0  # a few degrees west
    assert 45.0 < np.degrees(el.inclination) < 56.0
    assert 45e-6 < el.intensity < 56e-6
    day = datetime.date.fromisoformat(DATE)
    ref = GeoMag(base_year=day.year).calculate(glat=SITE[0], glon=SITE[1], alt=SITE[2] / 1000,
                                               time=decimal_year_from_date(day))
    assert el.declination == pytest.approx(np.radians(ref.d), abs=1e-12)
    assert el.inclination == pytest.approx(np.radians(ref.i), abs=1e-12)
    assert el.intensity == pytest.approx(ref.f * 1e-9, rel=1e-12)
    b_n = earth_field_n(*SITE, DATE)  # ENU from pygeomag's north, east, down
    np.testing.assert_allclose(b_n, np.array([ref.y, ref.x, -ref.z]) * 1e-9, rtol=1e-12)
    assert np.linalg.norm(b_n) == pytest.approx(el.intensity, rel=1e-12)
    assert np.arctan2(b_n[0], b_n[1]) == pytest.approx(el.declination, abs=1e-12)  # east of north
    assert np.arctan2(-b_n[2], np.hypot(b_n[0], b_n[1])) == pytest.approx(el.inclination, abs=1e-12)
    scn = scenario()
    assert site_field_elements(scn) == el
    np.testing.assert_array_equal(site_field_n(scn), b_n)


def test_bad_magnetometer_date_is_a_clear_error():
    with pytest.raises(ValueError, match="no World Magnetic Model"):
        earth_field_n(*SITE, "1990-01-01")


# ---------------------------------------------------------------------------------------- shearer stream


def test_error_free_stream_is_the_rotated_earth_field():
    truth = shearer_truth()
    scn = scenario(QUIET_MAG)
    out = mag_stream(scn, truth, np.random.default_rng(0), [])
    np.testing.assert_array_equal(out["t"], truth["t"][::4])  # 50 Hz from 200 Hz: the truth samples
    q, _ = attitude(truth, out["t"])
    expected = quat_rotate(quat_conj(q), site_field_n(scn))
    np.testing.assert_allclose(columns(out, "b"), expected, rtol=0, atol=1e-18)
    table = make_table(MAG, out)
    check_table(MAG, table, "mag")

    # A rate that does not divide the truth rate interpolates between truth samples.
    out = mag_stream(scenario({**QUIET_MAG, "rate_hz": 30.0}), truth, np.random.default_rng(0), [])
    t = out["t"]
    assert t[0] == 0.0 and t[-1] == pytest.approx(120.0) and np.allclose(np.diff(t), 1 / 30)
    q = euler_to_quat(0.03 * np.sin(0.1 * t), 0.02 * np.cos(0.07 * t), -0.5 + 0.05 * np.sin(0.05 * t))
    np.testing.assert_allclose(columns(out, "b"), quat_rotate(quat_conj(q), site_field_n(scn)), rtol=0,
                               atol=1e-13)


def test_tilt_compensated_heading_recovers_yaw():
    rng = np.random.default_rng(7)
    n = 2000
    pitch, roll = rng.uniform(-np.pi / 6, np.pi / 6, (2, n))
    yaw = rng.uniform(-np.pi, np.pi, n)
    c_bn = np.swapaxes(euler_to_mat(pitch, roll, yaw), -1, -2)
    el = field_elements(*SITE, DATE)
    # The site's field, and a strongly declined one (D = 20 deg east, I = 65 deg).
    dec, inc = np.radians(20.0), np.radians(65.0)
    other = 48e-6 * np.array([np.cos(inc) * np.sin(dec), np.cos(inc) * np.cos(dec), -np.sin(inc)])
    for b_n, d in ((earth_field_n(*SITE, DATE), el.declination), (other, dec)):
        b_b = c_bn @ b_n
        est = tilt_compensated_heading(b_b, pitch, roll, d)
        err = np.degrees(np.angle(np.exp(1j * (est - yaw))))
        assert np.abs(err).max() < 0.01
        assert np.all((est > -np.pi) & (est <= np.pi))
    # Scalar use, level: body axes on n read the field as it is (yaw 0); a field along the body y axis
    # puts that axis on magnetic north, yaw = -declination (heading = declination clockwise).
    h_n = np.array([np.sin(dec), np.cos(dec), 0.0])
    assert tilt_compensated_heading(h_n, 0.0, 0.0, dec) == pytest.approx(0.0, abs=1e-15)
    assert tilt_compensated_heading(np.array([0.0, 1.0, -0.5]), 0.0, 0.0, dec) == pytest.approx(-dec)


def test_hard_and_soft_iron_and_motor_field_appear_as_configured():
    soft = [[1.02, 0.01, 0.0], [0.03, 0.98, 0.02], [0.0, -0.01, 1.01]]  # not symmetric: rows matter
    hard = [2.0e-6, -1.0e-6, 0.5e-6]
    motor = [1.5e-6, 0.5e-6, -1.0e-6]
    scn = scenario({**QUIET_MAG, "soft_iron": soft, "hard_iron_t": hard, "motor_disturbance_t": motor})
    truth = shearer_truth()
    out = mag_stream(scn, truth, np.random.default_rng(0), [])
    q, idx = attitude(truth, out["t"])
    residual = columns(out, "b") - quat_rotate(quat_conj(q), site_field_n(scn)) @ np.array(soft).T - hard
    phase = truth["phase"][idx]
    k = np.select([phase == 1, phase == 2], [1.0, 18.0 / 8.0], 0.0)  # speed / cutting speed, 0 when stopped
    np.testing.assert_allclose(residual, k[:, None] * np.array(motor), rtol=0, atol=1e-17)
    assert (phase == 0).any() and (phase == 1).any() and (phase == 2).any()


def test_interference_fault_changes_the_stream_exactly_inside_its_window():
    truth = shearer_truth(duration=60.0)
    fault = {"kind": "mag_interference", "t_start_s": 10.0, "t_end_s": 30.0, "value": 2.0e-5}
    clean_scn = scenario()
    clean = columns(mag_stream(clean_scn, truth, np.random.default_rng(3), []), "b")
    # The targeted one belongs to support 3's canopy unit (a fault may only target a unit that exists).
    scn = scenario(support_imu={"supports": [3]}, faults=[fault, {**fault, "target": 3}])
    out = mag_stream(scn, truth, np.random.default_rng(3), scn.faults)
    diff = columns(out, "b") - clean
    inside = (out["t"] >= 10.0) & (out["t"] < 30.0)
    assert inside.sum() == 20 * 50
    assert np.all(diff[~inside] == 0.0)
    np.testing.assert_allclose(np.linalg.norm(diff[inside], axis=1), 2.0e-5, rtol=1e-9)
    np.testing.assert_allclose(diff[inside], np.broadcast_to(diff[inside][0], diff[inside].shape), atol=1e-18)


def test_noise_has_the_configured_deviation():
    truth = shearer_truth(duration=200.0, rate=50.0)
    scn = scenario({**QUIET_MAG, "noise_t": 1e-7})
    out = mag_stream(scn, truth, np.random.default_rng(4), [])
    q, _ = attitude(truth, out["t"])
    noise = columns(out, "b") - quat_rotate(quat_conj(q), site_field_n(scn))
    assert np.std(noise, axis=0) == pytest.approx([1e-7] * 3, rel=0.05)


def test_interference_directions_come_from_a_child_generator():
    """The directions are drawn from rng.spawn(1)[0] at construction: the noise is `rng`'s first draws, with or
    without faults."""
    truth = shearer_truth(duration=20.0)
    fault = {"kind": "mag_interference", "t_start_s": 5.0, "t_end_s": 8.0, "value": 2.0e-5}
    scn = scenario({**QUIET_MAG, "noise_t": 1e-7}, faults=[fault])
    out = mag_stream(scn, truth, np.random.default_rng(6))
    q, _ = attitude(truth, out["t"])
    noise = np.random.default_rng(6).normal(0.0, 1e-7, (out["t"].size, 3))
    u = np.random.default_rng(6).spawn(1)[0].normal(size=3)
    inside = ((out["t"] >= 5.0) & (out["t"] < 8.0))[:, None]
    expected = quat_rotate(quat_conj(q), site_field_n(scn)) + noise + inside * 2.0e-5 * u / np.linalg.norm(u)
    np.testing.assert_allclose(columns(out, "b"), expected, rtol=0, atol=1e-18)


MAG_FAULTS = [{"kind": "mag_interference", "t_start_s": 10.0, "t_end_s": 30.0, "value": 2.0e-5},
              {"kind": "mag_interference", "t_start_s": 25.013, "t_end_s": 61.3, "value": 1.0e-5}]


@pytest.mark.parametrize("rate", [50.0, 30.0])
@pytest.mark.parametrize("seed", range(3))
def test_magnetometer_over_random_partitions_is_the_whole_run(rate, seed):
    """Soft and hard iron, motor field, noise and two overlapping interference faults; at 30 Hz the samples fall
    between truth rows (interpolated from the halo)."""
    truth = shearer_truth()
    soft = [[1.02, 0.01, 0.0], [0.03, 0.98, 0.02], [0.0, -0.01, 1.01]]
    scn = scenario({"soft_iron": soft, "rate_hz": rate}, faults=MAG_FAULTS)
    halo = halo_rows(scn)
    whole = mag_stream(scn, truth, np.random.default_rng(8))
    chunks = list(split_truth(truth, random_starts(np.random.default_rng(seed), truth["t"].size, halo), halo))
    mag = Magnetometer(scn, np.random.default_rng(8))
    assert same(joined([mag.step(c) for c in chunks]), whole)
    # The comparison catches a stepper that does not carry its generator on (a Magnetometer per chunk).
    assert not same(joined([Magnetometer(scn, np.random.default_rng(8)).step(c) for c in chunks]), whole)


def test_magnetometer_over_random_partitions_of_a_simulated_run():
    scn, result = simulated("seed003_interference")
    truth = result.tables["truth_shearer"]
    halo = halo_rows(scn)
    edges = [t for f in scn.faults if f.kind == "mag_interference" for t in (f.t_start_s, f.t_end_s)]
    assert edges
    whole = mag_stream(scn, truth, np.random.default_rng(2))
    for seed in range(2):
        starts = random_starts(np.random.default_rng(seed), truth["t"].size, halo, np.searchsorted(truth["t"], edges))
        mag = Magnetometer(scn, np.random.default_rng(2))
        assert same(joined([mag.step(c) for c in split_truth(truth, starts, halo)]), whole)


# ------------------------------------------------------------------------------------------ support units

PAN = 1.75


def support_truth(scn, ids, advances=()):
    """truth_supports rows: every support in `ids` set at t = 0 on a level floor; then, for each
    (support, t_lower, t_set, advance, rise) in `advances`, a lowered row and a set row."""
    mat_tf = FaceFrame(np.radians(scn.face.azimuth_deg)).mat_tf
    state = {j: np.array([0.0, PAN * (j + 0.5), 0.2]) for j in ids}
    rows = [(0.0, j, state[j].copy(), 1) for j in ids]
    for j, t0, t1, adv, rise in advances:
        rows.append((t0, j, state[j].copy(), 0))
        state[j] = state[j] + [adv, 0.0, rise]
        rows.append((t1, j, state[j].copy(), 1))
    rows.sort(key=lambda r: (r[0], r[1]))
    p_f = np.array([r[2] for r in rows])
    p_t = p_f @ mat_tf.T
    is_set = np.array([r[3] for r in rows], np.int8)
    return {"t": np.array([r[0] for r in rows]), "support": np.array([r[1] for r in rows], np.int32),
            "p_t_e": p_t[:, 0], "p_t_n": p_t[:, 1], "p_t_u": p_t[:, 2], "advance": p_f[:, 0],
            "ram": np.full(len(rows), 1.2), "canopy": np.full(len(rows), 3.0),
            "set": is_set}


def passing_shearer(duration=240.0, rate=50.0, speed=0.4, s0=0.0):
    """A shearer running from arc length s0 along the face at constant speed."""
    t = np.arange(round(duration * rate) + 1) / rate
    q = np.broadcast_to(euler_to_quat(0.0, 0.0, -np.radians(30.0)), (t.size, 4))
    truth = {"t": t, "s": s0 + speed * t, "phase": np.ones(t.size, np.int8)}
    truth.update({f"q_nb_{a}": q[:, k] for k, a in enumerate("wxyz")})
    truth.update({f"v_n_{a}": np.zeros(t.size) for a in "enu"})
    return truth


def expected_static(scn, j):
    """(C_c^n, C_c^t) of a level, face-aligned canopy at support j's station."""
    mat_tf = FaceFrame(np.radians(scn.face.azimuth_deg)).mat_tf
    site = scn.site
    lat0, lon0 = np.radians(site.lat_deg), np.radians(site.lon_deg)
    p_t = mat_tf @ np.array([0.0, PAN * (j + 0.5), 0.2])
    lat, lon, h = earth.enu_to_lla(p_t, lat0, lon0, site.height_m)
    return earth.mat_nt(lat, lon, lat0, lon0) @ mat_tf, mat_tf, lat, h


def unit(out, j):
    m = out["support"] == j
    return out["t"][m], columns(out, "gyro")[m], columns(out, "accel")[m], columns(out, "mag")[m]


def test_support_units_at_rest_sense_gravity_earth_rate_and_earth_field():
    ids = [3, 20]
    scn = scenario({"noise_t": 0.0}, {"supports": ids, "grade": "ideal"})
    shearer = passing_shearer(duration=60.0, speed=0.0, s0=5.0)  # parked next to support 3
    truth = support_truth(scn, range(44))
    out = support_imu_stream(scn, truth, shearer, np.random.default_rng(0), [])
    check_table(SUPPORT_IMU, make_table(SUPPORT_IMU, out), "support_imu")
    assert out["t"].size == 2 * 3001 and np.all(out["support"][:2] == ids)
    w_ie_t = earth.earth_rate_n(np.radians(scn.site.lat_deg))
    for j in ids:
        c_cn, c_ct, lat, h = expected_static(scn, j)
        t, gyro, accel, mag = unit(out, j)
        np.testing.assert_allclose(quat_to_mat(canopy_attitude_n(scn, truth, j, t[:3])), [c_cn] * 3, atol=1e-15)
        np.testing.assert_allclose(accel, np.broadcast_to(-c_cn.T @ earth.gravity_n(lat, h), accel.shape),
                                   atol=1e-12)
        assert accel[0] == pytest.approx([0.0, 0.0, earth.normal_gravity(lat, h)], abs=1e-3)
        np.testing.assert_allclose(gyro, np.broadcast_to(c_ct.T @ w_ie_t, gyro.shape), atol=1e-18)
        near = abs(5.0 - PAN * (j + 0.5)) < DISTURBANCE_RANGE_PANS * PAN  # true for support 3 only
        assert near == (j == 3)
        b_c = c_cn.T @ site_field_n(scn)
        assert np.all(np.abs(mag - b_c).max(axis=1) > 0) if near else np.allclose(mag, b_c, rtol=0, atol=1e-18)

    # With a noisy grade the means stay on gravity and Earth rate within the noise.
    for grade, sensor, density in (("par4", 1, np.radians(1.0) / 60), ("par10", 2, 1e-3 * 9.80665)):
        scn = scenario({"noise_t": 0.0}, {"supports": [20], "grade": grade})
        out = support_imu_stream(scn, support_truth(scn, [20]), shearer, np.random.default_rng(1), [])
        c_cn, c_ct, lat, h = expected_static(scn, 20)
        ideal = (c_ct.T @ w_ie_t, -c_cn.T @ earth.gravity_n(lat, h))[sensor - 1]
        err = unit(out, 20)[sensor] - ideal
        sigma = density * np.sqrt(scn.sensors.support_imu.rate_hz)
        assert np.std(err, axis=0) == pytest.approx([sigma] * 3, rel=0.05)
        assert np.all(np.abs(err.mean(axis=0)) < 5 * sigma / np.sqrt(err.shape[0]))


def test_support_magnetometer_is_disturbed_only_while_the_shearer_is_near():
    j = 20
    scn = scenario({"noise_t": 0.0}, {"supports": [j], "grade": "ideal", "shearer_disturbance_t": 5e-6})
    shearer = passing_shearer()
    out = support_imu_stream(scn, support_truth(scn, [j]), shearer, np.random.default_rng(2), [])
    t, _, _, mag = unit(out, j)
    c_cn, _, _, _ = expected_static(scn, j)
    dist = np.linalg.norm(mag - c_cn.T @ site_field_n(scn), axis=1)
    d = np.interp(t, shearer["t"], shearer["s"]) - PAN * (j + 0.5)
    near = np.abs(d) < DISTURBANCE_RANGE_PANS * PAN
    assert near.any() and (~near).any()
    assert np.all(dist[~near] < 1e-18) and np.all(dist[near] > 0)
    assert dist.max() == pytest.approx(5e-6, rel=1e-3)
    assert np.abs(d[np.argmax(dist)]) < 0.01


def test_support_advance_moves_and_tilts_the_canopy_smoothly():
    j = 10
    # First advance over a floor rising 14 mm per 0.8 m (tilt -1 deg), the second falling as much (+1 deg).
    advances = [(j, 100.0, 112.0, 0.8, 0.8 * np.tan(np.radians(1.0))),
                (j, 200.0, 212.0, 0.8, -0.8 * np.tan(np.radians(1.0)))]
    scn = scenario({"noise_t": 0.0}, {"supports": [j], "grade": "ideal"})
    truth = support_truth(scn, [j], advances)
    rows = canopy_rows(scn, truth, j)
    np.testing.assert_allclose(np.degrees(rows.tilt), [-1, -1, -1, -1, 1], atol=1e-12)  # back-filled at t=0

    # Kinematics of the model: the unit starts and ends each advance at rest, moved by the advance.
    mat_tf = FaceFrame(np.radians(scn.face.azimuth_deg)).mat_tf
    for (_, t0, t1, adv, rise), (tilt0, tilt1) in zip(advances, np.radians([(-1.0, -1.0), (-1.0, 1.0)])):
        dtilt = tilt1 - tilt0
        t = np.linspace(t0, t1, 120001)
        mo = canopy_motion(scn, rows, t)
        assert np.trapezoid(mo.tilt_rate, t) == pytest.approx(dtilt, abs=1e-9)
        np.testing.assert_allclose(np.trapezoid(mo.a_t, t, axis=0), 0.0, atol=1e-9)
        np.testing.assert_allclose(np.trapezoid(mo.v_t, t, axis=0), mo.p_t[-1] - mo.p_t[0], atol=1e-9)
        # The base moves by the advance and rise; the unit 3 m up on the canopy also swings with the tilt.
        moved_f = [adv + 3.0 * (np.sin(tilt1) - np.sin(tilt0)), 0.0, rise + 3.0 * (np.cos(tilt1) - np.cos(tilt0))]
        np.testing.assert_allclose(mo.p_t[-1] - mo.p_t[0], mat_tf @ moved_f, atol=1e-12)
        np.testing.assert_allclose(mo.v_t[[0, -1]], 0.0, atol=1e-15)
        np.testing.assert_allclose(np.gradient(mo.v_t, t, axis=0)[1:-1], mo.a_t[1:-1], atol=1e-6)
        if dtilt == 0.0:  # no lever-arm motion: the smooth step's peak speed, forwards
            x_t = mat_tf[:, 0]
            assert mo.v_t[t.size // 2] @ x_t == pytest.approx(0.8 / 12 * 1.875, rel=1e-9)
            # Half way, the base has risen half the rise and the canopy is lowered by supports.lower_m.
            dz = mo.p_t[t.size // 2, 2] - mo.p_t[0, 2]
            assert dz == pytest.approx(rise / 2 - scn.supports.lower_m * np.cos(tilt0), abs=1e-12)
        # The canopy dips by the lowering while moving: the vertical velocity changes sign.
        assert (mo.v_t[:, 2] < 0).any() and (mo.v_t[:, 2] > 0).any()

    # The stream: the gyro's y axis integrates to the tilt change, and the rates stay small.
    shearer = passing_shearer(duration=300.0, speed=0.0)
    out = support_imu_stream(scn, truth, shearer, np.random.default_rng(5), [])
    t, gyro, accel, _ = unit(out, j)
    w_ie = np.linalg.norm(earth.earth_rate_n(np.radians(scn.site.lat_deg)))
    assert np.abs(gyro).max() < 0.01
    sel = (t >= 200.0) & (t <= 212.0)
    assert np.trapezoid(gyro[sel, 1], t[sel]) == pytest.approx(np.radians(2.0), abs=12 * w_ie + 1e-6)
    before = accel[t < 100.0][0]
    after = accel[t > 300.0 - 1][0]
    assert np.degrees(np.arctan2(before[0], before[2])) == pytest.approx(1.0, abs=1e-3)  # x down the rise
    assert np.degrees(np.arctan2(after[0], after[2])) == pytest.approx(-1.0, abs=1e-3)


def test_targeted_interference_acts_on_its_support_unit_only_inside_the_window():
    ids = [5, 6]
    fault = {"kind": "mag_interference", "t_start_s": 10.0, "t_end_s": 30.0, "value": 3e-5, "target": 5}
    shearer = passing_shearer(duration=60.0, speed=0.0)
    clean_scn = scenario(None, {"supports": ids, "grade": "icm-42605"})
    scn = scenario(None, {"supports": ids, "grade": "icm-42605"}, [fault])
    clean = support_imu_stream(clean_scn, support_truth(scn, ids), shearer, np.random.default_rng(9), [])
    out = support_imu_stream(scn, support_truth(scn, ids), shearer, np.random.default_rng(9), scn.faults)
    for key in out:
        if not key.startswith("mag"):
            np.testing.assert_array_equal(out[key], clean[key])
    diff = columns(out, "mag") - columns(clean, "mag")
    hit = (out["support"] == 5) & (out["t"] >= 10.0) & (out["t"] < 30.0)
    assert np.all(diff[~hit] == 0.0)
    np.testing.assert_allclose(np.linalg.norm(diff[hit], axis=1), 3e-5, rtol=1e-9)


def test_streams_are_reproducible_from_the_seed():
    truth = shearer_truth(duration=30.0)
    scn = scenario(None, {"supports": [4], "grade": "icm-42605"})
    a = mag_stream(scn, truth, np.random.default_rng(11))
    b = mag_stream(scn, truth, np.random.default_rng(11))
    c = mag_stream(scn, truth, np.random.default_rng(12))
    assert all(np.array_equal(a[k], b[k]) for k in a) and not np.array_equal(a["b_x"], c["b_x"])
    sup = support_truth(scn, [4])
    shearer = passing_shearer(duration=30.0)
    s1 = support_imu_stream(scn, sup, shearer, np.random.default_rng(11))
    s2 = support_imu_stream(scn, sup, shearer, np.random.default_rng(11))
    assert all(np.array_equal(s1[k], s2[k]) for k in s1)
