"""The twin stage of a run as it streams: the face simulated, the shearer truth and trial 0's shearer streams drawn
and appended to the run directory a chunk at a time.

twin.pipeline.simulate hands over the shearer truth a ride chunk (a cycle) at a time; this module cuts it into
TruthChunks with their halos (twin.sensors.chunks), draws the shearer's sensor streams for each
(twin.sensors.streams.ShearerSensors, which carries the sensors' state), and appends truth and readings to their
Parquet files in fixed row groups (estimators.io.logformat.StreamAppender), so the files' bytes do not depend on
the chunking. The supports' push-ram and pressure streams are drawn after the face, a span of time at a time
(twin.sensors.streams.SupportSensors), and appended the same way. What stays in memory for the whole run: the face's
own tables (pans and supports, a row per move) and the shearer's (t, s), which the support streams read for the
shearer's place along the face.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from estimators.io.logformat import ALIGNMENT, STREAMS, StreamAppender, write_stream
from twin.config.scenario import Scenario
from twin.face.drift import OffsetSource
from twin.face.haulage import Timeline
from twin.pipeline.alignment_loop import alignment_table
from twin.pipeline.simulate import LiveTaps, Progress, SimResult, cycles_table, last_truth_time, simulate_stream
from twin.sensors.chunks import ChunkAssembler, TruthChunk, halo_rows
from twin.sensors.faults import faults_table
from twin.sensors.streams import ShearerSensors, SupportSensors, support_imu_readings
from twin.view.summary import ShearerStats

SHEARER_STREAMS = ("imu", "odometer", "mag", "survey", "face_survey")
"""The streams drawn from the shearer's truth chunk by chunk."""
SENSOR_CHUNK_ROWS = 1 << 18
"""The shearer's truth goes to the sensor models in chunks of at most this many rows (22 min at 200 Hz): their
intermediate arrays stay small whatever a cycle's length (seed004's 77 min cycles: peak 2.07 -> 1.27 GB)."""
SUPPORT_TRUTH = ("t", "s")
"""The shearer truth columns the support streams read (held for the whole run)."""


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
    names = ("truth_shearer", *(SHEARER_STREAMS if sensors else ()))
    appenders = {name: StreamAppender(run_dir, STREAMS[name]) for name in names}
    assembler = ChunkAssembler(halo_rows(scn))
    stats = ShearerStats()
    held = {k: [] for k in SUPPORT_TRUTH}

    def take(chunk: TruthChunk) -> None:
        appenders["truth_shearer"].append(chunk.rows)
        stats.update(chunk.rows)
        for k in SUPPORT_TRUTH:
            held[k].append(chunk.rows[k])
        if shearer_sensors is not None:
            for name, cols in shearer_sensors.step(chunk).items():
                appenders[name].append(cols)

    def sink(rows: dict[str, np.ndarray]) -> None:
        for a in range(0, rows["t"].size, chunk_rows):
            for chunk in assembler.push({k: v[a:a + chunk_rows] for k, v in rows.items()}):
                take(chunk)

    try:
        result = simulate_stream(scn, sink, progress, offsets, live)
        for chunk in assembler.finish():
            take(chunk)
    finally:
        for appender in appenders.values():
            appender.close()
    for name, cols in result.tables.items():
        write_stream(run_dir, STREAMS[name], cols)
    write_stream(run_dir, ALIGNMENT, alignment_table(scn, cycles["t"], result.offsets, result.alignment))
    if sensors:
        shearer = {k: np.concatenate(v) for k, v in held.items()}
        supports = result.tables["truth_supports"]
        support_sensors = SupportSensors(scn, 0)
        with StreamAppender(run_dir, STREAMS["pushram"]) as pushram, \
                StreamAppender(run_dir, STREAMS["pressure"]) as pressure:
            for t0, t1, last in support_sensors.spans(float(shearer["t"][-1])):
                readings = support_sensors.step(t0, t1, last, supports, shearer)
                pushram.append(readings["pushram"])
                pressure.append(readings["pressure"])
        write_stream(run_dir, STREAMS["faults"], faults_table(scn))
        imu = support_imu_readings(scn, supports, shearer, 0)
        if imu is not None:
            write_stream(run_dir, STREAMS["support_imu"], imu)
        report("sensors", 1.0)
    return result, stats
