"""004's federated INS/odometer + INS/rail-kinematics-model filter (estimators.shearer.rail_kinematics.run_rail) on the
default face: the face survey's fixes, the odometer calibration they give, and the isolation of a rail-model fault
reported by the push-ram sensors."""

import dataclasses

import numpy as np
import pytest

from estimators.faults.detectors import fsprt_state
from estimators.io import metrics
from estimators.io.log import Log, log_from_columns
from estimators.io.logformat import (
    ESTIMATE_DETECTORS,
    FLAG_ISOLATED,
    FLAG_POSITION,
    read_estimate,
    write_estimate,
)
from estimators.kalman import error_state as es
from estimators.shearer import odometer_filter as kf
from estimators.shearer import rail_fix_update as rf
from estimators.shearer import rail_kinematics as rk
from estimators.shearer.config import Config, ImuNoise, PositioningError
from estimators.shearer.cpoem import ALONG_FACE_SD, Points
from estimators.shearer.position_fixes import Fixes, face_survey_points
from estimators.shearer.positioning import run_kf
from estimators.shearer.prepare import prepare
from estimators.shearer.solution import estimate_columns
from tests.conftest import simulated
from twin.config.scenario import parse_scenario
from twin.pipeline.estimate import positioning_config, true_states
from twin.sensors.streams import imu_truth, sensor_streams

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")


def _log(scn, result, trial=0) -> Log:
    s = sensor_streams(scn, result.tables, imu_truth(scn, result.tables["truth_shearer"]), trial)
    return log_from_columns(s["imu"], s["odometer"], s["survey"], s["pushram"], face_survey=s["face_survey"])


@pytest.fixture(scope="module")
def face():
    scn, result = simulated("default")
    log = _log(scn, result)
    cfg = positioning_config(scn)
    return scn, result, log, cfg, prepare(log, cfg)


def test_the_face_survey_fixes_the_first_cut_and_calibrates_the_odometer(face, tmp_path):
    scn, result, log, cfg, prep = face
    rail = rk.run_rail(log, cfg, prep)
    odo = run_kf(log, cfg, prep, cpoem=False, smooth=False)[0]
    assert np.isfinite(rail.llh).all() and np.isfinite(rail.sd).all()
    d = rail.detectors
    # The surveyed face ends are applied without the detectors (NaN statistics) and the table still writes.
    assert np.isnan(d["residual"]).any()
    write_estimate(tmp_path, "fkf_rail", d, ESTIMATE_DETECTORS)
    back = read_estimate(tmp_path, "fkf_rail", ESTIMATE_DETECTORS)
    np.testing.assert_array_equal(back.column("fsprt").to_numpy(), d["fsprt"])
    cut_end = result.tables["truth_cycles"]["t_cut_end"][0]
    assert d["applied"].all() and np.sum(d["t"] <= cut_end) >= 0.8 * log.face_u.size
    assert not (rail.flags & FLAG_ISOLATED).any() and (rail.flags & FLAG_POSITION).any()
    truth = true_states(scn)["odo_scale"]
    # The surveyed face ends calibrate the odometer scale (0.3 %), the face survey's fixes across the face and
    # vertically holding the path between them; the odometer filter without fixes keeps its error.
    assert abs(rail.cal[-1, 9] - truth) < 0.25 * abs(truth) < abs(odo.cal[-1, 9] - truth)
    errs = []
    for sol in (odo, rail):  # over the first cut, on the surveyed face line
        t, err = metrics.position_errors(estimate_columns(sol), result.tables["truth_shearer"])
        errs.append(np.hypot(err[:, 0], err[:, 1])[t <= cut_end].max())
    assert errs[1] < 0.5 * errs[0], errs


def test_the_detectors_judge_a_fix_by_what_its_innovations_show(face):
    """A rail fix comes from the filter's own previous pass, so its error and the filter's are largely one error:
    judged by the model's variance h P h^T + R (004 eq. 16, window 0) the across-face innovation's normalized
    square (the residual statistic, 1 dof) averages far below 1, and a fault hides below it. Scaled by what the
    last accepted fixes' innovations show (a window of 10 here: the default face has 39 rail fixes), it averages
    about 1 over a fault-free run."""
    _, _, log, cfg, prep = face
    nis = []
    for window in (10, 0):
        run_cfg = dataclasses.replace(cfg, detector=dataclasses.replace(cfg.detector, window=window))
        d = rk.run_rail(log, run_cfg, prep).detectors
        tested = d["residual"][np.isfinite(d["residual"])]
        assert tested.size > 30
        nis.append(tested[10 + rk.ARM_FIXES:].mean())
    assert 0.5 < nis[0] < 2.0 and nis[1] < 0.2, nis


@pytest.fixture(scope="module")
def deviation(face):
    """The default face with a rail deviation over the first cut: (t0, t1, log, prep, solution)."""
    scn, result, _, cfg, _ = face
    cut_end = float(result.tables["truth_cycles"]["t_cut_end"][0])
    t0, t1 = 0.35 * cut_end, 0.6 * cut_end
    faulted = parse_scenario({**scn.model_dump(), "faults": [
        {"kind": "rail_deviation", "t_start_s": t0, "t_end_s": t1, "value": 2.0}]}, "default-rail-fault")
    f_log = _log(faulted, result)
    f_prep = prepare(f_log, cfg)
    return t0, t1, f_log, f_prep, rk.run_rail(f_log, cfg, f_prep)


def test_a_rail_deviation_is_isolated_and_the_filter_readmits_the_model(face, deviation):
    _, result, _, cfg, _ = face
    t0, t1, f_log, _, sol = deviation
    isolated = (sol.flags & FLAG_ISOLATED) > 0
    assert isolated[(sol.t > t0) & (sol.t < t1 + 60.0)].any()
    assert not isolated[sol.t > t1 + 120.0].any()
    d = sol.detectors
    # The alarm (T1 crossed) comes after the onset; the isolation is dated back to the fix where the statistic
    # was last at its lowest (the filter rolls back to it), at most N_BACK fixes before the alarm.
    alarm = d["t"][np.argmax(d["fsprt"] > cfg.detector.t_on)]
    assert t0 < alarm < t1 + 60.0
    first_out = sol.t[np.argmax(isolated)]
    assert np.sum((d["t"] >= first_out) & (d["t"] < alarm)) <= rf.N_BACK
    during = (d["t"] > t0) & (d["t"] < t1)
    assert np.nanmax(d["residual"][during]) > 3 * np.nanmax(d["residual"][d["t"] < t0])
    assert (d["applied"][during] == 0).any()
    # Isolated, the filter rides on the odometer: the deviation does not bend the estimate.
    blind = rk.run_rail(f_log, dataclasses.replace(cfg), prepare(f_log, cfg), isolate_by=None)
    errs = []
    for s in (sol, blind):
        _, err = metrics.position_errors(estimate_columns(s), result.tables["truth_shearer"])
        errs.append(np.hypot(err[:, 0], err[:, 1]).max())
    assert errs[0] < errs[1]


def test_a_surveyed_fix_inside_the_rolled_back_fixes_is_applied_again(face, deviation, monkeypatch):
    """When the fading SPRT raises the fault the filter goes back to where the fault began and leaves out the
    rail-model fixes it had taken since; a surveyed (trusted) fix among them is taken again, not dropped."""
    _, result, _, cfg, _ = face
    _, _, f_log, f_prep, sol = deviation
    d = sol.detectors
    alarm = d["t"][np.argmax(d["fsprt"] > cfg.detector.t_on)]
    first_out = sol.t[np.argmax((sol.flags & FLAG_ISOLATED) > 0)]
    rolled = d["t"][(d["t"] >= first_out) & (d["t"] < alarm)]
    assert rolled.size >= 2
    j_fix = int(np.searchsorted(f_prep.t_kf, 0.5 * (rolled[0] + rolled[1])))
    true = metrics.truth_at(result.tables["truth_shearer"], f_prep.t_kf[[j_fix]])
    rail_fixes = rk._rail_fixes

    def with_surveyed_fix(prep, cfg_, log, a, b, *rest):
        fixes, var_floor = rail_fixes(prep, cfg_, log, a, b, *rest)
        if not a < j_fix <= b:
            return fixes, var_floor
        order = np.argsort(np.append(fixes.epoch, j_fix), kind="stable")
        llh = np.column_stack([true["lat"], true["lon"], true["h"]])
        fixes = Fixes(np.append(fixes.epoch, j_fix), np.vstack([fixes.llh, llh]),
                      np.vstack([fixes.r, np.diag([0.01 ** 2] * 3)[None]]), np.append(fixes.gate, np.inf),
                      np.vstack([fixes.advance, np.zeros((1, 3))])).take(order)
        return fixes, np.append(var_floor, 0.0)[order]

    monkeypatch.setattr(rk, "_rail_fixes", with_surveyed_fix)
    again = rk.run_rail(f_log, cfg, f_prep).detectors
    row = np.flatnonzero(np.isclose(again["t"], f_prep.t_kf[j_fix]) & np.isnan(again["fsprt"]))
    assert row.size == 1
    assert again["isolated"][row[0]] == 1  # inside the rolled-back stretch
    assert again["applied"][row[0]] == 1


def test_unknown_detector_and_missing_rams_are_one_line(face):
    _scn, _result, log, cfg, prep = face
    with pytest.raises(PositioningError, match="detector 'cusum'"):
        rk.run_rail(log, cfg, prep, isolate_by="cusum")
    bare = dataclasses.replace(log, ram_t=np.zeros(0), ram_support=np.zeros(0, int), ram_extension=np.zeros(0),
                               ram_valid=np.zeros(0, int))
    with pytest.raises(PositioningError, match="pushram"):
        rk.run_rail(bare, cfg, prepare(bare, cfg))


def _detectors(window: int) -> rf.DetectorState:
    return rf.DetectorState(fsprt_state(rf.DET_DOF), np.zeros(1, np.int8), np.zeros(rf.N_COUNTS, np.int64),
                            np.zeros((window, 2)))


def _one_fix(llh, r, advance, var_floor) -> rf.RailFixes:
    """One rail fix of an earlier pass's point (not trusted)."""
    return rf.RailFixes(np.zeros(1, np.int64), llh[None], r[None], advance[None],
                        np.array([var_floor]), np.zeros(1, bool))


def test_a_shrinking_fault_is_readmitted_only_once_its_fix_passes_the_residual_test():
    """The readmission rule of rail_fix_update.rail_fix_update, fix by fix: a 1 m fault across the face is isolated;
    when it shrinks to 0.15 m (15 sigma) the fading SPRT alone falls below T0 in one step, yet the fix stays out; a
    fix within the noise readmits the model."""
    cfg = Config(imu=ImuNoise(gyro_arw=1e-6, accel_vrw=1e-5, gyro_bias=1e-7, accel_bias=1e-5))
    det = cfg.detector
    params = rk.detector_params(det, "fsprt")
    nav = np.zeros(es.N_NAV)
    nav[kf.LAT], nav[kf.QUAT] = 0.5, (1.0, 0.0, 0.0, 0.0)
    r_m = 6.36e6  # metres per radian of latitude near 0.5 rad (the fix offsets are small)
    p0 = np.eye(kf.N_STATES) * 1e-4
    detectors, stats = _detectors(det.window), np.zeros(3)
    isolated = detectors.isolated
    advance = np.array([0.0, 1.0, 0.0])
    rng = np.random.default_rng(7)

    def fix(offset_north: float) -> bool:
        x, p = np.zeros(kf.N_STATES), p0.copy()  # the same prior at every fix: only the offsets differ
        llh = np.array([nav[kf.LAT] - offset_north / r_m, 0.0, 0.0])
        fix_k = _one_fix(llh, np.eye(3) * 1e-4, advance, 0.0)
        return rf.rail_fix_update(x, p, nav, np.zeros(3), fix_k, 0, x.copy(), p0.copy(), params,
                                  detectors, stats)

    assert all(fix(0.01 * rng.standard_normal()) for _ in range(det.window + 5))
    assert not isolated[0]
    for _ in range(3):
        fix(1.0)
    assert isolated[0] and stats[rf.DET_FSPRT] == pytest.approx(rk.CAP * det.t_on)
    assert not fix(0.15)
    assert stats[rf.DET_FSPRT] <= det.t_off  # the fading SPRT alone would readmit this fix
    assert stats[rf.DET_RESIDUAL] > params[rf.D_CHI2]
    assert isolated[0]
    assert fix(0.005)
    assert not isolated[0]


def test_the_next_pass_takes_no_fix_from_points_recorded_while_settling_or_isolated():
    """Of a pass's points, the next pass leaves out those before its detectors were armed (the ARM_FIXES-th tested
    fix) and those recorded while the rail model was isolated (the push-ram readings were held faulty)."""
    t = np.arange(0.0, 100.0, 1.0)
    flags = np.zeros(t.size, np.int32)
    flags[(t >= 50.0) & (t < 70.0)] = FLAG_ISOLATED
    t_pts = np.arange(2.5, 100.0, 5.0)
    n = t_pts.size
    points = Points(t_pts * 0.1, t_pts, np.zeros((n, 3)), np.zeros((n, 3, 3)), np.zeros((n, 3, 3)), 0.5)
    t_tested = np.arange(5.0, 100.0, 10.0)
    kept = rk.next_pass_points(points, t, flags, t_tested)
    assert np.all(kept.t >= t_tested[rk.ARM_FIXES])
    assert not np.any((kept.t >= 50.0) & (kept.t < 70.0))
    assert kept.t.size == np.sum((t_pts >= t_tested[rk.ARM_FIXES]) & ~((t_pts >= 50.0) & (t_pts < 70.0)))


STROKE_VAR_SEED004 = (rk.STROKE_SD_PER_NOISE * 0.02) ** 2
"""The variance floor of a rail fix from seed004's 0.02 m ram readings: the stroke's own spread."""


def test_a_rail_fix_is_floored_at_its_strokes_own_spread(face):
    """Every rail fix's detector variance is at least its stroke's (the filter cannot share an error each pass
    measures anew), a face-survey fix's also at least its smoothed point's; a surveyed face end has none."""
    _, _, log, cfg, prep = face
    cfg = dataclasses.replace(cfg, end_zone_m=0.0, cpoem_spacing_m=cfg.chute_length_m, ram_noise_sd=0.02)
    points = face_survey_points(log, prep, cfg.cpoem_spacing_m)
    a, b = prep.segments[0]
    earlier, floor = rk._rail_fixes(prep, cfg, log, a, b, points, False, [])
    rail = np.isfinite(earlier.gate)
    assert rail.any() and (~rail).any()
    assert np.allclose(floor[rail], STROKE_VAR_SEED004) and np.all(floor[~rail] == 0.0)
    surveyed, floor = rk._rail_fixes(prep, cfg, log, a, b, points, True, [])
    rail = np.isfinite(surveyed.gate)
    assert np.all(floor[rail] >= STROKE_VAR_SEED004) and np.any(floor[rail] > STROKE_VAR_SEED004)


@pytest.mark.parametrize("var_floor, offsets, flagged", [
    (0.021 ** 2, [0.0, -0.016, -0.03, -0.05, -0.06, -0.065], False),  # seed004 trial 10's swing of the survey
    (0.0, [0.0, -0.016, -0.03, -0.05, -0.06, -0.065], True),
    (0.021 ** 2, [-0.05, -0.09, -0.135], True),  # the first fixes of 004's rail deviation (seed004_fault)
    (STROKE_VAR_SEED004, [0.031], False),  # seed004 trial 21: one stroke 31 mm off, on an earlier pass's point
    (0.0, [0.031], True),
])
def test_a_fix_is_judged_against_at_least_the_error_the_filter_cannot_share(var_floor, offsets, flagged):
    """After a calm stretch the window's kappa takes the fading SPRT's sigma down to the 5 mm floor. A face-survey
    fix is judged against at least its smoothed point's variance (0.021 m): the survey's own swing of a few
    centimetres over three chutes is not a fault, 004's rail deviation still is, by its third fix. A rail fix is
    judged against at least its stroke's spread: one stroke a few centimetres off is not a fault."""
    det = Config(imu=ImuNoise(gyro_arw=1e-6, accel_vrw=1e-5, gyro_bias=1e-7, accel_bias=1e-5)).detector
    params = rk.detector_params(det, "fsprt")
    nav = np.zeros(es.N_NAV)
    nav[kf.LAT], nav[kf.QUAT] = 0.5, (1.0, 0.0, 0.0, 0.0)
    r_m = 6.36e6
    p0, r_fix = np.eye(kf.N_STATES) * 1e-6, np.eye(3) * 0.047 ** 2  # the fix's R as cpoem.predict_fixes makes it
    detectors, stats = _detectors(det.window), np.zeros(3)
    isolated = detectors.isolated
    rng = np.random.default_rng(3)

    def fix(offset_north: float, floor: float) -> None:
        x, p = np.zeros(kf.N_STATES), p0.copy()
        llh = np.array([nav[kf.LAT] - offset_north / r_m, 0.0, 0.0])
        fix_k = _one_fix(llh, r_fix, np.array([0.0, 1.0, 0.0]), floor)
        rf.rail_fix_update(x, p, nav, np.zeros(3), fix_k, 0, x.copy(), p0.copy(), params, detectors,
                           stats)

    for _ in range(det.window + 5):
        fix(0.002 * rng.standard_normal(), var_floor)
    fix(0.01, var_floor)
    assert stats[rf.DET_RESIDUAL] == pytest.approx(0.01 ** 2 / max(var_floor, det.sd_floor ** 2), rel=0.02)
    for offset in offsets:
        fix(offset, var_floor)
    assert bool(isolated[0]) == flagged


def test_a_fix_from_a_point_says_nothing_along_the_face(face):
    """A point of an earlier pass was placed along the face by the filter's own odometer, a face-survey point by
    the survey's distance along the pans: either fix constrains the shearer across the face and vertically only
    (cpoem.ALONG_FACE_SD), its one loose axis along the face line."""
    _, _, log, cfg, prep = face
    cfg = dataclasses.replace(cfg, end_zone_m=0.0, cpoem_spacing_m=cfg.chute_length_m)  # as run_rail; 68 m face
    points = face_survey_points(log, prep, cfg.cpoem_spacing_m)
    a, b = prep.segments[0]
    along = points.c_nb[0][:, 1]
    for surveyed in (True, False):
        fixes, floor = rk._rail_fixes(prep, cfg, log, a, b, points, surveyed, [])
        rail = np.isfinite(fixes.gate)
        assert rail.sum() > 10
        if not surveyed:
            assert np.allclose(floor, np.where(rail, (rk.STROKE_SD_PER_NOISE * cfg.ram_noise_sd) ** 2, 0.0))
        var, axes = np.linalg.eigh(fixes.r[rail])
        assert np.all(var[:, 2] > (0.5 * ALONG_FACE_SD) ** 2) and np.all(var[:, 1] < 0.1 ** 2)
        assert np.all(np.abs(axes[:, :, 2] @ along) > 0.99)
