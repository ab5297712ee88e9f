"""The face alignment loop in the twin: the offsets the roof support system applied are those the alignment system
computes from the saved run's shearer path (no simulation)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import capped
from twin.config.scenario import ScenarioError
from twin.pipeline.alignment_loop import AlignmentLoop
from twin.pipeline.simulate import simulate
from twin.view.summary import ShearerStats, format_summary, twin_summary

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")


def test_the_loop_applies_the_offsets_a_saved_run_gives():
    """Truth mode on the default face (its installed line crooked: 0.3 deg random yaw): cycle 0 is pushed as
    planned, cycle 1 with shear 0's offsets (up to 3 mm), as the saved truth_shearer and truth_cycles replayed
    through the system give them, to the last bit."""
    scn = capped("default", alignment={"mode": "truth"})
    res = simulate(scn)
    cycles = res.tables["truth_cycles"]
    replay = AlignmentLoop(scn, list(zip(cycles["t"], cycles["t_cut_end"])))
    replay.observe(res.tables["truth_shearer"])
    assert [s.sequence for s in replay.published] == [s.sequence for s in res.alignment] == [1, 2]
    np.testing.assert_array_equal(res.offsets[0], 0.0)
    np.testing.assert_array_equal(res.offsets[1], replay.published[0].offsets_m)
    assert np.abs(res.offsets[1]).max() > 0.002
    stats = ShearerStats()
    stats.update(res.tables["truth_shearer"])
    summary = twin_summary(scn, res.tables, stats, res.offsets, [a.sequence for a in res.alignment])
    assert [c["alignment_sequence"] for c in summary["cycles"]] == [1, 2]
    assert summary["cycles"][1]["offsets_rms_mm"] == np.sqrt(np.mean(res.offsets[1] ** 2)) * 1e3 > 0.0
    assert "face alignment: truth path" in format_summary(summary, 1.0)


def test_a_loop_needs_the_reversal_stops():
    """The twin hands each shear's path over at the reversal stop after it; without one, a loop is refused."""
    with pytest.raises(ScenarioError, match="alignment.mode: truth needs .* set haulage.reversal_stop_s to at least 1 s"):
        capped("default", alignment={"mode": "truth"}, haulage={"reversal_stop_s": 0.5})
