"""Push-advance controller and haulage timeline, without physics."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import capped
from twin.config.scenario import ScenarioError
from twin.face import snake
from twin.face.haulage import CUTTING, RETURN, Leg, Timeline, run_profile
from twin.face.layout import INITIAL_BEND_FRACTION
from twin.face.pushadvance import PushAdvanceController


def joints_from_pans(advance: np.ndarray) -> np.ndarray:
    """Advance of the joints of a chain of pans whose centres advance by `advance`, its first pan straight."""
    joints = np.empty(advance.size + 1)
    joints[0] = advance[0]
    for i, centre in enumerate(advance):
        joints[i + 1] = 2 * centre - joints[i]
    return joints


@pytest.mark.parametrize("direction", [+1, -1])
def test_snake_bends_stay_within_their_share_of_the_limit(direction):
    """At the largest web the validator accepts, the pans the controller pushes mid-cut bend by at most the limit
    less the initial face's share (twin.face.layout.INITIAL_BEND_FRACTION), and by all of it at the steepest joint,
    and the snake takes up the web: each pan's yaw from the advance of its two joints over its length."""
    base = capped("default")
    length, limit = base.face.pan_length_m, np.radians(base.face.bend_limit_horizontal_deg)
    web = snake.capacity_m(base.pattern.snake_length_pans, length, limit)
    with pytest.raises(ScenarioError, match="snake_length_pans"):
        capped("default", face={"web_depth_m": web + 1e-3})
    ctrl = PushAdvanceController(capped("default", face={"web_depth_m": web}))
    ctrl.begin_cycle(direction)
    ctrl.update((30 if direction > 0 else 14) * length)  # the snake mid-face, both its ends straight
    joints = joints_from_pans(ctrl.pan_target)
    bends = np.abs(np.diff(np.arcsin(np.diff(joints) / length)))
    share = (1 - INITIAL_BEND_FRACTION) * limit
    assert share * (1 - 1e-9) <= bends.max() <= share * (1 + 1e-9)
    np.testing.assert_allclose(sorted([joints[0], joints[-1]]), [0.0, web], atol=1e-12)  # unpushed ahead, a web behind


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


def test_timeline_holds_legs_not_grids_and_samples_as_the_grid_does():
    """A panel_100 timeline (100 cycles of a 360 m face) holds each segment's legs, not its 2 mm speed grid (5 MB a
    cut): pickled it stays small whatever the number of cycles. Sampling makes the grid again where it is read, so s
    and its phase at a time equal run_profile's grid interpolated there."""
    import pickle

    from tests.conftest import SCENARIO_DIR
    from twin.config.scenario import load_scenario

    scn = load_scenario(SCENARIO_DIR / "panel_100.toml")
    tl = Timeline(scn)
    assert len(tl.cycles) == 100 and len(pickle.dumps(tl.segments)) < 1_000_000
    seg = next(s for s in tl.segments if s.legs and s.cycle == 7)
    t_g, x_g, _, phase_g = run_profile(list(seg.legs), seg.accel)
    out = tl.sample(seg.t0 + t_g[1:-1:997])
    np.testing.assert_allclose(out["s"], seg.s0 + seg.direction * x_g[1:-1:997], rtol=0, atol=1e-9)
    assert np.array_equal(out["phase"], phase_g[1:-1:997]) and set(out["cycle"]) == {7}
