"""Tests for estimators.nav.earth (WGS-84, ENU navigation frame)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.nav import earth as E

# per-test settings (no global profile, no example database written to the tree)
SETTINGS = settings(max_examples=150, deadline=None, database=None)

lat_st = st.floats(-math.pi / 2, math.pi / 2, allow_nan=False)
lat_nav = st.floats(-np.deg2rad(89.0), np.deg2rad(89.0), allow_nan=False)
lon_st = st.floats(-math.pi, math.pi, allow_nan=False)
h_st = st.floats(-1000.0, 10000.0, allow_nan=False)

# Float64 resolution at the Earth radius: ulp(6.4e6 m) = 2**-30 m = 9.3e-10 m.
# The lla <-> ecef round trip is at that level: RMS < 1e-9 m; the worst case
# is a few ulp (the forward map alone rounds up to ~2.6e-9 m), hence MAX_ERR.
ULP_R = 2.0**-30
RMS_ERR = 1e-9
MAX_ERR = 5 * ULP_R


def random_lla(n, seed=0):
    rng = np.random.default_rng(seed)
    lat = rng.uniform(-math.pi / 2, math.pi / 2, n)
    lon = rng.uniform(-math.pi, math.pi, n)
    h = rng.uniform(-1000.0, 10000.0, n)
    # include the poles, the equator and the height limits
    lat = np.r_[lat, math.pi / 2, -math.pi / 2, 0.0, 0.0, 1e-300, np.deg2rad(89.0)]
    lon = np.r_[lon, 0.0, 2.0, math.pi, -math.pi, 0.5, -3.0]
    h = np.r_[h, 0.0, 10000.0, -1000.0, 10000.0, 0.0, -1000.0]
    return lat, lon, h


def lla_error_m(lat1, lon1, h1, lat2, lon2, h2):
    """Metric distance between two nearby geodetic points (local approximation)."""
    r_m, r_n = E.radii(lat1)
    dlon = (lon2 - lon1 + math.pi) % (2 * math.pi) - math.pi
    return np.sqrt(
        ((lat2 - lat1) * (r_m + h1)) ** 2
        + (dlon * (r_n + h1) * np.cos(lat1)) ** 2
        + (h2 - h1) ** 2
    )


# --------------------------------------------------------------------------- constants


def test_constants():
    assert E.A == 6378137.0
    assert E.F == 1 / 298.257223563
    assert E.E2 == pytest.approx(6.69437999014e-3, rel=1e-12)
    assert E.B == pytest.approx(6356752.314245, abs=1e-6)
    assert E.OMEGA_IE == 7.292115e-5
    assert E.M == pytest.approx(0.00344978650684, rel=1e-11)  # NIMA TR8350.2


def test_normal_gravity_published_values():
    # WGS-84 (NIMA TR8350.2) normal gravity on the ellipsoid
    assert E.normal_gravity(0.0, 0.0) == pytest.approx(9.7803253359, abs=1e-10)
    assert E.normal_gravity(math.pi / 2, 0.0) == pytest.approx(9.8321849378, abs=1e-9)
    assert E.normal_gravity(-math.pi / 2, 0.0) == pytest.approx(9.8321849378, abs=1e-9)


def test_normal_gravity_height_dependence():
    # free-air gradient ~ -0.3086 mGal/m = -3.086e-6 s^-2
    grad = (E.normal_gravity(0.7, 100.0) - E.normal_gravity(0.7, -100.0)) / 200.0
    assert grad == pytest.approx(-3.086e-6, rel=2e-3)
    # exact first-order coefficient at the equator
    g0 = E.GAMMA_E
    d = E.normal_gravity(0.0, 1.0) - g0
    assert d == pytest.approx(-2 * g0 / E.A * (1 + E.F + E.M) + 3 * g0 / E.A**2, rel=1e-6)
    lat = np.linspace(-1.5, 1.5, 7)
    assert np.all(np.diff(E.normal_gravity(lat[:, None], [[0.0, 5000.0]]), axis=-1) < 0)


def test_gravity_vector():
    lat = np.array([0.1, 0.5])
    g = E.gravity_n(lat, 100.0)
    assert g.shape == (2, 3)
    np.testing.assert_array_equal(g[:, :2], 0.0)
    np.testing.assert_array_equal(g[:, 2], -E.normal_gravity(lat, 100.0))
    assert E.gravity_n(0.3, np.zeros((4, 5))).shape == (4, 5, 3)


def test_radii_known_values():
    r_m, r_n = E.radii(math.pi / 4)
    assert r_m == pytest.approx(6367381.8156, abs=1e-3)
    assert r_n == pytest.approx(6388838.2901, abs=1e-3)
    r_m, r_n = E.radii(0.0)
    assert r_n == E.A
    assert r_m == pytest.approx(6335439.3273, abs=1e-3)  # a (1 - e^2)
    r_m, r_n = E.radii(np.array([math.pi / 2, -math.pi / 2]))
    np.testing.assert_allclose(r_m, 6399593.6258, atol=1e-3)  # a^2 / b at the poles
    np.testing.assert_allclose(r_n, 6399593.6258, atol=1e-3)


@SETTINGS
@given(lat_st, lon_st, h_st)
def test_radii_match_ecef_derivatives(lat, lon, h):
    # |d r_e / d lat| = R_M + h ; |d r_e / d lon| = (R_N + h) cos L
    d = 1e-6
    r_m, r_n = E.radii(lat)
    dlat = (E.lla_to_ecef(lat + d, lon, h) - E.lla_to_ecef(lat - d, lon, h)) / (2 * d)
    dlon = (E.lla_to_ecef(lat, lon + d, h) - E.lla_to_ecef(lat, lon - d, h)) / (2 * d)
    assert np.linalg.norm(dlat) == pytest.approx(r_m + h, rel=1e-6)
    assert np.linalg.norm(dlon) == pytest.approx((r_n + h) * math.cos(lat), rel=1e-6, abs=1e-3)


# --------------------------------------------------------------------------- rates


def test_earth_rate():
    w = E.OMEGA_IE
    np.testing.assert_allclose(E.earth_rate_n(0.0), [0, w, 0], atol=1e-20)
    np.testing.assert_allclose(E.earth_rate_n(math.pi / 2), [0, 0, w], atol=1e-20)
    lat = np.linspace(-1.5, 1.5, 11)
    wn = E.earth_rate_n(lat)
    assert wn.shape == (11, 3)
    np.testing.assert_allclose(np.linalg.norm(wn, axis=-1), w, rtol=1e-15)
    # equals C_e^n [0, 0, w] (Earth rotation axis seen in ENU)
    c_ne = np.swapaxes(E.mat_en(lat, 0.3), -1, -2)
    np.testing.assert_allclose(wn, c_ne @ [0, 0, w], atol=1e-19)


def test_transport_rate():
    lat, h = 0.6, 250.0
    r_m, r_n = E.radii(lat)
    v = np.array([3.0, -2.0, 0.5])
    expected = [2.0 / (r_m + h), 3.0 / (r_n + h), 3.0 * math.tan(lat) / (r_n + h)]
    np.testing.assert_allclose(E.transport_rate_n(lat, h, v), expected, rtol=1e-15)
    vs = np.random.default_rng(0).normal(size=(6, 3))
    lats = np.linspace(-1, 1, 6)
    batch = E.transport_rate_n(lats, h, vs)
    assert batch.shape == (6, 3)
    for i in range(6):
        np.testing.assert_array_equal(batch[i], E.transport_rate_n(lats[i], h, vs[i]))


@SETTINGS
@given(lat_nav, lon_st, h_st, st.floats(-50, 50), st.floats(-50, 50))
def test_transport_rate_matches_position_rates(lat, lon, h, ve, vn):
    # the n frame turns with the position: omega_en = [-lat_dot, lon_dot cos L, lon_dot sin L]
    r_m, r_n = E.radii(lat)
    lat_dot = vn / (r_m + h)
    lon_dot = ve / ((r_n + h) * math.cos(lat))
    w = E.transport_rate_n(lat, h, [ve, vn, 0.0])
    expected = [-lat_dot, lon_dot * math.cos(lat), lon_dot * math.sin(lat)]
    np.testing.assert_allclose(w, expected, rtol=1e-12, atol=1e-20)


# --------------------------------------------------------------------------- lla <-> ecef


def test_ecef_known_points():
    np.testing.assert_allclose(E.lla_to_ecef(0.0, 0.0, 0.0), [E.A, 0, 0], atol=1e-9)
    np.testing.assert_allclose(E.lla_to_ecef(0.0, math.pi / 2, 100.0), [0, E.A + 100, 0], atol=1e-9)
    np.testing.assert_allclose(E.lla_to_ecef(math.pi / 2, 0.0, 0.0), [0, 0, E.B], atol=1e-9)
    lat, lon, h = E.ecef_to_lla(np.array([[E.A, 0, 0], [0, 0, -E.B - 10.0]]))
    np.testing.assert_allclose(lat, [0, -math.pi / 2], atol=1e-15)
    np.testing.assert_allclose(h, [0, 10.0], atol=1e-9)


def test_lla_ecef_round_trip_vectorised():
    lat, lon, h = random_lla(100_000)
    xyz = E.lla_to_ecef(lat, lon, h)
    assert xyz.shape == (lat.size, 3)
    lat2, lon2, h2 = E.ecef_to_lla(xyz)
    err = lla_error_m(lat, lon, h, lat2, lon2, h2)
    assert np.sqrt(np.mean(err**2)) < RMS_ERR
    assert err.max() < MAX_ERR
    # and the other way round, starting from (exactly representable) ECEF points
    back = E.lla_to_ecef(lat2, lon2, h2)
    d = np.linalg.norm(back - xyz, axis=-1)
    assert np.sqrt(np.mean(d**2)) < RMS_ERR
    assert d.max() < MAX_ERR


@SETTINGS
@given(lat_st, lon_st, h_st)
def test_lla_ecef_round_trip(lat, lon, h):
    lat2, lon2, h2 = E.ecef_to_lla(E.lla_to_ecef(lat, lon, h))
    assert lla_error_m(lat, lon, h, lat2, lon2, h2) < MAX_ERR


@SETTINGS
@given(lat_st, lon_st, h_st)
def test_ecef_to_lla_height_along_normal(lat, lon, h):
    # independent construction: go h metres along the ellipsoid normal (Up)
    up = E.mat_en(lat, lon)[:, 2]
    xyz = E.lla_to_ecef(lat, lon, 0.0) + h * up
    _, _, h2 = E.ecef_to_lla(xyz)
    assert abs(h2 - h) < MAX_ERR


def test_ecef_to_lla_far_points():
    # orbital and deep-underground-but-outside-evolute points stay accurate
    lat, lon, h = np.meshgrid(np.linspace(-1.5, 1.5, 7), [0.3], [-1e5, 4e5, 3.6e7])
    lat2, lon2, h2 = E.ecef_to_lla(E.lla_to_ecef(lat, lon, h))
    np.testing.assert_allclose(lat2, lat, atol=1e-15)
    np.testing.assert_allclose(h2, h, atol=1e-8)


# --------------------------------------------------------------------------- frames


@SETTINGS
@given(lat_st, lon_st)
def test_mat_en_columns(lat, lon):
    C = E.mat_en(lat, lon)
    np.testing.assert_allclose(C.T @ C, np.eye(3), atol=1e-15)
    assert np.linalg.det(C) == pytest.approx(1.0, abs=1e-15)
    d = 1e-6
    up = E.lla_to_ecef(lat, lon, 1.0) - E.lla_to_ecef(lat, lon, 0.0)
    np.testing.assert_allclose(C[:, 2], up, atol=1e-8)
    north = E.lla_to_ecef(lat + d, lon, 0.0) - E.lla_to_ecef(lat - d, lon, 0.0)
    np.testing.assert_allclose(C[:, 1], north / np.linalg.norm(north), atol=1e-7)
    if math.cos(lat) > 1e-3:
        east = E.lla_to_ecef(lat, lon + d, 0.0) - E.lla_to_ecef(lat, lon - d, 0.0)
        np.testing.assert_allclose(C[:, 0], east / np.linalg.norm(east), atol=1e-7)


def test_mat_en_shape():
    assert E.mat_en(np.zeros(5), 0.2).shape == (5, 3, 3)
    assert E.mat_en(np.zeros((2, 1)), np.zeros(4)).shape == (2, 4, 3, 3)


@SETTINGS
@given(lat_nav, lon_st, lat_nav, lon_st)
def test_mat_nt(lat, lon, lat0, lon0):
    C = E.mat_nt(lat, lon, lat0, lon0)
    np.testing.assert_allclose(C @ C.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(C) == pytest.approx(1.0, abs=1e-15)
    np.testing.assert_allclose(E.mat_nt(lat0, lon0, lat0, lon0), np.eye(3), atol=1e-15)
    np.testing.assert_allclose(E.mat_nt(lat0, lon0, lat, lon), C.T, atol=1e-15)
    # maps t components to n components of the same ECEF vector
    v_t = np.array([1.0, -2.0, 0.5])
    v_e = E.mat_en(lat0, lon0) @ v_t
    np.testing.assert_allclose(C @ v_t, E.mat_en(lat, lon).T @ v_e, atol=1e-14)


def test_mat_nt_vectorised():
    rng = np.random.default_rng(3)
    lat = rng.uniform(-1.5, 1.5, 50)
    lon = rng.uniform(-3, 3, 50)
    C = E.mat_nt(lat, lon, 0.9, 0.1)
    assert C.shape == (50, 3, 3)
    np.testing.assert_allclose(C @ np.swapaxes(C, -1, -2), np.broadcast_to(np.eye(3), C.shape), atol=1e-15)
    np.testing.assert_array_equal(C[7], E.mat_nt(lat[7], lon[7], 0.9, 0.1))
    # a small displacement gives a small rotation: about -d_lat about East etc.
    C = E.mat_nt(0.9 + 1e-6, 0.1, 0.9, 0.1)
    np.testing.assert_allclose(C, np.eye(3), atol=1.1e-6)


# --------------------------------------------------------------------------- enu <-> lla


enu_st = st.tuples(
    st.floats(-5000, 5000), st.floats(-5000, 5000), st.floats(-1000, 1000)
).map(np.array)


@SETTINGS
@given(enu_st, lat_nav, lon_st, h_st)
def test_enu_lla_round_trip(enu, lat0, lon0, h0):
    lat, lon, h = E.enu_to_lla(enu, lat0, lon0, h0)
    back = E.lla_to_enu(lat, lon, h, lat0, lon0, h0)
    np.testing.assert_allclose(back, enu, atol=3 * MAX_ERR)
    lat2, lon2, h2 = E.ecef_to_lla(E.lla_to_ecef(lat, lon, h))
    assert lla_error_m(lat, lon, h, lat2, lon2, h2) < MAX_ERR


def test_enu_known_geometry():
    lat0, lon0, h0 = 0.8, -0.4, 120.0
    np.testing.assert_allclose(E.lla_to_enu(lat0, lon0, h0, lat0, lon0, h0), 0.0, atol=1e-9)
    # straight up along the normal
    lat, lon, h = E.enu_to_lla([0.0, 0.0, 55.0], lat0, lon0, h0)
    assert lat == pytest.approx(lat0, abs=1e-15)
    assert lon == pytest.approx(lon0, abs=1e-15)
    assert h == pytest.approx(h0 + 55.0, abs=1e-8)
    # small steps East/North follow the radii of curvature
    r_m, r_n = E.radii(lat0)
    lat, lon, h = E.enu_to_lla([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], lat0, lon0, h0)
    assert lon[0] - lon0 == pytest.approx(1.0 / ((r_n + h0) * math.cos(lat0)), rel=1e-6)
    assert lat[1] - lat0 == pytest.approx(1.0 / (r_m + h0), rel=1e-6)
    # the plane is tangent: 1 km East drops below it by ~ d^2 / (2 R)
    _, _, h = E.enu_to_lla([1000.0, 0.0, 0.0], lat0, lon0, h0)
    assert h - h0 == pytest.approx(1000.0**2 / (2 * (r_n + h0)), rel=1e-2)


def test_enu_lla_vectorised():
    rng = np.random.default_rng(4)
    enu = rng.uniform(-5000, 5000, size=(4, 250, 3))
    lat, lon, h = E.enu_to_lla(enu, 0.5, 2.0, 300.0)
    assert lat.shape == lon.shape == h.shape == (4, 250)
    back = E.lla_to_enu(lat, lon, h, 0.5, 2.0, 300.0)
    assert back.shape == (4, 250, 3)
    np.testing.assert_allclose(back, enu, atol=3 * MAX_ERR)


# --------------------------------------------------------------------------- guard


@pytest.mark.parametrize("deg", [0.0, 45.0, -60.0, 89.0, -89.0])
def test_check_latitude_accepts(deg):
    E.check_latitude(np.deg2rad(deg))


@pytest.mark.parametrize(
    "lat",
    [
        np.deg2rad(89.01),
        -math.pi / 2,
        np.array([0.1, 0.2, np.deg2rad(-89.5)]),
        np.array([[0.0], [np.nan]]),
    ],
)
def test_check_latitude_rejects(lat):
    with pytest.raises(ValueError, match="89"):
        E.check_latitude(lat)


def test_check_latitude_array_ok():
    E.check_latitude(np.linspace(-np.deg2rad(89.0), np.deg2rad(89.0), 101))
