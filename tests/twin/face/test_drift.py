"""A face that drifts (issue 25 item 5): stroke-controlled push errors that add up, creep down the seam dip, and
the per-support offsets of face alignment from the scenario and the Python API."""

from __future__ import annotations

import re
from functools import cache

import numpy as np
import pytest

from estimators.face.straightness import face_drift
from tests.conftest import capped
from twin.config.scenario import ScenarioError, support_count
from twin.face.drift import StrokeControl
from twin.face.pushadvance import PushAdvanceController
from twin.pipeline.simulate import simulate
from twin.view.summary import latest_per_id

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

STOP_NOISE_M = 0.01
OFFSET_TOLERANCE_M = 3e-3
"""A pan's extra advance against its support's offset: the push errors the stroke control keeps (floor, neighbours'
pulls: up to 2.4 mm measured on the default face in a cycle)."""


def test_stroke_errors_walk_as_the_square_root_of_the_cycles():
    """Kinematics of StrokeControl alone (no MuJoCo): a pan lands where its ram's goal puts it from its support, the
    support closes its ram to its advance goal behind the pan. Each push's stop error stays, so the pans' advance
    errors are a random walk: spread sigma sqrt(k) after k cycles, mean k times the overtravel."""
    scn = capped("default", face={"pan_count": 400}, supports={"push": {"stop_noise_m": STOP_NOISE_M,
                                                                          "stop_overtravel_m": 0.001}})
    ctrl = PushAdvanceController(scn)
    rest = np.full(ctrl.stations.size, scn.supports.ram_length_set_m)
    strokes = StrokeControl(scn, rest)
    sup_x = np.zeros(rest.size)
    spread = {}
    for k in range(1, 17):
        ctrl.begin_cycle(1 if k % 2 else -1)
        before = ctrl.sup_target.copy()
        pan_target, advancing = ctrl.update(None)
        push, _, _ = strokes.goals(rest, pan_target, before, ctrl.sup_target, np.ones(rest.size, bool))
        pan_x = sup_x + push  # pushed: the rams at their goals
        _, advance, _ = strokes.goals(push, pan_target, before, ctrl.sup_target, np.zeros(rest.size, bool))
        sup_x = pan_x - advance  # advanced: the rams closed
        error = pan_x - rest - k * scn.face.web_depth_m
        spread[k] = error.std()
        assert abs(error.mean() - k * 0.001) < 4 * STOP_NOISE_M * np.sqrt(k / error.size)
    assert spread[16] / spread[4] == pytest.approx(2.0, rel=0.12)
    assert spread[16] == pytest.approx(4 * STOP_NOISE_M, rel=0.12)


@cache
def _run(dip_deg: float = 1.5, noise_m: float = 0.0, offsets: tuple = (), api: bool = False):
    push = {"stop_noise_m": noise_m}
    if offsets and not api:
        push["offsets"] = [{"cycle": 0, "offsets_m": list(offsets)}]
    scn = capped("default", cycles=1, face={"seam_dip_deg": dip_deg}, supports={"push": push})
    source = (lambda cycle, pans: np.array(offsets)) if api else None
    res = simulate(scn, offsets=source)
    return scn, res


def _advance(scn, res, pans: dict | None = None) -> np.ndarray:
    """Every pan's advance at the end of the run (from `pans`, a truth_pans table, instead of the result's)."""
    pans = res.tables["truth_pans"] if pans is None else pans
    t_end = res.tables["truth_cycles"]["t_end"][-1]
    return pans["advance"][latest_per_id(pans["t"], pans["pan"], scn.face.pan_count, t_end)]


def _profile() -> tuple:
    n = support_count(capped("default"))
    return tuple(0.05 * np.sin(np.pi * np.arange(n) / (n - 1)))


def test_offsets_from_the_scenario_and_the_api_push_the_pans_further():
    """A smooth 5 cm offset profile in cycle 0: each pan advances by its support's offset more than without, from the
    scenario's offsets and from an API source alike, and both runs' truth is the same."""
    scn, base = _run()
    _, given = _run(offsets=_profile())
    _, called = _run(offsets=_profile(), api=True)
    extra = _advance(scn, given) - _advance(scn, base)
    np.testing.assert_allclose(extra, _profile(), atol=OFFSET_TOLERANCE_M)
    np.testing.assert_array_equal(_advance(scn, called), _advance(scn, given))
    np.testing.assert_array_equal(given.offsets, called.offsets)
    np.testing.assert_allclose(given.offsets, [_profile()])


def test_creep_goes_down_the_seam_dip():
    """The pans slide along the face during their pushes and the supports follow them: a 5 deg seam rising towards
    the tailgate creeps the face towards the headgate, the same seam falling creeps it towards the tailgate (1 cycle:
    -32 and +65 mm measured; their mean, +17 mm, is the snake's pull towards the first cut, as on a flat seam)."""
    creep = {}
    for dip in (5.0, -5.0):
        scn, res = _run(dip_deg=dip)
        cycles = res.tables["truth_cycles"]
        creep[dip] = face_drift(res.tables["truth_pans"], cycles["t_end"], scn.face.pan_count,
                                np.radians(scn.face.azimuth_deg)).creep[-1]
    assert creep[5.0] < -0.015 and creep[-5.0] > 0.015


def test_creep_on_a_flat_seam_does_not_depend_on_the_azimuth():
    """A flat seam has no downhill: the snake pulls the face along towards the cut and back on the return pass,
    the same at any azimuth. Against MuJoCo's pyramidal friction cones (edges along the world axes) the default face
    at azimuth 30 deg crept 26 mm towards the headgate in one cycle and 78 in two, against 5 and 7 mm the other way at
    azimuth 0; with the elliptic cones of twin.face.model, 4 then 1 mm at azimuth 30, 3 then 2 at azimuth 0."""
    creep = {}
    for azimuth in (0.0, 30.0):
        scn = capped("default", cycles=2, face={"seam_dip_deg": 0.0, "advance_dip_deg": 0.0, "azimuth_deg": azimuth})
        res = simulate(scn)
        creep[azimuth] = face_drift(res.tables["truth_pans"], res.tables["truth_cycles"]["t_end"],
                                    scn.face.pan_count, np.radians(azimuth)).creep
    np.testing.assert_allclose(creep[30.0], creep[0.0], atol=0.01)
    assert np.abs(creep[30.0][-1]) < 0.015


def test_the_supports_follow_their_pans_along_the_face():
    """On the 5 deg seam the pans creep up to 7 cm in a cycle and their supports with them: each keeps its place
    beside its pan's centre (the pan's ram point, 20 cm below its tilted running line) within 2 cm (19 mm measured)."""
    scn, res = _run(dip_deg=5.0)
    sups, pans = res.tables["truth_supports"], res.tables["truth_pans"]
    t_end = res.tables["truth_cycles"]["t_end"][-1]
    n_sup = support_count(scn)
    sup = latest_per_id(sups["t"], sups["support"], n_sup, t_end)
    pan = latest_per_id(pans["t"], pans["pan"], scn.face.pan_count, t_end)
    along = np.array([np.sin(np.radians(scn.face.azimuth_deg)), np.cos(np.radians(scn.face.azimuth_deg))])
    y_sup = np.column_stack([sups["p_t_e"][sup], sups["p_t_n"][sup]]) @ along
    y_pan = np.column_stack([pans["p_t_e"][pan], pans["p_t_n"][pan]]) @ along
    y_pan0 = np.column_stack([pans["p_t_e"][pans["t"] == 0.0], pans["p_t_n"][pans["t"] == 0.0]]) @ along
    y_sup0 = np.column_stack([sups["p_t_e"][sups["t"] == 0.0], sups["p_t_n"][sups["t"] == 0.0]]) @ along
    stations = np.arange(n_sup) * scn.supports.pans_per_support
    assert np.abs(y_pan - y_pan0).max() > 0.05
    assert np.abs((y_sup - y_pan[stations]) - (y_sup0 - y_pan0[stations])).max() < 0.025


@pytest.mark.parametrize("offsets, words", [
    ([0.0] * 43, "43 values, need one per support (44)"),
    ([0.0] * 20 + [0.6] + [0.0] * 23, "support 20: 0.6 m is more than 0.5 of the 0.8 m web"),
    ([0.0] * 20 + [0.03] + [0.0] * 23, "support 20 bends the face line"),
])
def test_offsets_a_face_cannot_push_are_refused_in_one_line(offsets, words):
    with pytest.raises(ScenarioError) as err:
        capped("default", supports={"push": {"offsets": [{"cycle": 1, "offsets_m": offsets}]}})
    assert str(err.value).startswith("default: supports.push.offsets[0].offsets_m: ") and words in str(err.value)
    assert "\n" not in str(err.value)
    with pytest.raises(ScenarioError, match="cycle 2 is not a cycle of the run"):
        capped("default", supports={"push": {"offsets": [{"cycle": 2, "offsets_m": [0.0] * 44}]}})
    scn = capped("default", cycles=1)
    with pytest.raises(ValueError, match=re.escape(words)):
        simulate(scn, offsets=lambda cycle, pans: np.array(offsets))


def test_twin_run_takes_the_offsets_of_the_api(tmp_path):
    """twin.run passes its `offsets` source to the face: its truth_pans are those of simulate with the same source."""
    import pyarrow.parquet as pq

    import twin

    scn, called = _run(offsets=_profile(), api=True)
    seen = []
    run = twin.run(scn, tmp_path / "run", sensors=False, offsets=lambda cycle, pans: seen.append(cycle) or
                   np.array(_profile()))
    written = {k: np.asarray(v) for k, v in pq.read_table(run.dir / "truth_pans.parquet").to_pydict().items()}
    assert seen == [0]
    np.testing.assert_array_equal(_advance(scn, called, written), _advance(scn, called))
