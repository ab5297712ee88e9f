"""estimators.io.metrics.TruthTrack at estimate times given in order, block by block, from one forward read of the
truth's blocks (cut anywhere, empty blocks included), equals truth_at over the whole truth, bit for bit."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from estimators.io.logformat import LogError
from estimators.io.metrics import TruthTrack, truth_at
from estimators.nav.rotations import quat_normalize


def _truth(rng: np.random.Generator, n: int) -> pa.Table:
    """A track at 100 Hz with repeated times that crosses the antimeridian (longitude wraps from +pi to -pi)."""
    t = np.cumsum(rng.choice([0.0, 0.01, 0.01, 0.01], n))
    lon = np.pi - 2e-7 + 1e-9 * np.arange(n)
    lon = np.where(lon > np.pi, lon - 2 * np.pi, lon)
    q = quat_normalize(np.cumsum(rng.normal(scale=0.01, size=(n, 4)), axis=0) + [1.0, 0, 0, 0])
    return pa.table({"t": t, "lat": 0.5 + 1e-8 * np.cumsum(rng.normal(size=n)), "lon": lon,
                     "h": 100 + np.cumsum(rng.normal(size=n)) * 0.01,
                     **{f"q_nb_{a}": q[:, i] for i, a in enumerate("wxyz")}, "cycle": (t // 3.0).astype(np.int64)})


def _split(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    return np.split(np.arange(n), np.sort(rng.integers(0, n + 1, int(rng.integers(0, 12)))))


@pytest.mark.parametrize("seed", range(4))
def test_truth_track_blocks_equals_truth_at_of_the_whole_truth(seed):
    rng = np.random.default_rng(seed)
    truth = _truth(rng, 2000)
    t_truth = truth.column("t").to_numpy()
    t = np.sort(np.r_[rng.uniform(t_truth[0], t_truth[-1], 700), t_truth[[0, 5, 999, -1]]])  # sample times too
    whole = truth_at(truth, t)
    along = TruthTrack([truth.take(pa.array(part, pa.int64())) for part in _split(rng, truth.num_rows)])
    parts = [along.at(t[part]) for part in _split(rng, t.size)]
    assert whole["lon"].max() > np.pi  # unwrapped across the antimeridian
    for key, value in whole.items():
        assert np.array_equal(np.concatenate([p[key] for p in parts]), value), key


def test_truth_track_refuses_times_outside_the_truth():
    truth = _truth(np.random.default_rng(1), 300)
    last = truth.column("t").to_numpy()[-1]
    with pytest.raises(LogError, match="outside the truth span"):
        TruthTrack(truth).at(np.array([last + 1.0]))
    with pytest.raises(LogError, match="outside the truth span"):
        TruthTrack(truth).at(np.array([-1.0]))
    with pytest.raises(LogError, match="no samples"):
        TruthTrack(truth.slice(0, 0)).at(np.array([0.0]))
