"""`longwall serve` (twin.opcua): the default face published on OPC UA at full speed, read and steered by an asyncua
client, and who may connect."""

from __future__ import annotations

import asyncio

import numpy as np
import pyarrow.parquet as pq
import pytest

from tests.twin.opcua.conftest import served
from twin.cli import main
from twin.config.scenario import load_scenario
from twin.view.layout import free_port

pytestmark = pytest.mark.slow  # the served run: over 3 s of the full suite

OFFSET_M = 0.01
"""Each shield's offset the test's face alignment system writes."""


def test_a_non_loopback_bind_without_credentials_is_refused(capsys, tmp_path):
    assert main(["serve", "--endpoint", "opc.tcp://0.0.0.0:4840", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "anonymous access is served on a loopback address only" in err[0]
    assert "LONGWALL_OPCUA_PASSWORD" in err[0] and not (tmp_path / "x").exists()


async def _client(asyncua, port: int) -> dict:
    """Connect as the run starts, read ShearerPosition until it moves, write a set of offsets with SequenceNumber
    1, wait for the roof support system to say it applied them."""
    from twin.opcua.address_space import NAMESPACE  # needs asyncua

    ua = asyncua.ua
    url = f"opc.tcp://127.0.0.1:{port}/longwall/"
    for _ in range(100):  # the server listens once the twin is set up
        try:
            client = asyncua.Client(url)
            await client.connect()
            break
        except (OSError, asyncio.TimeoutError):
            await asyncio.sleep(0.2)
    try:
        ns = await client.get_namespace_index(NAMESPACE)
        longwall = await client.nodes.objects.get_child(f"{ns}:Longwall")

        async def node(*path):
            return await longwall.get_child([f"{ns}:{p}" for p in path])

        position, cycle = await node("Shearer", "ShearerPosition"), await node("Shearer", "Cycle")
        seen = [await position.read_value()]
        while len(set(seen)) < 3:
            await asyncio.sleep(0.1)
            seen.append(await position.read_value())
        ram = await (await node("RoofSupportSystem", "Shield005", "RamStroke")).read_value()
        offsets = await node("FaceAlignmentSystem", "Offsets")
        n = len(await offsets.read_value())
        written_in = await cycle.read_value()
        await offsets.write_value(ua.Variant([OFFSET_M] * n, ua.VariantType.Double))
        await (await node("FaceAlignmentSystem", "SequenceNumber")).write_value(ua.Variant(1, ua.VariantType.UInt32))
        status = await node("FaceAlignmentSystem", "Status")
        while "applied" not in (said := await status.read_value()):
            await asyncio.sleep(0.2)
        applied = await (await node("FaceAlignmentSystem", "AppliedSequenceNumber")).read_value()
        return {"seen": seen, "ram": ram, "written_in": written_in, "status": said, "applied": applied}
    finally:
        await client.disconnect()


def test_a_client_reads_the_shearer_moving_and_its_offsets_steer_the_next_shear(asyncua, tmp_path):
    """The default face (3 cycles) served on 127.0.0.1 at full speed: the client sees ShearerPosition change and a
    shield's ram stroke; the offsets it writes during a cycle are applied on the next one only (alignment.parquet),
    and the pans' advance over that cycle is a web plus the offset (truth_pans)."""
    port, out = free_port(), tmp_path / "served"
    seen, stdout = served(3, port, out, lambda: _client(asyncua, port), 300, 600)
    assert "x real time" in stdout
    assert np.ptp(seen["seen"]) > 0 and seen["ram"] > 0
    cycle = seen["written_in"] + 1
    assert seen["status"] == f"sequence 1 applied on cycle {cycle}" and seen["applied"] == 1
    table = pq.read_table(out / "alignment.parquet").to_pydict()
    per_cycle = {k: np.unique(np.array(table["offset"])[np.array(table["cycle"]) == k]) for k in range(3)}
    assert per_cycle[cycle].tolist() == [OFFSET_M]
    assert all(per_cycle[k].tolist() == [0.0] for k in range(3) if k != cycle)
    pans = pq.read_table(out / "truth_pans.parquet").to_pydict()
    cycles = pq.read_table(out / "truth_cycles.parquet").to_pydict()
    t, pan, advance = (np.array(pans[k]) for k in ("t", "pan", "advance"))

    def line_at(t_end: float) -> np.ndarray:
        """Each pan's advance at t_end (its latest row)."""
        out = np.zeros(pan.max() + 1)
        for k in range(out.size):
            rows = (pan == k) & (t <= t_end)
            out[k] = advance[rows][-1]
        return out

    ends = np.array(cycles["t_end"])
    step = line_at(ends[cycle]) - line_at(ends[cycle - 1])
    middle = step[step.size // 4: -step.size // 4]  # away from the face ends' snakes
    web = load_scenario(out / "scenario.toml").face.web_depth_m
    assert abs(np.median(middle) - (web + OFFSET_M)) < 0.003, (np.median(middle), web)
