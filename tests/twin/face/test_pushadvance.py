"""Push-advance controller and haulage timeline, without physics."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import capped
from twin.face import snake
from twin.face.haulage import CUTTING, RETURN, Leg, Timeline, run_profile
from twin.face.pushadvance import PushAdvanceController


def test_snake_bends_stay_within_their_share_of_the_limit():
    scn = capped("default")
    step = np.radians(scn.face.bend_limit_horizontal_deg) * snake.BEND_FRACTION
    offsets = snake.joint_offsets(scn.pattern.snake_length_pans, scn.face.pan_length_m, step)
    yaw = np.arcsin(np.diff(offsets) / scn.face.pan_length_m)
    assert np.abs(np.diff(yaw)).max() <= step + 1e-12
    assert offsets[-1] >= scn.face.web_depth_m


def test_pushes_trail_the_shearer_and_supports_follow():
    scn = capped("default")
    ctrl = PushAdvanceController(scn)
    ctrl.begin_cycle(+1)
    length, lag = scn.face.pan_length_m, scn.pattern.push_lag_pans
    s_trail = 20 * length
    targets, advancing = ctrl.update(s_trail)
    pans = ctrl.pan_target
    # Nothing ahead of the snake head (lag pans behind the trailing end) moves; far behind, a full web.
    assert np.all(pans[int(s_trail / length) - lag:] == 0.0)
    assert np.all(pans[: int(s_trail / length) - lag - scn.pattern.snake_length_pans] == scn.face.web_depth_m)
    assert np.all(np.diff(pans[: int(s_trail / length)]) <= 1e-12)  # monotone S towards the shearer
    assert np.all(ctrl.sup_target[advancing] == scn.face.web_depth_m)
    # The end push completes every pan and support.
    ctrl.update(None)
    assert np.all(ctrl.pan_target == scn.face.web_depth_m) and np.all(ctrl.sup_target == scn.face.web_depth_m)


def test_per_support_offsets_add_to_the_push():
    scn = capped("default")
    ctrl = PushAdvanceController(scn)
    offsets = np.linspace(-0.05, 0.05, ctrl.stations.size)
    ctrl.begin_cycle(+1, offsets)
    ctrl.update(None)
    np.testing.assert_allclose(ctrl.pan_target[ctrl.stations], scn.face.web_depth_m + offsets)
    ctrl.begin_cycle(-1)
    ctrl.update(None)
    np.testing.assert_allclose(ctrl.pan_target[ctrl.stations], 2 * scn.face.web_depth_m + offsets)
    with pytest.raises(ValueError, match="offsets"):
        ctrl.begin_cycle(+1, offsets[:-1])


def test_rest_to_rest_profile_respects_speed_and_acceleration():
    t, x, v, phase = run_profile([Leg(5.0, 0.3, RETURN), Leg(20.0, 0.1, CUTTING)], accel=0.05)
    assert v[0] == 0.0 and v[-1] == 0.0 and np.isclose(x[-1], 25.0)
    assert v.max() <= 0.3 + 1e-12
    accel = np.diff(v ** 2) / (2 * np.diff(x))
    assert np.abs(accel).max() <= 0.05 + 1e-9
    assert set(np.unique(phase)) == {RETURN, CUTTING}


def test_timeline_samples_are_continuous_and_reach_both_ends():
    scn = capped("default")
    tl = Timeline(scn)
    t = np.arange(0.0, tl.duration, 0.05)
    out = tl.sample(t)
    assert np.abs(np.diff(out["s"])).max() <= 0.05 * max(scn.haulage.return_speed_m_min, 1) / 60 + 1e-9
    assert np.isclose(out["s"].min(), tl.s_min) and np.isclose(out["s"].max(), tl.s_max, atol=1e-6)
    np.testing.assert_allclose(np.gradient(out["s"], t)[1:-1], out["ds"][1:-1], atol=3e-3)
