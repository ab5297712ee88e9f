"""Fixtures of the OPC UA tests (`longwall serve`, `longwall record`)."""

from __future__ import annotations

import os

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
