"""Reproducible Rerun recordings (twin.view.rrd_stream): the same content, the same bytes."""

from __future__ import annotations

import numpy as np
import pytest
import rerun as rr
from rerun.chunk import RrdReader

from tests.conftest import capped
from twin.view.rrd_stream import recording_id, recording_stream

ROW_ID = "rerun.controls.RowId"


def write(path, recording="fixed"):
    with recording_stream(path, recording) as rec:
        rec.send_recording_name("test")
        rec.log("world/a", rr.Points3D([[1.0, 2.0, 3.0]]), static=True)
        rec.send_columns("plots/x", indexes=[rr.TimeColumn("sim_time", duration=np.arange(5.0))],
                         columns=rr.Scalars.columns(scalars=np.arange(5.0)))
        rec.set_time("sim_time", duration=7.0)
        rec.log("plots/y", rr.Scalars(1.0))  # not static: Rerun adds log_time and log_tick
        rec.log("world/b", rr.Points3D([[0.0, 0.0, 0.0]]), static=True)
    return [(c.id, c.entity_path, c.to_record_batch()) for c in RrdReader(str(path)).stream().to_chunks()]


def test_the_same_content_twice_gives_the_same_chunks_ids_and_rows(tmp_path):
    a, b = write(tmp_path / "a" / "run.rrd"), write(tmp_path / "b" / "run.rrd")
    assert [(i, e) for i, e, _ in a] == [(i, e) for i, e, _ in b]
    for (_, entity, x), (_, _, y) in zip(a, b):
        assert x.equals(y, check_metadata=True), entity
    assert all("log_time" not in batch.schema.names for _, _, batch in a)
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["run.rrd"]  # no scratch file left


WRITER = """
import sys
sys.path.insert(0, {root!r})
from pathlib import Path
from tests.twin.view.test_rrd_stream import write
write(Path({path!r}))
"""


def test_two_processes_write_the_same_bytes(tmp_path):
    """Every id Rerun stamps from the clock, the footer's hash-map order and the blueprint's random store id are
    gone: two processes (each with its own hash seed and clock) write byte-identical files, with no footer and no
    blueprint, whose SetStoreInfo row ids are the ones twin.view.rrd_stream gives them."""
    import filecmp
    import subprocess
    import sys
    from pathlib import Path

    import twin.view.rrd_stream as rrd_stream

    root = str(Path(__file__).resolve().parents[3])
    paths = [tmp_path / name / "run.rrd" for name in ("a", "b")]
    for path in paths:
        subprocess.run([sys.executable, "-c", WRITER.format(root=root, path=str(path))], check=True)
    assert filecmp.cmp(*paths, shallow=False)
    assert RrdReader(str(paths[0])).blueprints() == []
    data = paths[0].read_bytes()
    messages, off = [], rrd_stream.FILE_HEADER
    while off < len(data):
        kind, size = (int(v) for v in np.frombuffer(data[off:off + 16], "<u8"))
        messages.append((kind, data[off + 16:off + 16 + size]))
        off += 16 + size
    assert off == len(data) and rrd_stream.END not in [k for k, _ in messages]  # no footer
    infos = [body for kind, body in messages if kind == rrd_stream.STORE_INFO]
    base = rrd_stream._base("fixed", "run.rrd/store_info")
    assert [(int.from_bytes(b[3:11], "little"), int.from_bytes(b[12:20], "little")) for b in infos] == [
        (base, k + 1) for k in range(len(infos))] and infos


def test_row_ids_keep_the_logging_order(tmp_path):
    first_row = {entity: bytes(batch.column(ROW_ID)[0].as_py()) for _, entity, batch in write(tmp_path / "r.rrd")}
    order = ["/world/a", "/plots/x", "/plots/y", "/world/b"]
    assert sorted(order, key=first_row.get) == order


def test_two_files_of_one_recording_share_no_id(tmp_path):
    a, b = write(tmp_path / "run.rrd"), write(tmp_path / "estimates.rrd")
    assert not {i for i, _, _ in a} & {i for i, _, _ in b}
    rows = [{bytes(r) for _, _, batch in chunks for r in batch.column(ROW_ID).to_pylist()} for chunks in (a, b)]
    assert not rows[0] & rows[1]


def test_an_exception_leaves_no_recording(tmp_path):
    with pytest.raises(RuntimeError), recording_stream(tmp_path / "run.rrd", "x") as rec:
        rec.log("world/a", rr.Points3D([[1.0, 2.0, 3.0]]), static=True)
        raise RuntimeError("disk full")
    assert list(tmp_path.iterdir()) == []


def test_the_recording_id_comes_from_the_scenario_and_seed():
    assert recording_id(capped("default")) == recording_id(capped("default"))
    assert recording_id(capped("default")) != recording_id(capped("default", seed=2))


def test_the_file_is_written_from_its_chunks_one_at_a_time(tmp_path):
    """The final file's chunks are made from the scratch file's read back one at a time (a first pass for the row ids,
    then each chunk identified and handed on before the next is read), not from the whole recording at once; they
    are the chunks of the file written."""
    import twin.view.rrd_stream as rrd_stream

    scratch = tmp_path / "scratch.rrd"
    with rr.RecordingStream("test", recording_id="fixed", batcher_config=rr.ChunkBatcherConfig.NEVER()) as rec:
        rec.save(scratch)
        for k in range(4):
            rec.send_columns(f"plots/x{k}", indexes=[rr.TimeColumn("sim_time", duration=np.arange(3.0))],
                             columns=rr.Scalars.columns(scalars=np.arange(3.0)))
    read = []

    def chunks():
        for k, chunk in enumerate(RrdReader(scratch).stream()):
            read.append(k)
            yield chunk

    identified = rrd_stream._identified(chunks, "fixed", "run.rrd")
    made = [next(identified)]
    n = len(read) - 1
    assert n > 4 and read == [*range(n), 0]  # the row ids of all, then the first chunk only
    made += list(identified)
    assert read == [*range(n), *range(n)] and len(made) == n
    rows = np.concatenate([rrd_stream._row_words(c.to_record_batch().column(ROW_ID))[:, 1] for c in made])
    assert np.array_equal(rows, np.arange(1, rows.size + 1)) and rows.size >= 12  # numbered in logging order


def test_rows_out_of_logging_order_in_the_file_are_ranked_by_their_ids(tmp_path):
    """Rows the file holds in logging order are numbered as they come (one pass, only the late rows' ids held); rows
    written later than logged (here: static logs, the batcher's, and the chunks read in a shuffled order) are ranked
    by their ids: every row gets the rank of its id among all."""
    import twin.view.rrd_stream as rrd_stream

    scratch = tmp_path / "scratch.rrd"
    with rr.RecordingStream("test", recording_id="fixed", batcher_config=rr.ChunkBatcherConfig.NEVER()) as rec:
        rec.save(scratch)
        for k in range(5):
            rec.log(f"plots/x{k}", rr.SeriesLines(names=[f"x{k}"]), static=True)  # written at the flush
            rec.send_columns(f"plots/x{k}", indexes=[rr.TimeColumn("sim_time", duration=np.arange(4.0))],
                             columns=rr.Scalars.columns(scalars=np.arange(4.0) + 10 * k))
    chunks = list(RrdReader(scratch).stream())
    for late, order in ((5, np.arange(len(chunks))), (None, np.random.default_rng(0).permutation(len(chunks)))):
        shuffled = [chunks[i] for i in order]
        words = [rrd_stream._row_words(c.to_record_batch().column(ROW_ID)) for c in shuffled]
        stacked = np.concatenate(words)
        expected = np.empty(len(stacked), np.uint64)
        expected[np.lexsort((stacked[:, 1], stacked[:, 0]))] = np.arange(1, len(stacked) + 1)
        ranks = rrd_stream._Ranks(lambda: shuffled)
        got = np.concatenate([ranks.of(k, w) for k, w in enumerate(words)])
        assert np.array_equal(got, expected)
        assert late is None or len(ranks._late) == late  # in the file's order only the logged looks are held
