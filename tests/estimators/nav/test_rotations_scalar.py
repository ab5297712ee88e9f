"""The scalar-form kernel helpers (estimators.nav.rotations_scalar) agree with the array-form algebra of
estimators.nav.rotations."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.nav import rotations as R
from estimators.nav import rotations_scalar as S

RNG = np.random.default_rng(11)
QUATS = R.quat_normalize(RNG.normal(size=(20, 4)))
VECS = RNG.normal(size=(20, 3))


def test_mul_exp_is_the_product_with_exp_half_on_both_branches():
    for q, v in zip(QUATS, VECS):
        for scale in (1e-4, 1e-3, 0.5):  # |a| below and above exp_half's series switch at 0.01 rad
            a = scale * v
            got = q.copy()
            S.mul_exp(got, *a)
            np.testing.assert_allclose(got, R.quat_mul(q, R.rotvec_to_quat(a)), rtol=0, atol=1e-15)


def test_rotations_into_arrays_match_the_array_forms():
    for q, v in zip(QUATS, VECS):
        acc = np.ones(3)
        S.add_rotated(q, v, acc)
        np.testing.assert_allclose(acc, 1.0 + R.quat_rotate(q, v), rtol=0, atol=1e-14)
        out = np.empty(3)
        S.sub_rotated_back(np.ones(3), q, v, out)
        np.testing.assert_allclose(out, 1.0 - R.quat_rotate(R.quat_conj(q), v), rtol=0, atol=1e-14)
        c_nb = np.empty((3, 3))
        S.quat_mat_into(q, c_nb)
        np.testing.assert_array_equal(c_nb, R.quat_mat(q))


def test_normalize_continuous_keeps_the_side_of_prev():
    for q in QUATS:
        x = -3.0 * q
        S.normalize_continuous(x, q)
        np.testing.assert_allclose(x, q, rtol=0, atol=1e-15)


@pytest.mark.parametrize("angles", [(0.3, -1.2, 2.9), (-1.5, 2.5, -0.4), (0.0, 0.0, 0.0)])
def test_euler_quat_round_trip_and_sign(angles):
    q = np.array(S.euler_quat(*angles))
    w_positive = R.euler_to_quat(*angles)
    np.testing.assert_allclose(q * np.sign(q[0] or 1.0), w_positive, rtol=0, atol=1e-15)
    np.testing.assert_allclose(S.quat_euler(*(2.0 * q)), angles, rtol=0, atol=1e-12)

