"""`longwall serve --estimator` (twin.opcua.estimator): the shearer positioning method run online on the published
sensor rows, its passes under Longwall/Estimator and its alarms as events."""

from __future__ import annotations

import asyncio
import math
from types import SimpleNamespace

import numpy as np
import pytest

from estimators.io.log import log_from_columns
from estimators.io.logformat import ESTIMATE, FLAG_ISOLATED, STREAMS, read_stream
from estimators.shearer.methods import estimate
from estimators.shearer.online import OnlinePositioning
from tests.twin.opcua.conftest import served
from twin.cli import main
from twin.config.scenario import load_scenario
from twin.opcua.estimator import FED_STREAMS, LOST_TRACK, RAIL_ISOLATED, EstimatedPass, pass_alarms
from twin.pipeline.estimate import positioning_config, solution_columns
from twin.view.layout import free_port

pytestmark = pytest.mark.slow  # the served run: over 3 s of the full suite

METHOD = "kf_cpoem_rts"


def test_a_method_that_does_not_run_online_is_refused_in_one_line(capsys, tmp_path):
    assert main(["serve", "--estimator", "bogus", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--estimator bogus: not a method that runs online" in err[0] and "kf_cpoem_rts" in err[0]
    assert not (tmp_path / "x").exists()


class Events:
    """The alarm events a subscription received."""

    def __init__(self):
        self.received = []

    def event_notification(self, event) -> None:
        self.received.append(event)


async def _connect(asyncua, port: int):
    for _ in range(300):  # the server listens once the twin is set up
        try:
            client = asyncua.Client(f"opc.tcp://127.0.0.1:{port}/longwall/")
            await client.connect()
            return client
        except (OSError, asyncio.TimeoutError):
            await asyncio.sleep(0.2)
    raise TimeoutError("no server")


async def _estimator_nodes(client):
    from twin.opcua.address_space import ALARM_EVENT_TYPE, NAMESPACE  # needs asyncua

    ns = await client.get_namespace_index(NAMESPACE)
    longwall = await client.nodes.objects.get_child(f"{ns}:Longwall")
    estimator = await longwall.get_child(f"{ns}:Estimator")
    alarm_type = await client.nodes.base_event_type.get_child(f"{ns}:{ALARM_EVENT_TYPE}")
    return ns, longwall, estimator, alarm_type


async def _read_path(asyncua, estimator, ns: int) -> dict[str, np.ndarray]:
    """Estimator/ReadBlocks from the first block on, until no more: the estimated path's columns joined."""
    from twin.opcua.address_space import column_values

    read = await estimator.get_child(f"{ns}:ReadBlocks")
    parts, sequence = [], 1
    while True:
        sequences, first_rows, counts, until, columns = await estimator.call_method(
            read, asyncua.ua.Variant(sequence, asyncua.ua.VariantType.UInt32))
        if not sequences:
            break
        assert sequences[0] == sequence and first_rows[0] == sum(p["t"].size for p in parts)  # nothing lost
        parts.append({c.name: column_values(v.Value, c.dtype) for c, v in zip(ESTIMATE.columns, columns)})
        sequence = sequences[-1] + 1
    return {c.name: np.concatenate([p[c.name] for p in parts]) for c in ESTIMATE.columns}


async def _served_client(asyncua, port: int) -> dict:
    """Subscribe to the estimator's alarms as the run starts; once it is Finished, read the estimator's nodes and
    its whole path."""
    client = await _connect(asyncua, port)
    try:
        ns, longwall, estimator, alarm_type = await _estimator_nodes(client)
        events = Events()
        sub = await client.create_subscription(50, events)
        await sub.subscribe_events(estimator, alarm_type)
        state = await longwall.get_child(f"{ns}:State")
        while await state.read_value() != "Finished":
            await asyncio.sleep(0.5)
        out = {name: await (await estimator.get_child(f"{ns}:{name}")).read_value()
               for name in ("Method", "ShearerPosition", "ShearerPositionSigma", "Time", "Healthy", "Passes")}
        out["path"] = await _read_path(asyncua, estimator, ns)
        await asyncio.sleep(0.5)  # the last events reach the subscription
        out["events"] = [(e.Kind, e.Method) for e in events.received]
        return out
    finally:
        await client.disconnect()


def test_the_served_estimate_is_the_method_run_on_the_served_logs(asyncua, tmp_path):
    """The default face (2 cycles) served at full speed with the default estimator: the path a client reads from
    Estimator/ReadBlocks is, bit for bit, OnlinePositioning run offline on the run directory's sensor files and the
    batch method's rows; ShearerPosition is its last row, its sigma above 0, within 4 sigma of the truth at its
    Time; the alarm events received are those the offline passes raise."""
    port, out = free_port(), tmp_path / "served"
    seen, stdout = served(2, port, out, lambda: _served_client(asyncua, port), 600, 120)
    scn = load_scenario(out / "scenario.toml")
    cfg = positioning_config(scn)
    streams = {name: read_stream(out, STREAMS[name]).to_pydict() for name in FED_STREAMS}
    streams = {name: {k: np.asarray(v) for k, v in cols.items()} for name, cols in streams.items()}
    passes = OnlinePositioning(cfg, METHOD).feed(streams, final=True)
    offline = [solution_columns(p.solution, scn) for p in passes]
    path = seen["path"]
    assert seen["Method"] == METHOD and seen["Passes"] == len(passes) >= scn.cycles
    for c in ESTIMATE.columns:
        np.testing.assert_array_equal(path[c.name], np.concatenate([o[c.name] for o in offline]), err_msg=c.name)
    batch = estimate(log_from_columns(*(streams[k] for k in ("imu", "odometer", "survey")),
                                      pushram=streams["pushram"], face_survey=streams["face_survey"]),
                     cfg, (METHOD,), workers=1)[METHOD]
    np.testing.assert_array_equal(path["t"], batch.t[1:])
    np.testing.assert_array_equal(np.column_stack([path["lat"], path["lon"], path["h"]]), batch.llh[1:])
    np.testing.assert_array_equal(path["flags"], batch.flags[1:])

    position, sigma = np.array(seen["ShearerPosition"]), np.array(seen["ShearerPositionSigma"])
    assert seen["Time"] == path["t"][-1] and seen["Healthy"] == passes[-1].healthy
    assert position.tolist() == [path[k][-1] for k in ("p_f_x", "p_f_y", "p_f_z", "p_t_e", "p_t_n", "p_t_u")]
    assert sigma[3:].tolist() == [path[f"sd_pos_{a}"][-1] for a in "enu"] and (sigma > 0).all()
    truth = read_stream(out, STREAMS["truth_shearer"], ("t", "p_t_e", "p_t_n", "p_t_u")).to_pydict()
    true_t = np.array([np.interp(seen["Time"], truth["t"], truth[f"p_t_{a}"]) for a in "enu"])
    assert (np.abs(position[3:] - true_t) < 4 * sigma[3:]).all(), (position[3:] - true_t, sigma[3:])

    expected = [(a.kind, METHOD) for p in passes for a in pass_alarms(METHOD, p)]
    assert seen["events"] == expected
    assert f"{len(passes)} estimated passes" in stdout


def _columns(t: np.ndarray, flags: np.ndarray) -> dict[str, np.ndarray]:
    """ESTIMATE columns of a made-up pass: positions of 1, 2, 3 m, one-sigma 0.1 m."""
    cols = {c.name: np.zeros(t.size, c.dtype) for c in ESTIMATE.columns}
    cols.update(t=t, flags=flags.astype(np.int32), p_f_x=np.ones(t.size), p_t_u=np.full(t.size, 3.0))
    for a in "enu":
        cols[f"sd_pos_{a}"] = np.full(t.size, 0.1)
    return cols


async def _in_process(asyncua, port: int, items: list) -> dict:
    """A server with the Estimator's nodes only; a fake feed handing `items` over; a client subscribed to the
    alarms reads what the publisher wrote."""
    from twin.opcua.address_space import blocks_variants, build
    from twin.opcua.publishers import EstimatorPublisher, server_write

    server = asyncua.Server()
    await server.init()
    server.set_endpoint(f"opc.tcp://127.0.0.1:{port}/longwall/")
    published = None
    nodes = await build(server, 2, {}, lambda name, seq: [], "",
                        (METHOD, lambda seq: blocks_variants(ESTIMATE, published.path.read(seq))))
    feed = SimpleNamespace(method=METHOD, take=lambda: [items.pop(0) for _ in range(len(items))])
    published = EstimatorPublisher(server_write(server), nodes.estimator, feed, 10, 0.0)
    async with server:
        client = asyncua.Client(f"opc.tcp://127.0.0.1:{port}/longwall/")
        async with client:
            ns, _, estimator, alarm_type = await _estimator_nodes(client)
            events = Events()
            sub = await client.create_subscription(20, events)
            await sub.subscribe_events(estimator, alarm_type)
            await published.publish(5.0)  # the pass is known at 10 s: not yet
            early = await (await estimator.get_child(f"{ns}:Passes")).read_value()
            await published.publish(math.inf)
            for _ in range(50):
                if events.received:
                    break
                await asyncio.sleep(0.1)
            return {"early": early, "events": events.received,
                    "healthy": await (await estimator.get_child(f"{ns}:Healthy")).read_value(),
                    "position": await (await estimator.get_child(f"{ns}:ShearerPosition")).read_value(),
                    "path": await _read_path(asyncua, estimator, ns)}


def test_an_unhealthy_pass_is_published_once_known_and_raises_a_lost_track_event(asyncua):
    """A made-up pass over which the filter lost track, its rail model isolated over two epochs: it is published
    only once the publisher's clock reaches the time it became known, with Healthy false, and a client subscribed
    to the Estimator's alarms receives a LostTrack then a RailIsolated event with the method, the simulated time,
    a severity and a message."""
    t = np.array([7.0, 8.0, 9.0])
    flags = np.array([0, FLAG_ISOLATED, FLAG_ISOLATED])
    one = SimpleNamespace(solution=SimpleNamespace(t=t, flags=flags), healthy=False, cut=None)
    alarms = pass_alarms(METHOD, one)
    assert [a.kind for a in alarms] == [LOST_TRACK, RAIL_ISOLATED] and alarms[1].t == 8.0
    assert pass_alarms(METHOD, SimpleNamespace(solution=SimpleNamespace(t=t, flags=flags * 0), healthy=True)) == []
    item = EstimatedPass(_columns(t, flags), False, alarms, 10.0)
    seen = asyncio.run(asyncio.wait_for(_in_process(asyncua, free_port(), [item]), 60))
    assert seen["early"] == 0 and seen["healthy"] is False
    assert seen["position"] == [1.0, 0.0, 0.0, 0.0, 0.0, 3.0]
    np.testing.assert_array_equal(seen["path"]["t"], t)
    got = [(e.Kind, e.Method, e.SimulationTime, e.Severity) for e in seen["events"]]
    assert got == [(LOST_TRACK, METHOD, 9.0, 800), (RAIL_ISOLATED, METHOD, 8.0, 600)]
    assert "lost track" in seen["events"][0].Message.Text


def test_an_estimator_that_fails_says_so_and_does_not_hold_the_publisher_up():
    """Rows the method cannot read (IMU rows without their increments): the worker hands over one EstimatorFailed
    alarm naming the method, and takes every row added after it (more than its queue holds) without blocking."""
    from twin.opcua.estimator import FAILED, FEED_QUEUE, EstimatorFeed
    from twin.pipeline.api import default_scenario

    async def run() -> list:
        feed = EstimatorFeed(load_scenario(default_scenario()), "kf", ("imu",))
        for k in range(2 * FEED_QUEUE + 2):
            await feed.add("imu", {"t": np.arange(k, k + 1.0, 0.5)}, k + 1.0)
        await feed.finish()
        return feed.take()

    out = asyncio.run(asyncio.wait_for(run(), 60))
    assert len(out) == 1 and out[0].kind == FAILED and out[0].message.startswith("kf stopped: ")
