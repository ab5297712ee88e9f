"""`longwall serve`: the twin on OPC UA (issue 27). The twin runs (streaming, twin.pipeline.twin_stream) in a thread
and writes its run directory as it goes; its shearer and supports are published on an asyncua server
(twin.opcua.address_space), paced at `speed` times real time (inf: as fast as the twin runs), `publish_hz` of
simulated time; an external face alignment system's offsets, written to FaceAlignmentSystem/Offsets with a new
SequenceNumber, are applied by the twin's roof support system on the next shear (FasInput, through the face's
per-cycle offset input, twin.face.drift.OffsetSource).

The sensor streams (sensor trial 0, the rows its run directory's Parquet files get) are published in blocks, one
per stream per publication with rows (twin.opcua.blocks), the last `history_s` of simulated time of them held for
ReadBlocks. When the run ends, State says Finished and the server stays up while clients are connected or one has
left within REJOIN_S (at least MIN_LINGER_S, at most LINGER_S), so that a recorder fetches the last blocks, also one
whose connection dropped and is coming back.

The estimator (`estimator`, default kf_cpoem_rts): the same sensor rows, as they reach the publisher, go to the
method run online in a worker thread (twin.opcua.estimator); each pass is published under Longwall/Estimator once
the publisher's clock reaches the time it became known (twin.opcua.publishers.EstimatorPublisher), its alarms as
events.

The supports' hydraulic and push-ram checks run on the PushRam and Pressure rows as they reach the publisher, on a
sliding window (estimators.faults.online_checks, in an executor: the server keeps answering its clients); each fault
they find is an event of the RoofSupportSystem once (twin.opcua.publishers.HydraulicAlarms).

Memory is bounded: the twin hands its chunks (a cycle of shearer truth, a cycle's support rows, sensor rows of
SENSOR_CHUNK_S) through a queue of QUEUE_CHUNKS, so it runs at most that far ahead of what is published.

Access: anonymous on a loopback address only; binding any other address needs a user (its password from the
environment variable PASSWORD_ENV), checked by the server's user manager, and is refused without one, in one line.
"""

from __future__ import annotations

import asyncio
import logging
import math
import os
import queue
import threading
import time
from pathlib import Path

import numpy as np
from asyncua import Server, ua
from asyncua.server.user_managers import User, UserManager, UserRole

from estimators.faults.online_checks import OnlineChecks
from estimators.io.logformat import ESTIMATE, STREAMS
from twin.config.push import check_offsets, offset_limits
from twin.config.scenario import Scenario, scenario_to_toml
from twin.face.layout import support_stations
from twin.opcua.access import PASSWORD_ENV, ServeError, check_access, parse_endpoint
from twin.opcua.address_space import HAULAGE_STATES, STATE_FINISHED, FaceNodes, SensorNodes, blocks_variants, build
from twin.opcua.blocks import HISTORY_S, SENSOR_NODES, BlockStream
from twin.opcua.estimator import DEFAULT_ESTIMATOR, NO_ESTIMATOR, EstimatorFeed, check_method
from twin.opcua.publishers import EstimatorPublisher, HydraulicAlarms, server_write, write_block
from twin.pipeline.estimate import hydraulic_layout, ram_layout
from twin.pipeline.rundir import atomic_run_dir, check_target
from twin.pipeline.simulate import LiveTaps

QUEUE_CHUNKS = 4
"""Chunks the twin may run ahead of the publisher."""
PUBLISH_HZ = 10.0
"""Default publication rate [Hz of simulated time]."""
SENSOR_CHUNK_S = 60.0
"""The shearer's truth goes to the sensor models this much at a time (their rows wait no longer for a cycle's end)."""
LINGER_S = 30.0
"""After the run, the server stays up at most this long [s of wall time] while clients are connected."""
MIN_LINGER_S = 5.0
"""... and at least this long, for a recorder reconnecting just then."""
REJOIN_S = 10.0
"""... and this long after a client left, for a recorder whose connection dropped to connect again (it retries every
half second once its old connection is given up, within 2 s: twin.opcua.recorder)."""


class _PasswordUsers(UserManager):
    """One user, its password from the environment: read and write access; nobody else."""

    def __init__(self, name: str, password: str):
        self.name, self.password = name, password

    def get_user(self, iserver, username=None, password=None, certificate=None):
        if username == self.name and password == self.password:
            return User(role=UserRole.User, name=username)
        return None


class FasInput:
    """The roof support system's offsets from OPC UA (an OffsetSource): at cycle k's start it waits until the shear
    before is published (the twin's first k chunks of shearer truth, which end in the reversal stop after cycle
    k - 1; twin.pipeline.simulate.shearer_chunks), then takes
    the Offsets last written if their SequenceNumber is new (a face-pushable set: twin.config.push.check_offsets;
    another is refused, Status says why, none applied)."""

    def __init__(self, scn: Scenario, server: Server, nodes: FaceNodes):
        self.scn, self.nodes = scn, nodes
        self.aspace = server.iserver.aspace
        self.chunks = 0  # shearer chunks published
        self.condition = threading.Condition()
        self.applied_sequence = 0
        self.status = "no offsets written yet"
        self.applied = np.zeros(support_stations(scn).size)
        self.stopped = False

    def _read(self, node):
        return self.aspace.read_attribute_value(node.nodeid, ua.AttributeIds.Value).Value.Value

    def published(self) -> None:
        """The publisher has published one more chunk."""
        with self.condition:
            self.chunks += 1
            self.condition.notify_all()

    def stop(self) -> None:
        with self.condition:
            self.stopped = True
            self.condition.notify_all()

    def __call__(self, cycle: int, pans: np.ndarray) -> np.ndarray | None:
        if cycle > 0:
            with self.condition:
                self.condition.wait_for(lambda: self.stopped or self.chunks >= cycle)
        sequence = int(self._read(self.nodes.sequence))
        offsets = np.zeros(self.applied.size)
        if sequence != self.applied_sequence:
            written = np.asarray(self._read(self.nodes.offsets), float)
            try:
                check_offsets(written, self.applied.size, **offset_limits(self.scn))
            except ValueError as err:
                self.status = f"sequence {sequence} refused at cycle {cycle}: {err}"
            else:
                offsets = written
                self.status = f"sequence {sequence} applied on cycle {cycle}"
            self.applied_sequence = sequence
        self.applied = offsets
        return offsets


class Publisher:
    """Writes the twin's truth to the nodes at `publish_hz` of simulated time, paced at `speed` times real time."""

    def __init__(self, server: Server, nodes: FaceNodes, fas: FasInput, speed: float, publish_hz: float,
                 sensors: dict[str, BlockStream], estimator: EstimatorPublisher | None = None,
                 hydraulics: HydraulicAlarms | None = None):
        self.server, self.nodes, self.fas, self.speed, self.publish_hz = server, nodes, fas, speed, publish_hz
        self.sensors = sensors  # browse name -> its blocks
        self.estimator, self.hydraulics = estimator, hydraulics
        self._write = server_write(server)
        self.complete_until = {name: 0.0 for name in sensors}  # as last written
        self.supports: list[dict[str, np.ndarray]] = []  # rows not yet published, in time order
        self.start: tuple[float, float] | None = None  # (simulated, wall) time of the first row
        self.last_tick = -math.inf
        self.shown = (None, None)  # (applied sequence, status) last written
        self.ticks = 0

    async def shearer(self, chunk: dict[str, np.ndarray]) -> None:
        t = chunk["t"]
        tick = np.floor(t * self.publish_hz)
        rows = np.flatnonzero(np.diff(tick, prepend=self.last_tick) > 0)
        speed = np.sqrt(chunk["v_n_e"] ** 2 + chunk["v_n_n"] ** 2 + chunk["v_n_u"] ** 2)
        direction = np.sign(np.gradient(chunk["s"], t)) if t.size > 1 else np.zeros(t.size)
        for i in rows:
            await self._pace(float(t[i]))
            values = {"ShearerPosition": float(chunk["s"][i]), "PositionEast": float(chunk["p_t_e"][i]),
                      "PositionNorth": float(chunk["p_t_n"][i]), "PositionUp": float(chunk["p_t_u"][i]),
                      "Speed": float(speed[i]), "Direction": int(direction[i]),
                      "HaulageState": HAULAGE_STATES[int(chunk["phase"][i])], "Cycle": int(chunk["cycle"][i]),
                      "SimulationTime": float(t[i])}
            for name, value in values.items():
                await self.nodes.shearer[name].write_value(value)
            await self._shields(float(t[i]))
            await self._blocks(float(t[i]))
            self.ticks += 1
            await asyncio.sleep(0)  # the clients' requests are served between publications
        if t.size:
            self.last_tick = float(tick[-1])
        self.fas.published()

    async def add_rows(self, name: str, columns: dict[str, np.ndarray], made_until: float) -> None:
        """A sensor stream's rows as the twin drew them (logformat name), published when their time comes, and
        fed to the estimator and the supports' checks."""
        if SENSOR_NODES[name] in self.sensors:
            self.sensors[SENSOR_NODES[name]].add(columns, made_until)
            if self.estimator is not None:
                await self.estimator.feed.add(name, columns, made_until)
            if self.hydraulics is not None:
                await self.hydraulics.add(name, columns, made_until)

    async def finish(self) -> None:
        """The run is over: every row left goes in a last block, the estimator's last passes are run, the supports'
        last rows checked, and State says Finished."""
        for stream in self.sensors.values():
            stream.made_until = math.inf
        if self.estimator is not None:
            await self.estimator.feed.finish()
        if self.hydraulics is not None:
            await self.hydraulics.finish()
        await self._blocks(math.inf)
        await self.nodes.state.write_value(STATE_FINISHED)

    async def _blocks(self, t: float) -> None:
        """Each sensor stream's block of the rows up to t, if it has any; how far each is published; the
        estimator's passes known by t."""
        for name, stream in self.sensors.items():
            nodes: SensorNodes = self.nodes.sensors[name]
            block = stream.publish(t)
            if block is not None:
                await write_block(self._write, nodes, stream, block)
            if stream.complete_until != self.complete_until[name]:
                self.complete_until[name] = stream.complete_until
                await self._write(nodes.complete_until, ua.Variant(stream.complete_until, ua.VariantType.Double))
        if self.estimator is not None:
            await self.estimator.publish(t)


    async def _pace(self, t: float) -> None:
        if self.start is None:
            self.start = (t, time.perf_counter())
        if math.isfinite(self.speed):
            due = self.start[1] + (t - self.start[0]) / self.speed - time.perf_counter()
            if due > 0:
                await asyncio.sleep(due)

    async def _shields(self, t: float) -> None:
        """The shields whose rows up to t are new: their latest values; the face alignment system's state."""
        if self.supports and min(r["t"][0] for r in self.supports) <= t:  # rows in time order
            rows = {k: np.concatenate([r[k] for r in self.supports]) for k in self.supports[0]}
            now = rows["t"] <= t
            if now.any():
                new = {k: v[now] for k, v in rows.items()}
                order = np.lexsort((np.arange(now.sum()), new["support"]))  # by shield, then as recorded
                sup = new["support"][order]
                for i in order[np.flatnonzero(np.append(sup[1:] != sup[:-1], True))]:  # each shield's latest row
                    k = int(new["support"][i])
                    node = self.nodes.shields[k]
                    for name, col in (("RamStroke", "ram"), ("RamPressure", "ram_pressure"),
                                      ("LegPressure", "leg_pressure"), ("Advance", "advance")):
                        await node[name].write_value(float(new[col][i]))
                    await node["Set"].write_value(bool(new["set"][i]))
                    await node["AppliedOffset"].write_value(float(self.fas.applied[k]))
                self.supports = [{k: v[~now] for k, v in rows.items()}] if (~now).any() else []
        shown = (self.fas.applied_sequence, self.fas.status)
        if shown != self.shown:
            await self.nodes.applied_sequence.write_value(ua.Variant(shown[0], ua.VariantType.UInt32))
            await self.nodes.status.write_value(shown[1])
            self.shown = shown


async def _linger(server: Server) -> None:
    """Stay up while clients are connected (a recorder fetching the last blocks) or one left within REJOIN_S, at
    least MIN_LINGER_S and at most LINGER_S."""
    start = left = time.perf_counter()
    held = 0
    while (now := time.perf_counter()) - start < LINGER_S:
        clients = len(server.bserver.clients) if server.bserver is not None else 0
        if clients < held:
            left = now
        held = clients
        if now - start >= MIN_LINGER_S and not clients and now - left >= REJOIN_S:
            return
        await asyncio.sleep(0.1)


async def serve(scn: Scenario, out: Path, endpoint: str, speed: float = 1.0,
                publish_hz: float = PUBLISH_HZ, user: str | None = None, force: bool = False, sensors: bool = True,
                ready=None, history_s: float = HISTORY_S, estimator: str | None = DEFAULT_ESTIMATOR) -> dict:
    """Serve `scn` on `endpoint` until its run ends (the run directory `out` written as it goes), each sensor
    stream's last `history_s` of blocks held for ReadBlocks, the shearer positioning method `estimator` (one of
    ONLINE_METHODS; None: none) run on the sensor rows and published; `ready()` is called once the server listens.
    Returns what was published: simulated time, ticks, wall time, the estimator's passes, the hydraulic alarms."""
    from twin.pipeline.twin_stream import stream_twin

    host, port = parse_endpoint(endpoint)
    check_access(host, user)
    check_method(estimator or NO_ESTIMATOR)
    if not speed > 0:
        raise ServeError(f"--speed {speed:g}: must be above 0 (inf: as fast as the twin runs)")
    if not history_s > 0:
        raise ServeError(f"--history {history_s:g}: must be above 0 s (the simulated time of blocks held)")
    check_target(out, force)
    server = Server(user_manager=_PasswordUsers(user, os.environ[PASSWORD_ENV]) if user else None)
    await server.init()
    server.set_endpoint(f"opc.tcp://{host}:{port}/longwall/")
    server.set_server_name(f"longwall-twin {scn.name}")
    server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
    server.set_identity_tokens([ua.UserNameIdentityToken] if user else [ua.AnonymousIdentityToken])
    history = max(1, math.ceil(history_s * publish_hz))
    streams = {browse: BlockStream(STREAMS[name], history) for name, browse in SENSOR_NODES.items()
               if sensors and (name != "support_imu" or scn.sensors.support_imu.supports)}

    def read_blocks(name: str, from_sequence: int) -> list[ua.Variant]:
        return blocks_variants(streams[name].stream, streams[name].read(from_sequence))

    method = check_method(estimator or NO_ESTIMATOR) if streams else None
    estimated: EstimatorPublisher | None = None

    def read_estimates(from_sequence: int) -> list[ua.Variant]:
        return blocks_variants(ESTIMATE, estimated.path.read(from_sequence))

    nodes = await build(server, support_stations(scn).size, {k: v.stream for k, v in streams.items()}, read_blocks,
                        scenario_to_toml(scn), (method, read_estimates) if method else None)
    if method:
        feed = EstimatorFeed(scn, method, tuple(s.stream.name for s in streams.values()))
        estimated = EstimatorPublisher(server_write(server), nodes.estimator, feed, history,
                                       math.radians(scn.face.azimuth_deg))
    hydraulics = (HydraulicAlarms(OnlineChecks(ram_layout(scn), hydraulic_layout(scn)), nodes.hydraulic_alarms)
                  if nodes.hydraulic_alarms is not None else None)
    fas = FasInput(scn, server, nodes)
    publisher = Publisher(server, nodes, fas, speed, publish_hz, streams, estimated, hydraulics)
    chunks: queue.Queue = queue.Queue(maxsize=QUEUE_CHUNKS)
    loop = asyncio.get_running_loop()
    start = time.perf_counter()

    def run_twin(staging: Path) -> None:
        try:
            taps = LiveTaps(lambda rows: chunks.put(("shearer", rows)),
                            lambda rows, t_final: chunks.put(("supports", rows)),
                            lambda name, rows, until: chunks.put(("sensors", (name, rows, until))))
            stream_twin(scn, staging, sensors, chunk_rows=math.ceil(SENSOR_CHUNK_S * scn.rates.truth_hz),
                        offsets=fas, live=taps)
            (staging / "scenario.toml").write_text(scenario_to_toml(scn))
            chunks.put(("done", None))
        except BaseException as err:  # handed to the publisher, which raises it
            chunks.put(("error", err))

    asyncua_log = logging.getLogger("asyncua")
    level = asyncua_log.level
    asyncua_log.setLevel(logging.CRITICAL)  # a port that is taken is said in one line below, not as its traceback
    try:
        await server.start()
    except OSError as err:
        raise ServeError(f"--endpoint {endpoint}: cannot listen there ({err.strerror or err}); choose another port "
                         f"or stop what holds it") from None
    finally:
        asyncua_log.setLevel(level)
    try:
        if ready is not None:
            ready()
        with atomic_run_dir(out, force) as staging:
            twin = threading.Thread(target=run_twin, args=(staging,), daemon=True)
            twin.start()
            while True:
                kind, item = await loop.run_in_executor(None, chunks.get)
                if kind == "shearer":
                    await publisher.shearer(item)
                elif kind == "supports":
                    if item["t"].size:
                        publisher.supports.append(item)
                elif kind == "sensors":
                    await publisher.add_rows(*item)
                elif kind == "error":
                    raise item
                else:
                    break
            twin.join()
            await publisher.finish()
        wall_s = time.perf_counter() - start
        await _linger(server)
    finally:
        fas.stop()
        await server.stop()
    t = publisher.start
    return {"ticks": publisher.ticks, "wall_s": wall_s, "passes": estimated.passes if estimated else 0,
            "hydraulic_alarms": hydraulics.raised if hydraulics else 0,
            "simulated_s": publisher.last_tick / publish_hz - (t[0] if t else 0.0)}
