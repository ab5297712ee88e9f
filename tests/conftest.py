"""Shared fixtures: each shipped scenario simulated once per test session.

Long scenarios are capped at two cycles (enough for the closed path between consecutive cycles); the
checks are the same as over the full run, and the full runs are the benchmarks' job.
"""

from __future__ import annotations

import importlib.util
import sys
from functools import cache
from pathlib import Path
from types import ModuleType

import pytest

from twin.config.experiments import is_experiment
from twin.config.scenario import Scenario, load_scenario, parse_scenario
from twin.config.turntable import is_turntable
from twin.pipeline.simulate import SimResult, simulate

SCENARIO_DIR = Path(__file__).resolve().parent.parent / "scenarios"
SEED004_VARIANTS = ("seed004_fault", "seed004_20cycles", "panel_100")
"""seed004 with a fault or more cycles (panel_100: a panel's worth): the same face, checked against seed004 in tests/twin/config/test_scenario.py and run by
benchmarks/bench_rail.py (simulating them again here would only repeat seed004)."""
SCENARIOS = sorted(p.stem for p in SCENARIO_DIR.glob("*.toml")
                   if not (is_experiment(p) or is_turntable(p) or p.stem in SEED004_VARIANTS))
"""The shipped face scenarios; the SINS experiment files (kind = "sins_experiment") are tests/twin/papers/test_sins_experiments.py's."""
DRIFTING = ("drift_200", "face_alignment")
"""Scenarios whose faces drift by design (stroke-controlled pushes with stop errors, a shortfall kept; face_alignment
steers them back by offsets): their pans do not advance one web each, so the `run` fixture's checks leave them out;
benchmarks/bench_drift.py and bench_face_alignment.py run them."""
EXPERIMENTS = sorted(p.stem for p in SCENARIO_DIR.glob("*.toml") if is_experiment(p))
TEST_CYCLES = 2
VARIANTS = {"default-before-push": ("default", {"supports": {"sequence": "before_push"}})}
"""Runs beyond the shipped files: a shipped scenario with some sections changed."""


def capped(name: str, **overrides) -> Scenario:
    """A shipped scenario capped at TEST_CYCLES cycles; `overrides` replace keys, or keys of sections."""
    scn = load_scenario(SCENARIO_DIR / f"{name}.toml")
    data = scn.model_dump()
    data["cycles"] = min(scn.cycles, TEST_CYCLES)
    for key, value in overrides.items():
        if isinstance(value, dict):
            data[key].update(value)
        else:
            data[key] = value
    return parse_scenario(data, name)


@cache
def simulated(name: str) -> tuple[Scenario, SimResult]:
    base, overrides = VARIANTS.get(name, (name, {}))
    scn = capped(base, **overrides)
    return scn, simulate(scn)


@pytest.fixture(params=[s for s in SCENARIOS if s not in DRIFTING] + list(VARIANTS))
def run(request) -> tuple[Scenario, SimResult]:
    return simulated(request.param)


SHORT_RUN_S = 5.0
"""Length of the `short_default_run` fixture's log [s]."""


@pytest.fixture(scope="session")
def short_default_run(tmp_path_factory) -> Path:
    """The default scenario's run directory (truth of `simulated`, trial 0's sensors) with every stream cut to its
    first SHORT_RUN_S seconds: a log `longwall import`, `estimate` and `report` take, for the bad-input tests."""
    import pyarrow.compute as pc

    from estimators.io.logformat import STREAMS, make_table, write_stream
    from twin.config.scenario import scenario_to_toml
    from twin.sensors.streams import imu_truth, sensor_streams

    scn, result = simulated("default")
    truth = result.tables
    out = tmp_path_factory.mktemp("short_default") / "run"
    out.mkdir()
    for name, cols in {**truth, **sensor_streams(scn, truth, imu_truth(scn, truth["truth_shearer"]))}.items():
        table = make_table(STREAMS[name], cols)
        if STREAMS[name].time_order != "none":
            table = table.filter(pc.less_equal(table["t"], SHORT_RUN_S))
        write_stream(out, STREAMS[name], table)
    (out / "scenario.toml").write_text(scenario_to_toml(scn))
    (out / "metrics.json").write_text('{"twin": {}, "estimators": {}}\n')
    return out


def benchmark_module(name: str) -> ModuleType:
    """benchmarks/NAME.py imported as module NAME (the benchmarks are scripts, not a package)."""
    spec = importlib.util.spec_from_file_location(name, SCENARIO_DIR.parent / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(name, module)  # dataclasses look the module up
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def viewer_launches(monkeypatch) -> list:
    """`longwall view` with the viewer's launch recorded instead of run (twin.view.layout.open_viewer): the list
    each launch's argument list is appended to, the viewer found on PATH as /usr/bin/rerun, a display there."""
    from twin.view import layout

    monkeypatch.setenv("DISPLAY", ":0")
    launched: list = []
    monkeypatch.setattr(layout.subprocess, "Popen", lambda args, **kw: launched.append(args))
    monkeypatch.setattr(layout.shutil, "which", lambda name: "/usr/bin/rerun")
    monkeypatch.setattr(layout.sys, "executable", "/nonexistent/bin/python")
    return launched
