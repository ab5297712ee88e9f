"""twin.view.estimate_recording: an estimate (the simulated truth plus a known offset) written to estimates.rrd beside
run.rrd and read back with rerun.chunk.RrdReader."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest
from rerun.chunk import RrdReader

from estimators.io.logformat import (
    ESTIMATE_DETECTORS,
    ESTIMATE_FUSION,
    ESTIMATE_STATES,
    FLAG_POSITION,
    STREAMS,
    make_table,
)
from estimators.shearer.federated_filter import MAG_DISTURBED, MAG_USED
from tests.conftest import simulated
from tests.estimators.io.test_metrics import offset_estimate
from twin.view.estimate_recording import write_estimate_recording
from twin.view.recording import ESTIMATES_RRD, RUN_RRD, write_recording
from twin.view.rerun_columns import TIMELINE

OFFSET = np.array([0.3, -0.2, 0.1])  # m east, north, up
ROTVEC = np.array([1e-3, -2e-3, 5e-3])  # estimate = Exp([rotvec x]) truth: psi-angle error -rotvec
SIGMA = 0.05
D_POS = {"odometer": 0.05, "aiding": -0.4}  # sub-filter position minus the global one [m]
STATES_TRUTH = {"gyro_bias_z": np.radians(720.0) / 3600, "odo_scale": 0.003}


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    scn, result = simulated("default")
    truth = {name: make_table(STREAMS[name], cols) for name, cols in result.tables.items()}
    out = tmp_path_factory.mktemp("run")
    write_recording(out / RUN_RRD, scn, truth, result.floor_grid.mesh_t(result.frame))
    shearer = truth["truth_shearer"]
    t = result.tables["truth_shearer"]["t"][:60000:10]  # 300 s at 20 Hz
    flags = np.zeros(t.size, np.int32)
    flags[[7, 1003]] = FLAG_POSITION  # single-sample events between the plot instants
    estimate = offset_estimate(shearer, t, OFFSET, ROTVEC, sd=SIGMA, flags=flags)
    k = t.size
    states = make_table(ESTIMATE_STATES, {"t": t, **{c.name: np.full(k, 1e-5) for c in ESTIMATE_STATES.columns[1:]}})
    fusion = {"t": t, "beta_odometer": np.full(k, 0.3), "beta_aiding": np.full(k, 0.7), "r_yaw": np.full(k, 1e-4),
              "yaw_innovation": np.full(k, 1e-3), "mag_flags": np.full(k, MAG_USED, np.int32),
              **{f"{sub}_d_pos_{a}": np.full(k, D_POS[sub]) for sub in D_POS for a in "enu"},
              **{f"{sub}_d_yaw": np.zeros(k) for sub in D_POS}}
    fusion["mag_flags"][501] = MAG_DISTURBED
    write_estimate_recording(out / ESTIMATES_RRD, scn, shearer, {"kf": estimate}, {"kf": states}, STATES_TRUTH,
                             fusion={"kf": make_table(ESTIMATE_FUSION, fusion)})
    return out


def _scalars(chunks, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """(sim_time [s] (K,), scalars (K, n)) of an entity's temporal chunks."""
    times, values = [], []
    for chunk in chunks:
        if chunk.entity_path == entity and not chunk.is_static:
            batch = chunk.to_record_batch()
            times.append(batch.column(TIMELINE).cast(pa.int64()).to_numpy() / 1e9)
            values += batch.column("Scalars:scalars").to_pylist()
    order = np.argsort(np.concatenate(times))
    return np.concatenate(times)[order], np.array(values)[order]


def test_same_recording_as_the_run(run_dir):
    run, est = RrdReader(run_dir / RUN_RRD).recordings()[0], RrdReader(run_dir / ESTIMATES_RRD).recordings()[0]
    assert est.application_id == run.application_id == "longwall-twin"
    assert est.recording_id == run.recording_id
    assert RrdReader(run_dir / ESTIMATES_RRD).blueprints() == []


def test_entities_and_logged_errors_equal_the_offset(run_dir):
    chunks = RrdReader(run_dir / ESTIMATES_RRD).stream().to_chunks()
    entities = {c.entity_path for c in chunks}
    expected = {"/world/estimates/kf/path", "/world/estimates/kf/position", "/plots/flags/kf",
                *(f"/plots/errors/kf/{a}" for a in ("east", "north", "up")),
                *(f"/plots/sigma/kf/position/{a}" for a in ("east", "north", "up")),
                *(f"/plots/attitude_errors/kf/{a}" for a in "enu"),
                *(f"/plots/sigma/kf/attitude/{a}" for a in "enu"),
                *(f"/plots/{kind}/kf/{g}" for kind in ("states", "sigma")
                  for g in ("gyro_bias", "accel_bias", "odo_mount", "odo_scale"))}
    assert expected <= entities, expected - entities
    assert all(c.is_static for c in chunks if c.entity_path == "/world/estimates/kf/path")
    for i, axis in enumerate(("east", "north", "up")):
        t, err = _scalars(chunks, f"/plots/errors/kf/{axis}")
        np.testing.assert_allclose(err[:, 0], OFFSET[i], atol=1e-6)
        # At most 10 Hz (decimate keeps the last sample too), fewer where the line through the rows draws the others.
        assert t[0] == 0.0 and t[-1] == 299.95 and (t.size == 2 or np.diff(t[:-1]).min() >= 0.1 - 1e-9)
        _, band = _scalars(chunks, f"/plots/sigma/kf/position/{axis}")
        np.testing.assert_allclose(band, np.broadcast_to([SIGMA, -SIGMA], band.shape))
    for i, a in enumerate("enu"):
        _, phi = _scalars(chunks, f"/plots/attitude_errors/kf/{a}")
        np.testing.assert_allclose(phi[:, 0], -np.degrees(ROTVEC[i]), atol=1e-9)


def test_flags_survive_decimation_and_states_carry_the_truth(run_dir):
    chunks = RrdReader(run_dir / ESTIMATES_RRD).stream().to_chunks()
    t, flags = _scalars(chunks, "/plots/flags/kf")
    assert flags.shape[1] == 3 and flags[:, 0].sum() == 2 and flags[:, 1:].sum() == 0
    np.testing.assert_allclose(t[flags[:, 0] == 1], [0.3, 50.1])  # the plot instants before 0.35 s and 50.15 s
    _, gyro = _scalars(chunks, "/plots/states/kf/gyro_bias")
    np.testing.assert_allclose(gyro[:, :3], np.degrees(1e-5) * 3600)  # rad/s -> deg/h
    np.testing.assert_allclose(gyro[:, 3], 720.0)  # the flat truth series of gyro_bias_z
    _, scale = _scalars(chunks, "/plots/states/kf/odo_scale")
    np.testing.assert_allclose(scale, np.broadcast_to([1e-5, 0.003], scale.shape))


def test_view_opens_both_files(run_dir, viewer_launches):
    from twin.view import layout

    layout.open_viewer(run_dir)
    [args] = viewer_launches
    assert args[:3] == ["/usr/bin/rerun", str(run_dir / RUN_RRD), str(run_dir / ESTIMATES_RRD)]
    assert args[3].endswith(".rbl") and len(RrdReader(args[3]).blueprints()) == 1  # the layout (twin.view.layout)


def test_fusion_series_show_the_subfilters_and_the_disturbed_reading(run_dir):
    chunks = RrdReader(run_dir / ESTIMATES_RRD).stream().to_chunks()
    _, beta = _scalars(chunks, "/plots/fusion/kf/beta")
    np.testing.assert_allclose(beta, np.broadcast_to([0.3, 0.7], beta.shape))
    _, sd = _scalars(chunks, "/plots/fusion/kf/r_yaw")
    np.testing.assert_allclose(sd, np.degrees(1e-2))
    for i, axis in enumerate(("east", "north")):
        _, err = _scalars(chunks, f"/plots/fusion/kf/subfilter_errors/{axis}")
        np.testing.assert_allclose(err, np.broadcast_to(OFFSET[i] + np.array([0.0, D_POS["odometer"], D_POS["aiding"]]),
                                                        err.shape), atol=1e-6)
    _, flags = _scalars(chunks, "/plots/fusion/kf/magnetometer")
    assert flags[:, 0].all() and flags[:, 1].sum() == 1  # the single disturbed epoch survives the decimation


def test_detector_series_carry_their_thresholds(tmp_path):
    scn, result = simulated("default")
    shearer = make_table(STREAMS["truth_shearer"], result.tables["truth_shearer"])
    t = result.tables["truth_shearer"]["t"][1000:60000:2000]
    k = t.size
    est = offset_estimate(shearer, t, OFFSET, ROTVEC, sd=SIGMA)
    truth_at_t = {c: np.interp(t, result.tables["truth_shearer"]["t"], result.tables["truth_shearer"][c])
                  for c in ("lat", "lon", "h")}
    det = make_table(ESTIMATE_DETECTORS, {"t": t, **truth_at_t, "residual": np.linspace(0, 20, k),
                                          "dual_state": np.zeros(k), "fsprt": np.full(k, 3.0),
                                          "applied": np.ones(k, np.int32), "isolated": np.zeros(k, np.int32)})
    path = tmp_path / ESTIMATES_RRD
    write_estimate_recording(path, scn, shearer, {"fkf_rail": est}, {}, detectors={
        "fkf_rail": (det, {"residual": 16.3, "dual_state": 16.3, "t_on": 12.0, "t_off": 5.0})})
    chunks = RrdReader(path).stream().to_chunks()
    _, fsprt = _scalars(chunks, "/plots/detectors/fkf_rail/fsprt")
    np.testing.assert_allclose(fsprt, np.broadcast_to([3.0, 12.0, 5.0], fsprt.shape))
    t_res, res = _scalars(chunks, "/plots/detectors/fkf_rail/residual")
    np.testing.assert_allclose(np.interp(t, t_res, res[:, 0]), np.linspace(0, 20, k))  # the line through the rows
    np.testing.assert_allclose(res[:, 1], 16.3)
    assert any(c.entity_path == "/world/estimates/fkf_rail/rail" and c.is_static for c in chunks)


def test_the_layout_comes_from_what_the_run_directory_holds(tmp_path):
    """twin.view.layout: the run's 3-D view and twin plots, an Estimates tab with a method's views when
    estimates/METHOD.parquet is there, its sensor states with METHOD_states.parquet, the one-sigma instead of the
    error without truth."""
    import rerun.blueprint as rrb

    from twin.view.layout import run_blueprint

    def view_names(bp):
        out, todo = [], [bp.root_container]
        while todo:
            node = todo.pop()
            if isinstance(node, rrb.Container):
                todo += list(node.contents)
            else:
                out.append(str(node.name))
        return out

    bare = view_names(run_blueprint(tmp_path))
    assert "Face" in bare and not any("Position" in n for n in bare)
    (tmp_path / "estimates").mkdir()
    (tmp_path / "estimates" / "kf.parquet").write_bytes(b"")
    (tmp_path / "truth_shearer.parquet").write_bytes(b"")
    names = view_names(run_blueprint(tmp_path))
    assert any("Position error" in n for n in names) and not any("Sensor" in n and "kf" in n for n in names)
    (tmp_path / "truth_shearer.parquet").unlink()
    assert any("Position one-sigma" in n for n in view_names(run_blueprint(tmp_path)))
