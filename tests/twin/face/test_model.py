"""The MJCF pieces and the assembled MuJoCo models agree with the layout the rest of the twin assumes."""

from __future__ import annotations

import mujoco
import numpy as np

from tests.conftest import capped
from twin.face.layout import PAN_HEIGHT_M, PAN_WIDTH_M, Floor
from twin.face.model import (
    FloorGrid,
    build_face_spec,
    build_ride_spec,
    index_face_model,
    models_dir,
)


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
    grid = FloorGrid.from_scenario(scn, Floor.from_scenario(scn, rng))
    n = scn.face.pan_count
    model = build_face_spec(scn, grid, 0, n, anchors=False).compile()
    index = index_face_model(model, scn, 0, n)
    assert model.nbody == 1 + 2 * n + n  # world, pans, supports and their canopies
    assert all(model.body_parentid[model.body(f"pan{i}_pan").id] == 0 for i in range(n))  # no chain
    assert model.neq == n - 1  # a connect per joint
    assert model.ntendon == 2 * (n - 1) + n  # two bend limits per joint, a ram per support
    limits = model.tendon_range[[model.tendon(f"bend_yaw{i}").id for i in range(n - 1)]]
    np.testing.assert_allclose(limits[:, 1], np.radians(scn.face.bend_limit_horizontal_deg))
    assert index.ram_act.size == n and index.pan_qpos.shape == (n, 6)


def test_ride_model_suspension_from_the_scenario():
    scn = capped("default")
    model = build_ride_spec(scn).compile()
    assert np.isclose(model.opt.timestep, 1 / scn.rates.ride_hz)
    shoes = [model.site(f"shoe_{s}").pos for s in ("rear", "front")]
    assert np.isclose(np.linalg.norm(shoes[1] - shoes[0]), scn.shearer.shoe_spacing_m)
