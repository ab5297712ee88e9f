"""The served face's OPC UA address space, modelled on OPC 40561 (OPC UA for Mining, Longwall Operation) as far as
it is public: a Longwall object holding the Shearer, the RoofSupportSystem with one object per shield, and the
FaceAlignmentSystem (use case 4.2.6). Browse names are readable by a person (`ShearerPosition`,
`Shield042/RamStroke`), in the namespace NAMESPACE. Units: SI (m, m/s, MPa for pressures, as the twin's truth).

Shearer: ShearerPosition (along the face from the headgate end of the pans [m], the haulage's arc length s),
PositionEast/North/Up (the body point in the tangent plane t [m]), Speed [m/s], Direction (+1 towards the tailgate,
-1 back, 0 standing), HaulageState (STOPPED, CUTTING, RETURN, SUMPING, CUT_OUT), Cycle, SimulationTime [s].

Each shield: RamStroke [m], RamPressure and LegPressure [MPa], Advance (from where it stood at the start [m]), Set
(canopy set against the roof), AppliedOffset (the offset its push applied on the current shear [m]).

FaceAlignmentSystem: Offsets (one per shield, positive towards the coal wall [m]) and SequenceNumber, written by an
external face alignment system: the roof support system applies a set on the next shear once its SequenceNumber
is new; AppliedSequenceNumber is the set in force and Status says what became of the last one written.

Sensors: one object per sensor stream of the sensor log (twin.opcua.blocks.SENSOR_NODES: Sensors/Imu, ...), its
last block as one array variable per column (the log's names and units, estimators.io.logformat; Units lists them),
SequenceNumber (the block's, 1 for the first), FirstRow (its first row's index in the stream) and CompleteUntil
(every row before this simulated time is published; inf at the stream's end). Sensors/ReadBlocks(Stream,
FromSequence) returns a stream's blocks the server still holds from FromSequence on (a ring buffer of the last
ones): Sequences, FirstRows, RowCounts, CompleteUntil per block and Columns (one array per column, the blocks'
rows joined) - what a client that reconnects missed; an answer that starts after FromSequence says blocks were
lost.

Estimator (`longwall serve --estimator METHOD`, twin.opcua.estimator): the shearer positioning method run online
on the published sensor rows, updated as each pass ends: Method, ShearerPosition (the pass's last row: the face
frame's x, y, z then the tangent plane's e, n, u [m]; its Axes property names them), ShearerPositionSigma (their
one-sigma [m]), Time (that row's simulated time [s]), Healthy (the filter kept track over the pass), Passes, and
the estimated path in blocks, one per pass, as the sensors' (Estimator/Path: the ESTIMATE stream's columns,
estimators.io.logformat; SequenceNumber, FirstRow, CompleteUntil; Estimator/ReadBlocks(FromSequence) as
Sensors/ReadBlocks). Its alarms are events of EstimatorAlarmEventType (a BaseEventType with Method,
SimulationTime [s] and Kind: LostTrack, RailIsolated, EstimatorFailed; Message and Severity) emitted by the
Estimator object.

Hydraulic alarms (with the PushRam and Pressure sensors, estimators.faults.online_checks): each fault the supports'
hydraulic and push-ram checks find on the rows served, once, as an event of HydraulicAlarmEventType (a BaseEventType
with Support (0 for the headgate's first shield), Kind (hydraulic_checks' kinds: ram_stall, failed_set, ...), Cause
(face or sensor) and SimulationTime (when the logs confirmed it [s]); Message and Severity) emitted by the
RoofSupportSystem object.

Run: State ("Running", then "Finished" once every block is published) and Scenario (the run's scenario TOML, what
the estimators read their configuration from).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from asyncua import Node, Server, ua

from estimators.faults.online_checks import CHECKED_STREAMS
from estimators.io.logformat import ESTIMATE, Stream
from twin.opcua.blocks import SENSOR_NODES, Block
from twin.opcua.estimator import POSITION_AXES

NAMESPACE = "urn:longwall-twin:opc40561"
"""The namespace of the twin's nodes."""

SHEARER_VARIABLES = {"ShearerPosition": 0.0, "PositionEast": 0.0, "PositionNorth": 0.0, "PositionUp": 0.0,
                     "Speed": 0.0, "Direction": 0, "HaulageState": "STOPPED", "Cycle": 0, "SimulationTime": 0.0}
SHIELD_VARIABLES = {"RamStroke": 0.0, "RamPressure": 0.0, "LegPressure": 0.0, "Advance": 0.0, "Set": True,
                    "AppliedOffset": 0.0}
HAULAGE_STATES = ("STOPPED", "CUTTING", "RETURN", "SUMPING", "CUT_OUT")
"""The truth's phase codes (twin.face.haulage) by name."""


VARIANT_TYPES = {"f8": ua.VariantType.Double, "i8": ua.VariantType.Int64, "i4": ua.VariantType.Int32,
                 "i1": ua.VariantType.SByte}
"""The OPC UA type of each logformat column type (the values go bit for bit)."""
STATE_RUNNING, STATE_FINISHED = "Running", "Finished"
ESTIMATOR = "Estimator"
"""The estimator's object under Longwall."""
ALARM_EVENT_TYPE = "EstimatorAlarmEventType"
ALARM_FIELDS = (("Method", ua.VariantType.String), ("SimulationTime", ua.VariantType.Double),
                ("Kind", ua.VariantType.String))
"""The estimator's alarm events: a BaseEventType (Message, Severity, Time: wall clock) with these fields."""
HYDRAULIC_ALARM_EVENT_TYPE = "HydraulicAlarmEventType"
HYDRAULIC_ALARM_FIELDS = (("Support", ua.VariantType.UInt32), ("Kind", ua.VariantType.String),
                          ("Cause", ua.VariantType.String), ("SimulationTime", ua.VariantType.Double))
"""The supports' hydraulic alarm events: a BaseEventType with these fields."""
READ_BLOCKS_OUTPUTS = (("Sequences", ua.VariantType.UInt32), ("FirstRows", ua.VariantType.UInt64),
                       ("RowCounts", ua.VariantType.UInt32), ("CompleteUntil", ua.VariantType.Double),
                       ("Columns", ua.VariantType.Variant))


def column_variant(values: np.ndarray, dtype: str) -> ua.Variant:
    """A log column as an OPC UA array."""
    return ua.Variant(values.tolist(), VARIANT_TYPES[dtype])


def column_values(values: list, dtype: str) -> np.ndarray:
    """An OPC UA array back as a log column."""
    return np.array(values if values is not None else [], dtype=np.dtype(dtype))


def blocks_variants(stream: Stream, blocks: list[Block]) -> list[ua.Variant]:
    """ReadBlocks' answer for `blocks` of `stream` (READ_BLOCKS_OUTPUTS)."""
    def joined(name: str) -> np.ndarray:
        return np.concatenate([b.columns[name] for b in blocks]) if blocks else np.zeros(0)

    return [ua.Variant([b.sequence for b in blocks], ua.VariantType.UInt32),
            ua.Variant([b.first_row for b in blocks], ua.VariantType.UInt64),
            ua.Variant([b.rows for b in blocks], ua.VariantType.UInt32),
            ua.Variant([b.complete_until for b in blocks], ua.VariantType.Double),
            ua.Variant([column_variant(joined(c.name).astype(c.dtype), c.dtype) for c in stream.columns],
                       ua.VariantType.Variant)]


def shield_name(k: int) -> str:
    """Shield k's browse name: Shield001 for the headgate's first."""
    return f"Shield{k + 1:03d}"


@dataclass
class SensorNodes:
    """A sensor stream's block nodes (module docstring)."""

    columns: dict[str, Node]
    sequence: Node
    first_row: Node
    complete_until: Node


@dataclass
class EstimatorNodes:
    """The estimator's nodes (module docstring) and its alarms' event generator."""

    position: Node
    sigma: Node
    time: Node
    healthy: Node
    passes: Node
    path: SensorNodes
    alarms: object


@dataclass
class FaceNodes:
    """The nodes the server writes and reads."""

    shearer: dict[str, Node]
    shields: list[dict[str, Node]]
    offsets: Node
    sequence: Node
    applied_sequence: Node
    status: Node
    sensors: dict[str, SensorNodes]
    state: Node
    estimator: EstimatorNodes | None
    hydraulic_alarms: object | None
    """The hydraulic alarms' event generator (None without the PushRam and Pressure sensors)."""




ReadBlocks = Callable[[str, int], list[ua.Variant]]
"""(browse name of a stream, FromSequence) -> ReadBlocks' output arguments (blocks_variants)."""


def _argument(name: str, vtype: ua.VariantType, array: bool, doc: str) -> ua.Argument:
    return ua.Argument(Name=name, DataType=ua.NodeId(vtype.value), ValueRank=1 if array else -1,
                       ArrayDimensions=[], Description=ua.LocalizedText(doc))


async def _block_nodes(ns: int, obj: Node, stream: Stream) -> SensorNodes:
    """A stream's block nodes under `obj`: one array per column, Units, SequenceNumber, FirstRow, CompleteUntil."""
    await obj.add_property(ns, "Units", ua.Variant([c.unit for c in stream.columns], ua.VariantType.String))
    columns = {c.name: await obj.add_variable(ns, c.name, column_variant(np.zeros(0), c.dtype)) for c in stream.columns}
    return SensorNodes(columns, await obj.add_variable(ns, "SequenceNumber", ua.Variant(0, ua.VariantType.UInt32)),
                       await obj.add_variable(ns, "FirstRow", ua.Variant(0, ua.VariantType.UInt64)),
                       await obj.add_variable(ns, "CompleteUntil", 0.0))


async def _add_read_blocks(ns: int, obj: Node, call, inputs: list[ua.Argument]) -> None:
    """A ReadBlocks method under `obj` (READ_BLOCKS_OUTPUTS), `call(parent, *inputs)` answering it."""
    await obj.add_method(ns, "ReadBlocks", call, inputs,
                         [_argument(name, vtype, True, "per block" if name != "Columns" else
                                    "one array per column, rows joined") for name, vtype in READ_BLOCKS_OUTPUTS])


FROM_SEQUENCE = _argument("FromSequence", ua.VariantType.UInt32, False, "the first block's SequenceNumber wanted")


async def _sensors(ns: int, longwall: Node, streams: dict[str, Stream], read_blocks: ReadBlocks
                   ) -> dict[str, SensorNodes]:
    """Longwall/Sensors: an object per stream (`streams`: browse name -> its logformat Stream) and ReadBlocks."""
    sensors = await longwall.add_object(ns, "Sensors")
    out = {name: await _block_nodes(ns, await sensors.add_object(ns, name), stream) for name, stream in streams.items()}

    def call(parent, stream: ua.Variant, from_sequence: ua.Variant) -> list[ua.Variant]:
        if stream.Value not in streams:
            raise ua.UaStatusCodeError(ua.StatusCodes.BadInvalidArgument)
        return read_blocks(stream.Value, int(from_sequence.Value))

    await _add_read_blocks(ns, sensors, call, [_argument("Stream", ua.VariantType.String, False,
                                                         f"a stream's browse name ({', '.join(streams)})"),
                                               FROM_SEQUENCE])
    return out


async def _estimator(server: Server, ns: int, longwall: Node, method: str,
                     read_blocks: Callable[[int], list[ua.Variant]]) -> EstimatorNodes:
    """Longwall/Estimator (module docstring) and the alarm event type."""
    obj = await longwall.add_object(ns, ESTIMATOR)
    await obj.add_variable(ns, "Method", method)
    position = await obj.add_variable(ns, "ShearerPosition", ua.Variant([np.nan] * 6, ua.VariantType.Double))
    sigma = await obj.add_variable(ns, "ShearerPositionSigma", ua.Variant([np.nan] * 6, ua.VariantType.Double))
    for node in (position, sigma):
        await node.add_property(ns, "Axes", ua.Variant(list(POSITION_AXES), ua.VariantType.String))
    nodes = EstimatorNodes(position, sigma, await obj.add_variable(ns, "Time", np.nan),
                           await obj.add_variable(ns, "Healthy", True),
                           await obj.add_variable(ns, "Passes", ua.Variant(0, ua.VariantType.UInt32)),
                           await _block_nodes(ns, await obj.add_object(ns, "Path"), ESTIMATE), None)
    await _add_read_blocks(ns, obj, lambda parent, from_sequence: read_blocks(int(from_sequence.Value)),
                           [FROM_SEQUENCE])
    alarm_type = await server.create_custom_event_type(ns, ALARM_EVENT_TYPE, ua.ObjectIds.BaseEventType,
                                                       [(name, vtype) for name, vtype in ALARM_FIELDS])
    nodes.alarms = await server.get_event_generator(alarm_type, obj)
    return nodes


async def build(server: Server, n_shields: int, streams: dict[str, Stream], read_blocks: ReadBlocks,
                scenario_toml: str, estimator: tuple[str, Callable[[int], list[ua.Variant]]] | None = None
                ) -> FaceNodes:
    """The Longwall object and everything under it (module docstring); `estimator`: its method and the answer of
    its ReadBlocks (FromSequence -> blocks_variants), None without one; the hydraulic alarms' event type with the
    PushRam and Pressure streams."""
    ns = await server.register_namespace(NAMESPACE)
    longwall = await server.nodes.objects.add_object(ns, "Longwall")
    shearer_obj = await longwall.add_object(ns, "Shearer")
    shearer = {name: await shearer_obj.add_variable(ns, name, value) for name, value in SHEARER_VARIABLES.items()}
    rss = await longwall.add_object(ns, "RoofSupportSystem")
    shields = []
    for k in range(n_shields):
        obj = await rss.add_object(ns, shield_name(k))
        shields.append({name: await obj.add_variable(ns, name, value) for name, value in SHIELD_VARIABLES.items()})
    fas = await longwall.add_object(ns, "FaceAlignmentSystem")
    offsets = await fas.add_variable(ns, "Offsets", ua.Variant([0.0] * n_shields, ua.VariantType.Double))
    sequence = await fas.add_variable(ns, "SequenceNumber", ua.Variant(0, ua.VariantType.UInt32))
    applied = await fas.add_variable(ns, "AppliedSequenceNumber", ua.Variant(0, ua.VariantType.UInt32))
    status = await fas.add_variable(ns, "Status", "no offsets written yet")
    await offsets.set_writable()
    await sequence.set_writable()
    sensors = await _sensors(ns, longwall, streams, read_blocks)
    estimated = await _estimator(server, ns, longwall, *estimator) if estimator is not None else None
    hydraulic_alarms = None
    if {SENSOR_NODES[name] for name in CHECKED_STREAMS} <= streams.keys():
        alarm_type = await server.create_custom_event_type(ns, HYDRAULIC_ALARM_EVENT_TYPE, ua.ObjectIds.BaseEventType,
                                                           list(HYDRAULIC_ALARM_FIELDS))
        hydraulic_alarms = await server.get_event_generator(alarm_type, rss)
    state = await longwall.add_variable(ns, "State", STATE_RUNNING)
    await longwall.add_variable(ns, "Scenario", scenario_toml)
    return FaceNodes(shearer, shields, offsets, sequence, applied, status, sensors, state, estimated, hydraulic_alarms)
