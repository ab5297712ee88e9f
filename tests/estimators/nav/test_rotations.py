"""Tests for estimators.nav.rotations (scalar-first Hamilton quaternions)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from estimators.nav import rotations as R

# per-test settings (no global profile, no example database written to the tree)
SETTINGS = settings(max_examples=150, deadline=None, database=None)

TOL = 1e-12

finite = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)
vec3 = st.tuples(finite, finite, finite).map(lambda t: 10.0 * np.array(t))
angle = st.floats(-math.pi, math.pi, allow_nan=False)
pitch_st = st.floats(-math.pi / 2, math.pi / 2, allow_nan=False)
# keep the Euler angle round trip away from gimbal lock
pitch_free = st.floats(-math.pi / 2 + 1e-3, math.pi / 2 - 1e-3, allow_nan=False)


@st.composite
def unit_quat(draw):
    q = np.array([draw(finite) for _ in range(4)])
    if np.linalg.norm(q) < 1e-3:
        q = np.array([1.0, 0.0, 0.0, 0.0])
    return q / np.linalg.norm(q)


def same_rotation(p, q, tol=TOL):
    """Quaternions equal up to the sign ambiguity q ~ -q."""
    return min(np.max(np.abs(p - q)), np.max(np.abs(p + q))) < tol


def to_scipy(q):
    return Rotation.from_quat(np.asarray(q)[..., [1, 2, 3, 0]])  # scipy: scalar last


def from_scipy(rot):
    return rot.as_quat()[..., [3, 0, 1, 2]]


def random_quats(n, seed=0):
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


# --------------------------------------------------------------------------- basics


@SETTINGS
@given(vec3, vec3)
def test_skew_is_cross_product(v, u):
    np.testing.assert_allclose(R.skew(v) @ u, np.cross(v, u), atol=1e-12)
    np.testing.assert_array_equal(R.skew(v), -R.skew(v).T)


@SETTINGS
@given(unit_quat(), unit_quat(), unit_quat())
def test_quat_mul_associative(p, q, r):
    lhs = R.quat_mul(R.quat_mul(p, q), r)
    rhs = R.quat_mul(p, R.quat_mul(q, r))
    np.testing.assert_allclose(lhs, rhs, atol=TOL)


@SETTINGS
@given(unit_quat(), unit_quat())
def test_quat_mul_matches_matrix_product(p, q):
    np.testing.assert_allclose(
        R.quat_to_mat(R.quat_mul(p, q)), R.quat_to_mat(p) @ R.quat_to_mat(q), atol=TOL
    )


@SETTINGS
@given(unit_quat())
def test_conj_is_inverse(q):
    np.testing.assert_allclose(R.quat_mul(q, R.quat_conj(q)), [1, 0, 0, 0], atol=TOL)
    np.testing.assert_allclose(R.quat_to_mat(R.quat_conj(q)), R.quat_to_mat(q).T, atol=TOL)


def test_hamilton_unit_products():
    i, j, k = np.eye(4)[1], np.eye(4)[2], np.eye(4)[3]
    np.testing.assert_array_equal(R.quat_mul(i, j), k)
    np.testing.assert_array_equal(R.quat_mul(j, k), i)
    np.testing.assert_array_equal(R.quat_mul(k, i), j)
    np.testing.assert_array_equal(R.quat_mul(i, i), [-1, 0, 0, 0])


@SETTINGS
@given(unit_quat(), vec3)
def test_rotate_equals_matrix_and_sandwich(q, v):
    expected = R.quat_to_mat(q) @ v
    np.testing.assert_allclose(R.quat_rotate(q, v), expected, atol=1e-11)
    pure = np.concatenate([[0.0], v])
    sandwich = R.quat_mul(R.quat_mul(q, pure), R.quat_conj(q))
    np.testing.assert_allclose(sandwich[1:], expected, atol=1e-11)
    assert abs(sandwich[0]) < 1e-11


@SETTINGS
@given(unit_quat())
def test_quat_to_mat_is_proper_rotation(q):
    C = R.quat_to_mat(q)
    np.testing.assert_allclose(C @ C.T, np.eye(3), atol=TOL)
    assert abs(np.linalg.det(C) - 1.0) < TOL


@SETTINGS
@given(st.tuples(finite, finite, finite, finite).filter(lambda t: np.linalg.norm(t) > 1e-3))
def test_normalize(t):
    q = R.quat_normalize(np.array(t))
    assert abs(np.linalg.norm(q) - 1.0) < 1e-15
    np.testing.assert_allclose(q * np.linalg.norm(t), t, atol=1e-14)


# --------------------------------------------------------------------------- round trips


@SETTINGS
@given(unit_quat())
def test_quat_mat_round_trip(q):
    q2 = R.mat_to_quat(R.quat_to_mat(q))
    assert q2[0] >= 0.0
    assert same_rotation(q, q2)


def test_mat_to_quat_all_pivots():
    # 180 deg turns about each axis exercise the x, y and z pivots of Shepperd.
    for axis in np.eye(3):
        q = R.mat_to_quat(R.quat_to_mat(np.concatenate([[0.0], axis])))
        assert same_rotation(q, np.concatenate([[0.0], axis]))
    q = random_quats(2000, seed=3)
    np.testing.assert_allclose(
        np.abs(np.sum(R.mat_to_quat(R.quat_to_mat(q)) * q, axis=-1)), 1.0, atol=TOL
    )


@st.composite
def rotvec(draw):
    """Rotation vectors with angle in [0, pi - 1e-6] (unique representation)."""
    axis = draw(vec3)
    n = np.linalg.norm(axis)
    axis = np.array([0.0, 0.0, 1.0]) if n < 1e-6 else axis / n
    return axis * draw(st.floats(0.0, math.pi - 1e-6))


@SETTINGS
@given(rotvec())
def test_rotvec_round_trip(phi):
    q = R.rotvec_to_quat(phi)
    assert abs(np.linalg.norm(q) - 1.0) < 1e-15
    np.testing.assert_allclose(R.quat_to_rotvec(q), phi, atol=1e-12)


@SETTINGS
@given(unit_quat())
def test_quat_rotvec_round_trip(q):
    phi = R.quat_to_rotvec(q)
    assert np.linalg.norm(phi) <= math.pi + 1e-12
    assert same_rotation(R.rotvec_to_quat(phi), q)


@pytest.mark.parametrize(
    "ang", [0.0, 1e-300, 1e-12, 1e-9, 1e-6, 1e-4, 9.999e-4, 1e-3, 1.0001e-3, 1e-2, 1.0, 3.0]
)
def test_rotvec_small_angle_accuracy(ang):
    axis = np.array([2.0, -3.0, 6.0]) / 7.0
    phi = ang * axis
    q = R.rotvec_to_quat(phi)
    # reference: sin(x)/x evaluated directly (accurate to ~1 ulp for x > 0)
    k = 0.5 if ang == 0.0 else math.sin(0.5 * ang) / ang
    np.testing.assert_allclose(q[0], math.cos(0.5 * ang), rtol=0, atol=4.5e-16)
    np.testing.assert_allclose(q[1:], k * phi, rtol=4e-16, atol=0)
    assert abs(np.linalg.norm(q) - 1.0) <= 2.3e-16
    np.testing.assert_allclose(R.quat_to_rotvec(q), phi, rtol=4e-15, atol=0)


def test_rotvec_zero_is_identity():
    np.testing.assert_array_equal(R.rotvec_to_quat(np.zeros(3)), [1.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(R.quat_to_rotvec([1.0, 0.0, 0.0, 0.0]), np.zeros(3))
    np.testing.assert_array_equal(R.quat_to_rotvec([-1.0, 0.0, 0.0, 0.0]), np.zeros(3))


@SETTINGS
@given(pitch_free, angle, angle)
def test_euler_round_trip(pitch, roll, yaw):
    # Roll and yaw of +-pi are the same angle: compare on the circle.
    for p, r, y in (R.mat_to_euler(R.euler_to_mat(pitch, roll, yaw)),
                    R.quat_to_euler(R.euler_to_quat(pitch, roll, yaw))):
        np.testing.assert_allclose(_wrap(np.array([p - pitch, r - roll, y - yaw])), 0.0, atol=1e-9)


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


@SETTINGS
@given(pitch_st, angle, angle)
def test_euler_matrix_round_trip_including_gimbal_lock(pitch, roll, yaw):
    C = R.euler_to_mat(pitch, roll, yaw)
    p, r, y = R.mat_to_euler(C)
    assert -math.pi / 2 <= p <= math.pi / 2
    np.testing.assert_allclose(R.euler_to_mat(p, r, y), C, atol=1e-12)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_gimbal_lock_sets_roll_zero(sign):
    C = R.euler_to_mat(sign * np.pi / 2, 0.3, 1.1)
    p, r, y = R.mat_to_euler(C)
    assert r == 0.0
    np.testing.assert_allclose(R.euler_to_mat(p, r, y), C, atol=1e-15)


@SETTINGS
@given(pitch_free, angle)
def test_mat_to_euler_zero_roll(pitch, yaw):
    p, r, y = R.mat_to_euler(R.euler_to_mat(pitch, 0.0, yaw))
    assert abs(p - pitch) < 1e-12 and abs(r) < 1e-12 and abs(_wrap(y - yaw)) < 1e-12


@SETTINGS
@given(pitch_st, angle, angle)
def test_euler_quat_matches_euler_mat(pitch, roll, yaw):
    q = R.euler_to_quat(pitch, roll, yaw)
    assert q[0] >= 0.0
    np.testing.assert_allclose(R.quat_to_mat(q), R.euler_to_mat(pitch, roll, yaw), atol=TOL)


# --------------------------------------------------------------------------- conventions


def test_euler_elementary_conventions():
    # yaw 0: body y axis points North; positive yaw turns it West (counter-clockwise)
    np.testing.assert_allclose(R.euler_to_mat(0, 0, np.pi / 2) @ [0, 1, 0], [-1, 0, 0], atol=1e-15)
    # positive pitch about x raises the nose (body y) up
    np.testing.assert_allclose(R.euler_to_mat(np.pi / 2, 0, 0) @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    # positive roll about y lowers body x (right side) : Ry(+90) x -> -z
    np.testing.assert_allclose(R.euler_to_mat(0, np.pi / 2, 0) @ [1, 0, 0], [0, 0, -1], atol=1e-15)
    # order: Rz(yaw) Rx(pitch) Ry(roll)
    p, r, y = 0.2, -0.4, 1.3
    Rx = R.quat_to_mat(R.rotvec_to_quat([p, 0, 0]))
    Ry = R.quat_to_mat(R.rotvec_to_quat([0, r, 0]))
    Rz = R.quat_to_mat(R.rotvec_to_quat([0, 0, y]))
    np.testing.assert_allclose(R.euler_to_mat(p, r, y), Rz @ Rx @ Ry, atol=1e-15)


def test_heading():
    yaw = np.array([0.0, -0.0, np.pi / 2, -np.pi / 2, np.pi, 1e-20, -1e-20, 2 * np.pi])
    hdg = R.heading_deg_cw_from_north(yaw)
    np.testing.assert_allclose(hdg, [0, 0, 270, 90, 180, 0, 0, 0], atol=1e-12)
    assert np.all((hdg >= 0.0) & (hdg < 360.0))
    assert R.heading_deg_cw_from_north(np.deg2rad(-30.0)) == pytest.approx(30.0)


@SETTINGS
@given(angle)
def test_heading_matches_body_forward_azimuth(yaw):
    fwd = R.euler_to_mat(0.0, 0.0, yaw) @ [0, 1, 0]  # body y in ENU
    az = math.degrees(math.atan2(fwd[0], fwd[1])) % 360.0  # clockwise from North
    d = (R.heading_deg_cw_from_north(yaw) - az + 180.0) % 360.0 - 180.0
    assert abs(d) < 1e-9


# --------------------------------------------------------------------------- scipy cross-check


def test_against_scipy_vectorised():
    q = random_quats(500, seed=1)
    rot = to_scipy(q)
    np.testing.assert_allclose(R.quat_to_mat(q), rot.as_matrix(), atol=TOL)
    C = rot.as_matrix()
    q2 = R.mat_to_quat(C)
    assert np.all(q2[:, 0] >= 0)
    np.testing.assert_allclose(np.abs(np.sum(q2 * from_scipy(rot), axis=-1)), 1.0, atol=TOL)
    np.testing.assert_allclose(R.quat_to_rotvec(q), rot.as_rotvec(), atol=1e-10)
    phi = rot.as_rotvec()
    np.testing.assert_allclose(
        np.abs(np.sum(R.rotvec_to_quat(phi) * from_scipy(Rotation.from_rotvec(phi)), -1)),
        1.0,
        atol=TOL,
    )
    v = np.random.default_rng(2).normal(size=(500, 3))
    np.testing.assert_allclose(R.quat_rotate(q, v), rot.apply(v), atol=1e-12)
    p = random_quats(500, seed=4)
    np.testing.assert_allclose(
        R.quat_to_mat(R.quat_mul(p, q)), (to_scipy(p) * rot).as_matrix(), atol=TOL
    )


@SETTINGS
@given(pitch_st, angle, angle)
def test_euler_against_scipy(pitch, roll, yaw):
    # scipy intrinsic "ZXY" = Rz(yaw) @ Rx(pitch) @ Ry(roll)
    ref = Rotation.from_euler("ZXY", [yaw, pitch, roll])
    np.testing.assert_allclose(R.euler_to_mat(pitch, roll, yaw), ref.as_matrix(), atol=TOL)
    assert same_rotation(R.euler_to_quat(pitch, roll, yaw), from_scipy(ref))


@SETTINGS
@given(unit_quat())
def test_quat_to_mat_against_scipy(q):
    np.testing.assert_allclose(R.quat_to_mat(q), to_scipy(q).as_matrix(), atol=TOL)


# --------------------------------------------------------------------------- shapes


def test_broadcasting_shapes():
    p = random_quats(5, seed=5).reshape(5, 1, 4)
    q = random_quats(3, seed=6)
    assert R.quat_mul(p, q).shape == (5, 3, 4)
    assert R.quat_rotate(p, np.ones(3)).shape == (5, 1, 3)
    assert R.quat_to_mat(p).shape == (5, 1, 3, 3)
    assert R.mat_to_quat(R.quat_to_mat(p)).shape == (5, 1, 4)
    assert R.rotvec_to_quat(np.zeros((2, 7, 3))).shape == (2, 7, 4)
    assert R.quat_to_rotvec(p).shape == (5, 1, 3)
    assert R.skew(np.ones((4, 3))).shape == (4, 3, 3)
    assert R.euler_to_mat(np.zeros(4), 0.1, np.zeros((2, 1))).shape == (2, 4, 3, 3)
    assert R.euler_to_quat(np.zeros(4), 0.1, 0.2).shape == (4, 4)
    pitch, roll, yaw = R.quat_to_euler(p)
    assert pitch.shape == roll.shape == yaw.shape == (5, 1)
    # vectorised results equal element-wise results
    qs = random_quats(10, seed=7)
    batch = R.quat_to_rotvec(qs)
    for i in range(10):
        np.testing.assert_array_equal(batch[i], R.quat_to_rotvec(qs[i]))

