"""Shared fixtures: each shipped scenario simulated once per test session.

Long scenarios are capped at two cycles (enough for the closed path between consecutive cycles); the
checks are the same as over the full run, and the full runs are the benchmarks' job.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import pytest

from twin.scenario import Scenario, load_scenario, parse_scenario
from twin.simulate import SimResult, simulate

SCENARIO_DIR = Path(__file__).resolve().parent.parent / "scenarios"
SCENARIOS = sorted(p.stem for p in SCENARIO_DIR.glob("*.toml"))
TEST_CYCLES = 2


def capped(name: str, **overrides) -> Scenario:
    scn = load_scenario(SCENARIO_DIR / f"{name}.toml")
    data = scn.model_dump()
    data["cycles"] = min(scn.cycles, TEST_CYCLES)
    data.update(overrides)
    return parse_scenario(data, name)


@cache
def simulated(name: str) -> tuple[Scenario, SimResult]:
    scn = capped(name)
    return scn, simulate(scn)


@pytest.fixture(params=SCENARIOS)
def run(request) -> tuple[Scenario, SimResult]:
    return simulated(request.param)
