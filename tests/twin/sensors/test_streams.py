"""All sensor streams of a twin run: schemas, faults exactly in their windows, odometer scale, ram noise,
reproducible Monte Carlo trials from one truth."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from estimators.io.logformat import STREAMS, check_table, make_table
from estimators.io.metrics import geodetic_to_enu_offset, truth_at
from estimators.nav.rotations import quat_to_euler
from tests.conftest import capped, simulated
from twin.config.scenario import ScenarioError, parse_scenario
from twin.pipeline.simulate import simulate
from twin.sensors.faults import SHORTFALL_SPREAD
from twin.sensors.streams import imu_truth, sensor_streams
from twin.sensors.survey import survey_stream

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

FAULTS = [
    {"kind": "ram_offset", "t_start_s": 300.0, "t_end_s": 500.0, "target": 10, "value": 0.05},
    {"kind": "ram_dropout", "t_start_s": 600.0, "t_end_s": 650.0, "target": 20},
    {"kind": "push_shortfall", "t_start_s": 0.0, "t_end_s": 900.0, "target": 5, "value": 0.015},
    {"kind": "mag_interference", "t_start_s": 100.0, "t_end_s": 130.0, "value": 2.0e-5},
    {"kind": "odometer_slip", "t_start_s": 200.0, "t_end_s": 260.0, "value": 0.5},
]


@cache
def faulty_run():
    scn = capped("default", cycles=1, faults=FAULTS,
                 sensors={**capped("default").sensors.model_dump(),
                          "support_imu": {"supports": [3, 30], "rate_hz": 50.0, "grade": "icm-42605",
                                          "shearer_disturbance_t": 5.0e-6}})
    truth = simulate(scn).tables
    ideal = imu_truth(scn, truth["truth_shearer"])
    return scn, truth, ideal, sensor_streams(scn, truth, ideal, 0)


def test_every_stream_fits_its_schema():
    _, _, _, streams = faulty_run()
    assert {"imu", "odometer", "pushram", "mag", "faults", "support_imu", "survey"} <= set(streams)
    for name, cols in streams.items():
        check_table(STREAMS[name], make_table(STREAMS[name], cols), name)


def test_faults_appear_exactly_inside_their_windows():
    scn, truth, ideal, streams = faulty_run()
    clean = sensor_streams(parse_scenario({**scn.model_dump(), "faults": []}), truth, ideal, 0)
    ram, ram0 = streams["pushram"], clean["pushram"]
    differs = ~np.isclose(np.nan_to_num(ram["extension"], nan=-1), np.nan_to_num(ram0["extension"], nan=-1))
    for fault in FAULTS[:2]:
        inside = (ram["t"] >= fault["t_start_s"]) & (ram["t"] < fault["t_end_s"]) & (ram["support"] == fault["target"])
        assert differs[inside].all()
        if fault["kind"] == "ram_dropout":
            assert (ram["valid"][inside] == 0).all()
    assert not (differs & ~_any_window(ram, FAULTS)).any()
    mag_diff = np.linalg.norm(np.column_stack([streams["mag"][f"b_{a}"] - clean["mag"][f"b_{a}"] for a in "xyz"]),
                              axis=1)
    window = (streams["mag"]["t"] >= 100.0) & (streams["mag"]["t"] < 130.0)
    assert mag_diff[window].min() > 1e-5 and mag_diff[~window].max() == 0.0
    assert list(streams["faults"]["kind"]) == [f["kind"] for f in FAULTS]


def _any_window(ram, faults):
    """Rows of the ram stream inside the window of a fault on their support (a push shortfall reaches
    SHORTFALL_SPREAD supports to each side)."""
    hit = np.zeros(ram["t"].size, bool)
    for fault in faults:
        if fault.get("target") is not None:
            reach = SHORTFALL_SPREAD if fault["kind"] == "push_shortfall" else 0
            near = np.abs(ram["support"] - fault["target"]) <= reach
            hit |= (ram["t"] >= fault["t_start_s"]) & (ram["t"] < fault["t_end_s"]) & near
    return hit


def test_push_shortfall_moves_the_pans_not_the_readings():
    """While a push shortfall lasts, the pan of support 5 (and, tapering, its neighbours: the AFC is a chain)
    stops short, and the sensor reads the commanded stroke: the shortfall more than the true ram length."""
    scn, truth, _, streams = faulty_run()
    pans = truth["truth_pans"]
    rows = (pans["pan"] == 5 * scn.supports.pans_per_support + scn.supports.pans_per_support // 2) & (pans["t"] < 900)
    assert abs(pans["advance"][rows][-1] - (scn.face.web_depth_m - 0.015)) < 0.005
    ram, sup = streams["pushram"], truth["truth_supports"]
    late = (ram["support"] == 5) & (ram["t"] > 400.0) & (ram["t"] < 800.0)
    true = np.interp(ram["t"][late], sup["t"][sup["support"] == 5], sup["ram"][sup["support"] == 5])
    assert abs(np.median(ram["extension"][late] - true) - 0.015) < 0.002


def test_odometer_shows_its_scale_error():
    scn = capped("default", cycles=1)
    truth = simulate(scn).tables
    streams = sensor_streams(scn, truth, imu_truth(scn, truth["truth_shearer"]), 0)
    sh, odo = truth["truth_shearer"], streams["odometer"]
    # The straight cut (phases 1-2) in one direction: true path length from the speed.
    speed = np.hypot(np.hypot(sh["v_n_e"], sh["v_n_n"]), sh["v_n_u"])
    cut = (sh["phase"] == 1) | (sh["phase"] == 2)
    t0, t1 = sh["t"][cut][0], sh["t"][cut][-1]
    sel = (sh["t"] >= t0) & (sh["t"] <= t1)
    true = np.trapezoid(speed[sel], sh["t"][sel])
    reading = np.interp(t1, odo["t"], odo["distance"]) - np.interp(t0, odo["t"], odo["distance"])
    cfg = scn.sensors.odometer
    mount = np.cos(np.radians(cfg.mounting_deg[0])) * np.cos(np.radians(cfg.mounting_deg[2]))
    expected = true * mount / (1 + cfg.scale_error)
    assert abs(reading - expected) <= 3 * cfg.metres_per_pulse + 1e-3 * true * 0.01


def test_ram_readings_match_ram_length_within_noise():
    scn, truth, _, streams = faulty_run()
    ram = streams["pushram"]
    sup = truth["truth_supports"]
    clean = ~_any_window(ram, FAULTS) & (ram["valid"] == 1)
    true = np.empty(ram["t"].size)
    for j in np.unique(ram["support"]):
        rows = sup["support"] == j
        k = np.searchsorted(sup["t"][rows], ram["t"][ram["support"] == j], side="right") - 1
        true[ram["support"] == j] = sup["ram"][rows][np.maximum(k, 0)]
    resid = (ram["extension"] - true)[clean]
    sigma = scn.sensors.pushram.noise_m
    assert abs(resid.std() - sigma) < 0.1 * sigma and abs(resid.mean()) < 0.05 * sigma


def test_monte_carlo_trials_redraw_errors_from_one_truth():
    scn, truth, ideal, streams = faulty_run()
    again = sensor_streams(scn, truth, ideal, 0)
    other = sensor_streams(scn, truth, ideal, 1)
    for name in ("imu", "odometer", "pushram", "mag"):
        for col in streams[name]:
            np.testing.assert_array_equal(again[name][col], streams[name][col])
    assert not np.array_equal(other["imu"]["dtheta_x"], streams["imu"]["dtheta_x"])
    assert not np.array_equal(other["mag"]["b_x"], streams["mag"]["b_x"])
    np.testing.assert_array_equal(other["imu"]["t"], streams["imu"]["t"])


def test_bad_grade_and_fault_are_one_line():
    data = capped("default").model_dump()
    data["sensors"]["imu"]["grade"] = "tactical-9000"
    with pytest.raises(ScenarioError, match="no IMU preset 'tactical-9000'"):
        parse_scenario(data, "x.toml")
    data = capped("default").model_dump()
    data["faults"] = [{"kind": "ram_stuck", "t_start_s": 1.0, "t_end_s": 2.0, "target": 999}]
    with pytest.raises(ScenarioError, match="target support"):
        parse_scenario(data, "x.toml")


def test_survey_fixes_at_face_ends_with_the_configured_spread():
    """The start pose (t = 0, with yaw) and face end B of the first cut (no yaw); over many seeds the errors
    against the truth have zero mean and the configured one-sigma (001 Table 1: 0.05 m, 1 deg)."""
    scn, truth, _, streams = faulty_run()
    shearer, cycles = truth["truth_shearer"], truth["truth_cycles"]
    survey = streams["survey"]
    np.testing.assert_array_equal(survey["t"], [0.0, cycles["t_cut_end"][0]])
    assert np.isfinite(survey["yaw"][0]) and np.isnan(survey["yaw"][1]) and np.isnan(survey["sd_yaw"][1])
    cfg = scn.sensors.survey
    assert survey["sd_yaw"][0] == pytest.approx(np.radians(cfg.sd_yaw_deg))
    np.testing.assert_array_equal(survey["sd_horizontal"], cfg.sd_horizontal_m)
    # Many draws, against a thinned truth to keep them cheap (the reference is the same thinned truth).
    thin = {k: v[::50] for k, v in shearer.items()}
    true = truth_at(thin, survey["t"])
    yaw_true = quat_to_euler(true["q_nb"][0])[2]
    n = 2000
    draws = [survey_stream(scn, thin, cycles, np.random.default_rng([99, k])) for k in range(n)]
    pos = np.stack([geodetic_to_enu_offset(d["lat"], d["lon"], d["h"], true["lat"], true["lon"], true["h"])
                    for d in draws])                                    # (n, 2 fixes, 3)
    yaw = np.angle(np.exp(1j * (np.array([d["yaw"][0] for d in draws]) - yaw_true)))
    sd = np.array([cfg.sd_horizontal_m, cfg.sd_horizontal_m, cfg.sd_vertical_m])
    np.testing.assert_allclose(pos.std(axis=0), np.broadcast_to(sd, (2, 3)), rtol=0.07)
    assert (np.abs(pos.mean(axis=0)) < 4 * sd / np.sqrt(n)).all()
    assert abs(yaw.std() / np.radians(cfg.sd_yaw_deg) - 1) < 0.07 and abs(yaw.mean()) < 4 * np.radians(1) / 45
    assert abs(np.corrcoef(pos[:, 0, 0], pos[:, 1, 0])[0, 1]) < 0.1  # the two fixes are independent


def test_survey_is_reproducible_per_trial_and_leaves_the_other_streams():
    scn, truth, ideal, streams = faulty_run()
    again = sensor_streams(scn, truth, ideal, 0)["survey"]
    other = sensor_streams(scn, truth, ideal, 1)["survey"]
    for col in streams["survey"]:
        np.testing.assert_array_equal(again[col], streams["survey"][col])
    assert not np.array_equal(other["lat"], streams["survey"]["lat"])
    # Its own generator: the survey draws what a generator keyed (seed, trial, 5) gives, nothing else shifts.
    direct = survey_stream(scn, truth["truth_shearer"], truth["truth_cycles"],
                           np.random.default_rng([scn.seed, 0, 5]))
    np.testing.assert_array_equal(direct["lat"], streams["survey"]["lat"])


def test_survey_fixes_both_ends_of_every_cut_or_only_the_first():
    scn, result = simulated("default")
    shearer, cycles = result.tables["truth_shearer"], result.tables["truth_cycles"]
    every = survey_stream(scn, shearer, cycles, np.random.default_rng(0))["t"]
    want = [0.0, cycles["t_cut_end"][0], cycles["t"][1], cycles["t_cut_end"][1]]
    np.testing.assert_array_equal(every[:4], want)
    assert every.size in (4, 5) and every[-1] <= shearer["t"][-1]
    data = scn.model_dump()
    data["sensors"]["survey"]["face_ends"] = "first_cut"
    first = survey_stream(parse_scenario(data, "first"), shearer, cycles, np.random.default_rng(0))["t"]
    np.testing.assert_array_equal(first, want[:2])
