"""Batched Rerun logging: whole histories sent column-wise with `send_columns` on the `sim_time` timeline.

One call per entity carries its whole history (time columns, scalar series, bar-chart tensors), decimated to what
a person can see; shared by the run's and the estimators' recordings.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import rerun as rr

TIMELINE = "sim_time"
APPLICATION_ID = "longwall-twin"


def col(table: pa.Table, name: str) -> np.ndarray:
    return table.column(name).to_numpy()

def vec(table: pa.Table, prefix: str, axes: str = "enu") -> np.ndarray:
    return np.column_stack([col(table, f"{prefix}_{a}") for a in axes]).astype(float)

def time_column(t: np.ndarray) -> rr.TimeColumn:
    """Seconds as a duration timeline, rounded to whole nanoseconds (no truncation of 0.1 -> 99999999 ns)."""
    ns = np.round(np.asarray(t, float) * 1e9).astype(np.int64)
    return rr.TimeColumn(TIMELINE, duration=ns.astype("timedelta64[ns]"))

def xyzw(q_wxyz: np.ndarray) -> np.ndarray:
    """Scalar-first (w, x, y, z) to Rerun's (x, y, z, w)."""
    return np.ascontiguousarray(q_wxyz[..., [1, 2, 3, 0]], dtype=np.float32)

def latest_rows(t: np.ndarray, ident: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Forward-filled row index of every id at every distinct time of a (t, id)-keyed stream.

    Returns (times (n_t,), ids (n_id,), rows (n_t, n_id)): rows[k, j] is the table row holding the latest
    state of ids[j] at times[k]. An id that first appears after times[0] takes its first state before that.
    """
    order = np.lexsort((ident, t))  # by t, then id; later rows win for duplicates
    times, t_idx = np.unique(t[order], return_inverse=True)
    ids, id_idx = np.unique(ident[order], return_inverse=True)
    # Sorted positions increase with time, so the running maximum of the position is the latest update.
    pos = np.full((times.size, ids.size), -1, np.int64)
    pos[t_idx, id_idx] = np.arange(order.size)
    pos = np.maximum.accumulate(pos, axis=0)
    first = np.where(pos >= 0, pos, np.iinfo(np.int64).max).min(axis=0)
    pos = np.where(pos >= 0, pos, first[None, :])
    return times, ids, order[pos]

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

def decimate(t: np.ndarray, rate_hz: float) -> np.ndarray:
    """Indices of the first sample in each 1/rate_hz interval (plus the last sample)."""
    if t.size == 0:
        return np.zeros(0, np.int64)
    bins = np.floor(np.asarray(t, float) * rate_hz + 1e-9)
    keep = np.flatnonzero(np.r_[True, np.diff(bins) > 0])
    if keep[-1] != t.size - 1:
        keep = np.r_[keep, t.size - 1]
    return keep

def mean_rate(t: np.ndarray, values: np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Block means of increments per second at about rate_hz (sums over blocks / their duration)."""
    if t.size < 2:
        return t, values
    dt = float(np.median(np.diff(t)))
    step = max(1, int(round(1.0 / (rate_hz * dt))))
    n = (t.size // step) * step
    blocks = values[:n].reshape(n // step, step, -1).sum(axis=1)
    return t[step - 1:n:step], blocks / (step * dt)

def series(rec: rr.RecordingStream, entity: str, t: np.ndarray, values: np.ndarray, names: list[str]) -> None:
    rec.log(entity, rr.SeriesLines(names=names), static=True)
    rec.send_columns(entity, indexes=[time_column(t)], columns=rr.Scalars.columns(scalars=values))
