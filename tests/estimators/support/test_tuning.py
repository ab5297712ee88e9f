"""Gradient-descent tuning of Q (estimators.support.tuning, 002 eq. 35)."""

from __future__ import annotations

import pytest
import numpy as np

from estimators.support.tuning import tune_q
from tests.estimators.support.conftest import DT, exact_unit, model

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")


def test_gradient_descent_objective_decreases():
    rng = np.random.default_rng(4)
    _q0, q, w, f, m = exact_unit(1500)
    bias = np.array([0.004, -0.003, 0.002])
    f = f + rng.normal(0, 0.01, f.shape)
    m = m + rng.normal(0, 1e-7, m.shape)
    tuning = tune_q(w + bias, f, m, DT, model(1e-4, 1e-14), q, [1e-8] * 3, iterations=8)
    obj = np.asarray(tuning.objective)
    assert obj.size >= 3
    assert np.all(np.diff(obj) < 0)
    assert obj[-1] < 0.5 * obj[0]
