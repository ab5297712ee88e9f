"""The exact median of values pushed in blocks, held or spilled to the scratch file, against np.median."""

import numpy as np
import pytest

from estimators.io import stream_median
from estimators.io.stream_median import StreamMedian


def pushed(values: np.ndarray, cuts) -> StreamMedian:
    median = StreamMedian()
    for block in np.split(values, cuts):
        median.push(block)
    return median


@pytest.mark.parametrize("n", [1, 2, 7, 1000, 1001])
@pytest.mark.parametrize("spill", [False, True])
def test_equals_np_median_bit_for_bit(monkeypatch, n, spill):
    """Values of both signs, ties, +-0 and magnitudes from 1e-300 to 1e300, cut into blocks anywhere; held in
    memory or spilled to the scratch file (read a few values at a time): np.median's value exactly."""
    if spill:
        monkeypatch.setattr(stream_median, "IN_MEMORY", 5)
        monkeypatch.setattr(stream_median, "READ_VALUES", 13)
    rng = np.random.default_rng(n)
    values = rng.standard_normal(n) * 10.0 ** rng.integers(-300, 300, n)
    values[rng.integers(0, n, n // 5)] = 0.3  # ties
    values[: min(n, 2)] = [0.0, -0.0][: min(n, 2)]
    for cuts in ([], [n // 3, n // 3, n // 2], list(range(1, n, 7))):
        median = pushed(values, cuts)
        assert (median.scratch is not None) == (spill and n > 5)
        assert median.median() == np.median(values), f"cut at {cuts}"


def test_close_values_and_the_nan_and_empty_cases(monkeypatch):
    """Values a few ulps apart are told apart (the radix works on every bit); any NaN or no value gives NaN."""
    monkeypatch.setattr(stream_median, "IN_MEMORY", 3)
    values = 1.0 + np.arange(10) * np.spacing(1.0)  # 1 and the next nine floats above it
    rng = np.random.default_rng(0)
    rng.shuffle(values)
    median = pushed(values, [4])
    assert median.scratch is not None and median.median() == np.median(values)
    with_nan = values.copy()
    with_nan[6] = np.nan
    assert np.isnan(pushed(with_nan, [2]).median())
    assert np.isnan(StreamMedian().median())
