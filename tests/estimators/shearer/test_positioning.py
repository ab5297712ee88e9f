"""The 001 shearer positioning: the filter kernel on a standing IMU, and the whole chain on a simulated face."""

import dataclasses
import tracemalloc

import numpy as np
import pytest

from estimators.io.log import ImuArrays, log_from_columns
from estimators.io.logformat import FLAG_POSITION, FLAG_SKIPPED, FLAG_VELOCITY, FLAG_ZUPT
from estimators.kalman import error_state as es
from estimators.kalman import rts
from estimators.nav import earth
from estimators.nav.rotations import (
    euler_to_quat,
    quat_conj,
    quat_mul,
    quat_rotate,
    quat_to_rotvec,
)
from estimators.shearer import odometer_filter as kf
from estimators.shearer.config import PositioningError
from estimators.shearer.methods import METHODS, estimate
from estimators.shearer.positioning import initial_covariance, run_kf
from estimators.shearer.prepare import prepare
from estimators.shearer.solution import estimate_columns
from tests.conftest import simulated
from twin.pipeline.estimate import positioning_config
from twin.sensors.streams import imu_truth, sensor_streams

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

DEG_H = np.pi / 180 / 3600


def test_standing_filter_finds_the_gyro_bias_and_leaves_the_heading_alone():
    """At rest the zero-rate update makes the gyro bias observable (a MEMS heading would drift 0.3 deg/s
    otherwise); the heading itself is not (no gyrocompassing with such a gyro): it must not move."""
    lat, h = np.radians(34.0), 100.0
    q = euler_to_quat(0.01, 0.02, 0.3)
    bias = np.array([600.0, -1400.0, 1170.0]) * DEG_H
    w_b = quat_rotate(quat_conj(q), earth.earth_rate_n(lat)) + bias
    f_b = quat_rotate(quat_conj(q), np.array([0, 0, earth.normal_gravity(lat, h)]))
    steps, n_kf, dt = 5, 100, 0.02
    t_mech = np.arange(n_kf * steps + 1) * dt
    phi_b, dv_b = np.tile(w_b * dt, (n_kf * steps, 1)), np.tile(f_b * dt, (n_kf * steps, 1))
    nav = np.zeros(es.N_NAV)
    nav[:3] = lat, 0.0, h
    q0 = euler_to_quat(0.015, 0.015, 0.32)
    nav[kf.QUAT] = q0
    sd = np.array([0.01] * 3 + [0.005, 0.005, 0.02] + [0.05] * 3 + [720 * DEG_H] * 3 + [1e-4] * 3 + [0.02] * 3 +
                  [0.01] + [1e-6] * 3)
    p = np.diag(sd ** 2)
    params = np.zeros(kf.N_PARAMS)
    params[:7] = [0.01, 0.01, 0.01, 0.002, 5e-4, 1.0, 2.0]
    z = np.zeros
    out_nav, out_cal = z((n_kf + 1, es.N_NAV)), z((n_kf + 1, es.N_CAL))
    store = [z((n_kf + 1, kf.N_STATES))] + [z((n_kf + 1, kf.N_STATES, kf.N_STATES)) for _ in range(3)]
    flags = np.zeros(n_kf + 1, np.int32)
    cal = z(es.N_CAL)
    kf.run_filter(0, n_kf, 0, steps, t_mech, phi_b, dv_b, z(n_kf + 1), np.zeros(n_kf + 1, np.int8),
                  np.zeros(0, np.int64), z((0, 3)), z((0, 3, 3)), z(0), np.full(kf.N_STATES, 1e-12), params, nav, cal, p, z(es.N_NOMINAL),
                  out_nav, out_cal, *store, flags, z(0), z((n_kf + 1, 3)))
    assert np.all(flags[1:] & FLAG_ZUPT)
    assert np.abs(cal[kf.CAL_GYRO] - bias).max() < 10 * DEG_H
    # Level converges to the truth (an accelerometer known to 10 ug: level and accel bias are one at rest),
    # the heading keeps its initial error (0.02 rad).
    err = quat_to_rotvec(quat_mul(q, quat_conj(nav[kf.QUAT])))
    assert np.abs(err[:2]).max() < np.radians(0.01)
    err0 = quat_to_rotvec(quat_mul(q, quat_conj(q0)))
    assert abs(err[2] - err0[2]) < np.radians(0.01) and abs(err0[2]) > np.radians(1.0)


def test_standing_machine_tone_locked_to_the_epochs_does_not_move_the_position():
    """A standing IMU shaken by a 30 Hz tone (1 mm/s velocity amplitude along x and up): three periods per 0.1 s
    epoch, so every epoch ends at the same phase of it. The zero-velocity update of the epoch's mean velocity
    holds the position (an update of the epoch-end velocity moved it 0.06 m over these 100 s)."""
    lat, h = np.radians(34.0), 100.0
    q = euler_to_quat(0.01, 0.02, 0.3)
    w_b = quat_rotate(quat_conj(q), earth.earth_rate_n(lat))
    f_b = quat_rotate(quat_conj(q), np.array([0, 0, earth.normal_gravity(lat, h)]))
    steps, n_kf, dt = 5, 1000, 0.02
    t_mech = np.arange(n_kf * steps + 1) * dt
    v_tone = 1e-3 * np.sin(2 * np.pi * 30.0 * t_mech + 0.7)[:, None] * np.array([1.0, 0.0, 1.0])
    phi_b, dv_b = np.tile(w_b * dt, (n_kf * steps, 1)), np.tile(f_b * dt, (n_kf * steps, 1)) + np.diff(v_tone, axis=0)
    nav = np.zeros(es.N_NAV)
    nav[:3] = lat, 0.0, h
    nav[kf.QUAT] = q
    nav[kf.VEL] = quat_rotate(q, v_tone[0])
    sd = np.array([0.01] * 3 + [1e-4] * 3 + [0.05] * 3 + [1 * DEG_H] * 3 + [1e-4] * 3 + [0.02] * 3 + [0.01] +
                  [1e-6] * 3)
    params = np.zeros(kf.N_PARAMS)
    params[:7] = [0.01, 0.01, 0.01, 0.002, 5e-4, 1.0, 2.0]
    z = np.zeros
    out_nav = z((n_kf + 1, es.N_NAV))
    store = [z((n_kf + 1, kf.N_STATES))] + [z((n_kf + 1, kf.N_STATES, kf.N_STATES)) for _ in range(3)]
    kf.run_filter(0, n_kf, 0, steps, t_mech, phi_b, dv_b, z(n_kf + 1), np.zeros(n_kf + 1, np.int8),
                  np.zeros(0, np.int64), z((0, 3)), z((0, 3, 3)), z(0), np.full(kf.N_STATES, 1e-12), params, nav,
                  z(es.N_CAL), np.diag(sd ** 2), z(es.N_NOMINAL), out_nav, z((n_kf + 1, es.N_CAL)), *store,
                  np.zeros(n_kf + 1, np.int32), z(0), z((n_kf + 1, 3)))
    r_m, r_n = earth.radii(lat)
    moved = np.array([out_nav[-1, kf.LON] * (r_n + h) * np.cos(lat), (out_nav[-1, kf.LAT] - lat) * (r_m + h),
                      out_nav[-1, kf.HGT] - h])
    assert np.abs(moved).max() < 0.01, moved


@pytest.fixture(scope="module")
def default_log():
    scn, result = simulated("default")
    streams = sensor_streams(scn, result.tables, imu_truth(scn, result.tables["truth_shearer"]), 0)
    log = log_from_columns(streams["imu"], streams["odometer"], streams["survey"], streams["pushram"],
                           streams["mag"])
    return scn, log


def test_every_method_runs_on_a_simulated_face_without_nan(default_log):
    scn, log = default_log
    sols = estimate(log, positioning_config(scn))
    assert set(sols) == set(METHODS)
    for name, sol in sols.items():
        assert np.isfinite(sol.llh).all() and np.isfinite(sol.q_nb).all(), name
    flags = sols["kf"].flags
    assert (flags & FLAG_ZUPT).any() and (flags & FLAG_VELOCITY).any()


def test_level_prior_is_the_accelerometer_error_so_a_stand_learns_no_bias(default_log):
    """P0 ties the start level to the accelerometer bias and non-orthogonality the way the filter's own F does
    at rest (no horizontal velocity drift from the pair), so conditioning on what a stand's zero-velocity
    updates see, the drift f_n x phi + C_b^n e, leaves the bias variance as it was. A diagonal P0 (001 Appendix
    A) turns the level prior into across-face bias information."""
    scn, log = default_log
    cfg = positioning_config(scn)
    q_nb0 = euler_to_quat(0.03, -0.02, 1.1)
    nav = np.zeros(es.N_NAV)
    nav[:3] = log.survey_llh[0]
    nav[kf.QUAT] = q_nb0
    g = earth.normal_gravity(log.survey_llh[0, 0], log.survey_llh[0, 2])
    drift = kf.system_matrix(nav, np.array([0.0, 0.0, g]))[kf.DV][:2]
    bias_var = {}
    for correlated in (True, False):
        p0 = initial_covariance(dataclasses.replace(cfg, level_from_accelerometers=correlated), log, q_nb0)
        if correlated:
            cols = np.r_[kf.ACCEL_BIAS, kf.ACCEL_NONORTH]
            tied = drift @ p0[:, cols]  # covariance of the drift with the accelerometer errors
            assert np.abs(tied).max() < 1e-12 * np.abs(drift @ p0 @ drift.T).max()
        cross = p0 @ drift.T
        posterior = p0 - cross @ np.linalg.solve(drift @ p0 @ drift.T, cross.T)
        bias_var[correlated] = np.diag(posterior)[kf.ACCEL_BIAS] / np.diag(p0)[kf.ACCEL_BIAS]
    assert np.allclose(bias_var[True], 1.0, atol=1e-9), bias_var
    assert bias_var[False].min() < 0.9, bias_var


def test_odometer_dropout_is_skipped_and_flagged(default_log):
    scn, log = default_log
    keep = (log.odo_t < 100.0) | (log.odo_t > 110.0)
    cut = dataclasses.replace(log, odo_t=log.odo_t[keep], odo_distance=log.odo_distance[keep],
                              odo_direction=log.odo_direction[keep])
    sol = estimate(cut, positioning_config(scn), ("kf",))["kf"]
    gap = (sol.t > 100.5) & (sol.t < 109.5)
    assert np.all(sol.flags[gap] & FLAG_SKIPPED) and np.isfinite(sol.llh).all()
    assert any("odometer: no data" in n for n in sol.notes)


@pytest.mark.parametrize("change, words", [
    ({"survey_t": np.zeros(0), "survey_llh": np.zeros((0, 3)), "survey_yaw": np.zeros(0), "survey_sd": np.zeros((0, 3))},
     "survey: no rows"),
    ({"survey_yaw": np.array([np.nan, np.nan])}, "start heading"),
])
def test_unusable_log_is_one_clear_line(default_log, change, words):
    scn, log = default_log
    with pytest.raises(PositioningError, match=words) as err:
        estimate(dataclasses.replace(log, **change), positioning_config(scn), ("kf",))
    assert "\n" not in str(err.value)


def test_nan_increment_names_the_row(default_log):
    scn, log = default_log
    dtheta = log.dtheta.copy()
    dtheta[1234, 1] = np.nan
    with pytest.raises(PositioningError, match=r"imu: dtheta row 1234 is not finite"):
        estimate(dataclasses.replace(log, imu=ImuArrays(log.imu_t, dtheta, log.dv)), positioning_config(scn), ("kf",))


def test_true_mounting_is_in_the_frame_the_filter_estimates_it_in():
    """The machine moves along its body y, so the motion constraints see only the IMU's uncalibrated yaw mounting
    (the filter is given the pitch and roll mounting): the truth is (0, 0, -m_z) whatever the encoder's axis."""
    import math

    from twin.config.scenario import load_scenario
    from twin.pipeline.estimate import true_states

    scn = load_scenario("scenarios/default.toml")
    sensors = scn.sensors.model_copy(update={
        "imu": scn.sensors.imu.model_copy(update={"misalignment_deg": [0.3, -0.2, 0.5]}),
        "odometer": scn.sensors.odometer.model_copy(update={"mounting_deg": [0.2, 0.0, -0.3]})})
    truth = true_states(scn.model_copy(update={"sensors": sensors}))
    assert [math.degrees(truth[f"odo_mount_{a}"]) for a in "xyz"] == pytest.approx([0.0, 0.0, -0.5], abs=1e-9)


def test_machine_vibration_does_not_turn_the_heading():
    """An error-free IMU on the cutting shearer of seed001, with its drum and pick vibration: the heading must stay
    well inside the filter's own one-sigma (0.5 deg rms against 2.0 claimed over these two cycles). With F at the
    step's specific force (a 0.1 s low-pass), the drum's velocity in the innovations and its acceleration in F
    rectify into a heading drift well past that."""
    from estimators.io import metrics

    scn, result = simulated("seed001")
    ideal_scn = scn.model_copy(update={"sensors": scn.sensors.model_copy(update={
        "imu": scn.sensors.imu.model_copy(update={"grade": "ideal", "misalignment_deg": [0.0] * 3})})})
    truth = result.tables["truth_shearer"]
    streams = sensor_streams(ideal_scn, result.tables, imu_truth(ideal_scn, truth), 0)
    log = log_from_columns(streams["imu"], streams["odometer"], streams["survey"], streams["pushram"])
    cfg = dataclasses.replace(positioning_config(scn), imu_mounting_rad=(0.0, 0.0, 0.0))
    ratio = {}
    for tau in (cfg.force_tau_s, 0.1):
        sol = estimate(log, dataclasses.replace(cfg, force_tau_s=tau), ("kf",))["kf"]
        _, att = metrics.attitude_errors(estimate_columns(sol), truth)
        ratio[tau] = np.sqrt(np.mean(att[1:, 2] ** 2)) / np.sqrt(np.mean(sol.sd[1:, 8] ** 2))
    assert ratio[cfg.force_tau_s] < 0.5 < ratio[0.1], ratio


def test_nonorthogonality_states_move_the_velocity_as_the_mechanization_does():
    """F's block of the accelerometer non-orthogonality against the mechanization itself: correcting the
    increments by a symmetric A changes the velocity over an epoch by -C_b^n N(f_b) da T, as F says for a change of
    -da in the residual (the state is the truth minus the correction)."""
    lat, h, steps, dt = np.radians(34.0), 100.0, 5, 0.02
    q = euler_to_quat(0.03, -0.02, 0.7)
    f_b = quat_rotate(quat_conj(q), np.array([0.2, -0.1, earth.normal_gravity(lat, h)]))
    t_mech = np.arange(steps + 1) * dt
    phi_b = np.tile(quat_rotate(quat_conj(q), earth.earth_rate_n(lat)) * dt, (steps, 1))
    dv_b = np.tile(f_b * dt, (steps, 1))
    nav0 = np.zeros(es.N_NAV)
    nav0[:3] = lat, 0.0, h
    nav0[kf.QUAT] = q
    da = np.array([3e-4, -2e-4, 5e-4])
    vel = []
    for a in (np.zeros(3), da):
        nav, cal = nav0.copy(), np.zeros(es.N_CAL)
        cal[kf.CAL_NONORTH] = a
        kf.mechanize_epoch(nav, cal, t_mech, phi_b, dv_b, 0, steps)
        vel.append(nav[kf.VEL])
    f_n = quat_rotate(q, f_b)
    expected = -kf.system_matrix(nav0, f_n)[kf.DV, kf.ACCEL_NONORTH] @ da * steps * dt
    assert np.abs(vel[1] - vel[0] - expected).max() < 1e-4 * np.abs(expected).max()


def test_a_pass_gives_the_same_estimate_whether_or_not_it_keeps_the_smoothers_rows(default_log):
    """Without smoothing the kernel keeps one row of predicted covariance and transition as scratch instead of one
    per epoch (odometer_filter.run_filter); the forward estimate is the one the smoothed run's forward pass gives."""
    scn, log = default_log
    cfg = positioning_config(scn)
    prep = prepare(log, cfg)
    plain, none = run_kf(log, cfg, prep, cpoem=False, smooth=False)
    kept, smoothed = run_kf(log, cfg, prep, cpoem=False, smooth=True)
    assert none is None and smoothed is not None
    for key in ("llh", "v_n", "q_nb", "sd", "flags", "cal"):
        assert np.array_equal(getattr(plain, key), getattr(kept, key)), key


def test_a_smoothed_pass_holds_its_covariances_a_block_at_a_time(default_log, monkeypatch):
    """The smoother's matrices go to disk a block at a time (estimators.kalman.rts.StoredInterval): a run in blocks
    of 40 epochs gives the run in whole passes bit for bit, and holds far less than a pass's matrices."""
    scn, log = default_log
    cfg = positioning_config(scn)
    prep = prepare(log, cfg)
    longest = max(b - a for a, b in prep.segments)
    whole = run_kf(log, cfg, prep, cpoem=True, smooth=True)
    monkeypatch.setattr(rts, "BLOCK", 40)
    assert longest > 10 * rts.BLOCK
    tracemalloc.start()
    blocks = run_kf(log, cfg, prep, cpoem=True, smooth=True)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    for one, other in zip(whole, blocks):
        for key in ("llh", "v_n", "q_nb", "sd", "flags", "cal"):
            assert np.array_equal(getattr(one, key), getattr(other, key)), key
    pass_matrices = 3 * longest * es.N_STATES ** 2 * 8
    assert peak < pass_matrices / 2, (peak, pass_matrices)


@pytest.mark.parametrize("from_survey", [True, False])
def test_the_first_cut_is_fixed_by_the_face_survey_at_the_cpoem_spacing(from_survey):
    """Config.cpoem_face_survey: the first pass's CPOEM fixes are the installed face line's surveyed points (at their
    own step); without them, as in 001, the first pass has none."""
    scn, result = simulated("default")
    streams = sensor_streams(scn, result.tables, imu_truth(scn, result.tables["truth_shearer"]), 0)
    log = log_from_columns(streams["imu"], streams["odometer"], streams["survey"], streams["pushram"],
                           face_survey=streams["face_survey"])
    cfg = dataclasses.replace(positioning_config(scn), cpoem_face_survey=from_survey)
    prep = prepare(log, cfg)
    assert log.face_u.size
    fwd, _ = run_kf(log, cfg, prep, cpoem=True, smooth=False)
    a, b = prep.segments[0]
    fixed = np.flatnonzero(fwd.flags[a + 1:b + 1] & FLAG_POSITION) + a + 1
    cpoem_fixed = np.setdiff1d(fixed, prep.survey_epochs)
    first, last = prep.cuts[0]
    cut_length = abs(prep.odo[last] - prep.odo[first - 1])
    if from_survey:  # a fix every surveyed point of the straight cut that the supports' strokes cover
        assert cpoem_fixed.size >= 0.7 * cut_length / np.median(np.diff(log.face_u)), (cpoem_fixed.size, cut_length)
        assert np.all((cpoem_fixed >= first) & (cpoem_fixed <= last))
    else:
        assert cpoem_fixed.size == 0
