"""The correlation-scaled Cholesky kernels (estimators.kalman.cholesky) against numpy's independent LAPACK
inverse and Cholesky, across state scales, and their positive-definiteness and symmetry tests at their limits."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.kalman.cholesky import PD_RTOL, SYMMETRY_RTOL, correlation_cholesky, spd_inverse, whiten

SCALES = np.array([1e2, 3.0, 1.0, 1e-3, 2e-5, 1e-6, 1e-8])


def random_spd(rng, n, scales=None):
    a = rng.normal(size=(n, n))
    p = a @ a.T + 0.1 * np.eye(n)
    if scales is not None:
        p = p * np.outer(scales, scales)
    return p


@pytest.mark.parametrize("n", [1, 2, 7, 22])
def test_spd_inverse_equals_lapack_and_is_exactly_symmetric(n):
    rng = np.random.default_rng(n)
    scales = np.resize(SCALES, n)
    for _ in range(5):
        p = random_spd(rng, n, scales)
        inv, ok = spd_inverse(p)
        assert ok and np.array_equal(inv, inv.T)
        # (P^-1)_ij is of the order 1 / (s_i s_j): compare relative to that, and P^-1 P = I relative to s_j / s_i.
        ref = np.linalg.inv(p)
        scale = np.outer(scales, scales)
        cond = np.linalg.cond(p / scale)
        assert np.abs((inv - ref) * scale).max() < 1e-13 * cond**2
        assert np.abs((inv @ p - np.eye(n)) * scales[:, None] / scales[None, :]).max() < 1e-12 * cond


def test_factor_and_whitening_give_the_quadratic_form():
    rng = np.random.default_rng(3)
    s = random_spd(rng, 7, SCALES)
    chol, d, ok = correlation_cholesky(s)
    assert ok
    corr = s * np.outer(d, d)
    assert np.allclose(chol, np.linalg.cholesky(corr), rtol=0, atol=1e-12)
    v = rng.normal(size=7) * SCALES
    y = whiten(chol, d, v)
    assert float(y @ y) == pytest.approx(float(v @ np.linalg.solve(s, v)), rel=1e-10)


def test_singular_negative_and_broken_matrices_are_refused():
    rng = np.random.default_rng(4)
    p = random_spd(rng, 5, SCALES[:5])
    cases = {"duplicate state": p.copy(), "negative": p.copy(), "nan": p.copy(), "inf": p.copy(),
             "zero variance": p.copy(), "asymmetric": p.copy()}
    cases["duplicate state"][:, 4] = cases["duplicate state"][:, 3] * 2.0
    cases["duplicate state"][4, :] = cases["duplicate state"][3, :] * 2.0
    w, v = np.linalg.eigh(p)
    cases["negative"] = (v * np.array([-w[0], *w[1:]])) @ v.T
    cases["nan"][1, 2] = np.nan
    cases["inf"][0, 0] = np.inf
    cases["zero variance"][2, :] = cases["zero variance"][:, 2] = 0.0
    cases["asymmetric"][0, 1] += 10 * SYMMETRY_RTOL * np.sqrt(p[0, 0] * p[1, 1])
    for name, bad in cases.items():
        inv, ok = spd_inverse(bad)
        assert not ok and not inv.any(), name
    # Just inside the symmetry tolerance is still a covariance.
    near = p.copy()
    near[0, 1] += 0.1 * SYMMETRY_RTOL * np.sqrt(p[0, 0] * p[1, 1])
    assert spd_inverse(near)[1]


def test_positive_definite_limit_is_the_pivot_tolerance():
    """Two states of correlation rho: the second pivot is 1 - rho^2; refused at or below PD_RTOL, taken above."""
    for pivot, taken in ((0.5 * PD_RTOL, False), (4.0 * PD_RTOL, True)):
        rho = np.sqrt(1.0 - pivot)
        p = np.array([[4.0, 2.0 * 3e-4 * rho], [2.0 * 3e-4 * rho, 9e-8]])
        assert spd_inverse(p)[1] is taken
        assert correlation_cholesky(p)[2] is taken
