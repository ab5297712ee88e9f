"""Sensor streams published in blocks (`longwall serve`, twin.opcua.server): a stream at its full rate (the IMU's
200 Hz) cannot go as one value change per sample, so each publication puts the rows made since the last into one
block (arrays of each column, a SequenceNumber that grows by one a block, the index of its first row in the stream),
and the server keeps the last blocks of each stream in a ring buffer a client that reconnects reads what it missed
from (ReadBlocks, twin.opcua.address_space). No asyncua here.

A stream's rows come from the twin as they are drawn (twin.pipeline.simulate.LiveTaps.sensors), often ahead of the
publisher's clock: they wait until the publication whose simulated time reaches them. `complete_until` says how far
the stream is published: every row before that time is in a block (rows of one time are never split).
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass

import numpy as np

from estimators.io.logformat import Stream

SENSOR_NODES = {"imu": "Imu", "odometer": "Odometer", "mag": "Magnetometer", "survey": "Survey",
                "face_survey": "FaceSurvey", "pushram": "PushRam", "pressure": "Pressure", "support_imu": "SupportImu"}
"""The sensor streams published (logformat stream name -> browse name under Longwall/Sensors)."""
HISTORY_S = 60.0
"""Default simulated time of each stream's ring buffer [s] (its blocks: that times the publication rate)."""
MAX_READ_ROWS = 1 << 16
"""Most rows one ReadBlocks answer holds (at least one block): the client asks again for the rest."""


@dataclass(frozen=True)
class Block:
    """One publication's rows of a stream: its SequenceNumber (1 for the first), the index of its first row in the
    stream, the columns (logformat names) and how far the stream was published with it."""

    sequence: int
    first_row: int
    columns: dict[str, np.ndarray]
    complete_until: float

    @property
    def rows(self) -> int:
        return int(self.columns["t"].size)


class BlockStream:
    """One sensor stream's rows waiting for their publication (`add`), its blocks (`publish`) and the last `history`
    of them (`read`). `read` may be called from another thread (asyncua answers method calls in a thread pool) while
    the publisher appends: the ring is read and appended under a lock."""

    def __init__(self, stream: Stream, history: int):
        if history < 1:
            raise ValueError(f"history: at least one block (got {history})")
        self.stream = stream
        self.pending: deque[dict[str, np.ndarray]] = deque()
        self.made_until = 0.0  # every row before it has been added
        self.sequence = 0  # the last block's
        self.rows = 0  # rows published
        self.ring: deque[Block] = deque(maxlen=history)
        self._ring_lock = threading.Lock()

    def add(self, columns: dict[str, np.ndarray], made_until: float) -> None:
        """The stream's next rows (in time order), and the time before which it has no more to come."""
        if columns["t"].size:
            self.pending.append(columns)
        self.made_until = made_until

    @property
    def complete_until(self) -> float:
        """Every row before this time is published (inf: the whole stream)."""
        return float(self.pending[0]["t"][0]) if self.pending else self.made_until

    def publish(self, t: float) -> Block | None:
        """The block of the rows waiting up to time t (inclusive; inf: all), None when there are none."""
        taken = []
        while self.pending:
            piece = self.pending[0]
            k = int(np.searchsorted(piece["t"], t, side="right"))
            if k == piece["t"].size:
                taken.append(self.pending.popleft())
                continue
            if k:
                taken.append({c: v[:k] for c, v in piece.items()})
                self.pending[0] = {c: v[k:] for c, v in piece.items()}
            break
        if not taken:
            return None
        columns = {c.name: np.concatenate([p[c.name] for p in taken]) for c in self.stream.columns}
        self.sequence += 1
        block = Block(self.sequence, self.rows, columns, self.complete_until)
        self.rows += block.rows
        with self._ring_lock:
            self.ring.append(block)
        return block

    def read(self, from_sequence: int, max_rows: int = MAX_READ_ROWS) -> list[Block]:
        """The blocks held from `from_sequence` on (those before the oldest held are gone: the answer starts later),
        at most `max_rows` rows but at least one block when there is one."""
        with self._ring_lock:
            held = list(self.ring)
        out, rows = [], 0
        for block in held:
            if block.sequence < from_sequence:
                continue
            if out and rows + block.rows > max_rows:
                break
            out.append(block)
            rows += block.rows
        return out
