"""Canopy attitude of every instrumented support in a face run (twin.pipeline.support_estimate.support_attitude, issue 8):
the in-face scenario seed002_face end to end, the batch against one support at a time, bad support_imu logs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from estimators.io.logformat import (
    ESTIMATE_SUPPORT_ATTITUDE,
    STREAMS,
    SUPPORT_IMU,
    LogError,
    make_table,
    read_estimate,
    write_stream,
)
from estimators.support.batch import support_batch
from estimators.support.error_state import ours
from estimators.support.filters_002 import kf, ukf
from tests.conftest import simulated
from twin.cli import main
from twin.config.scenario import scenario_to_toml
from twin.pipeline.support_estimate import (
    METHODS,
    SUPPORT_ATTITUDE,
    ours_settings,
    support_attitude,
    unit_model,
)
from twin.sensors.support_imu import (
    support_imu_stream,
)

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

NAME = "seed002_face"


def write_run(path, streams=None):
    """A run directory of seed002_face: scenario, the truth it scores against and the support_imu stream."""
    scn, result = simulated(NAME)
    path.mkdir(parents=True, exist_ok=True)
    (path / "scenario.toml").write_text(scenario_to_toml(scn))
    for name in ("truth_supports", "truth_shearer"):
        write_stream(path, STREAMS[name], make_table(STREAMS[name], result.tables[name]))
    cols = streams or support_imu_stream(scn, result.tables["truth_supports"], result.tables["truth_shearer"],
                                         np.random.default_rng(scn.seed))
    write_stream(path, SUPPORT_IMU, make_table(SUPPORT_IMU, cols))
    return scn, cols


@pytest.fixture(scope="module")
def face(tmp_path_factory):
    """seed002_face's log, estimated once by `longwall estimate` (the scenario runs no shearer estimator)."""
    path = tmp_path_factory.mktemp("face")
    scn, cols = write_run(path)
    assert main(["estimate", str(path), "--quiet"]) == 0
    return scn, cols, path


def test_every_instrumented_support_gets_estimates_from_every_method(face):
    scn, _, path = face
    metrics = json.loads((path / "metrics.json").read_text())["estimators"][SUPPORT_ATTITUDE]
    supports = sorted(scn.sensors.support_imu.supports)
    assert metrics["supports"] == supports and metrics["skipped"] == {} and metrics["methods"] == list(METHODS)
    for name in METHODS:
        table = read_estimate(path, name, ESTIMATE_SUPPORT_ATTITUDE)  # checks columns, units, NaN, time order
        ids = table.column("support").to_numpy()
        assert sorted(np.unique(ids)) == supports
        for col in ("q_nc_w", "pitch", "roll", "yaw"):
            assert np.isfinite(table.column(col).to_numpy()).all()
    assert (path / "estimates.rrd").stat().st_size > 0


def test_in_face_errors_are_bounded_and_ours_keeps_the_yaw_while_the_shearer_passes(face):
    """Pitch and roll are what the uncalibrated ICM-42605 accelerometer allows (its 20 mg turn-on bias tilts a unit
    by ~1 deg; 3 sigma bounds it); the shearer's field throws 002's filters' yaw by degrees, ours holds it."""
    _, _, path = face
    metrics = json.loads((path / "metrics.json").read_text())["estimators"][SUPPORT_ATTITUDE]
    for j, per in metrics["per_support"].items():
        for name, e in per.items():
            assert e["rmse_deg"]["pitch"] < 4.0 and e["rmse_deg"]["roll"] < 4.0, (j, name)
            assert e["rmse_deg"]["yaw"] < 6.0, (j, name)
        assert per["ours"]["rmse_deg"]["yaw"] < 3.0 and per["ours"]["max_deg"]["yaw"] < 4.0, j
    for cls, entry in metrics["by_class"].items():
        paper = min(entry[name]["yaw_near_rmse_deg"] for name in ("kf", "ukf", "gd_ukf"))
        assert entry["ours"]["yaw_near_rmse_deg"] < 0.6 * paper, cls
    d = metrics["detection"]
    assert d["near_updates"] > 1000 and d["flagged_near"] > 0.9 * d["near_updates"]
    assert d["flagged_far"] < 0.01 * d["far_updates"]
    objective = metrics["tuning"]["objective_deg"]
    assert len(objective) > 2 and np.all(np.diff(objective) < 0)


def test_summary_table_is_printed(face):
    """What `longwall run` and `longwall estimate` print after the twin's summary (twin.pipeline.estimate.format_estimators)."""
    from twin.pipeline.estimate import format_estimators

    _, _, path = face
    out = format_estimators(json.loads((path / "metrics.json").read_text())["estimators"])
    assert "support canopy attitude" in out and "face ends" in out and "mid-face" in out
    assert "GD-UKF objective" in out and "flagged" in out and "shearer position" not in out


def test_batch_equals_one_support_at_a_time(face):
    """Every method run on all supports in one call gives what it gives on each support alone."""
    scn, cols, _ = face
    batch = support_batch(cols, scn.sensors.support_imu.supports)
    sel = slice(0, 6000)  # two minutes keep it quick; the kernels see no difference
    model = unit_model(scn, 1.0 / batch.dt)
    args = (batch.gyro[:, sel], batch.accel[:, sel], batch.mag[:, sel], batch.dt, model)
    var = np.full(3, 3e-6)
    together = {"kf": kf(*args, var), "ukf": ukf(*args, var),
                "ours": ours(*args, ours_settings(scn, 1.0 / batch.dt)).q_nb}
    for i in range(batch.supports.size):
        one = (batch.gyro[i, sel], batch.accel[i, sel], batch.mag[i, sel], batch.dt, model)
        alone = {"kf": kf(*one, var), "ukf": ukf(*one, var),
                 "ours": ours(*one, ours_settings(scn, 1.0 / batch.dt)).q_nb}
        for name, q in together.items():
            np.testing.assert_array_equal(alone[name][0], q[i], err_msg=name)


def test_nan_rows_and_missing_supports_are_skipped_with_their_reason(face):
    scn, cols, _ = face
    bad = {k: v.copy() for k, v in cols.items()}
    rows = np.flatnonzero(bad["support"] == 26)
    bad["mag_x"][rows[100]] = np.nan
    gap = np.flatnonzero(bad["support"] == 33)[500:510]
    keep = np.ones(bad["t"].size, bool)
    keep[gap] = False
    keep[bad["support"] == 50] = False
    bad = {k: v[keep] for k, v in bad.items()}
    batch = support_batch(bad, scn.sensors.support_imu.supports)
    assert set(batch.skipped) == {26, 33, 50}
    assert "NaN" in batch.skipped[26] and "10 of the" in batch.skipped[33] and "no rows" in batch.skipped[50]
    assert 26 not in batch.supports and batch.supports.size == len(scn.sensors.support_imu.supports) - 3
    for arr in (batch.gyro, batch.accel, batch.mag):
        assert np.isfinite(arr).all()
    with pytest.raises(ValueError, match="no support with usable readings") as err:
        support_batch({k: v[bad["support"] == 26] for k, v in bad.items()}, [26])
    assert "\n" not in str(err.value)


def test_a_run_without_a_unit_skips_it_and_a_log_with_nan_is_one_line(face, tmp_path, capsys):
    scn, cols, _ = face
    gone = {k: v[cols["support"] != 39] for k, v in cols.items()}
    write_run(tmp_path / "gone", gone)
    res = support_attitude(tmp_path / "gone", scn)
    assert res.metrics["skipped"] == {39: "no rows in support_imu"}
    assert any("support 39 skipped" in note for note in res.metrics["notes"])
    assert 39 not in res.supports and all(np.isfinite(e).all() for e in res.euler.values())

    nan = {k: v.copy() for k, v in cols.items()}
    nan["gyro_z"][7] = np.nan
    path = tmp_path / "nan"
    write_run(path, nan)
    with pytest.raises(LogError, match="gyro_z.*row 7"):
        support_attitude(path, scn)
    assert main(["estimate", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("longwall: error:") and "support_imu.parquet" in err and "\n" not in err


def test_recording_carries_attitude_errors_flags_and_the_tuning_objective(face):
    """estimates.rrd: each support's angles and errors per method (ours' errors RMS = its metric), ours' flags
    beside the shearer's field, the GD objective."""
    from rerun.chunk import RrdReader

    from twin.view.rerun_columns import TIMELINE

    scn, _, path = face
    metrics = json.loads((path / "metrics.json").read_text())["estimators"][SUPPORT_ATTITUDE]
    chunks = RrdReader(path / "estimates.rrd").stream().to_chunks()
    entities = {c.entity_path for c in chunks}
    root = "/plots/support_attitude"
    for j in scn.sensors.support_imu.supports:
        assert f"{root}/magnetometer/{j}" in entities
        for angle in ("pitch", "roll", "yaw"):
            assert f"{root}/angles/{angle}/{j}/truth" in entities
            assert {f"{root}/{kind}/{angle}/{j}/{name}" for kind in ("angles", "errors") for name in METHODS} <= entities
    assert f"{root}/gd_objective" in entities

    def values(entity: str) -> np.ndarray:
        out = [c.to_record_batch().column("Scalars:scalars").to_pylist() for c in chunks
               if c.entity_path == entity and not c.is_static]
        assert all(TIMELINE in c.to_record_batch().schema.names for c in chunks if c.entity_path == entity
                   and not c.is_static)
        return np.array([v for part in out for v in part])

    j = scn.sensors.support_imu.supports[3]
    err = values(f"{root}/errors/pitch/{j}/ours")[:, 0]
    assert np.sqrt(np.mean(err ** 2)) == pytest.approx(metrics["per_support"][str(j)]["ours"]["rmse_deg"]["pitch"],
                                                       rel=0.02)
    mag = values(f"{root}/magnetometer/{j}")
    assert mag.shape[1] == 5 and mag[:, 4].max() > 0.9 and mag[:, :3].max() == 1.0
