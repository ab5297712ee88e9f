"""`longwall record --opcua ENDPOINT --out DIR`: a server speaking the twin's model (twin.opcua.address_space)
recorded into a run directory in the log format, without truth (as `longwall import` makes one), so that the
estimators run on live data (`longwall estimate DIR`).

The client subscribes to each sensor stream's SequenceNumber and the run's State (a subscription with a queue); each
change wakes it to fetch the blocks it has not yet (Sensors/ReadBlocks from the next SequenceNumber it wants), which
it appends to the stream's Parquet file as they come. A dropped connection is reconnected (for up to RECONNECT_S)
and the blocks published meanwhile are fetched from the server's ring buffer: nothing is lost unless the server no
longer holds them, which is said in one line and recorded in REPORT_FILE (the gap's blocks, rows and times). It ends
when the server says the run is Finished (every block fetched) or, with a duration, once every stream is published
past it (rows at or after it are left out). The scenario the server publishes is written as scenario.toml, which
the estimators read their configuration from. A server running an estimator (`longwall serve --estimator`) has its
estimated path recorded too, as estimates/METHOD.parquet, from Estimator/ReadBlocks the same way (a recording with
a duration ends with the sensor streams; the estimate holds the passes published by then). The directory appears
only when complete (twin.pipeline.rundir.atomic_run_dir).
"""

from __future__ import annotations

import asyncio
import json
import logging
import sys
from dataclasses import dataclass, field
from pathlib import Path

from asyncua import Client, ua

from estimators.io.csvio import SCENARIO_FILE
from estimators.io.logformat import ESTIMATE, ESTIMATES_DIR, STREAMS, Stream, StreamAppender, estimate_file
from twin.opcua.access import ServeError, parse_endpoint
from twin.opcua.address_space import ESTIMATOR, NAMESPACE, STATE_FINISHED, column_values
from twin.opcua.blocks import SENSOR_NODES
from twin.pipeline.rundir import atomic_run_dir, check_target

REPORT_FILE = "record_report.json"
RECONNECT_S = 30.0
"""How long a dropped connection is tried again [s of wall time] before the recording is given up."""
POLL_S = 0.5
"""Longest wait between fetches when no change is notified [s]."""
REQUEST_TIMEOUT_S = 30.0
"""How long a request may wait for its answer [s]: a server publishing at full speed answers late (a shorter timeout
took for a drop reconnects the recorder over and over); a dropped connection is seen at once."""
QUEUE_SIZE = 100
"""Data changes the server queues per monitored SequenceNumber between the subscription's publications."""
LOST = (ConnectionError, OSError, asyncio.TimeoutError, ua.UaError)
"""What a dropped connection raises in the client's calls."""


@dataclass
class StreamRecord:
    """One stream's recording: the next block wanted, how far it is published, the gaps lost."""

    name: str  # logformat stream name (estimates/METHOD: the estimator's path)
    browse: str
    stream: Stream
    appender: StreamAppender
    next_sequence: int = 1
    next_row: int = 0
    rows: int = 0
    complete_until: float = 0.0
    gaps: list[dict] = field(default_factory=list)


class Recorder:
    """Records the server at `endpoint` into `out` (module docstring); `client` is the connection in use."""

    def __init__(self, endpoint: str, out: Path, duration_s: float | None = None, force: bool = False,
                 warn=None):
        parse_endpoint(endpoint, "--opcua")
        if duration_s is not None and not duration_s > 0:
            raise ServeError(f"--duration {duration_s:g}: must be above 0 s of simulated time")
        check_target(out, force)
        self.endpoint, self.out, self.duration_s, self.force = endpoint, Path(out), duration_s, force
        self.warn = warn or (lambda line: print(f"longwall record: warning: {line}", file=sys.stderr, flush=True))
        self.client: Client | None = None
        self.changed = asyncio.Event()
        self.reconnects = 0
        self.finished = False
        self.streams: dict[str, StreamRecord] = {}
        self.nodes: dict[str, object] = {}
        self.method: str | None = None  # the server's estimator's

    def datachange_notification(self, node, val, data) -> None:
        self.changed.set()

    async def _connect(self) -> None:
        """Connect, find the model's nodes and subscribe; ServeError (one line) when there is no such server."""
        client = Client(self.endpoint, timeout=REQUEST_TIMEOUT_S)
        logging.getLogger("asyncua").setLevel(logging.CRITICAL)  # a failed connect is said in one line, by the caller
        await client.connect()
        self.client = client
        try:
            ns = await client.get_namespace_index(NAMESPACE)
        except ValueError:
            raise ServeError(f"--opcua {self.endpoint}: the server does not publish the longwall model (no namespace "
                             f"{NAMESPACE}); record a `longwall serve` endpoint") from None
        longwall = await client.nodes.objects.get_child(f"{ns}:Longwall")
        sensors = await longwall.get_child(f"{ns}:Sensors")
        self.nodes = {"state": await longwall.get_child(f"{ns}:State"),
                      "scenario": await longwall.get_child(f"{ns}:Scenario"), "sensors": sensors,
                      "read": await sensors.get_child(f"{ns}:ReadBlocks")}
        published = {(await n.read_browse_name()).Name: n for n in await sensors.get_children()}
        self.stream_nodes = {}

        async def blocks(browse: str, obj, parent, read, *args) -> None:
            """A stream's SequenceNumber, CompleteUntil and its ReadBlocks(FromSequence) under `obj`."""
            self.stream_nodes[browse] = (
                await obj.get_child(f"{ns}:SequenceNumber"), await obj.get_child(f"{ns}:CompleteUntil"),
                lambda sequence: parent.call_method(read, *args, ua.Variant(sequence, ua.VariantType.UInt32)))

        for browse in SENSOR_NODES.values():
            if browse in published:
                await blocks(browse, published[browse], sensors, self.nodes["read"],
                             ua.Variant(browse, ua.VariantType.String))
        children = {(await n.read_browse_name()).Name: n for n in await longwall.get_children()}
        if ESTIMATOR in children:
            estimator = children[ESTIMATOR]
            self.method = await (await estimator.get_child(f"{ns}:Method")).read_value()
            await blocks(ESTIMATOR, await estimator.get_child(f"{ns}:Path"), estimator,
                         await estimator.get_child(f"{ns}:ReadBlocks"))
        self.changed.set()
        sub = await client.create_subscription(50, self)
        await sub.subscribe_data_change([n[0] for n in self.stream_nodes.values()] + [self.nodes["state"]],
                                        queuesize=QUEUE_SIZE)

    async def _reconnect(self) -> None:
        """Connect again (the blocks published meanwhile are then fetched); ServeError after RECONNECT_S."""
        await self._drop()
        loop = asyncio.get_running_loop()
        end = loop.time() + RECONNECT_S
        while True:
            try:
                await self._connect()
                self.reconnects += 1
                return
            except LOST:
                await self._drop()
                if loop.time() > end:
                    raise ServeError(f"--opcua {self.endpoint}: the connection dropped and the server did not answer "
                                     f"again for {RECONNECT_S:g} s; nothing written") from None
                await asyncio.sleep(0.5)

    async def _drop(self) -> None:
        if self.client is not None:
            try:
                await asyncio.wait_for(self.client.disconnect(), 2)
            except Exception:  # the connection is gone already
                pass
            self.client = None

    async def _fetch(self, rec: StreamRecord) -> None:
        """The stream's blocks from the next wanted on, appended; how far it is published."""
        complete = float(await self.stream_nodes[rec.browse][1].read_value())  # before the blocks: they cover it
        while True:
            sequences, first_rows, counts, until, columns = await self.stream_nodes[rec.browse][2](rec.next_sequence)
            if not sequences:
                break
            if sequences[0] > rec.next_sequence:
                self._gap(rec, sequences[0], first_rows[0])
            rows = {c.name: column_values(v.Value, c.dtype) for c, v in zip(rec.stream.columns, columns)}
            if self.duration_s is not None:
                rows = {k: v[rows["t"] < self.duration_s] for k, v in rows.items()}
            rec.appender.append(rows)
            rec.rows += rows["t"].size
            rec.next_sequence, rec.next_row = sequences[-1] + 1, first_rows[-1] + counts[-1]
            complete = max(complete, until[-1])
        rec.complete_until = max(rec.complete_until, complete)

    def _gap(self, rec: StreamRecord, sequence: int, first_row: int) -> None:
        gap = {"sequences": [rec.next_sequence, sequence - 1], "rows": [rec.next_row, first_row - 1],
               "t_after_s": rec.complete_until}
        rec.gaps.append(gap)
        self.warn(f"{rec.name}: blocks {gap['sequences'][0]}-{gap['sequences'][1]} (rows {gap['rows'][0]}-"
                  f"{gap['rows'][1]}, after t = {rec.complete_until:.1f} s) were lost: the server no longer held them "
                  f"(`longwall serve --history`); {REPORT_FILE} lists the gaps")

    def _done(self) -> bool:
        if self.finished:
            return True
        return self.duration_s is not None and all(r.complete_until >= self.duration_s
                                                   for r in self.streams.values() if r.browse != ESTIMATOR)

    async def run(self) -> dict:
        """Record until the run is Finished or the duration published; what was recorded (REPORT_FILE's)."""
        try:
            await self._connect()
        except LOST as err:
            await self._drop()
            raise ServeError(f"--opcua {self.endpoint}: no OPC UA server answers there ({err or type(err).__name__}); "
                             f"start `longwall serve` there or check the address") from None
        try:
            with atomic_run_dir(self.out, self.force) as staging:
                scenario = await self.nodes["scenario"].read_value()
                self.streams = {browse: StreamRecord(name, browse, STREAMS[name],
                                                     StreamAppender(staging, STREAMS[name]))
                                for name, browse in SENSOR_NODES.items() if browse in self.stream_nodes}
                if ESTIMATOR in self.stream_nodes:
                    folder, named = estimate_file(staging, self.method)
                    folder.mkdir()
                    self.streams[ESTIMATOR] = StreamRecord(f"{ESTIMATES_DIR}/{self.method}", ESTIMATOR, ESTIMATE,
                                                           StreamAppender(folder, named))
                try:
                    while not self._done():
                        try:
                            await asyncio.wait_for(self.changed.wait(), POLL_S)
                        except asyncio.TimeoutError:
                            pass
                        self.changed.clear()
                        try:
                            finished = await self.nodes["state"].read_value() == STATE_FINISHED  # before the blocks
                            for rec in self.streams.values():
                                await self._fetch(rec)
                            self.finished = finished
                        except LOST:
                            await self._reconnect()
                finally:
                    for rec in self.streams.values():
                        rec.appender.close()
                (staging / SCENARIO_FILE).write_text(scenario)
                report = {"endpoint": self.endpoint, "duration_s": self.duration_s, "finished": self.finished,
                          "reconnects": self.reconnects, "rows": {r.name: r.rows for r in self.streams.values()},
                          "gaps": {r.name: r.gaps for r in self.streams.values() if r.gaps}}
                (staging / REPORT_FILE).write_text(json.dumps(report, indent=1) + "\n")
        finally:
            await self._drop()
        return report


def summary(report: dict, out: Path) -> str:
    """One line of what `longwall record` wrote."""
    gaps = sum(len(g) for g in report["gaps"].values())
    ended = "the run finished" if report["finished"] else f"{report['duration_s']:g} s of simulated time"
    rows = ", ".join(f"{name} {n}" for name, n in report["rows"].items())
    return (f"recorded until {ended}: {rows} rows; {report['reconnects']} reconnects, "
            f"{'no gap' if not gaps else f'{gaps} gaps ({REPORT_FILE})'}; run directory: {out}")


async def record(endpoint: str, out: Path, duration_s: float | None = None, force: bool = False) -> dict:
    return await Recorder(endpoint, out, duration_s, force).run()

