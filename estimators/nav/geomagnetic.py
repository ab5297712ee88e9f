"""Magnetic heading for the SINS/magnetometer sub-filter (issue 6): the geomagnetic reference, tilt-compensated
yaw (002 eqs. 3-6), the yaw closing-error measurement of 003 section 3.2 with its Jacobian on the psi-angle
attitude error, a disturbance test, and hard/soft-iron calibration by an ellipsoid fit.

Conventions (docs DESIGN.md): n is East-North-Up, b is x right (towards the coal wall), y forward, z up,
C_b^n = Rz(yaw) Rx(pitch) Ry(roll), yaw counter-clockwise from true north. Fields are in tesla, angles in
radians. The magnetometer model the functions invert is that of the twin (and of 003 section 3.2):

    b_b = S (C_b^n)^T B_n + h + disturbance + noise,

S the soft-iron matrix, h the hard-iron offset, B_n the geomagnetic field in n.

How 002's convention maps onto this one
---------------------------------------
002 (section 2.3.1) writes the field in NED with a forward-right-down body frame and Z-Y-X Euler angles
(psi clockwise from north, theta about the right axis, phi about the forward axis). The change of axes
T = [[0, 1, 0], [1, 0, 0], [0, 0, -1]] (a proper rotation, E<->N, U->D, right<->forward, up->down) maps one
onto the other: T Rz(yaw) Rx(pitch) Ry(roll) T = Rz(-yaw) Ry(pitch) Rx(roll), so

    002 psi = -yaw,   002 theta = pitch,   002 phi = roll,   002 (m_x, m_y, m_z) = (b_y, b_x, -b_z),

and 002's declination alpha (positive east) is the WMM/pygeomag declination D. tests/estimators/nav/test_geomagnetic.py evaluates
002 eqs. 4-6 literally in 002's frames against :func:`tilt_compensated_yaw`.
"""

from __future__ import annotations

import datetime
from functools import lru_cache
from typing import NamedTuple

import numba as nb
import numpy as np
from pygeomag import GeoMag, decimal_year_from_date

__all__ = [
    "FieldCheck",
    "GeomagneticReference",
    "MagCalibration",
    "YawMeasurement",
    "apply_calibration",
    "field_check",
    "fit_ellipsoid",
    "geomagnetic_reference",
    "tilt_compensated_yaw",
    "wrap_angle",
    "yaw_closing_error",
    "yaw_closing_error_nb",
    "yaw_h_phi",
    "yaw_measurement",
    "yaw_noise_variance",
]

NT = 1e-9
"""One nanotesla in tesla (pygeomag works in nT)."""

NORM_TOLERANCE = 0.03
"""Default relative field-norm deviation beyond which a reading is disturbed (1.6 uT of a 53 uT field: well
above the noise and a calibration residual, below the motor and interference fields of the twin)."""
DIP_TOLERANCE = np.radians(2.0)
"""Default dip deviation beyond which a reading is disturbed (a 1.8 uT field across a 53 uT one)."""
MIN_COVERAGE = 0.01
"""Smallest singular value of the normalised ellipsoid design matrix, relative to the largest, that a
calibration data set must reach. Measured on simulated readings (53 uT field, 0.1 uT noise): attitudes over the
whole sphere give 0.6; full turns in yaw with tilts of sd 0.3 / 0.2 / 0.1 rad give 0.018 / 0.007 / 0.002 with
field errors after calibration of 0.3 / 1.5 / 16 %; a shearer on its face (yaw within a few degrees) 4e-5."""


# --------------------------------------------------------------------------------------- geomagnetic model


class GeomagneticReference(NamedTuple):
    """The geomagnetic field at a point and date (World Magnetic Model through pygeomag)."""

    declination: float
    """Angle of magnetic north from true north [rad], positive east (clockwise seen from above)."""
    inclination: float
    """Dip of the field below the horizontal [rad], positive downwards."""
    intensity: float
    """Total field strength [T]."""
    field_n: np.ndarray
    """The field vector in n (East, North, Up) [T], shape (3,)."""

    @property
    def horizontal(self) -> float:
        """Strength of the horizontal component [T]."""
        return float(np.hypot(self.field_n[0], self.field_n[1]))


@lru_cache(maxsize=64)
def _wmm(lat_deg: float, lon_deg: float, height_m: float, day: datetime.date) -> tuple[float, ...]:
    """(declination [deg], inclination [deg], intensity, north, east, down [nT]) from pygeomag."""
    try:
        res = GeoMag(base_year=day.year).calculate(glat=lat_deg, glon=lon_deg, alt=height_m / 1000.0,
                                                   time=decimal_year_from_date(day))
    except ValueError as err:
        raise ValueError(f"geomagnetic date {day}: no World Magnetic Model for it ({err})") from None
    return res.d, res.i, res.f, res.x, res.y, res.z


def geomagnetic_reference(lat: float, lon: float, height: float,
                          date: str | datetime.date) -> GeomagneticReference:
    """WMM declination, inclination, intensity and ENU field at geodetic lat, lon [rad], height [m] on `date`.

    `height` is ellipsoidal (the WMM's altitudes refer to WGS-84); `date` is a `datetime.date` or "YYYY-MM-DD".
    pygeomag gives north (x), east (y) and down (z) in nT; ENU = (east, north, -down). Over a face and its panel
    (< 1 km) the field changes by a few nT, so one evaluation serves a run.
    """
    if isinstance(date, str):
        try:
            date = datetime.date.fromisoformat(date)
        except ValueError:
            raise ValueError(f"geomagnetic date {date!r} is not a date YYYY-MM-DD") from None
    d, i, f, north, east, down = _wmm(float(np.degrees(lat)), float(np.degrees(lon)), float(height), date)
    return GeomagneticReference(float(np.radians(d)), float(np.radians(i)), float(f * NT),
                                np.array([east, north, -down]) * NT)


# ------------------------------------------------------------------------------------- tilt-compensated yaw


def wrap_angle(a):
    """Angle(s) wrapped to (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(a, float), 2 * np.pi)


def _tilt_yaw(bx, by, bz, pitch, roll, declination):
    """Scalar core of :func:`tilt_compensated_yaw` (compiled twice: as a numba ufunc and as a jitted function)."""
    sp, cp = np.sin(pitch), np.cos(pitch)
    sr, cr = np.sin(roll), np.cos(roll)
    h_x = cr * bx + sr * bz
    h_y = cp * by + sp * (sr * bx - cr * bz)
    yaw = np.arctan2(h_x, h_y) - declination
    return np.pi - np.mod(np.pi - yaw, 2 * np.pi)


_tilt_yaw_ufunc = nb.vectorize(["float64(float64, float64, float64, float64, float64, float64)"],
                               cache=True)(_tilt_yaw)
_tilt_yaw_nb = nb.njit(cache=True)(_tilt_yaw)


def tilt_compensated_yaw(mag_b, pitch, roll, declination):
    """Yaw [rad] (counter-clockwise from true north, in (-pi, pi]) from a calibrated body-frame field and tilt.

    002 eqs. 3-6 in this project's convention (see the module docstring for the mapping). Levelling the reading,
    h = Rx(pitch) Ry(roll) b_b = Rz(yaw)^T B_n, leaves the horizontal components (002 eq. 4)

        h_x = cos(roll) b_x + sin(roll) b_z                           (002: -M_N sin psi_m)
        h_y = cos(pitch) b_y + sin(pitch) (sin(roll) b_x - cos(roll) b_z)   (002:  M_N cos psi_m)

    and, B_n's horizontal part pointing to magnetic north at the declination D east of true north,
    h_x = H sin(yaw + D), h_y = H cos(yaw + D), so (002 eqs. 5-6 with psi_mag = psi_m + alpha = -yaw)

        yaw = atan2(h_x, h_y) - D.

    Arrays broadcast: mag_b (..., 3), pitch, roll, declination (...).
    """
    mag_b = np.asarray(mag_b, float)
    out = _tilt_yaw_ufunc(mag_b[..., 0], mag_b[..., 1], mag_b[..., 2], np.asarray(pitch, float),
                          np.asarray(roll, float), np.asarray(declination, float))
    return out[()] if isinstance(out, np.ndarray) else float(out)


@nb.njit(cache=True)
def yaw_closing_error_nb(mag_b, mat_nb, declination):
    """z = yaw_SINS - yaw_mag (wrapped) for one sample: mag_b (3,), the SINS C_b^n (3, 3); for numba kernels.

    The magnetic yaw uses the SINS pitch and roll (003 section 4.1: "according to the roll and pitch angles
    measured by SINS"), taken from C_b^n like estimators.nav.rotations.mat_to_euler.
    """
    c20, c21, c22 = mat_nb[2, 0], mat_nb[2, 1], mat_nb[2, 2]
    cp = np.hypot(c20, c22)
    pitch = np.arctan2(c21, cp)
    roll = np.arctan2(-c20, c22) if cp > 1e-12 else 0.0
    yaw_sins = np.arctan2(-mat_nb[0, 1], mat_nb[1, 1])  # C01 = -sin(yaw) cos(pitch), C11 = cos(yaw) cos(pitch)
    z = yaw_sins - _tilt_yaw_nb(mag_b[0], mag_b[1], mag_b[2], pitch, roll, declination)
    return np.pi - np.mod(np.pi - z, 2 * np.pi)


def yaw_closing_error(mag_b, mat_nb, declination):
    """z = yaw_SINS - yaw_mag (003 section 3.2), wrapped to (-pi, pi]; mag_b (..., 3), mat_nb (..., 3, 3)."""
    mat_nb = np.asarray(mat_nb, float)
    c20, c21, c22 = mat_nb[..., 2, 0], mat_nb[..., 2, 1], mat_nb[..., 2, 2]
    cp = np.hypot(c20, c22)
    pitch = np.arctan2(c21, cp)
    roll = np.where(cp > 1e-12, np.arctan2(-c20, c22), 0.0)
    yaw_sins = np.arctan2(-mat_nb[..., 0, 1], mat_nb[..., 1, 1])
    return wrap_angle(yaw_sins - tilt_compensated_yaw(mag_b, pitch, roll, declination))


def yaw_h_phi(field_n) -> np.ndarray:
    """H row (3,) of z = yaw_SINS - yaw_mag on the psi-angle attitude error phi, C_b^n' = (I - [phi x]) C_b^n.

    With the SINS attitude C' = Rz(yaw') A', A' = Rx(pitch') Ry(roll'), the levelled reading is
    h = A' C^T B_n = Rz(yaw')^T C' C^T B_n = Rz(yaw')^T (I - [phi x]) B_n: the magnetic yaw computed with the
    SINS tilt is yaw' + (azimuth of the horizontal part of B' = B_n - phi x B_n) - D. So z is minus the change
    of that azimuth, whatever the vehicle's attitude; to first order in phi

        z = (B_e B_u phi_e + B_n B_u phi_n) / H^2 - phi_u,   H^2 = B_e^2 + B_n^2,

    i.e. h_phi = [-sin(D) tan(I), -cos(D) tan(I), -1]. 003 keeps only the -phi_u term (its yaw error state);
    the levelling terms matter: at a dip of 55 deg a 0.1 deg tilt error moves the magnetic yaw by 0.14 deg.
    The lead embeds it as H[0, PHI] = yaw_h_phi(ref.field_n).
    """
    b_e, b_n, b_u = np.asarray(field_n, float)
    h2 = b_e * b_e + b_n * b_n
    return np.array([b_e * b_u / h2, b_n * b_u / h2, -1.0])


def yaw_noise_variance(ref: GeomagneticReference, noise_t: float) -> float:
    """Variance [rad^2] of the magnetic yaw from white magnetometer noise of `noise_t` [T] per axis.

    002 eqs. 26-27 with equal variances on the three axes: the gradients of h_x and h_y with respect to b_b are
    orthogonal unit vectors, so sigma_yaw^2 = sigma_m^2 (h_x^2 + h_y^2) / H^4 = sigma_m^2 / H^2, with H the
    horizontal field strength (0.1 uT of noise in a 30 uT horizontal field: 0.19 deg).
    """
    return float(noise_t) ** 2 / ref.horizontal ** 2


class YawMeasurement(NamedTuple):
    """One yaw closing error as an error-state measurement block: z = h_phi . phi + v, var(v) = r."""

    z: np.ndarray
    """yaw_SINS - yaw_mag [rad], wrapped, shape (...)."""
    h_phi: np.ndarray
    """H row on phi (3,) (the other states have zero coefficients)."""
    r: float
    """Noise variance [rad^2] (the nominal R; estimators.kalman.adaptive_noise estimates it online)."""


def yaw_measurement(mag_b, mat_nb, ref: GeomagneticReference, noise_t: float,
                    extra_sigma: float = 0.0) -> YawMeasurement:
    """The SINS/MAG sub-filter's measurement (003 section 3.2): z = yaw_SINS - yaw_mag, H row on phi, R.

    `mag_b` is the calibrated reading (..., 3) [T], `mat_nb` the SINS C_b^n (..., 3, 3), `noise_t` the
    magnetometer noise per axis [T]; `extra_sigma` [rad] adds what the noise does not cover (declination error,
    calibration residual, an undetected motor field). R = yaw_noise_variance + extra_sigma^2.
    """
    z = yaw_closing_error(mag_b, mat_nb, ref.declination)
    return YawMeasurement(np.asarray(z), yaw_h_phi(ref.field_n), yaw_noise_variance(ref, noise_t) + extra_sigma ** 2)


# --------------------------------------------------------------------------------------- disturbance test


class FieldCheck(NamedTuple):
    """The disturbance test of a reading against the geomagnetic reference."""

    norm_error: np.ndarray
    """(|b| - F) / F: relative deviation of the field strength."""
    dip_error: np.ndarray
    """Measured dip (from the reading levelled with the SINS tilt) minus the reference inclination [rad]."""
    ok: np.ndarray
    """True where the reading is finite, unsaturated and both deviations are within their tolerances."""


def field_check(mag_b, pitch, roll, ref: GeomagneticReference, norm_tol: float = NORM_TOLERANCE,
                dip_tol: float = DIP_TOLERANCE, saturation_t: float | None = None) -> FieldCheck:
    """Is a calibrated reading the undisturbed Earth field? Field norm and dip against the WMM reference.

    The vertical component of C_b^n b_b does not depend on yaw: b_u = -cos(pitch) sin(roll) b_x +
    sin(pitch) b_y + cos(pitch) cos(roll) b_z, and the dip is atan2(-b_u, |b_horizontal|). A NaN reading, one
    with a component at or beyond `saturation_t`, or one off by more than `norm_tol` (relative) or `dip_tol`
    [rad] is not ok. Arrays broadcast as in :func:`tilt_compensated_yaw`.
    """
    mag_b = np.asarray(mag_b, float)
    pitch, roll = np.asarray(pitch, float), np.asarray(roll, float)
    norm = np.linalg.norm(mag_b, axis=-1)
    b_u = (-np.cos(pitch) * np.sin(roll) * mag_b[..., 0] + np.sin(pitch) * mag_b[..., 1]
           + np.cos(pitch) * np.cos(roll) * mag_b[..., 2])
    horizontal = np.sqrt(np.maximum(norm ** 2 - b_u ** 2, 0.0))
    norm_error = norm / ref.intensity - 1.0
    dip_error = np.arctan2(-b_u, horizontal) - ref.inclination
    with np.errstate(invalid="ignore"):
        ok = (np.abs(norm_error) <= norm_tol) & (np.abs(dip_error) <= dip_tol)
        if saturation_t is not None:
            ok &= np.all(np.abs(mag_b) < saturation_t, axis=-1)
    return FieldCheck(norm_error, dip_error, ok & np.all(np.isfinite(mag_b), axis=-1))


# ------------------------------------------------------------------------------------------- calibration


class MagCalibration(NamedTuple):
    """Hard- and soft-iron calibration: B_b = correction @ (b_b - hard_iron_t)."""

    hard_iron_t: np.ndarray
    """Offset h [T], (3,)."""
    soft_iron: np.ndarray
    """S (3, 3): the symmetric soft-iron matrix of b_b = S B_b + h (the inverse of `correction`)."""
    correction: np.ndarray
    """S^-1 (3, 3), symmetric positive definite."""
    residual_rms: float
    """RMS of |corrected field| - F over the fitted samples [T]."""
    coverage: float
    """Smallest over largest singular value of the normalised design matrix (see MIN_COVERAGE)."""


def fit_ellipsoid(mag_b, intensity: float, min_coverage: float = MIN_COVERAGE) -> MagCalibration:
    """Hard/soft-iron calibration from readings over many attitudes: a linear least-squares ellipsoid fit.

    Undisturbed readings lie on the ellipsoid (b - h)^T S^-T S^-1 (b - h) = F^2. With u = b / F the quadric
    a u_x^2 + b u_y^2 + c u_z^2 + 2 f u_y u_z + 2 g u_x u_z + 2 k u_x u_y + 2 p u_x + 2 q u_y + 2 r u_z = 1 is
    linear in its nine coefficients (numpy.linalg.lstsq). With A' = [[a, k, g], [k, b, f], [g, f, c]] and
    v = [p, q, r] the centre is c = -A'^-1 v, and (u - c)^T A (u - c) = 1 with A = A' / (1 + c^T A' c); then
    h = F c and the correction is the symmetric square root of A. S is only defined up to a rotation by the
    field data; the symmetric root is S^-1 itself when S is symmetric, as the induced (soft-iron) field is.

    The data must span attitudes (a calibration manoeuvre, not a shearer on its face, whose yaw hardly changes):
    a ValueError names the coverage when the smallest singular value of the normalised design is below
    `min_coverage` of the largest, or when the fit is not an ellipsoid.
    """
    mag_b = np.asarray(mag_b, float)
    if mag_b.ndim != 2 or mag_b.shape[1] != 3:
        raise ValueError(f"fit_ellipsoid: readings must have shape (K, 3), got {mag_b.shape}")
    mag_b = mag_b[np.all(np.isfinite(mag_b), axis=1)]
    if mag_b.shape[0] < 9:
        raise ValueError(f"fit_ellipsoid: {mag_b.shape[0]} finite readings, need at least 9")
    u = mag_b / intensity
    x, y, z = u.T
    design = np.column_stack([x * x, y * y, z * z, 2 * y * z, 2 * x * z, 2 * x * y, 2 * x, 2 * y, 2 * z])
    sv = np.linalg.svd(design / np.linalg.norm(design, axis=0), compute_uv=False)
    coverage = float(sv[-1] / sv[0])
    if coverage < min_coverage:
        raise ValueError(f"fit_ellipsoid: the readings cover too few attitudes (coverage {coverage:.2e} < "
                         f"{min_coverage}); rotate the unit through many headings and tilts")
    coef = np.linalg.lstsq(design, np.ones(len(u)), rcond=None)[0]
    a, b, c, f, g, k, p, q, r = coef
    quad = np.array([[a, k, g], [k, b, f], [g, f, c]])
    centre = -np.linalg.solve(quad, np.array([p, q, r]))
    quad = quad / (1.0 + centre @ quad @ centre)
    w, v = np.linalg.eigh(quad)
    if not np.all(w > 0):
        raise ValueError("fit_ellipsoid: the fitted quadric is not an ellipsoid; check the data for disturbances")
    correction = (v * np.sqrt(w)) @ v.T
    soft_iron = (v / np.sqrt(w)) @ v.T
    hard_iron = intensity * centre
    residual = np.linalg.norm((mag_b - hard_iron) @ correction.T, axis=1) - intensity
    return MagCalibration(hard_iron, soft_iron, correction, float(np.sqrt(np.mean(residual ** 2))), coverage)


def apply_calibration(mag_b, cal: MagCalibration) -> np.ndarray:
    """Calibrated field B_b = S^-1 (b_b - h), shape of mag_b (..., 3)."""
    return (np.asarray(mag_b, float) - cal.hard_iron_t) @ cal.correction.T
