"""Ideal shearer-IMU increments: exact round trip through a mechanization, closed-form coning, vibration."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from estimators.nav import earth
from estimators.nav.rotations import (
    mat_to_quat,
    quat_conj,
    quat_mul,
    quat_rotate,
    quat_to_mat,
    quat_to_rotvec,
)
from estimators.sins.strapdown import mechanize
from tests.conftest import simulated
from twin.config.scenario import parse_scenario
from twin.papers.motions import coning, coning_increments_closed_form, sculling
from twin.sensors import imu
from twin.sensors.chunks import halo_rows, split_truth
from twin.sensors.imu import (
    IdealImu,
    ideal_increments,
    mounting_matrix,
    sensor_increments,
    time_derivative,
)
from twin.sensors.vibration import (
    COAL,
    ENVELOPE_S,
    IDLE,
    VIBRATION_STREAM,
    machine_state,
    state_envelope,
    vibration_tones,
)

ARCSEC = np.radians(1.0 / 3600)


@pytest.mark.parametrize("n_samples", [2, 4])
def test_error_free_imu_reproduces_the_truth_through_a_mechanization(n_samples):
    """30 min of shearer motion on a bent, undulating face, lever arm and misalignment included, no errors,
    no vibration: horizontal <= 1 cm, vertical <= 10 cm, attitude <= 2 arcsec (issue 3)."""
    scn, res = simulated("default")
    sh = res.tables["truth_shearer"]
    n = int(1800 * scn.rates.truth_hz) + 1
    inc = ideal_increments(scn, sh, np.random.default_rng(0), vibration=False)
    dtheta = np.column_stack([inc[f"dtheta_{a}"] for a in "xyz"])[:n]
    dv = np.column_stack([inc[f"dv_{a}"] for a in "xyz"])[:n]
    lat0, lon0, h0 = np.radians(scn.site.lat_deg), np.radians(scn.site.lon_deg), scn.site.height_m
    # The sensor: at the lever arm, axes turned by the mounting misalignment.
    q_nb = np.column_stack([sh[f"q_nb_{a}"] for a in "wxyz"])[:n]
    q_bs = mat_to_quat(mounting_matrix(scn.sensors.imu.misalignment_deg))
    q_ns = quat_mul(q_nb, np.broadcast_to(q_bs, q_nb.shape))
    mat_tn = np.swapaxes(earth.mat_nt(sh["lat"][:n], sh["lon"][:n], lat0, lon0), -1, -2)
    p_t = np.column_stack([sh[f"p_t_{a}"] for a in "enu"])[:n]
    p_imu_t = p_t + np.einsum("kij,kjl,l->ki", mat_tn, quat_to_mat(q_nb), np.asarray(scn.sensors.imu.lever_arm_m))
    lat_s, lon_s, h_s = earth.enu_to_lla(p_imu_t[:1], lat0, lon0, h0)
    assert np.linalg.norm(np.column_stack([sh[f"v_n_{a}"] for a in "enu"])[0]) < 1e-9  # starts at rest
    # The sensor's attitude in its own local-level frame: the verticals differ by lever arm / Earth radius.
    q_nn = quat_mul(quat_conj(earth.quat_en(lat_s[0], lon_s[0])), earth.quat_en(sh["lat"][0], sh["lon"][0]))
    nav = mechanize(sh["t"][:n], dtheta, dv, lat_s[0], lon_s[0], h_s[0], np.zeros(3), quat_mul(q_nn, q_ns[0]),
                    n_samples=n_samples)
    p_imu_t, q_ns = p_imu_t[::n_samples][: nav.t.size], q_ns[::n_samples][: nav.t.size]
    err = earth.lla_to_enu(nav.lat, nav.lon, nav.h, lat0, lon0, h0) - p_imu_t
    assert np.hypot(err[:, 0], err[:, 1]).max() <= 0.01
    assert np.abs(err[:, 2]).max() <= 0.10
    att = np.linalg.norm(quat_to_rotvec(quat_mul(quat_conj(q_ns), nav.q_nb)), axis=1)
    assert att.max() <= 2 * ARCSEC
    # Without the lever arm the same increments put the body, not the sensor, 0.5 m off: the test can fail.
    assert np.linalg.norm(p_imu_t[0] - p_t[0]) > 0.3


def test_coning_preset_matches_the_closed_form():
    """000 eq. 55 with the Earth rate off: increments equal eq. 61 (axes permuted) to 1e-12 rad."""
    alpha, psi = np.radians(1.0), 2 * np.pi
    t, dtheta, _ = coning(alpha, psi, dt=0.01, duration_s=40.0, earth_rate=False)
    np.testing.assert_allclose(dtheta, coning_increments_closed_form(t, alpha, psi), rtol=0, atol=1e-12)
    # The coning drift: a constant rate -2 psi sin^2(alpha/2) on x that a naive sum of rates keeps.
    assert np.isclose(dtheta[1:, 0].sum() / t[-1], -2 * psi * np.sin(alpha / 2) ** 2, rtol=1e-9)


def test_sculling_preset_gyro_and_accelerometer():
    freq, b, c = 1.0, np.radians(0.1), 0.01 * 9.80665
    t, dtheta, dv = sculling(freq, b, c, dt=0.006, duration_s=30.0)
    om = 2 * np.pi * freq
    np.testing.assert_allclose(dtheta[1:, 0], b * (np.sin(om * t[1:]) - np.sin(om * t[:-1])), atol=1e-15)
    assert np.abs(dtheta[:, 1:]).max() == 0.0
    # Specific force C sin(Omega t) along y, turned into z by the angular vibration (second order in B).
    dv_y = -c / om * (np.cos(om * t[1:]) - np.cos(om * t[:-1]))
    np.testing.assert_allclose(dv[1:, 1], dv_y, atol=2 * b ** 2 * c * 0.006)
    assert 0 < np.abs(dv[1:, 2]).max() <= 1.1 * b * c * 0.006


def test_vibration_amplitudes_follow_the_machine_state():
    """A body at rest vibrating as when cutting coal: gyro and accelerometer RMS as configured."""
    scn, _ = simulated("default")
    cfg = scn.sensors.vibration.cutting_coal
    rng = np.random.default_rng(1)
    tones = vibration_tones([scn.sensors.vibration.idle, cfg, scn.sensors.vibration.cutting_rock], rng)
    dt = 1 / 200
    t = np.arange(0, 60, dt)
    zeros = np.zeros((t.size, 3))
    amp = np.zeros((t.size, 3))
    amp[:, COAL] = 1.0
    dtheta, dv = sensor_increments(t, zeros, zeros, amp, tones, np.zeros(3), np.eye(3))
    # The pick band carries the configured RMS; the drum tone adds its own (amplitude x omega / sqrt 2).
    w_drum, w_pick = 2 * np.pi * np.array([cfg.drum_hz, cfg.pick_hz])
    rate_rms = np.sqrt(np.mean((dtheta[1:] / dt) ** 2, axis=0))
    want_rate = np.hypot(np.radians(cfg.angular_rms_deg_s), w_drum * np.radians(cfg.drum_angle_deg) / np.sqrt(2))
    np.testing.assert_allclose(rate_rms, want_rate, rtol=0.1)
    # Picks at 30 Hz are sampled at 200 Hz: the mean over an interval keeps sinc(f dt) of the amplitude.
    acc_rms = np.sqrt(np.mean((dv[1:] / dt) ** 2, axis=0))
    kept_pick = np.sinc(w_pick * dt / 2 / np.pi)
    want_acc = np.hypot(cfg.accel_rms_g * 9.80665 * kept_pick, w_drum ** 2 * cfg.drum_displacement_mm * 1e-3 / np.sqrt(2))
    np.testing.assert_allclose(acc_rms, want_acc, rtol=0.1)


def test_switching_vibration_on_and_off_leaves_no_velocity_behind():
    """The vibration is a motion of the sensor about its mount: whatever the machine state does, the sensor's
    velocity relative to the body stays zero-mean and returns to zero (no drift for the SINS to integrate)."""
    scn, _ = simulated("default")
    vib = scn.sensors.vibration
    tones = vibration_tones([vib.idle, vib.cutting_coal, vib.cutting_rock], np.random.default_rng(2))
    # Linear vibration alone: with the angular part the sensor frame turns and sculling (real, compensated by
    # the SINS) adds its own mean.
    tones = dataclasses.replace(tones, ang_amp=np.zeros_like(tones.ang_amp))
    dt = 1 / 200
    t = np.arange(0, 30, dt)
    state = np.where((t > 5) & (t < 20), COAL, IDLE)
    zeros = np.zeros((t.size, 3))
    _, dv = sensor_increments(t, zeros, zeros, state_envelope(state, 1 / dt), tones, np.zeros(3), np.eye(3))
    v = np.cumsum(dv, axis=0)  # relative to the (vibrating) start: a constant offset, the same before and after
    before, cutting, after = (v[(t > a) & (t < b)].mean(axis=0) for a, b in ((1, 5), (8, 18), (23, 29)))
    # A drum tone's velocity amplitude is ~4e-3 m/s; a switch that ignored the envelope's slope shifts the mean.
    assert np.abs(cutting - before).max() < 2e-4
    assert np.abs(after - before).max() < 2e-4


# ---------------------------------------------------------------------------------------------------------
# The IMU of a streaming run (issue 24): chunk by chunk as one chunk


def _vibrating_start(imu_hz: float) -> tuple:
    """The default run's first 30 s (idle, then cutting coal from 10 s: the envelope rises inside it) with the
    shearer IMU at imu_hz, vibration on."""
    scn, res = simulated("default")
    data = scn.model_dump()
    data["sensors"]["imu"]["rate_hz"] = imu_hz
    scn = parse_scenario(data, "default")
    truth = {k: v[:6000] for k, v in res.tables["truth_shearer"].items()}
    state = machine_state(scn, truth["phase"], truth["s"])
    assert scn.sensors.vibration.enabled and scn.rates.truth_hz == 200.0 and IDLE in state and COAL in state
    return scn, truth


def _stream(scn, truth, starts, halo) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IdealImu over the truth cut at the rows `starts`, each chunk's samples checked to be its own."""
    ideal = IdealImu(scn)
    out = []
    for chunk in split_truth(truth, starts, halo):
        out.append(ideal.step(chunk))
        assert chunk.owns(out[-1][0]).all()
    return tuple(np.concatenate([o[i] for o in out]) for i in range(3))


def _partitions(n: int, group: int, halo: int, rng: np.random.Generator):
    """Random chunk starts: some long chunks, runs of chunks shorter than the halo (down to one row), the run's
    start row alone, and cuts inside an IMU sample's group of truth intervals."""
    yield [1, 2, 3, 2000]
    for _ in range(4):
        cuts = rng.choice(np.arange(1, n), 6, replace=False)
        short = cuts[:3, None] + np.cumsum(rng.integers(1, halo // 3, (3, 4)), axis=1)
        yield np.concatenate([cuts, short.ravel(), [group * 7 + 2, group * 300 + group - 1]])


@pytest.mark.parametrize("imu_hz", [200.0, 40.0])
def test_ideal_imu_over_any_partition_equals_one_chunk(imu_hz):
    scn, truth = _vibrating_start(imu_hz)
    halo = halo_rows(scn)
    t, dtheta, dv = _stream(scn, truth, [], halo)
    group = int(scn.rates.truth_hz / imu_hz)
    assert t.size == (truth["t"].size - 1) // group and t[0] == truth["t"][group]
    for starts in _partitions(truth["t"].size, group, halo, np.random.default_rng(24)):
        for whole, parts in zip((t, dtheta, dv), _stream(scn, truth, starts, halo)):
            np.testing.assert_array_equal(parts, whole)


def _float_envelope(state, t, n_states=3):
    """state_envelope before issue 24: a float kernel, its width from the samples' median step."""
    amp = np.zeros((t.size, n_states))
    amp[np.arange(t.size), state] = 1.0
    width = max(1, int(0.5 / np.median(np.diff(t))))
    kernel = np.convolve(np.ones(width), np.ones(width)) / width ** 2
    return np.column_stack([np.convolve(amp[:, j], kernel, mode="same") for j in range(n_states)])


def _imu_truth_before_issue_24(scn, truth):
    """twin.sensors.streams.imu_truth before issue 24 (its start row dropped): the whole run's increments at the
    truth rate, summed to the IMU rate."""
    inc = ideal_increments(scn, truth, np.random.default_rng([scn.seed, VIBRATION_STREAM]))
    step = round(scn.rates.truth_hz / scn.sensors.imu.rate_hz)
    dtheta = np.column_stack([inc[f"dtheta_{a}"] for a in "xyz"])
    dv = np.column_stack([inc[f"dv_{a}"] for a in "xyz"])
    if step > 1:
        n = (dtheta.shape[0] - 1) // step
        dtheta = np.concatenate([dtheta[:1], dtheta[1:1 + n * step].reshape(n, step, 3).sum(axis=1)])
        dv = np.concatenate([dv[:1], dv[1:1 + n * step].reshape(n, step, 3).sum(axis=1)])
    t = inc["t"][::step][: dtheta.shape[0]]
    return t[1:], dtheta[1:], dv[1:]


@pytest.mark.parametrize("imu_hz", [200.0, 40.0])
def test_ideal_imu_in_one_chunk_is_the_former_imu_truth(imu_hz, monkeypatch):
    """The same numbers as before the run streamed, but for the envelope's integer convolution: with the former
    float envelope bit for bit; with the new one the envelope (100 samples wide at 200 Hz, as the median step gave)
    moves by its last bit, its slope (a difference over 5 ms) by ~1e-14 /s, and the increments by < 1e-12 of their
    largest."""
    scn, truth = _vibrating_start(imu_hz)
    t = truth["t"]
    state = machine_state(scn, truth["phase"], truth["s"])
    old_env, new_env = _float_envelope(state, t), state_envelope(state, scn.rates.truth_hz)
    assert np.abs(new_env - old_env).max() <= 1e-15
    assert int(ENVELOPE_S * scn.rates.truth_hz) == 100 == int(0.5 / np.median(np.diff(t)))
    # np.gradient's formulas for uneven steps, which it uses on the truth times.
    w = np.column_stack([truth[f"w_ib_b_{a}"] for a in "xyz"])
    for order in (1, 2):
        np.testing.assert_array_equal(time_derivative(w, t, order), np.gradient(w, t, axis=0, edge_order=order))

    now = _stream(scn, truth, [], halo_rows(scn))
    with monkeypatch.context() as m:
        m.setattr(imu, "state_envelope", lambda s, rate_hz: _float_envelope(s, t))
        before = _imu_truth_before_issue_24(scn, truth)
        for a, b in zip(_stream(scn, truth, [], halo_rows(scn)), before):
            np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(now[0], before[0])
    for a, b in zip(now[1:], before[1:]):
        assert np.abs(a - b).max() <= 1e-12 * np.abs(b).max()


def test_partition_needs_the_halo():
    """A chunk reads width + 1 truth rows before it (the envelope's triangle reaches width - 1 rows, its slope
    and the interval one more each) and width after: with that halo a partition gives the one chunk's numbers,
    with one row less, or a halo of 1, it does not. halo_rows (HALO_S = 1 s) has twice the reach."""
    scn, truth = _vibrating_start(200.0)
    width = int(ENVELOPE_S * scn.rates.truth_hz)
    assert halo_rows(scn) >= 2 * (width + 1)
    whole = _stream(scn, truth, [], halo_rows(scn))
    starts = [700, 1500, 1990, 2010, 2100, 2300, 4000]
    for halo, same in ((width + 1, True), (width, False), (1, False)):
        parts = _stream(scn, truth, starts, halo)
        assert all(np.array_equal(a, b) for a, b in zip(parts, whole)) == same, halo


def test_gravity_at_the_lever_arm_is_the_normal_field_at_the_displaced_point():
    """gravity_at_lever_arm_b against an independent form: the normal gravity vector at the sensor's own position
    (the body point displaced by C_b^n r, through ECEF) turned into the body point's ENU axes, minus the body
    point's, in b. They differ by gamma's change with latitude over d_N, which the twin leaves out (d gamma / d lat
    <= 0.0518 m/s^2 per rad over R_M >= 6.335e6 m: 8.2e-9 s^-2 per metre north), and second-order terms,
    (r / R)^2 g ~ 1e-13 m/s^2."""
    rng = np.random.default_rng(8)
    n = 200
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    lat, lon, h = rng.uniform(-1.2, 1.2, n), rng.uniform(-3, 3, n), rng.uniform(-500, 2000, n)
    lever_b = np.array([0.8, -2.5, 1.3])
    cols = {"lat": lat, "h": h, **{f"q_nb_{c}": q[:, i] for i, c in enumerate("wxyz")}}
    d_n = quat_rotate(q, np.broadcast_to(lever_b, (n, 3)))
    lat_s, lon_s, h_s = earth.enu_to_lla(d_n, lat, lon, h)
    up_s = earth.mat_en(lat_s, lon_s)[:, :, 2]  # the sensor's up in ECEF
    g_s_n = np.einsum("kji,kj->ki", earth.mat_en(lat, lon), -earth.normal_gravity(lat_s, h_s)[:, None] * up_s)
    dg_n = g_s_n - earth.gravity_n(lat, h)
    expected = quat_rotate(quat_conj(q), dg_n)
    got = imu.gravity_at_lever_arm_b(cols, lever_b)
    assert np.abs(expected).max() > 1e-6  # the effect itself: a few 1e-6 m/s^2 per metre
    bound = 8.2e-9 * np.abs(d_n[:, 1]) + 1e-12
    assert np.all(np.linalg.norm(got - expected, axis=1) <= bound)
    assert np.linalg.norm(got - expected, axis=1).max() > 0.3 * bound.max()  # the term left out, and no more


def test_state_envelope_is_the_integer_triangle_convolution_bit_for_bit():
    """The running sums give np.convolve's integer triangle (1, 2, .., width, .., 2, 1) in mode "same", exactly, for
    arrays shorter and longer than the triangle."""
    rng = np.random.default_rng(21)
    for n, rate_hz in ((1, 200.0), (7, 200.0), (150, 200.0), (999, 1.0), (5000, 200.0)):
        state = np.repeat(rng.integers(0, 3, n // 40 + 1), 40)[:n]
        width = max(1, int(ENVELOPE_S * rate_hz))
        triangle = np.convolve(np.ones(width, np.int64), np.ones(width, np.int64))
        onehot = (state[:, None] == np.arange(3)).astype(np.int64)
        expected = np.column_stack([np.convolve(onehot[:, j], triangle)[width - 1:width - 1 + n]
                                    for j in range(3)]) / width ** 2
        assert np.array_equal(state_envelope(state, rate_hz), expected)
