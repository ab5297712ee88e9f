"""The face alignment system on paths made here (not by the twin): the face line in closed form, the offsets against
an independent solve and the face's limits, the target line's turn, the start gate's end zone, the carried
deviation, and the held offsets of a shear that cannot steer."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimators.face.alignment import AlignmentConfig, FaceAlignmentSystem, path_at_shields, rail_line, solve_offsets
from tests.conftest import capped
from twin.config.push import check_offsets, offset_limits
from twin.config.scenario import support_count
from twin.pipeline.alignment_loop import alignment_config

SPACING_M = 1.75
N_SHIELDS = 120


def _cfg(**over) -> AlignmentConfig:
    base = dict(station_y_m=(np.arange(N_SHIELDS) + 0.5) * SPACING_M, spacing_m=SPACING_M, azimuth_rad=0.3,
                max_offset_m=0.4, max_extra_push_m=0.3, curvature_limit_rad=math.radians(0.25), gain=0.7,
                smoothing_shields=3.0, planned_slope=None, max_turn_rad=math.radians(0.05), min_coverage=0.8,
                end_zone_m=0.0)
    return AlignmentConfig(**{**base, **over})


def _path(x_of_y, y0: float = -5.0, y1: float = N_SHIELDS * SPACING_M + 5.0, step: float = 0.01) -> np.ndarray:
    """A straight cut from y0 to y1 in F: points every `step` along the face at x(y), z 0."""
    y = np.arange(y0, y1, step) if y1 > y0 else np.arange(y0, y1, -step)
    return np.column_stack([x_of_y(y), y, np.zeros_like(y)])


def test_the_path_at_a_shield_is_its_mean_over_the_shields_share():
    """The mean of A sin(k y) over [y_j - h, y_j + h] is A sin(k y_j) sin(k h) / (k h); of a line, its centre value."""
    amp, k, slope = 0.05, 2 * np.pi / 23.0, 0.004
    p_f = _path(lambda y: amp * np.sin(k * y) + slope * y, step=1e-4)
    y_st = _cfg().station_y_m
    line, sd = path_at_shields(p_f, np.full(p_f.shape[0], 0.02), y_st, SPACING_M)
    h = SPACING_M / 2
    np.testing.assert_allclose(line, amp * np.sin(k * y_st) * np.sin(k * h) / (k * h) + slope * y_st, atol=2e-6)
    np.testing.assert_allclose(sd, 0.02)


def test_the_line_under_a_two_shoe_machine_is_recovered_from_its_path():
    """A pan line with independent shield errors (5 mm) and the body path of a machine on two shoes 7 m apart (the
    mean of the line at its shoes, evaluated here with np.interp): the path itself does not correlate with the line;
    the solved line does (0.86 measured; the two-shoe mean is blind at wavelengths 14 m / (2m + 1), which white errors
    fill too), its error under 60 % of the line's spread."""
    rng = np.random.default_rng(5)
    y_st = _cfg().station_y_m
    line = 0.005 * rng.standard_normal(y_st.size)
    a = 3.5
    y = np.arange(y_st[0] + a, y_st[-1] - a, 0.01)
    path = np.column_stack([0.5 * (np.interp(y - a, y_st, line) + np.interp(y + a, y_st, line)), y, 0 * y])
    p_st, _ = path_at_shields(path, np.zeros(y.size), y_st, SPACING_M)
    rows = np.isfinite(p_st)
    solved = rail_line(p_st, rows, y_st, 2 * a)
    inner = rows & (y_st > y_st[0] + 2 * a) & (y_st < y_st[-1] - 2 * a)
    assert abs(np.corrcoef(p_st[inner], line[inner])[0, 1]) < 0.3
    assert np.corrcoef(solved[inner], line[inner])[0, 1] > 0.8
    assert np.std(solved[inner] - line[inner]) < 0.6 * np.std(line[inner])


def test_an_inertial_path_is_the_line_under_the_machines_heading():
    """An inertial estimate's path integrates the machine's heading, the chord between its shoes (here by a running sum
    of the chord's slope on a 1 cm grid, not the kernel's mean): read with the heading model it gives back the line (a
    10 m and a 45 m wave, 16 mm RMS) within 15 % (2.0 mm: the shields' shares average the path); read as a two-shoe mean the 10 m wave comes back turned over (the two
    kernels' signs differ between wavelengths 7 and 14 m), which the loop would steer further out."""
    y_st = _cfg().station_y_m
    short, long_ = 0.010 * np.sin(2 * np.pi * y_st / 10.0), 0.020 * np.sin(2 * np.pi * y_st / 45.0)
    line, a = short + long_, 3.5
    y = np.arange(y_st[0] + a, y_st[-1] - a, 0.01)
    chord = (np.interp(y + a, y_st, line) - np.interp(y - a, y_st, line)) / (2 * a)
    x = np.concatenate([[0.0], np.cumsum(0.5 * (chord[1:] + chord[:-1]) * np.diff(y))])
    x += np.mean(line[(y_st > y[0] + a) & (y_st < y[0] + 3 * a)]) - x[0]  # any constant: the target takes it out
    p_st, _ = path_at_shields(np.column_stack([x, y, 0 * y]), np.zeros(y.size), y_st, SPACING_M)
    rows = np.isfinite(p_st)
    inner = rows & (y_st > y_st[0] + 2 * a) & (y_st < y_st[-1] - 2 * a)

    def about_line(v):
        return v[inner] - np.polyval(np.polyfit(y_st[inner], v[inner], 1), y_st[inner])

    heading = rail_line(p_st, rows, y_st, 2 * a, "heading")
    assert np.sqrt(np.mean((about_line(heading) - about_line(line)) ** 2)) < 0.15 * np.std(about_line(line))
    shoes = rail_line(p_st, rows, y_st, 2 * a, "shoes")
    assert np.corrcoef(about_line(shoes - long_), short[inner])[0, 1] < -0.5


def test_offsets_within_the_limits_are_the_smoothing_solve():
    """With no bound active the offsets are argmin |o - d|^2 + lambda |D2 o|^2: (I + lambda D2'D2) o = d, solved here
    directly (not through the double running sum)."""
    cfg = _cfg()
    y = cfg.station_y_m
    wanted = 0.02 * np.sin(2 * np.pi * y / 60.0) + 0.01 * np.cos(2 * np.pi * y / 35.0)
    d2 = np.diff(np.eye(y.size), 2, axis=0)
    direct = np.linalg.solve(np.eye(y.size) + cfg.smoothing_shields ** 4 * d2.T @ d2, wanted)
    assert np.abs(np.diff(direct, 2)).max() < 0.9 * cfg.curvature_limit_rad * SPACING_M
    np.testing.assert_allclose(solve_offsets(wanted, cfg), direct, atol=1e-9)


def test_offsets_keep_within_the_faces_stroke_and_bend_limits():
    """A face line with a 0.25 m step and a 0.6 m kink: the wanted correction itself breaks the twin's offset checks
    (twin.config.push.check_offsets); the offsets pass them on the default face's figures."""
    scn = capped("default", face={"pan_count": 120})
    cfg = alignment_config(scn)
    n = support_count(scn)
    y = cfg.station_y_m
    wanted = np.where(y > y[n // 2], 0.25, 0.0) - 0.6 * np.exp(-(((y - y[30]) / 3.0) ** 2))
    with pytest.raises(ValueError):
        check_offsets(wanted, n, **offset_limits(scn))
    offsets = solve_offsets(wanted, cfg)
    check_offsets(offsets, n, **offset_limits(scn))
    assert np.abs(offsets).max() > 0.5 * 0.25  # it still corrects


def test_a_straight_face_gets_no_offsets_and_a_square_target_turns_it_slowly():
    """A straight face at 1 in 100 to F's y axis: kept straight, every offset is nil; squared, the target line turns
    by max_turn per shear, and the offsets are the gain times that turn's ramp (a line: the smoothing leaves it)."""
    slope = 0.01
    p_f = _path(lambda y: 0.3 + slope * y)
    sd = np.zeros(p_f.shape[0])
    straight = FaceAlignmentSystem(_cfg()).shear(p_f, sd)
    np.testing.assert_allclose(straight.offsets_m, 0.0, atol=1e-9)
    cfg = _cfg(planned_slope=0.0)
    square = FaceAlignmentSystem(cfg).shear(p_f, sd)
    y = cfg.station_y_m
    ramp = -cfg.gain * np.tan(cfg.max_turn_rad) * (y - y.mean())
    np.testing.assert_allclose(square.offsets_m, ramp, atol=1e-9)
    assert square.sequence == 1 and not square.held


def test_the_start_gates_end_zone_is_left_out():
    """The pans at the gate a cut starts from were pushed a web in the last sump: a web-high bump there changes
    nothing; the same bump at the far gate is corrected."""
    zone = 30.0
    cfg = _cfg(end_zone_m=zone)
    wave = lambda y: 0.02 * np.sin(2 * np.pi * y / 50.0)  # noqa: E731
    sd = lambda p: np.zeros(p.shape[0])  # noqa: E731
    plain = FaceAlignmentSystem(cfg).shear(p := _path(wave), sd(p))
    start = _path(lambda y: wave(y) + np.where(y < zone - 8.0, 0.8, 0.0))
    bumped = FaceAlignmentSystem(cfg).shear(start, sd(start))
    np.testing.assert_allclose(bumped.offsets_m, plain.offsets_m, atol=1e-12)
    y_end = N_SHIELDS * SPACING_M
    far = _path(lambda y: wave(y) + np.where(y > y_end - 20.0, 0.1, 0.0))
    assert np.abs(FaceAlignmentSystem(cfg).shear(far, sd(far)).offsets_m - plain.offsets_m).max() > 0.03


def test_a_deviation_not_measured_again_is_carried_less_what_was_corrected():
    """Shear 1 measures the whole face; shear 2 starts from the other gate, its end zone there unmeasured: the
    deviation there is shear 1's times (1 - gain)."""
    zone = 40.0
    cfg = _cfg(end_zone_m=zone)
    system = FaceAlignmentSystem(cfg)
    wave = lambda y: 0.03 * np.sin(2 * np.pi * y / 45.0)  # noqa: E731
    first = _path(wave)
    system.shear(first, np.zeros(first.shape[0]))
    dev1 = system.deviation.copy()
    back = _path(wave, y0=N_SHIELDS * SPACING_M + 5.0, y1=-5.0)
    system.shear(back, np.zeros(back.shape[0]))
    y0 = back[0, 1]
    zone_st = np.abs(cfg.station_y_m - y0) <= zone
    np.testing.assert_allclose(system.deviation[zone_st], (1 - cfg.gain) * dev1[zone_st], atol=1e-12)
    assert system.last.sequence == 2


def test_a_lost_estimator_or_a_partial_shear_does_not_steer():
    """The health monitor raised, or the path covers a third of the face: the last good offsets and their sequence
    number stand, with a note saying why."""
    system = FaceAlignmentSystem(_cfg())
    wave = lambda y: 0.03 * np.sin(2 * np.pi * y / 45.0)  # noqa: E731
    good = system.shear(p := _path(wave), np.zeros(p.shape[0]))
    lost = system.shear(_path(lambda y: 10.0 * y), np.zeros(p.shape[0]), healthy=False, label="shear 1")
    assert lost.held and lost.sequence == good.sequence == 1
    np.testing.assert_array_equal(lost.offsets_m, good.offsets_m)
    assert "lost track" in lost.note and "sequence 1 held" in lost.note
    part = _path(wave, y1=N_SHIELDS * SPACING_M / 3)
    held = system.shear(part, np.zeros(part.shape[0]))
    assert held.held and held.sequence == 1 and "not a full shear" in held.note


def test_the_shields_are_found_where_the_face_has_crept_to():
    """The face and its shields have crept 2 spacings towards the headgate, and the path's ends with them (a cut
    runs between the reversal points the drive frames carry): the creep is measured at the gates and a bump in the
    line at shield 40 is corrected at shield 40, not at the shield that stood there when the face was installed."""
    y_end = N_SHIELDS * SPACING_M
    cfg = _cfg(path_ends_m=(-5.0, y_end + 5.0))
    creep = -2 * SPACING_M
    bump_y = cfg.station_y_m[40] + creep
    p_f = _path(lambda y: 0.02 * np.exp(-(((y - bump_y) / 1.0) ** 2)), y0=-5.0 + creep, y1=y_end + 5.0 + creep)
    out = FaceAlignmentSystem(cfg).shear(p_f, np.zeros(p_f.shape[0]))
    assert out.creep_m == pytest.approx(creep, abs=0.02)
    assert int(np.argmin(out.offsets_m)) == 40
    unregistered = FaceAlignmentSystem(_cfg()).shear(p_f, np.zeros(p_f.shape[0]))
    assert int(np.argmin(unregistered.offsets_m)) == 38
