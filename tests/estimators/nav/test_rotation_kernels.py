"""estimators.nav.rotations is estimators.nav.rotation_kernels run over the rows of NumPy arrays: the same bits,
NumPy's broadcasting, any array-like input."""

import math

import numpy as np
import pytest

from estimators.nav import rotation_kernels as K
from estimators.nav import rotations as R


def random_quats(n, seed):
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _random_args(n, seed):
    rng = np.random.default_rng(seed)
    q, p = random_quats(n, seed), random_quats(n, seed + 1)
    angles = rng.uniform(-1.0, 1.0, size=(3, n)) * np.array([[math.pi / 2], [math.pi], [math.pi]])
    return q, p, rng.normal(size=(n, 3)), angles


def _kernel_rows(kernel, out_shape, *args):
    """The single-vector kernel applied row by row (from Python), for comparison with the vectorised API."""
    out = np.empty((len(args[0]), *out_shape))
    for i, row in enumerate(zip(*args)):
        out[i] = kernel(*row)
    return out


def _into(kernel, n_out):
    def call(*args):
        out = np.empty(n_out)
        kernel(*args, out)
        return out
    return call


def test_api_equals_the_kernels_bit_for_bit():
    q, p, v, (pitch, roll, yaw) = _random_args(300, seed=21)
    C = R.quat_to_mat(q)
    cases = [
        (R.skew(v), _kernel_rows(K.skew3, (3, 3), v)),
        (R.quat_mul(p, q), _kernel_rows(K.qmul, (4,), p, q)),
        (R.quat_normalize(3.0 * q), _kernel_rows(_into(K.qnormalize_into, 4), (4,), 3.0 * q)),
        (R.quat_rotate(q, v), _kernel_rows(K.qrot, (3,), q, v)),
        (C, _kernel_rows(K.quat_mat, (3, 3), q)),
        (R.mat_to_quat(C), _kernel_rows(_into(K.mat_quat_into, 4), (4,), C)),
        (R.quat_to_rotvec(-q), _kernel_rows(_into(K.quat_rotvec_into, 3), (3,), -q)),
        (R.euler_to_mat(pitch, roll, yaw), _kernel_rows(K.euler_mat, (3, 3), pitch, roll, yaw)),
        (np.stack(R.mat_to_euler(C), -1), _kernel_rows(K.mat_euler, (3,), C)),
        (np.stack(R.quat_to_euler(q), -1), _kernel_rows(lambda x: K.mat_euler(K.quat_mat(x)), (3,), q)),
        (R.euler_to_quat(pitch, roll, yaw),
         _kernel_rows(lambda *a: np.array(K.euler_quat(*a)) * np.sign(K.euler_quat(*a)[0]), (4,), pitch, roll, yaw)),
    ]
    for scale in (0.0, 1e-9, 1e-6, 1e-4, 1e-2, 1.0):  # both sides of qexp's series switch at 1e-8 rad
        cases.append((R.rotvec_to_quat(scale * v), _kernel_rows(K.qexp, (4,), scale * v)))
    for scale in (1e-6, 1e-2, 1.0):  # both sides of quat_rotvec's series switch at K.SMALL_ANGLE
        qs = R.rotvec_to_quat(scale * v)
        cases.append((R.quat_to_rotvec(qs), _kernel_rows(_into(K.quat_rotvec_into, 3), (3,), qs)))
    for api, kernel in cases:
        np.testing.assert_array_equal(api, kernel)


def test_broadcast_shapes_and_inputs_equal_the_element_wise_kernels():
    q, p, v, (pitch, _, yaw) = _random_args(12, seed=31)
    pm, qn = p[:6].reshape(2, 3, 1, 4), q[:4]  # (N, M, 1, 4) against (4, 4) -> (2, 3, 4, 4)
    prod = R.quat_mul(pm, qn)
    assert prod.shape == (2, 3, 4, 4) and prod.dtype == np.float64
    for i, j, k in np.ndindex(2, 3, 4):
        np.testing.assert_array_equal(prod[i, j, k], K.qmul(pm[i, j, 0], qn[k]))
    rot = R.quat_rotate(q.reshape(3, 4, 4), v[:4])  # (N, M, 4) with (M, 3)
    for i, j in np.ndindex(3, 4):
        np.testing.assert_array_equal(rot[i, j], K.qrot(q.reshape(3, 4, 4)[i, j], v[j]))
    # lists, integers, transposed (non-contiguous) and read-only arrays
    np.testing.assert_array_equal(R.quat_mul([0, 1, 0, 0], [0, 0, 1, 0]), [0.0, 0.0, 0.0, 1.0])
    frozen = q.copy()
    frozen.flags.writeable = False
    np.testing.assert_array_equal(R.quat_to_mat(frozen), R.quat_to_mat(q))
    np.testing.assert_array_equal(R.quat_to_mat(np.asfortranarray(q)), R.quat_to_mat(q))
    np.testing.assert_array_equal(R.quat_to_mat(q.T.copy().T), R.quat_to_mat(q))
    # scalar Euler angles broadcast against arrays; one set of angles gives floats
    c = R.euler_to_mat(pitch[:4], 0.1, yaw[:2, None])
    assert c.shape == (2, 4, 3, 3)
    np.testing.assert_array_equal(c[1, 2], K.euler_mat(pitch[2], 0.1, yaw[1]))
    angles = R.mat_to_euler(K.euler_mat(0.2, -0.3, 1.0))
    assert all(isinstance(a, float) for a in angles)
    assert R.quat_to_rotvec(np.zeros((0, 5, 4))).shape == (0, 5, 3)


@pytest.mark.parametrize("call", [
    lambda: R.quat_to_mat(np.ones(3)),
    lambda: R.quat_mul(np.ones((2, 4)), np.ones(3)),
    lambda: R.mat_to_quat(np.ones((4, 4))),
    lambda: R.quat_mul(np.ones((2, 4)), np.ones((3, 4))),  # leading dimensions that do not broadcast
])
def test_wrong_shapes_are_refused(call):
    with pytest.raises(ValueError):
        call()


def test_euler_matrix_and_back_match_the_array_forms():
    """Large angles included (fine alignment's heading error is tens of degrees)."""
    rng = np.random.default_rng(11)
    angles = rng.uniform(-1.4, 1.4, size=(20, 3)) * np.array([1.0, 2.0, 2.2])
    for pitch, roll, yaw in angles:
        c = K.euler_mat(pitch, roll, yaw)
        np.testing.assert_allclose(c, R.euler_to_mat(pitch, roll, yaw), rtol=0, atol=1e-15)
        np.testing.assert_allclose(K.mat_euler(c), R.mat_to_euler(c), rtol=0, atol=1e-12)
        np.testing.assert_allclose(K.mat_euler(c), (pitch, roll, yaw), rtol=0, atol=1e-12)
