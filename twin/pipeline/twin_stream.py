"""The twin stage of a run as it streams: the face simulated, the shearer truth and trial 0's shearer streams drawn
and appended to the run directory a chunk at a time.

twin.pipeline.simulate hands over the shearer truth a ride chunk (a cycle) at a time; this module cuts it into
TruthChunks with their halos (twin.sensors.chunks), draws the shearer's sensor streams for each
(twin.sensors.streams.ShearerSensors, which carries the sensors' state), and appends truth and readings to their
Parquet files in fixed row groups (estimators.io.logformat.StreamAppender), so the files' bytes do not depend on
the chunking. The supports' truth is written as its rows become final (after each cycle's events;
twin.pipeline.face_recorder.FinalRows), and their push-ram and pressure streams drawn from them a span of time at a
time (twin.sensors.streams.SupportSensors; SupportDraw) and appended the same way. What stays in memory for the whole
run: the pans' rows (a row per move), the supports' with support IMUs, and, where the support streams read the
shearer's place along the face, its (t, s) (ShearerTrack). Live taps get every sensor row the files get, as it is
drawn.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from estimators.io.logformat import ALIGNMENT, STREAMS, StreamAppender, write_stream
from twin.config.scenario import Scenario, support_count
from twin.face.drift import OffsetSource
from twin.face.haulage import Timeline
from twin.pipeline.alignment_loop import alignment_table
from twin.pipeline.face_recorder import FinalRows, concat_rows
from twin.pipeline.simulate import (
    LiveTaps,
    Progress,
    SensorSink,
    SimResult,
    cycles_table,
    last_truth_time,
    simulate_stream,
)
from twin.sensors.chunks import ChunkAssembler, TruthChunk, halo_rows
from twin.sensors.faults import faults_table
from twin.sensors.streams import ShearerSensors, SupportSensors, support_imu_readings
from twin.view.summary import LatestAt, ShearerStats

SHEARER_STREAMS = ("imu", "odometer", "mag", "survey", "face_survey")
"""The streams drawn from the shearer's truth chunk by chunk."""
SENSOR_CHUNK_ROWS = 1 << 18
"""The shearer's truth goes to the sensor models in chunks of at most this many rows (22 min at 200 Hz): their
intermediate arrays stay small whatever a cycle's length (seed004's 77 min cycles: peak 2.07 -> 1.27 GB)."""
SUPPORT_STREAMS = ("pushram", "pressure")
"""The streams drawn from the supports' truth a span of time at a time (SupportDraw)."""
SUPPORT_TRUTH = ("t", "s")
"""The shearer truth columns the support streams read (ShearerTrack)."""


class ShearerTrack:
    """The shearer truth's (t, s) the support streams read, held only where they read it: about each rail_deviation
    fault's window (twin.sensors.pushram places the deviation where the shearer's centre travels, s interpolated at
    the window's start), and over the whole run with support IMUs (the shearer's field at each canopy unit,
    twin.sensors.support_imu); a run with neither holds no per-sample row. The margin of two truth steps about a
    window keeps the samples on either side of its ends, so the readings are those of the whole run's (t, s)."""

    def __init__(self, scn: Scenario):
        self.everything = bool(scn.sensors.support_imu.supports)
        margin = 2.0 / scn.rates.truth_hz
        self.windows = np.array([(f.t_start_s - margin, f.t_end_s + margin) for f in scn.faults
                                 if f.kind == "rail_deviation"]).reshape(-1, 2)
        self.parts: dict[str, list[np.ndarray]] = {k: [] for k in SUPPORT_TRUTH}
        self.t_last = -np.inf

    def add(self, rows: dict[str, np.ndarray]) -> None:
        t = rows["t"]
        if t.size:
            self.t_last = float(t[-1])
        keep = slice(None) if self.everything else (
            (t[:, None] >= self.windows[:, 0]) & (t[:, None] <= self.windows[:, 1])).any(axis=1)
        for k in SUPPORT_TRUTH:
            self.parts[k].append(rows[k][keep])

    def rows(self) -> dict[str, np.ndarray]:
        """The held (t, s) in time order (concatenated once per call, kept as one block)."""
        for k in SUPPORT_TRUTH:
            self.parts[k] = [np.concatenate(self.parts[k])] if self.parts[k] else [np.empty(0)]
        return {k: v[0] for k, v in self.parts.items()}


class SupportDraw:
    """Sensor trial 0's push-ram and pressure streams drawn a span of time at a time, handed to `write` (a
    SensorSink): `until` draws every sample before t_end from the truth_supports rows `add`ed so far (final before
    it), `finish` the rest. Only each support's latest row before the drawn time and the
    rows after it are held (twin.sensors.clock.true_at reads no more)."""

    def __init__(self, scn: Scenario, write: SensorSink):
        self.sensors, self.write = SupportSensors(scn, 0), write
        self.rows: dict[str, np.ndarray] | None = None
        self.t_drawn = 0.0

    def add(self, rows: dict[str, np.ndarray]) -> None:
        if rows["t"].size:
            self.rows = rows if self.rows is None else concat_rows([self.rows, rows])

    def until(self, t_end: float, shearer: dict[str, np.ndarray]) -> None:
        if self.rows is not None and t_end > self.t_drawn:
            self._draw(t_end, False, self.rows, shearer)
            t, sup = self.rows["t"], self.rows["support"]
            before = t < t_end  # rows sorted by (t, support): each support's latest row before t_end is its last
            rows_before = np.flatnonzero(before)
            sup_before = sup[rows_before]
            latest = rows_before[sup_before.size - 1 - np.unique(sup_before[::-1], return_index=True)[1]]
            keep = np.concatenate([np.sort(latest), np.flatnonzero(~before)])
            self.rows = {k: v[keep] for k, v in self.rows.items()}

    def finish(self, shearer: dict[str, np.ndarray], t_end: float) -> None:
        """The rest up to the run's last truth time t_end (every row `add`ed)."""
        self._draw(t_end, True, self.rows, shearer)

    def _draw(self, t_end: float, last: bool, supports: dict[str, np.ndarray], shearer: dict[str, np.ndarray]) -> None:
        for t0, t1, end in self.sensors.spans(t_end, self.t_drawn, last):
            readings = self.sensors.step(t0, t1, end, supports, shearer)
            for name in ("pushram", "pressure"):
                self.write(name, readings[name], np.inf if end else t1)
        self.t_drawn = t_end


def stream_twin(scn: Scenario, run_dir: Path, sensors: bool = True, progress: Progress | None = None,
                chunk_rows: int = SENSOR_CHUNK_ROWS, offsets: OffsetSource | None = None, live: LiveTaps | None = None
                ) -> tuple[SimResult, ShearerStats]:
    """Simulate `scn` into `run_dir`: the truth streams and, with `sensors`, sensor trial 0's streams, written as the
    run goes. `chunk_rows` cuts the shearer's truth into chunks of at most that many rows; the files are the same
    whatever it is. `offsets`: the per-cycle offsets of the supports' pushes
    (twin.face.drift.OffsetSource); `live` taps the run as it goes (twin.pipeline.simulate.LiveTaps). Returns the simulation's result without the shearer's truth
    (which is on disk) and the shearer's statistics."""
    report = progress or (lambda stage, frac: None)
    timeline = Timeline(scn)
    cycles = cycles_table(timeline)
    shearer_sensors = ShearerSensors(scn, 0, cycles, last_truth_time(scn, timeline)) if sensors else None
    names = ("truth_shearer", *((*SHEARER_STREAMS, *SUPPORT_STREAMS) if sensors else ()))
    appenders = {name: StreamAppender(run_dir, STREAMS[name]) for name in names}
    assembler = ChunkAssembler(halo_rows(scn))
    stats = ShearerStats()
    track = ShearerTrack(scn)

    def write(name: str, cols: dict[str, np.ndarray], until: float) -> None:
        appenders[name].append(cols)
        if live is not None and live.sensors is not None:
            live.sensors(name, cols, until)

    def take(chunk: TruthChunk) -> None:
        appenders["truth_shearer"].append(chunk.rows)
        stats.update(chunk.rows)
        if shearer_sensors is not None:
            for name, cols in shearer_sensors.step(chunk).items():
                write(name, cols, np.inf if chunk.last else chunk.t_end)

    def sink(rows: dict[str, np.ndarray]) -> None:
        track.add(rows)
        for a in range(0, rows["t"].size, chunk_rows):
            for chunk in assembler.push({k: v[a:a + chunk_rows] for k, v in rows.items()}):
                take(chunk)

    supports_draw = SupportDraw(scn, write) if sensors else None
    final_rows = FinalRows()
    advance = LatestAt(cycles["t_end"], support_count(scn))
    supports_whole: list[dict[str, np.ndarray]] = []  # the supports' truth, held for support IMUs only
    supports_file = StreamAppender(run_dir, STREAMS["truth_supports"])

    def supports_sink(rows: dict[str, np.ndarray], t_final: float) -> None:
        """The face's support rows as they become final: written, summarized, and their readings drawn."""
        final = final_rows.split(rows, t_final)
        supports_file.append(final)
        advance.add(final["t"], final["support"], final["advance"])
        if scn.sensors.support_imu.supports:
            supports_whole.append(final)
        if supports_draw is not None:
            supports_draw.add(final)
            if np.isfinite(t_final) and np.isfinite(track.t_last):
                supports_draw.until(min(t_final, track.t_last), track.rows())

    try:
        result = simulate_stream(scn, sink, progress, offsets, live, supports_sink)
        for chunk in assembler.finish():
            take(chunk)
        if supports_draw is not None:
            supports_draw.finish(track.rows(), track.t_last)
    finally:
        for appender in (*appenders.values(), supports_file):
            appender.close()
    result.support_advance = advance.finish()
    for name, cols in result.tables.items():
        if name != "truth_supports":  # written as it came (an estimator-fed loop also keeps it in the result)
            write_stream(run_dir, STREAMS[name], cols)
    write_stream(run_dir, ALIGNMENT, alignment_table(scn, cycles["t"], result.offsets, result.alignment))
    if sensors:
        write_stream(run_dir, STREAMS["faults"], faults_table(scn))
        imu = support_imu_readings(scn, concat_rows(supports_whole), track.rows(), 0) if supports_whole else None
        if imu is not None:
            write_stream(run_dir, STREAMS["support_imu"], imu)
            if live is not None and live.sensors is not None:
                live.sensors("support_imu", imu, np.inf)
        report("sensors", 1.0)
    return result, stats
