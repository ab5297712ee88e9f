"""WGS-84 Earth model.

SI units throughout, angles in radians.  Frames:

* e -- Earth-centred Earth-fixed (ECEF), WGS-84.
* n -- local-level navigation frame East-North-Up (ENU) at the current
  position (lat, lon).
* t -- a *fixed* ENU tangent-plane frame at a reference point
  (lat0, lon0, h0), e.g. the origin of a site grid.

All functions are vectorised: scalar arguments broadcast against arrays of
shape ``(...,)``; vector arguments have shape ``(...,3)`` and matrices
``(...,3,3)``.  Nothing is validated here (for speed); call
:func:`check_latitude` once where inputs enter the system, because formulas
containing ``tan L`` or ``sec L`` degrade near the poles.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = [
    "A",
    "F",
    "B",
    "E2",
    "OMEGA_IE",
    "GM",
    "GAMMA_E",
    "GAMMA_P",
    "K",
    "M",
    "LAT_LIMIT",
    "check_latitude",
    "radii",
    "normal_gravity",
    "normal_gravity_kernel",
    "gravity_n",
    "earth_rate_n",
    "transport_rate_n",
    "lla_to_ecef",
    "ecef_to_lla",
    "mat_en",
    "lla_to_enu",
    "enu_to_lla",
    "mat_nt",
    "radii_nb",
    "gravity_nb",
    "nav_rates",
]

# --- WGS-84 defining and derived constants ---------------------------------
A = 6378137.0  #: semi-major axis [m]
F = 1.0 / 298.257223563  #: flattening [-]
B = A * (1.0 - F)  #: semi-minor axis [m]
E2 = F * (2.0 - F)  #: first eccentricity squared [-]
OMEGA_IE = 7.292115e-5  #: Earth rotation rate [rad/s]
GM = 3.986004418e14  #: geocentric gravitational constant [m^3/s^2]

# --- Normal gravity (Somigliana closed form + second-order free-air term) ---
GAMMA_E = 9.7803253359  #: normal gravity at the equator [m/s^2]
GAMMA_P = 9.8321849378  #: normal gravity at the poles [m/s^2] (reference only)
K = 0.00193185265241  #: Somigliana constant (b*gamma_p)/(a*gamma_e) - 1 [-]
M = OMEGA_IE**2 * A**2 * B / GM  #: m = omega^2 a^2 b / GM (~0.00344978650684)

#: Largest |latitude| accepted by :func:`check_latitude` [rad] (89 deg).
LAT_LIMIT = np.deg2rad(89.0)


def check_latitude(lat) -> None:
    """Raise ``ValueError`` unless every ``|lat| <= 89 deg`` (NaN also fails).

    The transport rate (``tan L``) and the longitude rate (``sec L``) blow up
    at the poles, so the navigation equations are only used away from them.
    """
    lat = np.asarray(lat, dtype=float)
    ok = np.abs(lat) <= LAT_LIMIT
    if not np.all(ok):
        bad = lat[~ok] if lat.ndim else lat
        worst = np.rad2deg(np.ravel(bad)[0])
        raise ValueError(
            f"latitude {worst:.6g} deg is outside [-89, 89] deg; the local-level "
            "ENU navigation equations (tan L, sec L terms) are not valid near the poles"
        )


def radii(lat):
    """Meridian and prime-vertical radii of curvature ``(R_M, R_N)`` [m].

    ``R_N = a / sqrt(1 - e^2 sin^2 L)``, ``R_M = R_N (1 - e^2) / (1 - e^2 sin^2 L)``.
    """
    s2 = np.sin(lat) ** 2
    w2 = 1.0 - E2 * s2
    r_n = A / np.sqrt(w2)
    r_m = r_n * (1.0 - E2) / w2
    return r_m, r_n


def normal_gravity(lat, h):
    """Magnitude of WGS-84 normal gravity [m/s^2] at geodetic ``lat``, height ``h`` (array-likes broadcast).

    Somigliana on the ellipsoid::

        gamma0(L) = GAMMA_E (1 + K sin^2 L) / sqrt(1 - e^2 sin^2 L)

    and the standard second-order height correction (NIMA TR8350.2 eq. 4-3)::

        gamma(L, h) = gamma0(L) (1 - 2/a (1 + f + m - 2 f sin^2 L) h + 3 h^2 / a^2)

    with ``m = omega^2 a^2 b / GM``.
    """
    return normal_gravity_kernel(np.asarray(lat, dtype=float), np.asarray(h, dtype=float))


def normal_gravity_kernel(lat, h):
    """:func:`normal_gravity` for floats or arrays only: plain arithmetic that numba compiles as it is."""
    s2 = np.sin(lat) ** 2
    gamma0 = GAMMA_E * (1.0 + K * s2) / np.sqrt(1.0 - E2 * s2)
    corr = 1.0 - 2.0 / A * (1.0 + F + M - 2.0 * F * s2) * h + 3.0 * h**2 / A**2
    return gamma0 * corr


def gravity_n(lat, h):
    """Normal gravity vector in n (ENU): ``[0, 0, -gamma]``, shape ``(...,3)``."""
    g = normal_gravity(lat, h)
    z = np.zeros_like(g)
    return np.stack([z, z, -g], axis=-1)


def earth_rate_n(lat):
    """Earth rotation rate omega_ie resolved in n (ENU): ``[0, w cos L, w sin L]``."""
    lat = np.asarray(lat, dtype=float)
    return np.stack(
        [np.zeros_like(lat), OMEGA_IE * np.cos(lat), OMEGA_IE * np.sin(lat)], axis=-1
    )


def transport_rate_n(lat, h, v_n):
    """Transport rate omega_en resolved in n (ENU) [rad/s].

    ``[-v_N/(R_M+h), v_E/(R_N+h), v_E tan L/(R_N+h)]`` for ENU velocity ``v_n``
    of shape ``(...,3)``.
    """
    v_n = np.asarray(v_n, dtype=float)
    r_m, r_n = radii(lat)
    v_e, v_nn = v_n[..., 0], v_n[..., 1]
    rm_h = r_m + h
    rn_h = r_n + h
    return np.stack(
        np.broadcast_arrays(
            -v_nn / rm_h, v_e / rn_h, v_e * np.tan(lat) / rn_h
        ),
        axis=-1,
    )


def lla_to_ecef(lat, lon, h):
    """Geodetic ``(lat, lon, h)`` to ECEF position, shape ``(...,3)`` [m]."""
    lat, lon, h = np.broadcast_arrays(
        np.asarray(lat, float), np.asarray(lon, float), np.asarray(h, float)
    )
    sl, cl = np.sin(lat), np.cos(lat)
    r_n = A / np.sqrt(1.0 - E2 * sl**2)
    rc = (r_n + h) * cl
    return np.stack(
        [rc * np.cos(lon), rc * np.sin(lon), (r_n * (1.0 - E2) + h) * sl], axis=-1
    )


def ecef_to_lla(xyz):
    """ECEF position ``(...,3)`` to geodetic ``(lat, lon, h)``.

    Closed form of Vermeille (J. Geodesy 76, 2002) -- exact in exact
    arithmetic, no iteration -- followed by one fixed-point polish
    ``L <- atan2(z + e^2 R_N sin L, p)`` (contraction factor ~e^2, it only
    removes float64 round-off of the closed form) and the well-conditioned
    height ``h = (p - R_N cos L) cos L + (z - R_N (1-e^2) sin L) sin L``,
    where ``p = sqrt(x^2 + y^2)``.

    Accuracy: at float64 resolution.  The spacing of doubles near the Earth
    radius is 9.3e-10 m, and the round trip lla -> ecef -> lla is off by
    ~6e-10 m RMS and at most ~3e-9 m (a few ulp; the forward map alone
    contributes up to ~2.6e-9 m).  Valid for any point farther than ~45 km
    from the Earth's centre (outside the evolute of the ellipse); the
    origin gives NaN.
    """
    xyz = np.asarray(xyz, dtype=float)
    x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
    e4 = E2 * E2
    rho2 = x * x + y * y
    rho = np.hypot(x, y)

    p = rho2 / A**2
    q = (1.0 - E2) / A**2 * z * z
    r = (p + q - e4) / 6.0
    s = e4 * p * q / (4.0 * r**3)
    t = np.cbrt(1.0 + s + np.sqrt(s * (2.0 + s)))
    u = r * (1.0 + t + 1.0 / t)
    v = np.sqrt(u * u + e4 * q)
    w = E2 * (u + v - q) / (2.0 * v)
    k = np.sqrt(u + v + w * w) - w
    d = k * rho / (k + E2)
    lat = 2.0 * np.arctan2(z, d + np.hypot(d, z))

    r_n = A / np.sqrt(1.0 - E2 * np.sin(lat) ** 2)
    lat = np.arctan2(z + E2 * r_n * np.sin(lat), rho)

    lon = np.arctan2(y, x)
    sl, cl = np.sin(lat), np.cos(lat)
    r_n = A / np.sqrt(1.0 - E2 * sl * sl)
    h = (rho - r_n * cl) * cl + (z - r_n * (1.0 - E2) * sl) * sl
    return lat, lon, h


def quat_en(lat, lon):
    """Quaternion of ``C_n^e`` (ENU -> ECEF), shape ``(...,4)``: ``Rz(lon + pi/2) Rx(pi/2 - lat)``."""
    lat, lon = np.broadcast_arrays(np.asarray(lat, float), np.asarray(lon, float))
    half_z, half_x = 0.5 * (lon + 0.5 * np.pi), 0.5 * (0.5 * np.pi - lat)
    cz, sz, cx, sx = np.cos(half_z), np.sin(half_z), np.cos(half_x), np.sin(half_x)
    return np.stack([cz * cx, cz * sx, sz * sx, sz * cx], axis=-1)


def mat_en(lat, lon):
    """Rotation ``C_n^e`` (ENU -> ECEF), shape ``(...,3,3)``.

    Columns are the East, North and Up unit vectors at ``(lat, lon)``
    expressed in ECEF, so ``r_e = C_n^e @ r_n``.
    """
    lat, lon = np.broadcast_arrays(np.asarray(lat, float), np.asarray(lon, float))
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    zero = np.zeros_like(lat)
    east = np.stack([-so, co, zero], axis=-1)
    north = np.stack([-sl * co, -sl * so, cl], axis=-1)
    up = np.stack([cl * co, cl * so, sl], axis=-1)
    return np.stack([east, north, up], axis=-1)


def lla_to_enu(lat, lon, h, lat0, lon0, h0):
    """Geodetic points to coordinates ``(...,3)`` [m] in the tangent-plane
    ENU frame t with origin at ``(lat0, lon0, h0)`` (exact, via ECEF)."""
    d = lla_to_ecef(lat, lon, h) - lla_to_ecef(lat0, lon0, h0)
    c_te = mat_en(lat0, lon0)
    return np.einsum("...ji,...j->...i", c_te, d)


def enu_to_lla(enu, lat0, lon0, h0):
    """Tangent-plane ENU coordinates ``(...,3)`` relative to the origin
    ``(lat0, lon0, h0)`` to geodetic ``(lat, lon, h)`` (exact, via ECEF)."""
    enu = np.asarray(enu, dtype=float)
    c_te = mat_en(lat0, lon0)
    xyz = lla_to_ecef(lat0, lon0, h0) + np.einsum("...ij,...j->...i", c_te, enu)
    return ecef_to_lla(xyz)


def mat_nt(lat, lon, lat0, lon0):
    """Rotation ``C_t^n`` from the fixed tangent-plane ENU frame t at
    ``(lat0, lon0)`` to the local-level ENU frame n at ``(lat, lon)``.

    ``C = C_en(lat, lon)^T @ C_en(lat0, lon0)`` with ``C_en`` from
    :func:`mat_en`, so ``v_n = C @ v_t``.  Identity at the reference point;
    shape ``(...,3,3)``.
    """
    c_ne = np.swapaxes(mat_en(lat, lon), -1, -2)
    return c_ne @ mat_en(lat0, lon0)


# ------------------------------------------------------------------------------------------------------------
# Kernel helpers: scalar forms compiled with numba for the sequential kernels (mechanization, filters).

radii_nb = nb.njit(cache=True)(radii)
gravity_nb = nb.njit(cache=True)(normal_gravity_kernel)


@nb.njit(cache=True)
def nav_rates(lat, h, v):
    """w_ie^n and w_en^n (ENU) at (lat, h) with velocity v."""
    ie_n, ie_u, en_e, en_n, en_u = nav_rate_parts(lat, h, v[0], v[1])
    return np.array([0.0, ie_n, ie_u]), np.array([en_e, en_n, en_u])


@nb.njit(cache=True, inline="always")
def nav_rate_parts(lat, h, v_e, v_n):
    """`nav_rates` as scalars (w_ie^n's north and up, w_en^n's east, north and up; w_ie^n's east is 0) for the
    velocity's east and north v_e, v_n."""
    r_m, r_n = radii_nb(lat)
    return (OMEGA_IE * np.cos(lat), OMEGA_IE * np.sin(lat), -v_n / (r_m + h), v_e / (r_n + h),
            v_e * np.tan(lat) / (r_n + h))
