"""The surveys drawn a truth chunk at a time (twin.sensors.survey.Survey, FaceSurvey): over random partitions of a
simulated run they give, bit for bit, the whole run's streams. Also the partition helpers the odometer and
magnetometer tests share."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import simulated
from twin.sensors.chunks import halo_rows, split_truth
from twin.sensors.survey import FaceSurvey, Survey, face_survey_stream, survey_stream


def random_starts(rng: np.random.Generator, n_rows: int, halo: int, near=()) -> np.ndarray:
    """Chunk starts (row indices) of a random partition of n_rows truth rows: a few anywhere, and runs of chunks
    shorter than the halo (single rows among them) across the run's first and last rows, random rows and the rows
    `near`."""
    lengths = [1, 1, 2, 3, halo // 2, halo - 1, halo, halo + 1]
    anchors = [0, n_rows, *rng.integers(1, n_rows, 3), *near]
    runs = [a - rng.integers(0, 4 * halo) + np.cumsum(rng.choice(lengths, 10)) for a in anchors]
    return np.unique(np.concatenate([rng.integers(1, n_rows, 8), [1, n_rows - 1], *runs]))


def joined(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """The chunks' outputs concatenated column by column."""
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def same(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> bool:
    """Whether two streams hold the same columns, bit for bit (NaN equal to NaN) and of the same dtypes."""
    return a.keys() == b.keys() and all(
        a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f") for k in a)


def survey_rows(truth, cycles) -> list[int]:
    """Truth rows at the survey times and at the first cut's ends, where a chunk boundary is most telling."""
    times = [0.0, *cycles["t"], *cycles["t_cut_end"]]
    return list(np.searchsorted(truth["t"], times))


@pytest.mark.parametrize("seed", range(4))
def test_survey_over_random_partitions_is_the_whole_run(seed):
    scn, result = simulated("default")
    truth, cycles = result.tables["truth_shearer"], result.tables["truth_cycles"]
    halo = halo_rows(scn)
    whole = survey_stream(scn, truth, cycles, np.random.default_rng(3))
    assert whole["t"].size == 4 and np.isfinite(whole["yaw"][0])
    starts = random_starts(np.random.default_rng(seed), truth["t"].size, halo, survey_rows(truth, cycles))
    chunks = list(split_truth(truth, starts, halo))
    survey = Survey(scn, cycles, np.random.default_rng(3), float(truth["t"][-1]))
    assert same(joined([survey.step(c) for c in chunks]), whole)
    # The comparison catches errors drawn chunk by chunk (here: a Survey per chunk, one generator).
    rng = np.random.default_rng(3)
    assert not same(joined([Survey(scn, cycles, rng, float(truth["t"][-1])).step(c) for c in chunks]), whole)


@pytest.mark.parametrize("seed", range(4))
def test_face_survey_over_random_partitions_is_the_whole_run(seed):
    scn, result = simulated("default")
    truth, cycles = result.tables["truth_shearer"], result.tables["truth_cycles"]
    halo = halo_rows(scn)
    whole = face_survey_stream(scn, truth, cycles, np.random.default_rng(4))
    assert whole["t"].size > 10
    rng = np.random.default_rng(seed)
    in_cut = rng.integers(1, np.searchsorted(truth["t"], cycles["t_cut_end"][0]), 3)
    starts = random_starts(rng, truth["t"].size, halo, [*survey_rows(truth, cycles), *in_cut])
    chunks = list(split_truth(truth, starts, halo))
    face = FaceSurvey(scn, cycles, np.random.default_rng(4))
    assert same(joined([face.step(c) for c in chunks]), whole)
    # The comparison catches a stepper that forgets the cut's earlier chunks.
    assert not same(joined([FaceSurvey(scn, cycles, np.random.default_rng(4)).step(c) for c in chunks]), whole)


def test_face_survey_of_a_run_ending_inside_the_first_cut():
    scn, result = simulated("default")
    full, cycles = result.tables["truth_shearer"], result.tables["truth_cycles"]
    end = np.searchsorted(full["t"], 0.6 * cycles["t_cut_end"][0])
    truth = {k: v[:end] for k, v in full.items()}
    halo = halo_rows(scn)
    whole = face_survey_stream(scn, truth, cycles, np.random.default_rng(5))
    assert 0 < whole["t"].size < face_survey_stream(scn, full, cycles, np.random.default_rng(5))["t"].size
    face = FaceSurvey(scn, cycles, np.random.default_rng(5))
    starts = random_starts(np.random.default_rng(9), end, halo)
    assert same(joined([face.step(c) for c in split_truth(truth, starts, halo)]), whole)
