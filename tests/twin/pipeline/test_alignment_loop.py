"""The face alignment loop in the twin: the offsets the roof support system applied are those the alignment system
computes from the saved run's shearer path (no simulation)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import capped
from twin.config.scenario import ScenarioError
from twin.pipeline.alignment_loop import AlignmentLoop
from twin.pipeline.simulate import simulate
from twin.sensors.streams import imu_truth, sensor_streams
from twin.view.summary import LatestAt, ShearerStats, format_summary, twin_summary

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")



def support_advance(res) -> np.ndarray:
    """Each support's advance at each cycle's end from a run's whole truth_supports (what a streaming run gathers)."""
    sups = res.tables["truth_supports"]
    advance = LatestAt(res.tables["truth_cycles"]["t_end"], int(sups["support"].max()) + 1)
    advance.add(sups["t"], sups["support"], sups["advance"])
    return advance.finish()

def test_the_loop_applies_the_offsets_a_saved_run_gives():
    """Truth mode on the default face (its installed line crooked: 0.3 deg random yaw): cycle 0 is pushed as
    planned, cycle 1 with shear 0's offsets (up to 3 mm), as the saved truth_shearer and truth_cycles replayed
    through the system give them, to the last bit."""
    scn = capped("default", alignment={"mode": "truth"})
    res = simulate(scn)
    cycles = res.tables["truth_cycles"]
    replay = AlignmentLoop(scn, cycles)
    replay.observe(res.tables["truth_shearer"])
    assert [s.sequence for s in replay.published] == [s.sequence for s in res.alignment] == [1, 2]
    np.testing.assert_array_equal(res.offsets[0], 0.0)
    np.testing.assert_array_equal(res.offsets[1], replay.published[0].offsets_m)
    assert np.abs(res.offsets[1]).max() > 0.002
    stats = ShearerStats()
    stats.update(res.tables["truth_shearer"])
    summary = twin_summary(scn, res.tables, stats, support_advance(res), res.offsets,
                           [a.sequence for a in res.alignment])
    assert [c["alignment_sequence"] for c in summary["cycles"]] == [1, 2]
    assert summary["cycles"][1]["offsets_rms_mm"] == np.sqrt(np.mean(res.offsets[1] ** 2)) * 1e3 > 0.0
    assert "face alignment: truth path" in format_summary(summary, 1.0)


@pytest.fixture(scope="module")
def estimator_fed():
    """The default face (2 cycles) steered by kf_cpoem_rts, and trial 0's sensor streams as its files hold them."""
    scn = capped("default", alignment={"mode": "kf_cpoem_rts"})
    res = simulate(scn)
    return scn, res, sensor_streams(scn, res.tables, imu_truth(scn, res.tables["truth_shearer"]), 0)


def test_an_estimator_steers_with_the_offsets_its_saved_readings_give(estimator_fed):
    """Mode kf_cpoem_rts: the twin draws trial 0's readings as it goes and runs the filter online; cycle 1 is pushed
    with the offsets of shear 0's estimated path. The run's sensor streams (drawn after the face, as its files hold
    them) replayed through the filter and the system give those offsets and their sigma (the filter's, where the
    face line was measured) to the last bit, and they differ from the truth-fed loop's by the estimate's error (mm), not by nothing."""
    scn, res, streams = estimator_fed
    assert [s.sequence for s in res.alignment] == [1, 2] and not res.alignment[0].held
    replay = AlignmentLoop(scn, res.tables["truth_cycles"]).replay(streams)
    assert [s.sequence for s in replay] == [1, 2]
    np.testing.assert_array_equal(res.offsets[1], replay[0].offsets_m)
    np.testing.assert_array_equal(replay[0].sd_m, res.alignment[0].sd_m)
    measured = np.isfinite(replay[0].line_x_m)  # outside the start gate's end zone
    assert measured.sum() >= 10 and np.all(replay[0].sd_m[measured] > 0)
    truth = AlignmentLoop(capped("default", alignment={"mode": "truth"}), res.tables["truth_cycles"])
    truth.observe(res.tables["truth_shearer"])
    diff = np.abs(truth.published[0].offsets_m - res.offsets[1]).max()
    assert 1e-5 < diff < 0.02, diff
    stats = ShearerStats()
    stats.update(res.tables["truth_shearer"])
    summary = twin_summary(scn, res.tables, stats, support_advance(res), res.offsets,
                           [a.sequence for a in res.alignment], res.path_errors)
    assert [e["shear"] for e in res.path_errors] == [0, 1]
    for c, e in zip(summary["cycles"], res.path_errors):  # the estimate's errors beside the straightness it gave
        assert c["path_sep_mm"] == e["sep_m"] * 1e3 and 0.0 < c["path_across_rms_mm"] < c["path_sep_mm"]
    assert "its path over 2 shears: SEP median" in format_summary(summary, 1.0)


def test_an_estimator_that_lost_track_does_not_steer(estimator_fed):
    """A knock in the middle of shear 0 (the accelerometer reads 3 m/s more over five samples): the filter's health
    monitor finds it lost track over the pass, so the system publishes no offsets for it (sequence 0, none applied)
    and says why."""
    scn, res, streams = estimator_fed
    cycles = res.tables["truth_cycles"]
    imu = dict(streams["imu"])
    knock = np.flatnonzero(imu["t"] > 0.5 * (cycles["t"][0] + cycles["t_cut_end"][0]))[:5]
    imu["dv_x"] = imu["dv_x"].copy()
    imu["dv_x"][knock] += 3.0
    replay = AlignmentLoop(scn, cycles).replay({**streams, "imu": imu})
    assert replay[0].held and replay[0].sequence == 0 and "the estimator lost track" in replay[0].note
    np.testing.assert_array_equal(replay[0].offsets_m, 0.0)


def test_a_loop_needs_the_reversal_stops():
    """The twin hands each shear's path over at the reversal stop after it; without one, a loop is refused."""
    with pytest.raises(ScenarioError, match="alignment.mode: truth needs .* set haulage.reversal_stop_s to at least 1 s"):
        capped("default", alignment={"mode": "truth"}, haulage={"reversal_stop_s": 0.5})
