"""The methods streamed in a run (twin.pipeline.estimate, estimators.shearer.config.STREAMED: 001's filters, offline
smoother and dead reckoning, and 004's federated rail-model filter): run online over the run directory's log read a
row group at a time, their estimate files written pass by pass (the rail model's fusion and detector rows too) hold
the batch method's rows bit for bit, with its notes and health flags."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest

import estimators.io.logformat as lf
from estimators.io.log import PIECE_STREAMS, load_log, log_pieces
from estimators.shearer.methods import estimate
from tests.conftest import simulated
from twin.config.scenario import scenario_to_toml
from estimators.shearer.solution import state_columns
from twin.pipeline.estimate import positioning_config, run_estimators, solution_columns
from twin.sensors.streams import imu_truth, sensor_streams

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

METHODS = ("kf_cpoem_rts", "rts_offline", "dr_compensated", "fkf_rail", "kf", "dr")
ROWS = 20_000
"""Rows per row group: the default run's IMU in 23 pieces, the odometer's and push rams' groups cut elsewhere."""


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    scn, result = simulated("default")
    scn = scn.model_copy(update={"estimators": scn.estimators.model_copy(update={
        "shearer": scn.estimators.shearer.model_copy(update={"methods": list(METHODS)})})})
    truth = result.tables
    out = tmp_path_factory.mktemp("streamed") / "run"
    out.mkdir()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(lf, "ROW_GROUP_ROWS", ROWS)
        for name, cols in {**truth, **sensor_streams(scn, truth, imu_truth(scn, truth["truth_shearer"]))}.items():
            lf.write_stream(out, lf.STREAMS[name], cols)
        (out / "scenario.toml").write_text(scenario_to_toml(scn))
        metrics = run_estimators(out, scn, recording=False)
    return scn, out, metrics


def test_the_log_in_pieces_is_the_whole_log_once(run_dir):
    """Each stream's pieces joined are its file's rows, each piece's rows up to the IMU piece's last time."""
    _, out, _ = run_dir
    pieces = list(log_pieces(out))
    assert len(pieces) > 20 and [final for _, final in pieces] == [False] * (len(pieces) - 1) + [True]
    for stream in PIECE_STREAMS:
        whole = pq.read_table(out / stream.filename)
        for name in whole.column_names:
            joined = np.concatenate([p[stream.name][name] for p, _ in pieces if stream.name in p])
            np.testing.assert_array_equal(joined, whole.column(name).to_numpy(), err_msg=f"{stream.name}.{name}")
    for piece, final in pieces[:-1]:
        t_imu = piece["imu"]["t"][-1]
        assert all(piece[s]["t"].size == 0 or piece[s]["t"][-1] <= t_imu for s in piece)


def test_the_log_in_pieces_reads_a_row_group_ahead(run_dir, monkeypatch):
    """The first piece comes once the IMU's first two row groups are read (one ahead, to know it is not the last):
    the log is not read whole before it starts."""
    import estimators.io.log as log_module

    read = {}

    class Counted(log_module.StreamBlocks):
        def __iter__(self):
            for block in super().__iter__():
                read[self.stream.name] = read.get(self.stream.name, 0) + 1
                yield block

    _, out, _ = run_dir
    monkeypatch.setattr(log_module, "StreamBlocks", Counted)
    pieces = log_pieces(out)
    next(pieces)
    assert read["imu"] == 2 and all(n <= 2 for n in read.values()), read
    assert sum(1 for _ in pieces) > 20


def test_streamed_estimates_are_the_batch_methods_rows(run_dir):
    scn, out, metrics = run_dir
    batch = estimate(load_log(out), positioning_config(scn), METHODS)
    for name in METHODS:
        sol = batch[name]
        written = lf.read_estimate(out, name)
        for key, values in solution_columns(sol, scn).items():
            np.testing.assert_array_equal(written.column(key).to_numpy(), values, err_msg=f"{name}.{key}")
        for stream, columns in ((lf.ESTIMATE_FUSION, sol.fusion), (lf.ESTIMATE_DETECTORS, sol.detectors)):
            if columns is not None:
                table = lf.read_estimate(out, name, stream)
                for key, values in columns.items():
                    np.testing.assert_array_equal(table.column(key).to_numpy(), values, err_msg=f"{name} {key}")
        assert metrics[name]["notes"] == sol.notes
        if sol.cal is None:
            assert not lf.estimate_path(out, name, lf.ESTIMATE_STATES).exists()
            continue
        states = lf.read_estimate(out, name, lf.ESTIMATE_STATES)
        for key, values in state_columns(sol).items():
            np.testing.assert_array_equal(states.column(key).to_numpy(), values, err_msg=f"{name} states {key}")
        assert metrics[name]["odo_scale"]["estimate"] == state_columns(sol)["odo_scale"][-1]
