"""Benchmark: `longwall serve` publishing the default scenario on OPC UA as fast as it runs (issue 27's target: at
least 50x real time), with an asyncua client subscribed to the shearer's position and every shield's ram stroke the
whole time (the load of a face automation system watching it): once with the truth only (--twin-only), then with
the sensor streams published in blocks and `longwall record` recording them (the whole run held for it, --history),
without the estimator (--estimator none) and with it (the default kf_cpoem_rts run online on the published rows,
its passes published and recorded: everything published). Prints, for each, the simulated time published, the wall
time, the factor of real time, the publications and estimated passes, the data changes the client received and the
rows recorded, and the machine's load average before and after (a loaded machine publishes slower).

Run: python benchmarks/bench_serve.py [--cycles N] [--publish-rate HZ]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import subprocess
import sys
import tempfile

from asyncua import Client

from twin.opcua.address_space import NAMESPACE, shield_name
from twin.view.layout import free_port

TARGET_X = 50.0


class Counter:
    """Counts the data changes of a subscription."""

    def __init__(self):
        self.changes = 0

    def datachange_notification(self, node, val, data) -> None:
        self.changes += 1


async def watch(port: int, server: subprocess.Popen) -> int:
    """Subscribe to ShearerPosition and every shield's RamStroke until the server ends; the changes received."""
    url = f"opc.tcp://127.0.0.1:{port}/longwall/"
    for _ in range(300):
        try:
            client = Client(url)
            await client.connect()
            break
        except (OSError, asyncio.TimeoutError):
            await asyncio.sleep(0.2)
    counter = Counter()
    try:
        ns = await client.get_namespace_index(NAMESPACE)
        longwall = await client.nodes.objects.get_child(f"{ns}:Longwall")
        nodes = [await longwall.get_child([f"{ns}:Shearer", f"{ns}:ShearerPosition"])]
        rss = await longwall.get_child(f"{ns}:RoofSupportSystem")
        for k in range(len(await rss.get_children())):
            nodes.append(await rss.get_child([f"{ns}:{shield_name(k)}", f"{ns}:RamStroke"]))
        sub = await client.create_subscription(100, counter)
        await sub.subscribe_data_change(nodes)
        state = await longwall.get_child(f"{ns}:State")
        while server.poll() is None and await state.read_value() != "Finished":
            await asyncio.sleep(0.5)
    except Exception:  # the server ended under the client: what it received counts
        pass
    finally:
        try:
            await client.disconnect()
        except Exception:
            pass
    return counter.changes


def serve_once(cycles: int, publish_rate: float, sensors: bool, estimator: str) -> None:
    """Serve (and with `sensors` record) once, running `estimator`; print the figures."""
    load = os.getloadavg()[0]
    port = free_port()
    endpoint = f"opc.tcp://127.0.0.1:{port}"
    with tempfile.TemporaryDirectory(prefix="bench-serve-") as tmp:
        server = subprocess.Popen([sys.executable, "-m", "twin.cli", "serve", "--speed", "max", "--cycles",
                                   str(cycles), "--publish-rate", str(publish_rate), "--endpoint", endpoint,
                                   "--out", f"{tmp}/served", "--estimator", estimator,
                                   *(["--history", "1e6"] if sensors else ["--twin-only"])],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        if sensors:
            server.stdout.readline()  # "serving on ...": the recorder connects to a server that listens
        recorder = subprocess.Popen([sys.executable, "-m", "twin.cli", "record", "--opcua", endpoint, "--out",
                                     f"{tmp}/recorded"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                    text=True) if sensors else None
        changes = asyncio.run(watch(port, server))
        out, err = server.communicate()
        recorded = recorder.communicate() if recorder else None
    if server.returncode:
        sys.exit(f"longwall serve failed: {err.strip().splitlines()[-1] if err.strip() else server.returncode}")
    line = out.strip().splitlines()[-1]
    factor = float(line.split("(")[1].split("x")[0])
    what = f"the sensor streams, estimator {estimator}" if sensors else "truth only"
    print(f"{what} (load average {load:.1f} before, {os.getloadavg()[0]:.1f} after, {os.cpu_count()} cores): {line}")
    print(f"  real-time factor {factor:.0f}x against the target {TARGET_X:.0f}x: "
          f"{'met' if factor >= TARGET_X else 'not met'}; the client received {changes} data changes")
    if recorded is not None:
        print(f"  longwall record: {(recorded[0] or recorded[1]).strip().splitlines()[-1]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=2)
    parser.add_argument("--publish-rate", type=float, default=10.0, metavar="HZ")
    args = parser.parse_args()
    for sensors, estimator in ((False, "none"), (True, "none"), (True, "kf_cpoem_rts")):
        serve_once(args.cycles, args.publish_rate, sensors, estimator)


if __name__ == "__main__":
    main()
