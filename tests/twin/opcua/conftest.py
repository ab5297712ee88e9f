"""Fixtures of the OPC UA tests (`longwall serve`, `longwall record`)."""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
from collections.abc import Awaitable, Callable
from pathlib import Path

import pytest


@pytest.fixture(scope="module")
def asyncua():
    """asyncua, skipped only when it is not installed outside CI."""
    try:
        import asyncua
    except ImportError:
        if os.environ.get("CI"):
            raise
        pytest.skip('asyncua is not installed (pip install -e ".[opcua]")')
    return asyncua


def served(cycles: int, port: int, out: Path, client: Callable[[], Awaitable], client_timeout_s: float,
           server_timeout_s: float) -> tuple[object, str]:
    """`longwall serve` of the default face (`cycles`) at full speed on 127.0.0.1:`port` into `out`, with `client()`
    run against it (at most client_timeout_s); returns what the client returned and the server's stdout, once the
    server has exited 0 (at most server_timeout_s)."""
    server = subprocess.Popen([sys.executable, "-m", "twin.cli", "serve", "--cycles", str(cycles), "--speed", "max",
                               "--endpoint", f"opc.tcp://127.0.0.1:{port}", "--out", str(out)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        seen = asyncio.run(asyncio.wait_for(client(), client_timeout_s))
        stdout, stderr = server.communicate(timeout=server_timeout_s)
    finally:
        server.kill()
    assert server.returncode == 0, stderr[-2000:]
    return seen, stdout
