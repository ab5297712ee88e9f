"""The supports' push-ram and pressure streams drawn a span at a time (twin.sensors.streams.SupportSensors): any
partition of the run gives, bit for bit, the streams of one span, faults of every kind included."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import simulated
from twin.config.sensors import Fault
from twin.sensors.streams import SupportSensors


@pytest.fixture(scope="module")
def run():
    scn, result = simulated("default")
    t, s = result.tables["truth_shearer"]["t"], result.tables["truth_shearer"]["s"]
    t_end = float(t[-1])
    faults = [Fault(kind=kind, t_start_s=t_end * a, t_end_s=t_end * b, target=target, value=value)
              for kind, a, b, target, value in (
                  ("ram_noise_burst", 0.1, 0.5, 3, 0.05), ("ram_stuck", 0.2, 0.6, 9, 0.0),
                  ("ram_dropout", 0.3, 0.35, 1, 0.0), ("ram_drift", 0.05, 0.9, 2, 1e-5),
                  ("leg_pressure_noise_burst", 0.15, 0.7, 4, 2.0), ("ram_pressure_stuck", 0.4, 0.8, 6, 0.0),
                  ("leg_pressure_noise_burst", 0.5, 0.9, 2, 1.0), ("push_shortfall", 0.3, 0.6, 4, 0.05),
                  ("rail_deviation", 0.25, 0.45, None, 1.0))]
    scn = scn.model_copy(update={"faults": faults})
    return scn, result.tables["truth_supports"], {"t": t, "s": s}, t_end


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_support_streams_over_random_partitions_are_the_whole_run(run, seed):
    scn, supports, shearer, t_end = run
    whole = SupportSensors(scn, 0).step(0.0, t_end, True, supports, shearer)
    rng = np.random.default_rng(seed)
    edges = np.unique(np.concatenate([[0.0, t_end], rng.uniform(0.0, t_end, 6),
                                      np.round(rng.uniform(0.0, t_end, 3))]))  # some on the clocks' ticks
    sensors = SupportSensors(scn, 0)
    parts = [sensors.step(a, b, k == edges.size - 2, supports, shearer)
             for k, (a, b) in enumerate(zip(edges[:-1], edges[1:]))]
    for name, cols in whole.items():
        for key, value in cols.items():
            joined = np.concatenate([p[name][key] for p in parts])
            assert np.array_equal(joined, value, equal_nan=True), (name, key)
    stuck = (whole["pushram"]["support"] == 9) & (whole["pushram"]["t"] >= 0.2 * t_end) \
        & (whole["pushram"]["t"] < 0.6 * t_end)
    assert np.unique(whole["pushram"]["extension"][stuck]).size == 1


def test_the_spans_cover_the_run_once(run):
    scn, _, _, t_end = run
    spans = SupportSensors(scn, 0).spans(t_end)
    assert spans[0][0] == 0.0 and spans[-1][1] == t_end and spans[-1][2] and not any(s[2] for s in spans[:-1])
    assert all(a[1] == b[0] for a, b in zip(spans[:-1], spans[1:]))


def test_the_shearer_track_held_gives_the_whole_runs_streams(run):
    """A streaming run holds the shearer's (t, s) only about the rail_deviation windows (twin_stream.ShearerTrack):
    fed in chunks cut anywhere, what it holds gives the streams of the whole (t, s) bit for bit, while holding a
    small part of the run; a window's deviation is present (the test can see a wrong window)."""
    from twin.pipeline.twin_stream import ShearerTrack

    scn, supports, shearer, t_end = run
    whole = SupportSensors(scn, 0).step(0.0, t_end, True, supports, shearer)
    track = ShearerTrack(scn)
    edges = [0, 1, 7_919, 7_920, 50_001, shearer["t"].size]
    for a, b in zip(edges[:-1], edges[1:]):
        track.add({k: v[a:b] for k, v in shearer.items()})
    held = track.rows()
    assert track.t_last == shearer["t"][-1]
    assert 0 < held["t"].size < 0.25 * shearer["t"].size  # the window is 20 % of the run
    got = SupportSensors(scn, 0).step(0.0, t_end, True, supports, held)
    for name, cols in whole.items():
        for key, value in cols.items():
            assert np.array_equal(got[name][key], value, equal_nan=True), (name, key)
    without = SupportSensors(scn.model_copy(update={"faults": [f for f in scn.faults if f.kind != "rail_deviation"]}),
                             0).step(0.0, t_end, True, supports, held)
    assert not np.array_equal(without["pushram"]["extension"], whole["pushram"]["extension"])
    empty = ShearerTrack(scn.model_copy(update={"faults": []}))
    empty.add(shearer)
    assert empty.rows()["t"].size == 0 and empty.t_last == shearer["t"][-1]
