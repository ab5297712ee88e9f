"""twin.view.estimate_recording without truth (a real face's log, no run.rrd beside it): every series that needs no
truth, no errors, the world's axes and the scenario's recording id; `longwall view` opens it alone."""

from __future__ import annotations

import numpy as np
import pytest
from rerun.chunk import RrdReader

from estimators.io.logformat import (
    ESTIMATE_DETECTORS,
    ESTIMATE_FUSION,
    ESTIMATE_STATES,
    make_table,
)
from estimators.nav import earth
from estimators.nav.rotations import euler_to_quat
from tests.conftest import SCENARIO_DIR
from tests.estimators.io.test_metrics import estimate_table
from tests.twin.view.test_estimate_recording import D_POS, _scalars
from twin.config.scenario import load_scenario
from twin.view.estimate_recording import write_estimate_recording
from twin.view.recording import ESTIMATES_RRD
from twin.view.rrd_stream import recording_id

SIGMA = 0.05


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """An estimate walking 0.1 m/s along the face for 300 s at 20 Hz, with states, fusion and detectors."""
    scn = load_scenario(SCENARIO_DIR / "default.toml")
    site = scn.site
    t = np.arange(0.0, 300.0, 0.05)
    k = t.size
    lat, lon, h = earth.enu_to_lla(np.column_stack([0.05 * t, 0.1 * t, np.zeros(k)]), np.radians(site.lat_deg),
                                   np.radians(site.lon_deg), site.height_m)
    est = estimate_table(t, lat, lon, h, euler_to_quat(np.zeros(k), np.zeros(k), np.full(k, 0.5)), sd=SIGMA)
    states = make_table(ESTIMATE_STATES, {"t": t, **{c.name: np.full(k, 1e-5) for c in ESTIMATE_STATES.columns[1:]}})
    fusion = make_table(ESTIMATE_FUSION, {
        "t": t, "beta_odometer": np.full(k, 0.3), "beta_aiding": np.full(k, 0.7), "r_yaw": np.full(k, 1e-4),
        "yaw_innovation": np.full(k, 1e-3), "mag_flags": np.zeros(k, np.int32),
        **{f"{sub}_d_pos_{a}": np.full(k, D_POS[sub]) for sub in D_POS for a in "enu"},
        **{f"{sub}_d_yaw": np.zeros(k) for sub in D_POS}})
    rows = slice(0, k, 200)
    det = make_table(ESTIMATE_DETECTORS, {"t": t[rows], "lat": lat[rows], "lon": lon[rows], "h": h[rows],
                                          **{s: np.ones(t[rows].size) for s in ("residual", "dual_state", "fsprt")},
                                          "applied": np.ones(t[rows].size, np.int32),
                                          "isolated": np.zeros(t[rows].size, np.int32)})
    path = tmp_path_factory.mktemp("no_truth") / ESTIMATES_RRD
    write_estimate_recording(path, scn, None, {"kf": est}, {"kf": states}, None, fusion={"kf": fusion},
                             detectors={"kf": (det, {"residual": 16.3, "dual_state": 16.3, "t_on": 12.0,
                                                     "t_off": 5.0})})
    return scn, path


def test_everything_but_the_errors(recorded):
    scn, path = recorded
    recording = RrdReader(path).recordings()[0]
    assert recording.recording_id == recording_id(scn)
    chunks = RrdReader(path).stream().to_chunks()
    entities = {c.entity_path for c in chunks}
    assert {"/world", "/world/estimates/kf/path", "/world/estimates/kf/position", "/plots/flags/kf",
            "/plots/sigma/kf/position/east", "/plots/sigma/kf/attitude/u", "/plots/states/kf/odo_scale",
            "/plots/fusion/kf/beta", "/plots/detectors/kf/fsprt", "/world/estimates/kf/rail"} <= entities
    assert not any(e.startswith(("/plots/errors", "/plots/attitude_errors")) for e in entities)
    _, sd = _scalars(chunks, "/plots/sigma/kf/position/north")
    np.testing.assert_allclose(sd, np.broadcast_to([SIGMA, -SIGMA], sd.shape))
    _, states = _scalars(chunks, "/plots/states/kf/odo_scale")
    assert states.shape[1] == 1  # no true value drawn beside the estimate


def test_subfilters_are_drawn_as_offsets_from_the_global_estimate(recorded):
    chunks = RrdReader(recorded[1]).stream().to_chunks()
    for axis in ("east", "north"):
        _, offsets = _scalars(chunks, f"/plots/fusion/kf/subfilter_errors/{axis}")
        np.testing.assert_allclose(offsets, np.broadcast_to([0.0, D_POS["odometer"], D_POS["aiding"]],
                                                            offsets.shape))


def test_view_opens_the_estimates_alone(recorded, viewer_launches):
    from twin.view import layout

    layout.open_viewer(recorded[1].parent)
    [args] = viewer_launches
    assert args[:2] == ["/usr/bin/rerun", str(recorded[1])] and args[2].endswith(".rbl")
