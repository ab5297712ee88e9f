"""The methods by name (estimators.shearer.methods): the groups on forked processes give the sequential results."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from estimators.shearer.config import PositioningError
from estimators.shearer.methods import METHODS, TASKS, estimate
from tests.estimators.shearer.test_independent_trajectories import NOISY, trajectory

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

FIELDS = ("t", "llh", "v_n", "q_nb", "sd", "flags", "cal", "sd_cal")


@pytest.fixture(scope="module")
def case():
    traj = trajectory("az45_eq")
    errors = dataclasses.replace(NOISY, seed=7)
    return traj.log(errors), traj.config(errors)


def test_every_method_is_in_exactly_one_group():
    grouped = [m for group in TASKS for m in group]
    assert sorted(grouped) == sorted(METHODS)


def test_forked_workers_give_the_sequential_results_bit_for_bit(case):
    log, cfg = case
    sequential = estimate(log, cfg, METHODS, workers=1)
    forked = estimate(log, cfg, METHODS, workers=2)
    assert list(forked) == list(METHODS)
    for name in METHODS:
        a, b = sequential[name], forked[name]
        for f in FIELDS:
            x, y = getattr(a, f), getattr(b, f)
            assert (x is None and y is None) or np.array_equal(x, y, equal_nan=True), (name, f)
        assert a.notes == b.notes, name


def test_a_subset_of_a_group_runs_alone(case):
    """dr_compensated without the smoother's outputs still runs the smoother it needs, and nothing else is returned."""
    log, cfg = case
    out = estimate(log, cfg, ("dr_compensated", "kf"), workers=2)
    assert list(out) == ["dr_compensated", "kf"]


def test_an_error_in_a_worker_is_raised_in_the_caller(case):
    log, cfg = case
    no_mag = dataclasses.replace(log, mag_t=np.zeros(0), mag_b=np.zeros((0, 3)))
    with pytest.raises(PositioningError, match="mag"):
        estimate(no_mag, cfg, ("kf", "afkf"), workers=2)
