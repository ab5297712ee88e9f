"""The twin stage as it streams: the files do not depend on the chunking and hold what the whole run in memory gives."""

from __future__ import annotations

import hashlib
import threading

import numpy as np
import pyarrow.parquet as pq
import pytest

import estimators.io.logformat as lf
from tests.conftest import capped, simulated
from twin.pipeline.simulate import simulate_stream
from twin.pipeline.twin_stream import SHEARER_STREAMS, stream_twin
from twin.sensors.streams import imu_truth, sensor_streams

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")


@pytest.fixture(scope="module")
def streamed(tmp_path_factory):
    """The capped default scenario streamed twice: by ride chunk (a cycle: chunks larger than any), and in chunks of
    7,919 truth rows (boundaries anywhere: inside an IMU sample's group, a survey's cut, a stop) with row groups of
    100,000 rows, so that both files span several row groups."""
    scn, _ = simulated("default")
    dirs = []
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(lf, "ROW_GROUP_ROWS", 100_000)
        for chunk_rows in (1 << 40, 7_919):
            out = tmp_path_factory.mktemp("stream")
            stream_twin(scn, out, chunk_rows=chunk_rows)
            dirs.append(out)
    return scn, dirs


def test_two_chunk_sizes_give_the_same_bytes(streamed):
    _, (by_cycle, by_rows) = streamed
    names = sorted(p.name for p in by_cycle.glob("*.parquet"))
    assert names == sorted(p.name for p in by_rows.glob("*.parquet"))
    assert {f"{n}.parquet" for n in ("truth_shearer", *SHEARER_STREAMS)} <= set(names)
    assert pq.ParquetFile(by_cycle / "imu.parquet").metadata.num_row_groups > 1
    for name in names:
        digest = [hashlib.sha256((d / name).read_bytes()).hexdigest() for d in (by_cycle, by_rows)]
        assert digest[0] == digest[1], name


def test_streamed_run_holds_what_the_whole_run_in_memory_gives(streamed):
    scn, (by_cycle, _) = streamed
    _, result = simulated("default")
    truth = result.tables
    whole = {**truth, **sensor_streams(scn, truth, imu_truth(scn, truth["truth_shearer"]), 0)}
    for name, cols in whole.items():
        table = pq.read_table(by_cycle / lf.STREAMS[name].filename)
        assert table.num_rows == len(next(iter(cols.values()))), name
        for key, values in cols.items():
            got = table.column(key).to_numpy()
            if np.asarray(values).dtype.kind in "fiu":
                np.testing.assert_array_equal(got, np.asarray(values), err_msg=f"{name}.{key}")
            else:
                assert list(got) == list(values), f"{name}.{key}"


def test_live_taps_get_the_files_rows_as_they_are_drawn(streamed, tmp_path):
    """A served run (live taps, twin.opcua.server): the files are the bytes of a run without taps; the sensor rows
    tapped, joined, are each file's rows; the push-ram rows come as the face's rows become final (before the
    run's last shearer chunk), each tap's rows before the time it says the stream is drawn to."""
    from twin.pipeline.simulate import LiveTaps

    scn, (by_cycle, _) = streamed
    tapped: dict[str, list] = {}
    shearer_chunks = [0]
    pushram_before_last_chunk = [0]

    def sensors(name, cols, until):
        assert np.all(cols["t"] < until), name
        tapped.setdefault(name, []).append(cols)
        if name == "pushram" and shearer_chunks[0] < 2:
            pushram_before_last_chunk[0] += cols["t"].size

    def shearer(rows):
        shearer_chunks[0] += 1

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(lf, "ROW_GROUP_ROWS", 100_000)
        stream_twin(scn, tmp_path, chunk_rows=20_000, live=LiveTaps(shearer, lambda rows, t_final: None, sensors))
    for path in by_cycle.glob("*.parquet"):
        assert (tmp_path / path.name).read_bytes() == path.read_bytes(), path.name
    assert pushram_before_last_chunk[0] > 0
    assert set(tapped) == {*SHEARER_STREAMS, "pushram", "pressure"} | (
        {"support_imu"} if scn.sensors.support_imu.supports else set())
    for name, parts in tapped.items():
        table = pq.read_table(by_cycle / lf.STREAMS[name].filename)
        for key in parts[0]:
            np.testing.assert_array_equal(np.concatenate([p[key] for p in parts]), table.column(key).to_numpy(),
                                          err_msg=f"{name}.{key}")


class SinkFailed(Exception):
    pass


def test_the_face_simulates_on_while_the_sink_takes_a_chunk():
    """The sink takes a ride chunk on a thread of its own: the first chunk's sink returns only once the face has
    reported a later cycle (it would wait in vain on the face's thread); an error in a later sink stops the run."""
    scn = capped("default", cycles=3)
    taken: list[float] = []
    face_moved = threading.Event()

    def progress(stage: str, frac: float) -> None:
        if stage == "face" and taken:
            face_moved.set()

    def sink(rows: dict[str, np.ndarray]) -> None:
        taken.append(float(rows["t"][0]))
        if len(taken) == 1:
            assert face_moved.wait(timeout=120), "the face did not simulate on while the sink took a chunk"
        else:
            raise SinkFailed

    with pytest.raises(SinkFailed):
        simulate_stream(scn, sink, progress)
    assert taken[0] == 0.0 and len(taken) >= 2
