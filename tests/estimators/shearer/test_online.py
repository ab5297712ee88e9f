"""001's filter online (estimators.shearer.online): a log fed in pieces gives, pass by pass as the passes end, the
batch method's rows bit for bit, holding a pass of IMU rows."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.io.log import ImuBuffer, log_from_columns
from estimators.shearer.config import PositioningError
from estimators.shearer.methods import estimate
from estimators.shearer.online import OnlinePositioning
from estimators.shearer.positioning import run_kf
from estimators.shearer.prepare import prepare
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


def _log(streams):
    return log_from_columns(*(streams[k] for k in STREAMS[:3]), pushram=streams["pushram"],
                            face_survey=streams["face_survey"])


def test_a_straight_cut_is_the_passes_run_across_the_face_and_the_epochs_before_the_last_pass_go(default_streams):
    """Each pass's cut rows run from one face end to the other: the odometer's travel over them is more than
    STRAIGHT_CUT_FRACTION of the face. The online run finds the whole log's cuts and passes holding the epochs from
    its last pass's first on, and keeps what the whole run says of them (the odometer's start and extremes)."""
    scn, streams = default_streams
    cfg = positioning_config(scn)
    online = OnlinePositioning(cfg)
    passes = online.feed(streams, final=True)
    face = scn.face.pan_count * scn.face.pan_length_m
    for p in passes:
        if p.cut is not None:
            llh = p.solution.llh[p.cut]
            assert llh.shape[0] > 10
    whole, held = prepare(_log(streams), cfg), online.preparer.prep
    assert held.cuts == whole.cuts and held.segments == whole.segments and held.n_kf == whole.n_kf
    assert held.first_epoch == whole.segments[-1][0] > 0
    for key in ("t_kf", "odo", "mode"):
        assert np.array_equal(getattr(held, key), getattr(whole, key)[held.first_epoch:]), key
    assert (held.odo0, held.odo_min, held.odo_max) == (whole.odo[0], whole.odo.min(), whole.odo.max())
    with pytest.raises(ValueError, match=f"filter epoch 0 was let go .* epochs from {held.first_epoch} are held"):
        held.span(0, 1)
    lengths = [whole.odo[last] - whole.odo[first - 1] for first, last in whole.cuts]
    assert all(abs(d) > 0.8 * (face - scn.shearer.length_m) for d in lengths)


def test_the_odometer_gaps_are_counted_over_the_whole_run(default_streams):
    """The odometer silent for 4 s in the first pass and 3 s in the last: fed in pieces, the online run (which lets
    the first pass's epochs go) names the gaps as the batch run does, their filter steps and the first's time."""
    scn, streams = default_streams
    cfg = positioning_config(scn)
    odo = streams["odometer"]
    t_end = odo["t"][-1]
    silent = ((odo["t"] > 300.0) & (odo["t"] < 304.0)) | ((odo["t"] > t_end - 200.0) & (odo["t"] < t_end - 197.0))
    streams = {**streams, "odometer": {k: v[~silent] for k, v in odo.items()}}
    whole = prepare(_log(streams), cfg)
    batch = run_kf(_log(streams), cfg, whole, cpoem=False, smooth=False)[0].notes
    online = OnlinePositioning(cfg, "kf")
    pieces = list(_pieces(streams, [1000.0, 1800.0, t_end - 100.0]))
    for k, piece in enumerate(pieces):
        online.feed(piece, final=k == len(pieces) - 1)
    gap = [n for n in batch if n.startswith("odometer: no data")]
    assert len(gap) == 1 and int(gap[0].split()[4]) == np.sum(whole.mode[1:] < 0) >= 60
    assert online.preparer.prep.first_epoch > np.flatnonzero(whole.mode < 0)[0] > 0  # the first gap was let go
    assert [n for n in online.finish() if n.startswith("odometer: no data")] == gap


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
