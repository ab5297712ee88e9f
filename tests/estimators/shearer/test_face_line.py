"""The surveyed face line's local quadratic fit (estimators.shearer.face_line)."""

import pytest
import numpy as np

from estimators.nav import earth
from estimators.shearer import face_line
from estimators.shearer.face_line import fit_face_line

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

LAT0, LON0, H0 = np.radians(34.0), np.radians(110.0), 40.0


def _undulating_line():
    """A face line that dips 2 deg and undulates 0.2 m across and 0.1 m up and down over 40 m, one point per
    1.8 m chute: face coordinate, true ENU points and their tangent d enu / d u."""
    u = np.arange(0.0, 360.0, 1.8)
    k = 2 * np.pi / 40.0
    enu = np.column_stack([u, 0.2 * np.sin(k * u), np.tan(np.radians(2.0)) * u + 0.1 * np.sin(k * u + 1.0)])
    tangent = np.column_stack([np.ones(u.size), 0.2 * k * np.cos(k * u),
                               np.tan(np.radians(2.0)) + 0.1 * k * np.cos(k * u + 1.0)])
    return u, enu, tangent


def _llh(enu):
    return np.column_stack(earth.enu_to_lla(enu, LAT0, LON0, H0))


def _sd(u, sd):
    return np.full((u.size, 2), sd)


def test_the_direction_follows_the_line_through_its_undulation():
    """Surveyed with 0.05 m noise: the fit's direction follows the local tangent across and up to 0.0052 rms (the
    window's attenuation of the 40 m wave, and the noise), where one straight direction misses it by the
    undulation's slope, 0.018 rms."""
    u, enu, tangent = _undulating_line()
    noisy = enu + np.random.default_rng(4).normal(0.0, 0.05, enu.shape)
    line = fit_face_line(_llh(noisy), u, _sd(u, 0.05))
    assert line.half_window_m == 14.5
    straight = (enu[-1] - enu[0]) / (u[-1] - u[0])
    rms = [np.sqrt(np.mean((d - tangent)[:, 1:] ** 2)) for d in (line.direction, straight)]
    assert rms[0] < 0.007 and rms[1] > 0.015, rms


def test_an_error_free_survey_stated_coarse_is_smoothed_for_its_scatter():
    """Error-free but stated at 0.05 m, the points scatter about nothing around the fit over +-4.5 m: the window is
    chosen for that scatter (+-9 m, where 0.05 m of scatter takes +-14.5 m) and the fit stays within 2 mm of the
    line (6 mm at +-14.5 m); its variances stay the stated sigma's (gain times 0.05^2)."""
    u, enu, _ = _undulating_line()
    exact = fit_face_line(_llh(enu), u, _sd(u, 0.05))
    assert exact.half_window_m == 9.0
    assert np.abs(exact.enu - (enu - enu[0])).max() < 0.002
    assert np.all(exact.gain > 0.2)


def test_the_noise_gain_is_the_smoothed_error(monkeypatch):
    """Error-free (stated at 0.05 m) over +-14.5 m, as a 0.05 m survey chooses, the fit bends with the undulation to
    within 6 mm. With 0.05 m noise, over 400 surveys, each smoothed point's error variance is 0.05^2 times its noise
    gain to within 15 % (the gain is 0.18 mid-face, more at the ends, where the window is one-sided), the smoothed
    points are 2.3 times closer to the line than the survey's, and neighbouring points' errors differ by 8 mm rms
    (an unweighted fit over +-9 m, with gain 0.21: 12 mm; the tricube weights let a point enter the window
    gradually)."""
    u, enu, _ = _undulating_line()
    origin = _llh(enu[:1])[0]
    monkeypatch.setattr(face_line, "HALF_WINDOWS_M", (14.5,))  # the draws' window, as a 0.05 m survey chooses
    exact = fit_face_line(_llh(enu), u, _sd(u, 0.05))
    assert np.abs(exact.enu - (enu - enu[0])).max() < 0.006
    assert np.allclose(exact.origin, origin)
    rng = np.random.default_rng(7)
    fits = [fit_face_line(_llh(enu + rng.normal(0.0, 0.05, enu.shape)), u, _sd(u, 0.05)).llh() for _ in range(400)]
    err = np.array([earth.lla_to_enu(*f.T, *origin) - exact.enu for f in fits])
    var = err.var(axis=0).mean(axis=1)
    assert np.all(np.abs(var / (0.05 ** 2 * exact.gain) - 1.0) < 0.15)
    assert 0.17 < exact.gain[u.size // 2] < 0.18 and exact.gain[0] > 0.5
    assert np.sqrt((err ** 2).mean()) < 0.05 / 2.3
    mid = slice(10, -10)
    assert np.sqrt(np.mean(np.diff(err[:, mid, :2], axis=1) ** 2)) < 0.0085


def test_short_lines():
    """Two points: a straight line through them; one point: kept, with no direction."""
    u, enu, _ = _undulating_line()
    two = fit_face_line(_llh(enu[:2]), u[:2], _sd(u[:2], 0.05))
    assert np.allclose(two.enu, enu[:2] - enu[0], atol=1e-6)
    assert np.allclose(two.direction, (enu[1] - enu[0]) / 1.8, atol=1e-6)
    one = fit_face_line(_llh(enu[:1]), u[:1], _sd(u[:1], 0.05))
    assert np.allclose(one.enu, 0.0, atol=1e-6) and np.isnan(one.direction).all() and one.gain[0] == 1.0


def test_a_precise_survey_of_a_sharply_undulating_floor_is_followed_not_flattened(monkeypatch):
    """A 5 mm survey of a floor undulating 0.3 m over 30 m, one point per 1.75 m: the risk estimate picks a
    narrower window than the +-14.5 m a 5 cm survey gets (+-6.5 m), and the smoothed heights are 5 times closer to
    the line than at +-14.5 m (3.2 mm against 15.9 mm rms)."""
    u = np.arange(0.0, 120.0, 1.75)
    enu = np.column_stack([u, np.zeros(u.size), 0.3 * np.sin(2 * np.pi * u / 30.0)])
    noisy = _llh(enu + np.random.default_rng(4).normal(0.0, 0.005, enu.shape))
    line = fit_face_line(noisy, u, _sd(u, 0.005))
    monkeypatch.setattr(face_line, "HALF_WINDOWS_M", (14.5,))
    wide = fit_face_line(noisy, u, _sd(u, 0.005))
    rms = [np.sqrt(np.mean((earth.lla_to_enu(*f.llh().T, LAT0, LON0, H0) - enu)[:, 2] ** 2)) for f in (line, wide)]
    assert line.half_window_m < 14.5 and rms[0] < 0.004 and rms[1] > 4 * rms[0], (line.half_window_m, rms)
