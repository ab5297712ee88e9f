"""CPOEM pieces: point crossings along the face, the pan advance from push-ram strokes, and the direction the
advance moves a point (on a floor dipping in the advance direction)."""

import numpy as np
import pytest

from estimators.nav import earth
from estimators.nav.rotations import quat_to_mat, rotvec_to_quat
from estimators.shearer.cpoem import (
    Points,
    RamLog,
    advance_direction,
    at_spacing,
    crossings,
    predict_fixes,
    ram_stroke,
)


def test_crossings_find_each_point_once_in_either_direction():
    u = np.array([0.0, 0.9, 2.1, 3.9, 4.1, 4.1, 2.5])  # up past 1..4, then back down past 4 and 3
    j, m = crossings(u, 1.0, 0, u.size - 1)
    assert list(m) == [1.0, 2.0, 3.0, 4.0]  # the way back recrosses 4 and 3: first crossings only
    assert list(j) == [2, 2, 3, 4]
    j, m = crossings(u[::-1].copy(), 1.0, 0, u.size - 1)
    assert list(m) == [3.0, 4.0, 2.0, 1.0]  # up past 3 and 4 first, then down past 2 and 1


def _ram(t, events, noise, rng):
    """Ram length 1.2 m plus steps (time, change) with 10 s ramps, sampled at t, with noise."""
    x = np.full(t.size, 1.2)
    for t0, dx in events:
        x += dx * np.clip((t - t0) / 10.0, 0.0, 1.0)
    return x + rng.normal(0, noise, t.size)


def test_stroke_sums_partial_pushes_and_ignores_the_support_advance():
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 600.0, 1.0)
    for noise in (1e-4, 0.02):
        # Snake formation: two partial pushes (0.4 then 0.8 m), the support advances in between and after.
        ext = _ram(t, [(100, 0.4), (200, -0.4), (300, 0.8), (400, -0.8)], noise, rng)
        got = ram_stroke(t, ext, np.ones(t.size), 0.0, 600.0, noise)
        assert abs(got - 1.2) < max(0.005, 2 * noise), (noise, got)
    # Support advance only (before_push sequence before the push): no pan advance.
    ext = _ram(t, [(100, -1.0)], 1e-4, rng)
    assert abs(ram_stroke(t, ext, np.ones(t.size), 0.0, 600.0, 1e-4)) < 0.002
    # The end push: a full stroke and the support's advance right after it, one reading at the top.
    ext = np.full(t.size, 1.2)
    ext[t == 300] = 2.4
    assert abs(ram_stroke(t, ext, np.ones(t.size), 0.0, 600.0, 1e-4) - 1.2) < 0.002
    # All readings invalid: no stroke, not zero.
    assert np.isnan(ram_stroke(t, ext, np.zeros(t.size), 0.0, 600.0, 1e-4))


def test_advance_interpolates_between_supports_and_propagates_a_missing_reading():
    t = np.arange(0.0, 300.0, 1.0)
    rng = np.random.default_rng(1)
    ext = [_ram(t, [(50, 1.0)], 1e-4, rng), _ram(t, [(50, 0.8)], 1e-4, rng), _ram(t, [(50, 0.8)], 1e-4, rng)]
    valid = [np.ones(t.size), np.ones(t.size), np.zeros(t.size)]
    rams = RamLog([t] * 3, ext, valid, np.array([0.0, 2.0, 4.0]), 1e-4)
    assert abs(rams.advance(0.5, 0.0, 300.0) - 0.95) < 0.003
    assert np.isnan(rams.advance(3.0, 0.0, 300.0))


@pytest.mark.parametrize("steps, advance_after_s", [
    ([0.0125, 0.0721, 0.142, 0.2142, 0.2412, 0.1791, 0.1058, 0.0363], 56.0),  # an odd support of seed004
    ([0.0356, 0.1069, 0.1784, 0.2416, 0.2133, 0.1407, 0.0706, 0.0078], 37.0),  # an even one: a last step of 8 mm
])
def test_stroke_of_a_noisy_sensor_over_a_snake_push_is_unbiased(steps, advance_after_s):
    """004's 0.02 m ram sensor over the twin's snake push (eight partial steps of 1-24 cm, 37 s apart, the support
    advancing in one reading 37-56 s after the last): over 300 noise draws the stroke is off by at most 0.3 mm on
    average and 8 mm rms.

    Levels taken within 6 sigma of a swing's extreme merged the last steps with the plateaus before them and read
    the stroke 10 mm short (7-8 mm per cycle on seed004, which bent the rail model's fixes 1 cm a cycle towards the
    goaf). The level before the advance taken from a minute of readings mixed an 8 mm last step, which the
    level-change test cannot resolve, with the plateau before it: 3.2 mm short (cpoem.RAM_TOP_SAMPLES)."""
    t = np.arange(0.0, 1200.0, 1.0)
    clean = np.full(t.size, 1.2)
    for k, dx in enumerate(steps):
        clean[t >= 300.0 + 37.0 * k] += dx
    clean[t >= 300.0 + 37.0 * (len(steps) - 1) + advance_after_s] -= sum(steps)
    rng = np.random.default_rng(3)
    err = np.array([ram_stroke(t, clean + rng.normal(0.0, 0.02, t.size), np.ones(t.size), 0.0, 1200.0, 0.02)
                    for _ in range(300)]) - sum(steps)
    assert abs(err.mean()) < 0.0015 and np.sqrt(np.mean(err ** 2)) < 0.008, (err.mean(), err.std())


ORIGIN = (np.radians(-27.5), np.radians(151.9), 400.0)
AZIMUTH = np.radians(30.0)
FACE = np.array([np.sin(AZIMUTH), np.cos(AZIMUTH)])  # horizontal, along the face (clockwise from north)
COAL = np.array([FACE[1], -FACE[0]])  # horizontal, square to the face, towards the coal wall
SEAM_DIP = np.radians(3.0)
ROLL_SD = 1e-3
"""One-sigma [rad] of a point's tilt across the face about the floor's (a MEMS filter's attitude noise)."""


def _floor_points(dip: float, roll_sd: float, n: int = 60) -> tuple[Points, np.ndarray]:
    """Points every metre along a face on the plane z = tan(dip) (p . COAL) + tan(SEAM_DIP) (p . FACE) (ENU about
    ORIGIN), each with the machine's frame on the plane (y up the face, z the plane's normal) turned 0.1 rad on
    the floor over the first 15 points (a cut-out's diagonal entry) and tilted across the face by N(0, roll_sd);
    and the plane's unit normal."""
    u = np.arange(n, dtype=float)
    enu = np.column_stack([np.outer(u, FACE), np.tan(SEAM_DIP) * u])
    normal = np.append(-np.tan(dip) * COAL - np.tan(SEAM_DIP) * FACE, 1.0)
    normal /= np.linalg.norm(normal)
    y = np.append(FACE, np.tan(SEAM_DIP))
    y /= np.linalg.norm(y)
    c_plane = np.column_stack([np.cross(y, normal), y, normal])
    turn = np.column_stack([np.zeros(n), np.random.default_rng(5).normal(0.0, roll_sd, n), np.where(u < 15, 0.1, 0.0)])
    c_nb = c_plane @ quat_to_mat(rotvec_to_quat(turn))
    llh = np.column_stack(earth.enu_to_lla(enu, *ORIGIN))
    return Points(u, np.zeros(n), llh, np.zeros((n, 3, 3)), c_nb, 1.0), normal


def _slope_tolerance(dip: float, n: int = 60) -> float:
    """4 sigma of the pass's mean slope: a tilt eps across the face moves a point's slope by eps (1 + tan^2 dip)."""
    return 4 * ROLL_SD * (1 + np.tan(dip) ** 2) / np.sqrt(n)


@pytest.mark.parametrize("dip_deg", [-5.0, -1.0, 0.0, 0.5, 1.0, 5.0])
def test_advance_direction_follows_the_floor_square_to_the_face(dip_deg):
    """The advance direction rises by the floor's slope in the advance direction (from the points' attitude,
    whatever the machine's turn on the floor and the seam's dip along the face), horizontally square to the face
    line towards the coal: within 4 sigma of the points' tilt noise averaged over the pass."""
    dip = np.radians(dip_deg)
    points, _ = _floor_points(dip, ROLL_SD)
    adv = advance_direction(points)
    assert np.linalg.norm(adv) == pytest.approx(1.0, abs=1e-12)
    across = np.hypot(adv[0], adv[1])
    assert np.allclose(adv[:2] / across, COAL, atol=1e-9)
    assert abs(adv[2] / across - np.tan(dip)) < _slope_tolerance(dip), (adv[2] / across, np.tan(dip))


def test_a_level_face_is_advanced_horizontally():
    """A face on a floor level across it (dipping along it, the machine turned on it) is advanced exactly
    horizontally, square to the face line."""
    points, _ = _floor_points(0.0, 0.0)
    adv = advance_direction(points)
    assert adv[2] == pytest.approx(0.0, abs=1e-12)
    assert np.allclose(adv, np.append(COAL, 0.0), atol=1e-12)


@pytest.mark.parametrize("dip_deg", [-1.0, 0.0, 1.0, 5.0])
def test_predicted_fixes_follow_the_floor(dip_deg):
    """Each point moved by a 0.8 m ram stroke lands on the floor's plane (a horizontal move left it d tan(dip) off:
    14 mm at 1 deg): within d times the slope's tolerance, and 1 um for the linearised move in llh."""
    dip, d = np.radians(dip_deg), 0.8
    points, normal = _floor_points(dip, ROLL_SD)
    t = np.arange(0.0, 300.0, 1.0)
    supports = np.arange(-2.0, points.u[-1] + 3.0, 1.5)
    ext = [_ram(t, [(50, d)], 0.0, np.random.default_rng(0))] * supports.size
    rams = RamLog([t] * supports.size, ext, [np.ones(t.size)] * supports.size, supports, 1e-4)
    epochs = np.arange(points.u.size)
    j, llh, _, skipped, _ = predict_fixes(points, points.u, np.full(epochs.size, 299.0), epochs, points.u, rams,
                                          0.05, 0.01)
    assert j.size == points.u.size and skipped.size == 0
    before = earth.lla_to_enu(*points.llh.T, *ORIGIN)
    after = earth.lla_to_enu(*llh.T, *ORIGIN)
    off_plane = (after - before) @ normal  # the plane passes through every point
    assert np.all(np.abs(off_plane) < d * _slope_tolerance(dip) + 1e-6), np.abs(off_plane).max()
    assert np.allclose(np.linalg.norm(after - before, axis=1), d, atol=1e-6)


def test_points_at_another_spacing_are_interpolated_along_the_line():
    """cpoem.at_spacing: a line surveyed every 1.75 m (u descending, as a first cut run towards the start gives it)
    read every 2 m: positions on the chord between the neighbours, the nearer neighbour's attitude."""
    u = -np.arange(0.0, 35.0, 1.75)
    llh = np.column_stack([1e-7 * u, 2e-7 * u, 0.01 * u ** 2])
    frames = np.repeat(np.eye(3)[None], u.size, axis=0) * np.arange(1, u.size + 1)[:, None, None]
    cov = np.repeat(np.eye(3)[None], u.size, axis=0) * (1 - u)[:, None, None]
    pts = at_spacing(Points(u, 100.0 - u, llh, cov, frames, 1.75), 2.0)
    assert np.array_equal(pts.u, np.arange(-16, 1) * 2.0)
    assert np.allclose(pts.llh[:, :2], np.column_stack([1e-7 * pts.u, 2e-7 * pts.u]), rtol=0, atol=1e-18)
    at_2 = np.flatnonzero(pts.u == -2.0)[0]  # between -3.5 and -1.75
    assert np.isclose(pts.llh[at_2, 2], 0.1225 + 1.5 / 1.75 * (0.030625 - 0.1225))
    assert np.allclose(pts.t, 100.0 - pts.u) and np.allclose(pts.cov[:, 0, 0], 1 - pts.u)
    nearest = np.argmin(np.abs(u[None, :] - pts.u[:, None]), axis=1)
    assert np.array_equal(pts.c_nb, frames[nearest])
    assert pts.spacing == 2.0
    own = at_spacing(Points(u, 100.0 - u, llh, cov, frames, 1.75))  # at the survey's own step: its own points
    assert own.spacing == 1.75 and np.array_equal(own.llh, llh[::-1]) and np.array_equal(own.c_nb, frames[::-1])
