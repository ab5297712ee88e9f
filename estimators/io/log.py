"""The sensor log as the estimators read it: the streams of a run directory (estimators.io.logformat) as arrays,
loaded and checked, or put together from stream columns.

The IMU stream, the log's largest (20 times the filter's epochs), is not held whole: the estimators read it a
window of rows at a time (`ImuRows`), from memory or from the run directory's Parquet file row group by row group,
so their memory does not grow with the length of the log."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from estimators.io.logformat import (
    FACE_SURVEY,
    IMU,
    MAG,
    ODOMETER,
    PUSHRAM,
    SURVEY,
    LogError,
    StreamBlocks,
    read_stream,
)

IMU_COLUMNS = ("t", *(f"dtheta_{a}" for a in "xyz"), *(f"dv_{a}" for a in "xyz"))
"""The IMU stream's columns, in the order ImuRows.read returns them."""

PERIOD_ROWS = 1 << 17
"""Rows from the start over which ImuRows.period takes the median sample interval."""


class ImuRows:
    """The IMU stream's rows (logformat IMU), read a window at a time: `size` rows, `read(i0, i1)` rows i0..i1-1 as
    (t (K,), dtheta (K, 3) [rad], dv (K, 3) [m/s]), `period` the median sample interval [s] over the first
    PERIOD_ROWS rows."""

    size: int

    def read(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        raise NotImplementedError

    def period(self) -> float:
        return float(np.median(np.diff(self.read(0, min(self.size, PERIOD_ROWS))[0])))

    def times_at(self, rows: np.ndarray) -> np.ndarray:
        """The times of the given rows (increasing), read a window of PERIOD_ROWS at a time."""
        out = np.empty(rows.size)
        for i0 in range(0, self.size, PERIOD_ROWS):
            k0, k1 = np.searchsorted(rows, [i0, i0 + PERIOD_ROWS])
            if k1 > k0:
                out[k0:k1] = self.read(i0, i0 + PERIOD_ROWS)[0][rows[k0:k1] - i0]
        return out


class ImuArrays(ImuRows):
    """IMU rows held in memory."""

    def __init__(self, t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray):
        self.t, self.dtheta, self.dv = t, dtheta, dv
        self.size = t.size

    def read(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.t[i0:i1], self.dtheta[i0:i1], self.dv[i0:i1]


class ImuBuffer(ImuRows):
    """IMU rows appended as they come (an online run), numbered from the log's first row; `forget_before` lets the
    rows before a given one go, so that the buffer holds what the passes still to run read."""

    def __init__(self):
        self.base = 0  # the number of the first row held
        self.size = 0
        self.t, self.dtheta, self.dv = np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))

    def append(self, t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray) -> None:
        self.t, self.dtheta, self.dv = (np.concatenate([self.t, t]), np.concatenate([self.dtheta, dtheta]),
                                        np.concatenate([self.dv, dv]))
        self.size += t.size

    def forget_before(self, row: int) -> None:
        k = min(max(row - self.base, 0), self.t.size)
        self.t, self.dtheta, self.dv = self.t[k:].copy(), self.dtheta[k:].copy(), self.dv[k:].copy()
        self.base += k

    def read(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        i0, i1 = max(i0, 0), min(i1, self.size)
        if i0 < self.base and i1 > i0:
            raise ValueError(f"IMU rows {i0}..{self.base - 1} were let go (ImuBuffer.forget_before)")
        k0, k1 = i0 - self.base, max(i1 - self.base, i0 - self.base)
        return self.t[k0:k1], self.dtheta[k0:k1], self.dv[k0:k1]

    def times_at(self, rows: np.ndarray) -> np.ndarray:
        return self.read(int(rows[0]), int(rows[-1]) + 1)[0][rows - rows[0]] if rows.size else np.zeros(0)


class ImuFile(ImuRows):
    """IMU rows read from a stream file row group by row group (the last group read is kept for the next window).
    `open` checks the whole file a row group at a time (logformat.StreamBlocks), so a window read later is known
    good."""

    def __init__(self, path: Path, starts: np.ndarray):
        self.path, self._starts = Path(path), starts  # first row of each row group, then the row count
        self.size = int(starts[-1])
        self._cached: tuple[int, np.ndarray] | None = None

    @classmethod
    def open(cls, path: Path) -> ImuFile:
        counts = [block.num_rows for block in StreamBlocks(Path(path).parent, IMU)]  # each row group checked
        return cls(path, np.concatenate([[0], np.cumsum(counts, dtype=np.int64)]))

    def _group(self, g: int) -> np.ndarray:
        if self._cached is None or self._cached[0] != g:
            table = pq.ParquetFile(self.path).read_row_group(g, columns=list(IMU_COLUMNS))
            self._cached = (g, np.column_stack([table.column(c).to_numpy() for c in IMU_COLUMNS]))
        return self._cached[1]

    def times_at(self, rows: np.ndarray) -> np.ndarray:
        """The times of the given rows (increasing), reading only the time column."""
        out = np.empty(rows.size)
        parquet = pq.ParquetFile(self.path)
        for g in range(self._starts.size - 1):
            k0, k1 = np.searchsorted(rows, self._starts[g:g + 2])
            if k1 > k0:
                t = parquet.read_row_group(g, columns=["t"]).column("t").to_numpy()
                out[k0:k1] = t[rows[k0:k1] - self._starts[g]]
        return out

    def read(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        i0, i1 = max(i0, 0), min(i1, self.size)
        if i1 <= i0:
            return np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))
        g0 = int(np.searchsorted(self._starts, i0, side="right")) - 1
        g1 = int(np.searchsorted(self._starts, i1, side="left"))
        rows = np.concatenate([self._group(g) for g in range(g0, g1)]) if g1 - g0 > 1 else self._group(g0)
        rows = rows[i0 - self._starts[g0]:i1 - self._starts[g0]]
        return np.ascontiguousarray(rows[:, 0]), np.ascontiguousarray(rows[:, 1:4]), np.ascontiguousarray(rows[:, 4:7])


@dataclass(frozen=True)
class Log:
    """The streams the positioning reads (columns as in estimators.io.logformat); the IMU's as ImuRows."""

    imu: ImuRows
    odo_t: np.ndarray
    odo_distance: np.ndarray
    odo_direction: np.ndarray
    survey_t: np.ndarray
    survey_llh: np.ndarray  # (S, 3)
    survey_yaw: np.ndarray
    survey_sd: np.ndarray  # (S, 3): horizontal, vertical [m], yaw [rad]
    ram_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ram_support: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    ram_extension: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ram_valid: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    mag_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mag_b: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (M, 3) [T]
    face_u: np.ndarray = field(default_factory=lambda: np.zeros(0))  # FACE_SURVEY: distance from the start pose
    face_llh: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    face_sd: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # horizontal, vertical [m]

    @property
    def imu_t(self) -> np.ndarray:
        """The IMU's times, all of them (read whole: for small logs)."""
        return self.imu.read(0, self.imu.size)[0]

    @property
    def dtheta(self) -> np.ndarray:
        """The IMU's angle increments, all of them (read whole: for small logs)."""
        return self.imu.read(0, self.imu.size)[1]

    @property
    def dv(self) -> np.ndarray:
        """The IMU's velocity increments, all of them (read whole: for small logs)."""
        return self.imu.read(0, self.imu.size)[2]


def log_from_columns(imu, odometer, survey, pushram=None, mag=None, face_survey=None) -> Log:
    """A Log from stream columns (pyarrow tables or mappings of arrays, logformat column names; the IMU's may be
    ImuRows)."""
    def col(table, name):
        c = table[name] if isinstance(table, dict) else table.column(name)
        return np.asarray(c if isinstance(c, np.ndarray) else c.to_numpy())

    optional = {}
    if pushram is not None:
        optional.update(ram_t=col(pushram, "t"), ram_support=col(pushram, "support"),
                        ram_extension=col(pushram, "extension"), ram_valid=col(pushram, "valid"))
    if mag is not None:
        optional.update(mag_t=col(mag, "t"), mag_b=np.column_stack([col(mag, f"b_{a}") for a in "xyz"]))
    if face_survey is not None:
        optional.update(face_u=col(face_survey, "u"),
                        face_llh=np.column_stack([col(face_survey, k) for k in ("lat", "lon", "h")]),
                        face_sd=np.column_stack([col(face_survey, k) for k in ("sd_horizontal", "sd_vertical")]))
    if not isinstance(imu, ImuRows):
        imu = ImuArrays(col(imu, "t"), np.column_stack([col(imu, f"dtheta_{a}") for a in "xyz"]),
                        np.column_stack([col(imu, f"dv_{a}") for a in "xyz"]))
    return Log(imu=imu, odo_t=col(odometer, "t"),
               odo_distance=col(odometer, "distance"), odo_direction=col(odometer, "direction"),
               survey_t=col(survey, "t"), survey_llh=np.column_stack([col(survey, k) for k in ("lat", "lon", "h")]),
               survey_yaw=col(survey, "yaw"),
               survey_sd=np.column_stack([col(survey, k) for k in ("sd_horizontal", "sd_vertical", "sd_yaw")]),
               **optional)


MIN_ROWS = {IMU.name: (2, "two IMU samples give the first sample interval"),
            ODOMETER.name: (1, "one odometer sample"), SURVEY.name: (1, "the surveyed start pose")}
"""Fewest rows of the streams the positioning needs, and why."""


def _check_rows(run_dir: Path, stream, rows: int) -> None:
    least, why = MIN_ROWS[stream.name]
    if rows < least:
        raise LogError(f"{Path(run_dir) / stream.filename}: {rows} rows, the positioning needs at least "
                       f"{least} ({why}); import a recording that has them")


def load_log(run_dir: Path) -> Log:
    """The streams of a run directory the positioning reads (push rams, magnetometer and face survey optional),
    checked on load; the IMU's stay on disk (ImuFile)."""
    def optional(stream):
        return read_stream(run_dir, stream) if (Path(run_dir) / stream.filename).is_file() else None

    def required(stream):
        table = read_stream(run_dir, stream)
        _check_rows(run_dir, stream, table.num_rows)
        return table

    path = Path(run_dir) / IMU.filename
    if not path.is_file():
        raise LogError(f"{path}: stream file not found")
    imu = ImuFile.open(path)
    _check_rows(run_dir, IMU, imu.size)
    return log_from_columns(imu, required(ODOMETER), required(SURVEY),
                            optional(PUSHRAM), optional(MAG), optional(FACE_SURVEY))


PIECE_STREAMS = (IMU, ODOMETER, SURVEY, PUSHRAM, FACE_SURVEY)
"""The streams an online run reads (estimators.shearer.online.OnlinePositioning.feed), the first two required."""


def log_pieces(run_dir: Path) -> Iterator[tuple[dict[str, dict[str, np.ndarray]], bool]]:
    """A run directory's log for an online run, in consecutive pieces of time: (stream name -> columns, last piece).
    Each piece is an IMU row group and every other stream's rows up to its last time (t <= it; the rest with the
    last piece), each stream read a row group at a time and checked as load_log checks it (logformat.StreamBlocks),
    so that only a row group of each is held."""
    run_dir = Path(run_dir)
    present = [s for s in PIECE_STREAMS if (run_dir / s.filename).is_file() or s in (IMU, ODOMETER, SURVEY)]
    for stream in present[:3]:
        if not (run_dir / stream.filename).is_file():
            raise LogError(f"{run_dir / stream.filename}: stream file not found")
        _check_rows(run_dir, stream, pq.ParquetFile(run_dir / stream.filename).metadata.num_rows)
    others = {s.name: _Cursor(StreamBlocks(run_dir, s)) for s in present[1:]}
    imu_blocks = iter(StreamBlocks(run_dir, IMU))
    block = next(imu_blocks)
    while block is not None:
        after = next(imu_blocks, None)  # one block ahead: whether this one is the last
        t_last = float(block.column("t")[-1].as_py()) if block.num_rows and after is not None else np.inf
        rows = {name: c.until(t_last) for name, c in others.items()}
        piece = {IMU.name: _columns(block)} | {name: r for name, r in rows.items() if r is not None}
        yield piece, after is None
        block = after


def _columns(table) -> dict[str, np.ndarray]:
    return {name: table.column(name).to_numpy() for name in table.column_names}


class _Cursor:
    """A stream's rows handed out in order of time, up to a given time, its row groups read as they are reached."""

    def __init__(self, blocks: StreamBlocks):
        self.blocks = iter(blocks)
        self.held: dict[str, np.ndarray] | None = None
        self.ended = False

    def until(self, t_end: float) -> dict[str, np.ndarray] | None:
        """The rows not handed out yet with t <= t_end (None once the stream has ended)."""
        parts = []
        while True:
            if self.held is None:
                block = None if self.ended else next(self.blocks, None)
                if block is None:
                    self.ended = True
                    break
                self.held = _columns(block)
            n = int(np.searchsorted(self.held["t"], t_end, side="right"))
            parts.append({k: v[:n] for k, v in self.held.items()})
            if n < self.held["t"].size:
                self.held = {k: v[n:] for k, v in self.held.items()}
                break
            self.held = None
        if not parts:
            return None
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
