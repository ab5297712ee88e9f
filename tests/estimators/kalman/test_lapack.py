"""estimators.kalman.lapack against numba's own np.linalg: the same LAPACK calls, so the same bits (it imports numba's
private LAPACK wrappers: this is what catches a numba release that changes them)."""

from __future__ import annotations

import numba as nb
import numpy as np
import pytest

from estimators.kalman import lapack

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")


@nb.njit
def _numba_linalg(a, b, v):
    return np.linalg.inv(a), np.linalg.solve(a, b), np.linalg.solve(a, v)


@pytest.mark.parametrize("n", [1, 3, 19])
def test_inverse_and_solves_equal_numbas_np_linalg_bit_for_bit(n):
    rng = np.random.default_rng(n)
    a = rng.standard_normal((n, n)) + n * np.eye(n)
    b = rng.standard_normal((n, 4))
    v = rng.standard_normal(n)
    inv, solve_b, solve_v = _numba_linalg(a, b, v)
    assert np.array_equal(lapack.inv(a), inv)
    assert np.array_equal(lapack.solve_matrix(a, b), solve_b)
    assert np.array_equal(lapack.solve_vector(a, v), solve_v)
    np.testing.assert_allclose(lapack.inv(a) @ a, np.eye(n), atol=1e-12)


def test_singular_and_non_finite_matrices_raise_as_np_linalg_does():
    with pytest.raises(np.linalg.LinAlgError):
        lapack.inv(np.zeros((3, 3)))
    with pytest.raises(np.linalg.LinAlgError):
        lapack.solve_vector(np.full((2, 2), np.nan), np.ones(2))
