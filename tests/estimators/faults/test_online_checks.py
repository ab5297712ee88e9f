"""The hydraulic and push-ram checks online (estimators.faults.online_checks): the default face's logs fed in
pieces of 100 s give each fault the whole-log checks find once, on its support and of its kind, and nothing on a
fault-free face."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.faults.hydraulic_checks import check_hydraulics
from estimators.faults.online_checks import OnlineChecks
from estimators.faults.ram_checks import check_log
from tests.conftest import capped
from twin.pipeline.estimate import hydraulic_layout, ram_layout
from twin.pipeline.simulate import simulate
from twin.sensors.streams import imu_truth, sensor_streams

pytestmark = pytest.mark.slow  # a twin run per face: over 3 s of the full suite

PIECE_S = 100.0
WINDOWS = ({}, {"window_s": 600.0, "step_s": 120.0})
"""The default window (one cycle: the whole 1-cycle log by its end) and one that slides over it."""


def _logs(faults: list[dict]):
    scn = capped("default", cycles=1, faults=faults)
    result = simulate(scn)
    streams = sensor_streams(scn, result.tables, imu_truth(scn, result.tables["truth_shearer"]), 0)
    return scn, streams["pushram"], streams["pressure"]


def _online(scn, pushram, pressure, **window) -> list[tuple[float, object]]:
    """(the end of the piece after which it was said, the fault) for the logs fed in pieces of PIECE_S, the last with
    no more rows to come (made until infinity, as the server ends a stream: the checks stop at its last row)."""
    checks = OnlineChecks(ram_layout(scn), hydraulic_layout(scn), **window)
    said = []
    edges = np.arange(0.0, float(pushram["t"][-1]) + PIECE_S, PIECE_S)
    for a, b in zip(edges[:-1], edges[1:]):
        for name, log in (("pushram", pushram), ("pressure", pressure)):
            now = (log["t"] >= a) & (log["t"] < b)
            checks.add(name, {c: np.asarray(v)[now] for c, v in log.items()}, np.inf if b == edges[-1] else float(b))
        said += [(float(b), f) for f in checks.take()]
        held = np.concatenate([p["t"] for pieces in checks.rows.values() for p in pieces])
        assert held.min() >= b - checks.window_s - checks.step_s  # the last window's rows and those since
    return said + [(np.inf, f) for f in checks.take(final=True)]


def test_a_fault_free_face_raises_nothing():
    logs = _logs([])
    for window in WINDOWS:
        assert _online(*logs, **window) == []


def test_a_failed_set_is_said_once_soon_after_the_set():
    """Support 25's legs set to 12 MPa of 31.5: the whole-log checks' failed_set on support 25, said once by the
    online checks, by the end of the piece a window's guard after it was confirmed (not at the log's end)."""
    scn, pushram, pressure = logs = _logs([{"kind": "failed_set", "t_start_s": 0.0, "t_end_s": 1200.0, "target": 25,
                                            "value": 12.0}])
    whole = check_hydraulics(pushram, pressure, hydraulic_layout(scn), check_log(pushram, ram_layout(scn)))
    assert [(a.support, a.kind) for a in whole] == [(25, "failed_set")]
    for window in WINDOWS:
        said = _online(*logs, **window)
        assert [(f.support, f.kind, f.t_detect) for _, f in said] == [(25, "failed_set", whole[0].t_detect)]
        assert said[0][0] <= whole[0].t_detect + 120.0 + 300.0 + PIECE_S
