"""The shearer truth in chunks, as a streaming run hands it to the sensor models.

A run streams: the twin hands over its shearer truth a chunk at a time (a cycle's ride, or a part of one), the
sensor models draw their readings for that chunk and carry their state (filters, counters, random generators) on
to the next. A model whose output depends on neighbouring truth samples (a derivative, a smoothing window, an
interpolation to its own clock) reads them from the chunk's halo: up to `halo_rows` truth rows before and after
it. Every sensor model's stepper obeys one contract, tested on random partitions of a run:

    concatenating its outputs over any partition of the truth into consecutive chunks gives, bit for bit,
    its output over the run in one chunk.

A stepper's `step(chunk)` returns the readings whose times fall in [chunk start, next chunk's start), and on
the last chunk those up to and including the run's last truth time.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from twin.config.scenario import Scenario
from twin.sensors.clock import sample_times

HALO_S = 1.0
"""Truth time on each side of a chunk the sensor models may read (more than the vibration envelope's reach)."""


def halo_rows(scn: Scenario) -> int:
    """Truth rows in a chunk's halo on each side: HALO_S at the truth rate, plus the rows of a difference stencil."""
    return int(np.ceil(HALO_S * scn.rates.truth_hz)) + 4


Columns = dict[str, np.ndarray]


def _take(cols: Columns, sl: slice) -> Columns:
    return {k: v[sl] for k, v in cols.items()}


def _join(parts: list[Columns]) -> Columns:
    parts = [p for p in parts if p and len(next(iter(p.values())))]
    if not parts:
        return {}
    if len(parts) == 1:
        return parts[0]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def _rows(cols: Columns) -> int:
    return len(next(iter(cols.values()))) if cols else 0


@dataclass(frozen=True)
class TruthChunk:
    """One chunk of the truth_shearer columns: its own `rows`, the halo `before` and `after` it (up to the halo's
    rows; none at the run's start or end), and whether it is the run's `first` and `last` chunk."""

    rows: Columns
    before: Columns
    after: Columns
    first: bool
    last: bool

    def padded(self) -> tuple[Columns, slice]:
        """The halo and the rows joined (before + rows + after) and the slice of the chunk's own rows in them."""
        n_before = _rows(self.before)
        return _join([self.before, self.rows, self.after]), slice(n_before, n_before + _rows(self.rows))

    @property
    def t_end(self) -> float:
        """Where the chunk's readings end: the next chunk's first truth time (excluded), or the run's last (included)."""
        return float(self.rows["t"][-1]) if self.last else float(self.after["t"][0])

    def clock(self, rate_hz: float) -> np.ndarray:
        """The times [s] of a sensor clock at rate_hz (twin.sensors.clock.sample_times between the run's first and
        last truth times) whose readings the chunk holds: those it owns, and on the last chunk every clock time up to
        the run's last truth time as sample_times takes it (within its rounding tolerance)."""
        t = sample_times(float(self.rows["t"][0]), self.t_end, rate_hz)
        keep = self.owns(t)
        if self.last:
            keep |= t > self.t_end
        return t[keep]

    def owns(self, t: np.ndarray) -> np.ndarray:
        """Which of the times t this chunk's readings hold (the contract's half-open interval)."""
        t0 = -np.inf if self.first else float(self.rows["t"][0])
        return (t >= t0) & ((t <= self.t_end) if self.last else (t < self.t_end))


class ChunkAssembler:
    """Turns truth pieces arriving in order (`push`) into TruthChunks with their halos: a piece is handed out once
    the rows after it fill its halo, the rest at `finish`. Holds at most a piece and two halos beyond it."""

    def __init__(self, halo: int):
        self.halo = halo
        self._tail: Columns = {}  # the rows before the first pending piece (at most a halo)
        self._pending: list[Columns] = []
        self._first = True

    def push(self, rows: Columns) -> Iterator[TruthChunk]:
        if _rows(rows):
            self._pending.append(rows)
        while len(self._pending) > 1 and sum(map(_rows, self._pending[1:])) >= self.halo:
            yield self._emit(last=False)

    def finish(self) -> Iterator[TruthChunk]:
        while self._pending:
            yield self._emit(last=len(self._pending) == 1)

    def _emit(self, last: bool) -> TruthChunk:
        rows = self._pending.pop(0)
        after = {} if last else _take(_join(self._pending), slice(0, self.halo))
        chunk = TruthChunk(rows, self._tail, after, self._first, last)
        self._tail = _take(_join([self._tail, rows]), slice(-self.halo, None))
        self._first = False
        return chunk


def split_truth(truth: Columns, starts, halo: int) -> Iterator[TruthChunk]:
    """The truth as chunks beginning at the row indices `starts` (0 first; an empty list: one chunk)."""
    n = _rows(truth)
    edges = sorted({0, *(int(s) for s in starts if 0 < int(s) < n)}) + [n]
    assembler = ChunkAssembler(halo)
    for a, b in zip(edges[:-1], edges[1:]):
        yield from assembler.push(_take(truth, slice(a, b)))
    yield from assembler.finish()
