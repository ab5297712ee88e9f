"""bench_scale's peak memory by stage, from a run's stage ends on the clock (timing.json's stage_ends_unix_s)."""

from __future__ import annotations

from tests.conftest import benchmark_module


def test_each_sample_goes_to_the_stage_running_then():
    bench = benchmark_module("bench_scale")
    # face and shearer alternate chunk by chunk; the time up to each end goes to its stage.
    ends = [[10.0, "face"], [11.0, "shearer"], [15.0, "face"], [16.0, "shearer"], [20.0, "estimators"]]
    samples = [(9.0, 1.0), (10.0, 2.0), (10.5, 7.0), (12.0, 5.0), (15.5, 3.0), (19.0, 4.0), (21.0, 6.0)]
    assert bench.stage_peaks(samples, ends) == {"face": 5.0, "shearer": 7.0, "estimators": 4.0, "closing": 6.0}
    assert bench.stage_peaks([], ends) == {}
