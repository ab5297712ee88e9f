"""Batched Rerun logging: whole histories sent column-wise with `send_columns` on the `sim_time` timeline.

An entity's history (time columns, scalar series, bar-chart tensors) goes out in one call, or in calls of SEND_ROWS
rows for a long series given in blocks, cut to what a person can see (twin.view.visible_cut.visible_rows: at most the record rate, and without the samples the drawn line passes
within a pixel of); shared by the run's and the estimators' recordings. A long stream comes in blocks
(twin.view.row_cuts.Blocks); `latest_frames` cuts a history of many instances (every pan or support at every frame)
into chunks sent one call each, `mean_rates` carries its state across blocks, and `PlottedSeries` cuts and sends
series given in blocks.

The record rate (twin.view.record_rate) is a rate in Hz, or FULL (None): every sample, neither decimated nor thinned.
"""

from __future__ import annotations

import pickle
import tempfile
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from typing import BinaryIO

import numpy as np
import pyarrow as pa
import rerun as rr

from twin.view.record_rate import FULL
from twin.view.row_cuts import Blocks, blocks_of, col
from twin.view.visible_cut import SeriesRange, VisibleCut

TIMELINE = "sim_time"
APPLICATION_ID = "longwall-twin"


def vec(table: pa.Table, prefix: str, axes: str = "enu") -> np.ndarray:
    return np.column_stack([col(table, f"{prefix}_{a}") for a in axes]).astype(float)


def time_column(t: np.ndarray) -> rr.TimeColumn:
    """Seconds as a duration timeline, rounded to whole nanoseconds (no truncation of 0.1 -> 99999999 ns)."""
    ns = np.round(np.asarray(t, float) * 1e9).astype(np.int64)
    return rr.TimeColumn(TIMELINE, duration=ns.astype("timedelta64[ns]"))


def xyzw(q_wxyz: np.ndarray) -> np.ndarray:
    """Scalar-first (w, x, y, z) to Rerun's (x, y, z, w)."""
    return np.ascontiguousarray(q_wxyz[..., [1, 2, 3, 0]], dtype=np.float32)


def latest_rows(t: np.ndarray, ident: np.ndarray, at: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Forward-filled row index of every id at every distinct time of a (t, id)-keyed stream (or at the times `at`).

    Returns (times (n_t,), ids (n_id,), rows (n_t, n_id)): rows[k, j] is the table row holding the latest
    state of ids[j] at times[k] (of two rows at one time the later). An id that first appears after times[k] takes its
    first state before that. Held: the rows at the times asked for, not a row per distinct time.
    """
    times = np.unique(t) if at is None else np.asarray(at, float)
    ids = np.unique(ident)
    rows = np.empty((times.size, ids.size), np.int64)
    for j, one in enumerate(ids):  # one pass per id (a face has a few hundred)
        mine = np.flatnonzero(ident == one)
        mine = mine[np.argsort(t[mine], kind="stable")]
        rows[:, j] = mine[np.maximum(np.searchsorted(t[mine], times, side="right") - 1, 0)]
    return times, ids, rows


def latest_frames(data: Blocks, ident: str, names: Sequence[str], rate_hz: float | None, states: int
                  ) -> Iterator[tuple[np.ndarray, dict[str, np.ndarray]]]:
    """`latest_rows` of a (t, id)-keyed stream (t nondecreasing; one table or blocks) at the last distinct time of each
    1/rate_hz interval (every distinct time at FULL rate), in chunks of F = states // n_id times (at least one):
    (times (F,), {name: (F, n_id)} the columns `names` of every id's latest row, ids in order), the last chunk with the
    rest. The same chunks whatever the blocks: the stream is read twice, first for each id's first row (its state
    before it appears), then a block at a time with each id's latest row carried across blocks and the rows of a
    block's last time held for the next (more rows at that time may follow)."""
    ids, state = _first_rows(data, ident, names)
    if ids.size == 0:
        return
    frames = max(1, states // ids.size)
    pending: list[tuple[np.ndarray, dict[str, np.ndarray]]] = []
    held = {"t": np.zeros(0), ident: ids[:0], **{name: state[name][:0] for name in names}}
    for block in [*blocks_of(data), None]:
        rows = held if block is None else {name: np.r_[held[name], col(block, name)] for name in held}
        if rows["t"].size == 0:
            continue
        distinct = np.unique(rows["t"])
        last = (np.ones(distinct.size, bool) if rate_hz is FULL
                else np.r_[np.diff(np.floor(distinct * rate_hz + 1e-9)) > 0, True])
        cut = rows["t"].size
        if block is not None:  # the block's last time waits for the rest of its rows and for the next time
            last[-1], cut = False, int(np.searchsorted(rows["t"], distinct[-1]))
        t = np.r_[np.full(ids.size, -np.inf), rows["t"][:cut]]  # each id's state before the block's rows
        who = np.r_[ids, rows[ident][:cut]]
        values = {name: np.r_[state[name], rows[name][:cut]] for name in names}
        times = distinct[last]
        for start in range(0, times.size, frames):
            at = latest_rows(t, who, times[start:start + frames])[2]
            pending.append((times[start:start + frames], {name: values[name][at] for name in names}))
            if sum(p[0].size for p in pending) >= frames:
                chunk, pending = _frame_chunks(pending, frames)
                yield chunk
        state = {name: values[name][latest_rows(t, who, [np.inf])[2][0]] for name in names}
        held = {name: rows[name][cut:] for name in rows}
    if pending:
        yield _frame_chunks(pending, frames)[0]


def _first_rows(data: Blocks, ident: str, names: Sequence[str]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The ids of a (t, id)-keyed stream, in order, and the columns `names` of each one's first row."""
    ids, firsts = np.zeros(0, np.int64), {name: [] for name in names}
    for block in blocks_of(data):
        new, at = np.unique(col(block, ident), return_index=True)
        at = at[~np.isin(new, ids)]
        ids = np.r_[ids, col(block, ident)[at]]
        for name in names:
            firsts[name].append(col(block, name)[at])
    order = np.argsort(ids)
    return ids[order], {name: np.concatenate(firsts[name])[order] for name in names}


def _frame_chunks(pending: list[tuple[np.ndarray, dict[str, np.ndarray]]], frames: int
                  ) -> tuple[tuple[np.ndarray, dict[str, np.ndarray]], list]:
    """The first `frames` of the frames pending (all of them when fewer), and the rest still pending."""
    times = np.concatenate([p[0] for p in pending])
    values = {name: np.concatenate([p[1][name] for p in pending]) for name in pending[0][1]}
    rest = [(times[frames:], {name: v[frames:] for name, v in values.items()})] if times.size > frames else []
    return (times[:frames], {name: v[:frames] for name, v in values.items()}), rest


class TensorColumn:
    """A column of 1-D float32 tensors (one per row) in Rerun's TensorData arrow layout.

    The Python TensorData batch accepts a single tensor only; this builds the same struct array for n rows
    so a BarChart history goes out in one `send_columns` call.
    """

    def __init__(self, values: np.ndarray) -> None:
        values = np.ascontiguousarray(values, np.float32)
        n_rows, n_vals = values.shape
        data_type = rr.BarChart(values=np.zeros(1, np.float32)).values.as_arrow_array().type
        shape_type = data_type.field("shape").type
        names_type = data_type.field("names").type
        union_type = data_type.field("buffer").type
        row_offsets = pa.array(np.arange(n_rows + 1, dtype=np.int32))
        shape = pa.ListArray.from_arrays(row_offsets, pa.array(np.full(n_rows, n_vals, np.uint64)), type=shape_type)
        names = pa.nulls(n_rows, names_type)
        # Dense union: every row is the F32 member, row k at offset k of the F32 child.
        children = [pa.nulls(0, type=f.type) for f in union_type]
        f32 = [f.name for f in union_type].index("F32")
        value_offsets = pa.array(np.arange(0, n_rows * n_vals + 1, n_vals, dtype=np.int32))
        children[f32] = pa.ListArray.from_arrays(value_offsets, pa.array(values.ravel())).cast(
            union_type[f32].type, safe=False)
        type_ids = pa.array(np.full(n_rows, union_type.type_codes[f32], np.int8))
        row_index = pa.array(np.arange(n_rows, dtype=np.int32))
        buffer = pa.Array.from_buffers(union_type, n_rows, [None, type_ids.buffers()[1], row_index.buffers()[1]],
                                       children=children)
        self._array = pa.StructArray.from_arrays([shape, names, buffer], fields=list(data_type)).cast(data_type)

    def as_arrow_array(self) -> pa.Array:
        return self._array


def send_bar_chart(rec: rr.RecordingStream, entity: str, times: np.ndarray, values: np.ndarray) -> None:
    column = rr.ComponentColumn(rr.BarChart.descriptor_values(), TensorColumn(values))
    rec.send_columns(entity, indexes=[time_column(times)], columns=[column])


def median_interval(data: Blocks) -> tuple[float, int]:
    """The median of a stream's sample intervals (np.median of np.diff of its times, NaN for fewer than two rows)
    and its number of rows, from its blocks: the intervals are counted by value (a sampled clock has few)."""
    values, counts, last, rows = np.zeros(0), np.zeros(0, np.int64), None, 0
    for block in blocks_of(data):
        t = col(block, "t")
        if t.size:
            values, at = np.unique(np.r_[values, np.diff(t) if last is None else np.diff(t, prepend=last)],
                                   return_inverse=True)
            counts = np.bincount(at, np.r_[counts, np.ones(at.size - counts.size, np.int64)]).astype(np.int64)
            last, rows = t[-1], rows + t.size
    n = int(counts.sum())
    if n == 0:
        return float("nan"), rows
    ranks = np.searchsorted(np.cumsum(counts), [(n - 1) // 2, n // 2], side="right")
    return float(np.mean(values[ranks[:2 - n % 2]])), rows


def mean_rates(data: Blocks, columns: list[str], rate_hz: float | None, interval: tuple[float, int]
               ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Means of increments (the stream's `columns`) per second at about rate_hz: sums over runs of `step` rows / their
    duration, `step` the record interval in median sample intervals (each sample at FULL rate); (times at the runs'
    ends, (M, len(columns))) a block at a time (a run of rows may span two). `interval`: the stream's
    median_interval."""
    dt, rows = interval
    if rows < 2:
        for block in blocks_of(data):
            yield col(block, "t"), np.column_stack([col(block, c) for c in columns]).astype(float)
        return
    step = 1 if rate_hz is FULL else max(1, int(round(1.0 / (rate_hz * dt))))
    n = (rows // step) * step
    carry, start = np.zeros((0, len(columns))), 0
    for block in blocks_of(data):
        at = np.arange((step - 1 - start) % step, block.num_rows, step)  # the runs' last rows
        values = np.concatenate([carry, np.column_stack([col(block, c) for c in columns]).astype(float)])
        m = (values.shape[0] // step) * step
        carry, start = values[m:], start + block.num_rows
        yield col(block, "t")[at[at + start - block.num_rows < n]], (values[:m].reshape(m // step, step, len(columns))
                                                                     .sum(axis=1) / (step * dt))


SEND_ROWS = 100_000
"""Rows of one entity sent in one call at most: a long stream's entity goes out in several chunks, not held whole."""


class RowBatches:
    """The rows kept of a long stream (arrays with a row per kept row), handed to `send` SEND_ROWS at a time and the
    rest at `flush` (at least once: a stream without rows is sent empty); `first` is called before the first send
    (to log the entity's look)."""

    def __init__(self, send: Callable[..., None], first: Callable[[], None] | None = None, rows: int = SEND_ROWS):
        self._send, self._first, self._limit = send, first, rows
        self._held: list[tuple[np.ndarray, ...]] = []
        self._rows, self._sent = 0, False

    def add(self, *columns: np.ndarray) -> None:
        self._held.append(columns)
        self._rows += len(columns[0])
        if self._rows >= self._limit:
            self.flush()

    def flush(self) -> None:
        if self._held and (self._rows or not self._sent):
            if not self._sent and self._first is not None:
                self._first()
            self._send(*(np.concatenate(c) for c in zip(*self._held)))
            self._sent = True
        self._held, self._rows = [], 0


SeriesBlock = Mapping[str, tuple[np.ndarray, np.ndarray]]
"""A block of plotted series: entity -> (times (k,), values (k, n)) of its next rows (an entity may be left out of a
block)."""


class PlottedSeries:
    """Time series given in blocks (the same entities in each), each cut to `visible_rows` at `rate_hz`
    (twin.view.row_cuts: the same rows as a whole series') and sent SEND_ROWS rows at a time. `measure` reads the
    blocks once, for each series' range (SeriesRange), and spools them to a scratch file; `send` reads them back from
    it to cut and send them, each entity's look logged before its first rows. So the blocks are made once (an
    estimate's errors interpolate the truth) and held a block at a time. `names`: entity -> its series' names;
    `steps`: the entities of flags and steps (band False: every edge kept)."""

    def __init__(self, names: Mapping[str, list[str]], rate_hz: float | None, steps: Iterable[str] = ()):
        self.names, self.rate_hz, self.steps = dict(names), rate_hz, set(steps)
        self.ranges: dict[str, SeriesRange] = {}
        self._spool: BinaryIO | None = None

    def measure(self, blocks: Iterable[SeriesBlock]) -> None:
        ranges = {entity: SeriesRange(self.rate_hz) for entity in self.names}
        spool = tempfile.TemporaryFile(prefix="longwall-series-")  # deleted when closed
        try:
            for block in blocks:
                for entity, rows in block.items():
                    ranges[entity].push(*rows)
                pickle.dump(dict(block), spool, protocol=pickle.HIGHEST_PROTOCOL)
        except BaseException:
            spool.close()
            raise
        for measured in ranges.values():
            measured.finish()
        self.ranges, self._spool = ranges, spool

    def finite(self, entity: str) -> bool:
        """Whether the entity's record-rate rows hold a finite value (measured)."""
        return self.ranges[entity].finite

    def drop(self, *entities: str) -> None:
        for entity in entities:
            self.names.pop(entity)

    def _spooled(self) -> Iterator[SeriesBlock]:
        if self._spool is None:
            raise RuntimeError("PlottedSeries.send before measure")
        spool, self._spool = self._spool, None
        with spool:
            spool.seek(0)
            while True:
                try:
                    yield pickle.load(spool)
                except EOFError:
                    return

    def send(self, rec: rr.RecordingStream) -> None:
        """The measured blocks cut and sent (once: the spool is closed after)."""
        cuts = {entity: VisibleCut(self.rate_hz, self.ranges[entity], entity not in self.steps)
                for entity in self.names}
        batches = {entity: series_batches(rec, entity, names) for entity, names in self.names.items()}
        for block in self._spooled():
            for entity, rows in block.items():
                if entity in cuts:
                    batches[entity].add(*cuts[entity].push(*rows)[1:])
        for entity, cut in cuts.items():
            batches[entity].add(*cut.finish()[1:])
            batches[entity].flush()

    def log(self, rec: rr.RecordingStream, blocks: Iterable[SeriesBlock]) -> None:
        """`measure` then `send`, every entity."""
        self.measure(blocks)
        self.send(rec)


def series_batches(rec: rr.RecordingStream, entity: str, names: list[str]) -> RowBatches:
    """A series' rows (times, values (k, n)) sent as Scalars, its look (SeriesLines) logged first."""
    return RowBatches(lambda t, values: rec.send_columns(entity, indexes=[time_column(t)],
                                                         columns=rr.Scalars.columns(scalars=values)),
                      lambda: rec.log(entity, rr.SeriesLines(names=names), static=True))


def series(rec: rr.RecordingStream, entity: str, t: np.ndarray, values: np.ndarray, names: list[str], *,
           rate_hz: float | None = FULL, band: bool = True) -> None:
    """A time series of (K, n) values given whole, its rows cut to `visible_rows` at `rate_hz` (every row by default);
    `band` False for flags and steps, whose every edge is kept (PlottedSeries for one in blocks)."""
    PlottedSeries({entity: names}, rate_hz, () if band else (entity,)).log(rec, [{entity: (t, values)}])
