"""What `longwall serve` writes beyond the face's own nodes (twin.opcua.server): the sensor streams' blocks, the
estimator's passes and alarms (EstimatorPublisher) and the supports' hydraulic alarms (HydraulicAlarms), each as an
OPC UA value or event of the address space (twin.opcua.address_space)."""

from __future__ import annotations

import asyncio
import math

import numpy as np
from asyncua import Server, ua

from estimators.faults.hydraulic_checks import Attribution
from estimators.faults.online_checks import CHECKED_STREAMS, OnlineChecks
from estimators.io.logformat import ESTIMATE
from twin.opcua.address_space import EstimatorNodes, SensorNodes, column_variant
from twin.opcua.blocks import Block, BlockStream
from twin.opcua.estimator import SEVERITY, Alarm, EstimatedPass, EstimatorFeed, shearer_position

HYDRAULIC_SEVERITY = {"face": 700, "sensor": 500}
"""The hydraulic alarms' OPC UA severity (1..1000) by cause: the face's faults stop the supports, a sensor's misleads."""


def server_write(server: Server):
    """`write(node, variant)`: a node's value set by the server."""
    async def write(node, value: ua.Variant) -> None:
        await server.write_attribute_value(node.nodeid, ua.DataValue(value))
    return write


async def write_block(write, nodes: SensorNodes, stream: BlockStream, block: Block) -> None:
    """A block's columns, FirstRow and SequenceNumber (the last: a client woken by it reads the rest) written with
    `write(node, variant)`."""
    for column in stream.stream.columns:
        await write(nodes.columns[column.name], column_variant(block.columns[column.name], column.dtype))
    await write(nodes.first_row, ua.Variant(block.first_row, ua.VariantType.UInt64))
    await write(nodes.sequence, ua.Variant(block.sequence, ua.VariantType.UInt32))


class EstimatorPublisher:
    """The estimator's passes and alarms (twin.opcua.estimator) written to Longwall/Estimator once the publisher's
    clock reaches the time each became known; its path's blocks (`path`, one per pass) held for ReadBlocks."""

    def __init__(self, write, nodes: EstimatorNodes, feed: EstimatorFeed, history: int, azimuth_rad: float):
        self.write, self.nodes, self.feed, self.azimuth_rad = write, nodes, feed, azimuth_rad
        self.path = BlockStream(ESTIMATE, history)
        self.waiting: list[EstimatedPass | Alarm] = []  # in the order they came
        self.passes = 0

    async def publish(self, t: float) -> None:
        """Every pass and alarm known by t (inf: all there are)."""
        self.waiting += self.feed.take()
        while self.waiting and (math.isinf(t) or self._known(self.waiting[0]) <= t):
            item = self.waiting.pop(0)
            if isinstance(item, Alarm):
                await self.alarm(item)
                continue
            self.path.add(item.columns, float(item.columns["t"][-1]))
            await write_block(self.write, self.nodes.path, self.path, self.path.publish(math.inf))
            await self.write(self.nodes.path.complete_until,
                             ua.Variant(self.path.complete_until, ua.VariantType.Double))
            t_last, position, sigma = shearer_position(item.columns, self.azimuth_rad)
            self.passes += 1
            for node, value in ((self.nodes.position, ua.Variant(position.tolist(), ua.VariantType.Double)),
                                (self.nodes.sigma, ua.Variant(sigma.tolist(), ua.VariantType.Double)),
                                (self.nodes.time, ua.Variant(t_last, ua.VariantType.Double)),
                                (self.nodes.healthy, ua.Variant(item.healthy, ua.VariantType.Boolean)),
                                (self.nodes.passes, ua.Variant(self.passes, ua.VariantType.UInt32))):
                await self.write(node, value)
            for alarm in item.alarms:
                await self.alarm(alarm)
        if math.isinf(t):
            self.path.made_until = math.inf
            await self.write(self.nodes.path.complete_until, ua.Variant(math.inf, ua.VariantType.Double))

    @staticmethod
    def _known(item: EstimatedPass | Alarm) -> float:
        return item.t if isinstance(item, Alarm) else item.t_known

    async def alarm(self, alarm: Alarm) -> None:
        """An alarm as an event of the Estimator object (address_space.ALARM_EVENT_TYPE's)."""
        event = self.nodes.alarms.event
        event.Method, event.SimulationTime, event.Kind = self.feed.method, alarm.t, alarm.kind
        event.Severity = SEVERITY[alarm.kind]
        await self.nodes.alarms.trigger(message=alarm.message)


class HydraulicAlarms:
    """The supports' checks (estimators.faults.online_checks) run on the PushRam and Pressure rows `add`ed; each new
    fault an event of `generator` (address_space.HYDRAULIC_ALARM_EVENT_TYPE's)."""

    def __init__(self, checks: OnlineChecks, generator):
        self.checks, self.generator = checks, generator
        self.raised = 0

    async def add(self, name: str, columns: dict[str, np.ndarray], made_until: float) -> None:
        """A stream's next rows (BlockStream.add's); the windows they complete checked and their faults raised."""
        if name in CHECKED_STREAMS:
            self.checks.add(name, columns, made_until)
            await self._raise(await asyncio.get_running_loop().run_in_executor(None, self.checks.take))

    async def finish(self) -> None:
        """The log ends: its last rows checked."""
        await self._raise(await asyncio.get_running_loop().run_in_executor(None, self.checks.take, True))

    async def _raise(self, found: list[Attribution]) -> None:
        for a in found:
            event = self.generator.event
            event.Support, event.Kind, event.Cause, event.SimulationTime = a.support, a.kind, a.cause, a.t_detect
            event.Severity = HYDRAULIC_SEVERITY[a.cause]
            await self.generator.trigger(message=f"support {a.support}: {a.kind} ({a.cause}) {a.evidence}")
            self.raised += 1
