"""The supports' hydraulic alarms of `longwall serve` (twin.opcua.publishers.HydraulicAlarms): each fault the online
checks find is an event of the RoofSupportSystem, once."""

from __future__ import annotations

import asyncio

import numpy as np

from estimators.faults.hydraulic_checks import Attribution
from estimators.io.logformat import STREAMS
from tests.twin.opcua.test_estimator import Events
from twin.view.layout import free_port

STALL = Attribution(3, "ram_stall", "face", 400.0, 402.0, 401.0, 1.5, "ram at 31.6 MPa with its stroke standing")


class FakeChecks:
    """Online checks that find STALL once the pushram is complete past 500 s, and nothing more."""

    def __init__(self):
        self.made_until, self.finished, self.said = 0.0, False, False

    def add(self, name, columns, made_until):
        self.made_until = made_until if name == "pushram" else self.made_until

    def take(self, final=False):
        self.finished |= final
        if self.made_until <= 500.0 or self.said:
            return []
        self.said = True
        return [STALL]


async def _in_process(asyncua, port: int) -> dict:
    from twin.opcua.address_space import HYDRAULIC_ALARM_EVENT_TYPE, NAMESPACE, build
    from twin.opcua.publishers import HydraulicAlarms

    server = asyncua.Server()
    await server.init()
    server.set_endpoint(f"opc.tcp://127.0.0.1:{port}/longwall/")
    nodes = await build(server, 4, {"PushRam": STREAMS["pushram"], "Pressure": STREAMS["pressure"]},
                        lambda name, seq: [], "")
    checks = FakeChecks()
    alarms = HydraulicAlarms(checks, nodes.hydraulic_alarms)
    rows = {"t": np.zeros(0)}
    async with server:
        client = asyncua.Client(f"opc.tcp://127.0.0.1:{port}/longwall/")
        async with client:
            ns = await client.get_namespace_index(NAMESPACE)
            rss = await (await client.nodes.objects.get_child(f"{ns}:Longwall")).get_child(f"{ns}:RoofSupportSystem")
            alarm_type = await client.nodes.base_event_type.get_child(f"{ns}:{HYDRAULIC_ALARM_EVENT_TYPE}")
            events = Events()
            sub = await client.create_subscription(20, events)
            await sub.subscribe_events(rss, alarm_type)
            await alarms.add("pushram", rows, 300.0)
            early = alarms.raised
            for made_until in (600.0, 900.0):
                await alarms.add("pushram", rows, made_until)
            await alarms.add("imu", rows, 1000.0)  # not read
            await alarms.finish()
            for _ in range(50):
                if events.received:
                    break
                await asyncio.sleep(0.1)
            await asyncio.sleep(0.3)  # a second event, if any, arrives
            return {"early": early, "raised": alarms.raised, "finished": checks.finished, "events": events.received}


def test_a_fault_found_online_is_one_event_of_the_roof_support_system(asyncua):
    """A stall found once the pushram is complete past 500 s: no event before, then exactly one, with the support,
    kind, cause, the time it was confirmed, the face's severity and a message naming the support; the log's end
    runs the checks' last window."""
    seen = asyncio.run(asyncio.wait_for(_in_process(asyncua, free_port()), 60))
    assert seen["early"] == 0 and seen["raised"] == 1 and seen["finished"]
    (event,) = seen["events"]
    assert (event.Support, event.Kind, event.Cause, event.SimulationTime) == (3, "ram_stall", "face", 401.0)
    assert event.Severity == 700 and event.Message.Text.startswith("support 3: ram_stall (face)")
