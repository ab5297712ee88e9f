"""twin.sensors.clock.sample_times: chunks of a run whose bounds lie on another clock give every sample once, over
panel-length runs (the float product t * rate_hz drifts from the integer by up to 7.5e-9 beyond 72.8 h at 200 Hz)."""

from __future__ import annotations

import numpy as np
import pytest

from twin.sensors.clock import sample_times


@pytest.mark.parametrize(("bound_hz", "rate_hz"), [(100.0, 200.0), (1000.0, 200.0), (100.0, 1.0), (200.0, 50.0)])
def test_chunks_bounded_on_another_clock_give_every_sample_once(bound_hz, rate_hz):
    """Chunks [t0, t1) with bounds m / bound_hz (the ride clock's chunk bounds), 100 s of them at 0 s, at 2^18 s
    (72.8 h, where 262144.03 s at 200 Hz was dropped) and at 1e6 s (278 h): the union of their samples (those at or
    past t1 left to the next chunk, as the twin's chunks do) is the whole clock over the span."""
    rng = np.random.default_rng(int(bound_hz + rate_hz))
    for start in (0, 262_144, 999_000):
        m = np.unique(rng.integers(0, int(100 * bound_hz), 300)) + start * int(bound_hz)
        bounds = np.r_[start, m[m > start * bound_hz] / bound_hz, start + 100.0]
        chunks = [sample_times(t0, t1, rate_hz) for t0, t1 in zip(bounds[:-1], bounds[1:])]
        got = np.concatenate([t[t < t1] for t, t1 in zip(chunks, bounds[1:])])
        k = np.round(got * rate_hz).astype(np.int64)
        assert np.array_equal(k, np.arange(start * rate_hz, (start + 100) * rate_hz))
        assert np.array_equal(got, k / rate_hz)


def test_bounds_off_the_clock_are_not_rounded_in():
    """A bound a hundredth of a sample off the clock leaves that sample out, at 1e6 s as at 0."""
    for t in (0.0, 1e6):
        assert sample_times(t + 0.0001, t + 1.0, 100.0)[0] == pytest.approx(t + 0.01)
        assert sample_times(t, t + 1.0 - 0.0001, 100.0)[-1] == pytest.approx(t + 0.99)
