"""The MJCF pieces and the assembled MuJoCo models agree with the layout the rest of the twin assumes."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from tests.conftest import capped
from twin.face.layout import PAN_HEIGHT_M, PAN_WIDTH_M, Floor
from twin.face.model import (
    FloorBand,
    FloorGrid,
    build_face_spec,
    build_ride_spec,
    index_face_model,
    models_dir,
)
from twin.face.ride import simulate_ride


def test_pan_piece_matches_layout_constants():
    pan = mujoco.MjSpec.from_file(str(models_dir() / "pan.xml")).body("pan")
    feet = [g for g in pan.geoms if "foot" in g.name]
    assert len(feet) == 4
    for foot in feet:
        assert np.isclose(foot.pos[2] - foot.size[0], -PAN_HEIGHT_M)  # feet stand the running line on the floor
    trough = next(g for g in pan.geoms if g.name == "trough")
    assert np.isclose(2 * trough.size[0], PAN_WIDTH_M)


def test_full_face_model_has_the_flat_layout():
    scn = capped("default")
    rng = np.random.default_rng(0)
    n = scn.face.pan_count
    band = FloorBand.for_window(scn, Floor.from_scenario(scn, rng), n)
    model = build_face_spec(scn, band, 0, n, anchors=False).compile()
    index = index_face_model(model, scn, 0, n)
    # World, the floor, pans, supports and their canopies, and a coupler (a connector's play) per joint.
    assert model.nbody == 2 + 2 * n + n + n - 1
    assert all(model.body_parentid[model.body(f"pan{i}_pan").id] == 0 for i in range(n))  # no chain
    assert model.neq == n - 1  # a pin per joint
    assert model.ntendon == 3 * (n - 1) + n  # bend and roll limits per joint, a ram per support
    limits = model.tendon_range[[model.tendon(f"bend_yaw{i}").id for i in range(n - 1)]]
    np.testing.assert_allclose(limits[:, 1], np.radians(scn.face.bend_limit_horizontal_deg))
    assert index.ram_act.size == n and index.pan_qpos.shape == (n, 6)


def test_ride_model_steps_at_the_ride_rate_on_its_shoes():
    scn = capped("default")
    model = build_ride_spec(scn).compile()
    assert np.isclose(model.opt.timestep, 1 / scn.rates.ride_hz)
    shoes = [model.site(f"shoe_{s}").pos for s in ("rear", "front")]
    assert np.isclose(np.linalg.norm(shoes[1] - shoes[0]), scn.shearer.shoe_spacing_m)
    # simulate_ride steps it without the collision pass: none of its geoms may collide with anything.
    assert not model.geom_contype.any() and not model.geom_conaffinity.any()


def natural_frequency_and_damping(decay: np.ndarray, dt: float) -> tuple[float, float]:
    """Natural frequency [Hz] and damping ratio of a free second-order decay sampled every dt.

    Its samples obey x[k+1] = a x[k] + c x[k-1] (fitted by least squares), whose roots z of z^2 - a z - c are
    exp(s dt) for the decay's poles s: s1 s2 = w^2 and s1 + s2 = -2 zeta w.
    """
    (a, c), *_ = np.linalg.lstsq(np.column_stack([decay[1:-1], decay[:-2]]), decay[2:], rcond=None)
    s = np.log(np.roots([1.0, -a, -c]).astype(complex)) / dt
    w = np.sqrt((s[0] * s[1]).real)
    return w / (2 * np.pi), -(s[0] + s[1]).real / (2 * w)


@pytest.mark.parametrize("frequency_hz, damping_ratio, ride_hz", [
    (10.0, 1.0, 100.0),  # the default scenario's
    (10.0, 0.1, 100.0),
    (40.0, 0.3, 100.0),
    (3.0, 0.7, 250.0),
])
def test_ride_model_suspension_from_the_scenario(frequency_hz, damping_ratio, ride_hz):
    """After its target steps 0.5 mm up and 1 mrad about the face line (the size of the ride's deflections), the body
    (simulate_ride) rises and tilts after it as a suspension of the scenario's natural frequency and damping ratio."""
    scn = capped("default", shearer={"suspension_frequency_hz": frequency_hz,
                                     "suspension_damping_ratio": damping_ratio}, rates={"ride_hz": ride_hz})
    rise, tilt, steps = 5e-4, 1e-3, int(4 * ride_hz)
    target_pos, target_quat = np.zeros((steps, 3)), np.tile([1.0, 0.0, 0.0, 0.0], (steps, 1))
    target_pos[1:, 2] = rise
    target_quat[1:] = [np.cos(tilt / 2), 0.0, np.sin(tilt / 2), 0.0]
    pos, quat = simulate_ride(scn, target_pos, target_quat)
    for decay in (pos[:, 2] - rise, 2 * np.arctan2(quat[:, 2], quat[:, 0]) - tilt):
        frequency, damping = natural_frequency_and_damping(decay, 1 / ride_hz)
        assert frequency == pytest.approx(frequency_hz, rel=0.01)
        assert damping == pytest.approx(damping_ratio, rel=0.01)


def test_a_window_models_floor_does_not_grow_with_the_panel():
    """The height field is a band under the window (FloorBand), the same size on a 12 m and a 2 km panel; the
    recording's floor mesh covers the run's face at most MESH_MAX_CELLS cells."""
    from twin.face.layout import MESH_MAX_CELLS

    short = capped("seed004")
    long = short.model_validate(short.model_dump() | {"cycles": 2000, "face": short.face.model_dump() | {
        "panel_length_m": 2000.0}})
    floor = Floor.from_scenario(short, np.random.default_rng(0))
    assert FloorBand.for_window(short, floor, 40) == FloorBand.for_window(long, floor, 40)
    grid = FloorGrid.from_scenario(long, floor)
    assert grid.z.size <= MESH_MAX_CELLS * 1.01 and grid.x[-1] >= 2000.0


def test_the_floor_band_follows_the_window_and_the_advance():
    """Placed under a window of advanced pans in the middle of the face, the height field holds the floor's heights
    on the lattice and covers the window's pans and supports."""
    from twin.face.layout import initial_pans
    from twin.face.simulator import SKID_OFFSET_X_M, FaceSimulator
    from twin.pipeline.simulate import window_sizes

    scn = capped("default")
    floor = Floor.from_scenario(scn, np.random.default_rng(3))
    sim = FaceSimulator(scn, floor, window_sizes(scn))
    state = sim.initial_supports(initial_pans(scn, floor, np.random.default_rng(4)))
    state.pans[:, 0] += 7.3  # the face seven webs on
    state.sup_x += 7.3
    win = sim.windows[0]
    first = 10
    pans, sups = sim._load(win, state, first)
    m = win.model
    hf = m.hfield("floor")
    nrow, ncol = int(m.hfield_nrow[hf.id]), int(m.hfield_ncol[hf.id])
    heights = m.hfield_data[m.hfield_adr[hf.id]:m.hfield_adr[hf.id] + nrow * ncol].reshape(nrow, ncol)
    centre_f = sim.frame.mat_tf.T @ win.data.mocap_pos[m.body_mocapid[m.body("floor").id]]
    half_x, half_y, elevation = m.hfield_size[hf.id, :3]
    x = centre_f[0] - half_x + np.arange(ncol) * 2 * half_x / (ncol - 1)
    y = centre_f[1] - half_y + np.arange(nrow) * 2 * half_y / (nrow - 1)
    np.testing.assert_allclose(centre_f[2] + heights * elevation, floor.height(x[None, :], y[:, None]), atol=1e-5)
    assert heights.min() >= 0.0 and heights.max() <= 1.0
    assert x[0] < state.sup_x[sups].min() + SKID_OFFSET_X_M - 1.0 and x[-1] > state.pans[pans, 0].max() + 2.0
    assert y[0] < first * scn.face.pan_length_m and y[-1] > (first + win.count) * scn.face.pan_length_m
    lattice = (x - win.band.origin_f[0]) / 0.25
    np.testing.assert_allclose(lattice, np.round(lattice), atol=1e-9)  # on the one lattice
