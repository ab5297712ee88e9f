"""001's filter online (estimators.shearer.online): a log fed in pieces gives, pass by pass as the passes end, the
batch method's rows bit for bit, holding a pass of IMU rows."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.io.log import ImuBuffer, log_from_columns
from estimators.shearer.config import PositioningError
from estimators.shearer.methods import estimate
from estimators.shearer.online import OnlinePositioning
from tests.conftest import simulated
from twin.pipeline.estimate import positioning_config
from twin.sensors.streams import imu_truth, sensor_streams

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

STREAMS = ("imu", "odometer", "survey", "pushram", "face_survey")


@pytest.fixture(scope="module")
def default_streams():
    scn, result = simulated("default")
    streams = sensor_streams(scn, result.tables, imu_truth(scn, result.tables["truth_shearer"]), 0)
    return scn, {name: streams[name] for name in STREAMS}


def _pieces(streams, edges):
    """The streams cut at the times `edges` into consecutive pieces (rows with edges[k] < t <= edges[k + 1])."""
    bounds = [-np.inf, *edges, np.inf]
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        yield {name: {k: v[(cols["t"] > lo) & (cols["t"] <= hi)] for k, v in cols.items()}
               for name, cols in streams.items()}


@pytest.mark.parametrize("method", ["kf_cpoem_rts", "kf_rts", "kf", "fkf_rail"])
def test_a_log_fed_in_pieces_gives_the_batch_rows_pass_by_pass(default_streams, method):
    """Cut anywhere (inside passes, inside stands, a cut of 0.3 s), the online run's passes joined are the batch
    method's epochs 1.. bit for bit; a pass comes out as soon as its cut has ended, before the log does; the IMU
    buffer then lets its rows go."""
    scn, streams = default_streams
    cfg = positioning_config(scn)
    batch = estimate(log_from_columns(*(streams[k] for k in STREAMS[:3]), pushram=streams["pushram"],
                                      face_survey=streams["face_survey"]), cfg, (method,), workers=1)[method]
    t_end = streams["imu"]["t"][-1]
    rng = np.random.default_rng(3)
    for edges in ([], sorted(rng.uniform(0, t_end, 7)), [1000.0, 1000.3, 2500.0]):
        online = OnlinePositioning(cfg, method)
        passes, before_end = [], 0
        pieces = list(_pieces(streams, edges))
        for k, piece in enumerate(pieces):
            out = online.feed(piece, final=k == len(pieces) - 1)
            passes += out
            if k < len(pieces) - 1:
                before_end += len(out)
        joined = {key: np.concatenate([getattr(p.solution, key) for p in passes]) for key in ("t", "llh", "sd", "flags")}
        for key, rows in joined.items():
            assert np.array_equal(rows, getattr(batch, key)[1:]), (edges, key)
        assert all(p.healthy for p in passes)
        cuts = [p for p in passes if p.cut is not None]
        assert len(cuts) == scn.cycles
        if edges:
            assert before_end >= 1  # passes came out before the log ended
            assert online.imu.base > 0  # and their IMU rows went


def test_a_straight_cut_is_the_passes_run_across_the_face(default_streams):
    """Each pass's cut rows run from one face end to the other: the odometer's travel over them is more than
    STRAIGHT_CUT_FRACTION of the face."""
    scn, streams = default_streams
    online = OnlinePositioning(positioning_config(scn))
    passes = online.feed(streams, final=True)
    face = scn.face.pan_count * scn.face.pan_length_m
    for p in passes:
        if p.cut is not None:
            llh = p.solution.llh[p.cut]
            assert llh.shape[0] > 10
    lengths = [online.preparer.prep.odo[last] - online.preparer.prep.odo[first - 1]
               for first, last in online.preparer.prep.cuts]
    assert all(abs(d) > 0.8 * (face - scn.shearer.length_m) for d in lengths)


def test_a_method_that_cannot_run_online_and_a_forgotten_row_are_refused(default_streams):
    scn, _ = default_streams
    with pytest.raises(PositioningError, match="afkf: not a method that runs online"):
        OnlinePositioning(positioning_config(scn), "afkf")
    buf = ImuBuffer()
    buf.append(np.arange(10.0), np.zeros((10, 3)), np.zeros((10, 3)))
    buf.forget_before(4)
    assert buf.read(4, 6)[0].tolist() == [4.0, 5.0] and buf.size == 10
    with pytest.raises(ValueError, match="IMU rows 2..3 were let go"):
        buf.read(2, 6)
