"""Rerun recordings written reproducibly: the same scenario and seed, the same bytes.

Rerun stamps what it logs with time-based ids (TUIDs: nanoseconds since the epoch plus a per-thread random
counter), one per row and one per chunk, and adds the wall-clock timeline `log_time` to `log` calls that are
not static. `recording_stream` lets the caller log as usual, into a scratch file; on leaving, the final file
is written from that file's chunks, read back a chunk at a time, as identified chunks
(rerun.chunk.Chunk.from_record_batch keeps the row-id column and chunk id it is given) with the ids numbered in
logging order under a base drawn from the recording id and the file name (run.rrd and estimates.rrd share a
recording id and are merged by the viewer, so they must not share a chunk or row id), and without `log_time`. The
logging stream never flushes on its own (ChunkBatcherConfig.NEVER), so the cut of rows into chunks is the same
every time.

Three things rerun-sdk 0.41 writes from the clock or a hash map, with no API to set them, are dealt with so:

* the row id of each SetStoreInfo message (16 bytes of a protobuf TUID, fixed width): rewritten in place in the
  finished file (`_pin_store_info`), from the same base;
* the footer's manifest (schema metadata in hash-map order, different in every process): cut off with the
  end-of-stream message that carries it, which leaves the file write_footer=False writes (without the SDK's
  warning about it); the viewer and rerun.chunk.RrdReader read such a file whole, as any footerless .rrd;
* the blueprint's store (a random store id, chunk and row ids): not in the file. `longwall view` builds the
  blueprint from the run directory and hands it to the viewer (twin.view.layout).
"""
from __future__ import annotations

import hashlib
import uuid
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pyarrow as pa
import rerun as rr
from rerun.chunk import Chunk, RrdReader

from twin.config.scenario import Scenario, scenario_to_toml
from twin.view.rerun_columns import APPLICATION_ID

RECORDINGS = uuid.UUID("5f0c1d2e-7a41-4b6e-9c3d-2b8e6f1a4c70")
"""Namespace of the recording ids (uuid5 of the resolved scenario)."""
WALL_CLOCK = ("log_time",)
"""Timelines Rerun fills from the clock, left out of the written recording."""
ROW_ID = "rerun.controls.RowId"
CHUNK_ID = b"rerun:id"


def recording_id(scn: Scenario) -> str:
    """The recording id of a run: from its resolved scenario (seed included), so a run and its re-run share it."""
    return str(uuid.uuid5(RECORDINGS, scenario_to_toml(scn)))


def _base(recording: str, name: str) -> int:
    """The TUID time field of a file's ids: from the recording id and file name, below 2^63."""
    return int.from_bytes(hashlib.sha256(f"{recording}/{name}".encode()).digest()[:8], "big") >> 1


def _tuids(high: int, low: np.ndarray) -> pa.Array:
    """TUIDs (16 bytes: time, counter; big-endian) with time field `high` and counters `low`."""
    words = np.empty((low.size, 2), ">u8")
    words[:, 0], words[:, 1] = high, low
    return pa.FixedSizeBinaryArray.from_buffers(pa.binary(16), low.size, [None, pa.py_buffer(words.tobytes())])


def _row_words(column: pa.Array) -> np.ndarray:
    """A row-id column as (n, 2) unsigned words (time, counter): sorting them sorts by logging order."""
    data = np.frombuffer(column.buffers()[1], ">u8").reshape(-1, 2)
    return data[column.offset:column.offset + len(column)]


def _keys(words: np.ndarray) -> np.ndarray:
    """Row ids (n, 2) big-endian words as 16-byte keys that sort as the ids do."""
    return np.ascontiguousarray(words.astype(">u8")).view("S16").ravel()


class _Ranks:
    """Each row's rank (from 1) in logging order, for the chunks in file order, without holding every row id: the file
    holds most rows in logging order (what `send_columns` sends, written as it goes) and a few later than logged
    (what `log` gave the batcher, written at the flush). A first pass over the chunks holds the ids of the chunks out
    of order ("late"), a second (only when there are some) counts the rows in order below each late id."""

    def __init__(self, chunks: Callable[[], Iterable[Chunk]]):
        last, late, self._late_chunks = b"", [], set()
        for k, chunk in enumerate(chunks()):
            keys = _keys(_row_words(chunk.to_record_batch().column(ROW_ID)))
            if keys.size and (keys[0] <= last or (keys[1:] <= keys[:-1]).any()):
                late.append(keys.copy())
                self._late_chunks.add(k)
            elif keys.size:
                last = keys[-1]
        self._late = np.sort(np.concatenate(late)) if late else np.zeros(0, "S16")
        below = np.zeros(self._late.size, np.uint64)  # rows in order below each late id
        if late:
            for k, chunk in enumerate(chunks()):
                if k not in self._late_chunks:
                    below += np.searchsorted(_keys(_row_words(chunk.to_record_batch().column(ROW_ID))),
                                             self._late).astype(np.uint64)
        self._late_rank = below + np.arange(1, self._late.size + 1, dtype=np.uint64)
        self._in_order = 0  # rows in order ranked so far

    def of(self, k: int, words: np.ndarray) -> np.ndarray:
        """The ranks of chunk k's rows (row ids `words`), the chunks asked for in file order."""
        keys = _keys(words)
        if k in self._late_chunks:
            return self._late_rank[np.searchsorted(self._late, keys)]
        ranks = (self._in_order + np.arange(1, keys.size + 1, dtype=np.uint64)
                 + np.searchsorted(self._late, keys).astype(np.uint64))
        self._in_order += keys.size
        return ranks


def _identified(chunks: Callable[[], Iterable[Chunk]], recording: str, name: str) -> Iterator[Chunk]:
    """The chunks with chunk ids numbered in file order and row ids in logging order, under `_base`, and
    without the WALL_CLOCK timelines, one at a time: `chunks` gives them anew for each of two passes (the row ids
    first: _Ranks), so that a chunk at a time is held, whatever the recording's length."""
    ranks = _Ranks(chunks)
    base = _base(recording, name)
    for k, chunk in enumerate(chunks()):
        batch = chunk.to_record_batch()
        keep = [i for i, f in enumerate(batch.schema) if f.name not in WALL_CLOCK]
        schema = pa.schema([batch.schema.field(i) for i in keep])
        schema = schema.with_metadata({**batch.schema.metadata, CHUNK_ID: f"chunk_{base + 1:016X}{k:016x}".encode()})
        rank = ranks.of(k, _row_words(batch.column(ROW_ID)))
        columns = [_tuids(base, rank) if batch.schema.field(i).name == ROW_ID else batch.column(i) for i in keep]
        yield from Chunk.from_record_batch(pa.RecordBatch.from_arrays(columns, schema=schema))


STORE_INFO, END = 1, 0
"""Kinds of the SetStoreInfo and the end-of-stream message (which carries the footer) in the .rrd stream: after
the 12-byte file header, each message is its kind and payload length as little-endian u64, then its payload."""
FILE_HEADER = 12
TUID_FIELD = b"\x0a\x12\x09"
"""A SetStoreInfo payload starts with its row id: field 1, 18 bytes, a TUID of two fixed64 (tags 0x09, 0x11)."""


def _pin_store_info(path: Path, recording: str) -> None:
    """Rewrite the row id of every SetStoreInfo message of `path` as (`_base`, message number), 16 bytes each in
    place, and cut the file at its end-of-stream message (the footer); only the message headers are read."""
    base, k = _base(recording, f"{path.name}/store_info"), 0
    with open(path, "r+b") as f:
        size_all, off = path.stat().st_size, FILE_HEADER
        while off + 16 <= size_all:
            f.seek(off)
            kind, size = (int(v) for v in np.frombuffer(f.read(16), "<u8"))
            if kind == END:
                f.truncate(off)
                break
            head = f.read(20)
            if kind == STORE_INFO and head[:3] == TUID_FIELD and head[11] == 0x11:
                k += 1
                f.seek(off + 16 + 3)
                f.write(base.to_bytes(8, "little"))
                f.seek(off + 16 + 12)
                f.write(k.to_bytes(8, "little"))
            off += 16 + size


@contextmanager
def recording_stream(path: Path, recording: str) -> Iterator[rr.RecordingStream]:
    """A stream to log into; on leaving without an exception, `path` is written reproducibly (module docstring).
    The scratch file `.NAME.chunks` beside `path` is removed either way."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    scratch = path.with_name(f".{path.name}.chunks")
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording, send_properties=False,
                             batcher_config=rr.ChunkBatcherConfig.NEVER())
    try:
        rec.save(scratch)
        try:
            yield rec
            rec.flush()
        finally:
            rec.disconnect()
        out = rr.RecordingStream(APPLICATION_ID, recording_id=recording, send_properties=False)
        out.save(path)
        try:
            for chunk in _identified(lambda: RrdReader(scratch).stream(), recording, path.name):
                out.send_chunks(chunk)
                out.flush()  # written before the next is read: the sink's queue holds a chunk, not the recording
        finally:
            out.disconnect()
        _pin_store_info(path, recording)
    finally:
        scratch.unlink(missing_ok=True)
