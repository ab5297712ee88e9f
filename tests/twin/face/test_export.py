"""`longwall model`: the assembled face as one MJCF file (pans, supports, floor, shearer) that stands as the face's
state and at rest, and its offscreen render."""

from __future__ import annotations

import os
import subprocess
import sys

import matplotlib.image
import mujoco
import numpy as np
import pytest

from tests.conftest import SCENARIO_DIR, capped
from twin.cli import main
from twin.config.scenario import support_count
from twin.face.layout import FaceFrame, bend_angles
from twin.face.model import PAN_JOINTS
from twin.face.ride import target_pose_f
from twin.pipeline.simulate import settled_face

pytestmark = pytest.mark.slow  # two settled faces and a render in a fresh process: about 8 s

SCENARIO = SCENARIO_DIR / "default.toml"


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """The default face written by `longwall model --xml`, loaded from another folder; the face's state."""
    out = tmp_path_factory.mktemp("model") / "face.xml"
    assert main(["model", str(SCENARIO), "--xml", str(out)]) == 0
    elsewhere = tmp_path_factory.mktemp("elsewhere")
    cwd = os.getcwd()
    os.chdir(elsewhere)
    try:
        model = mujoco.MjModel.from_xml_path(str(out))
    finally:
        os.chdir(cwd)
    scn = capped("default")
    sim, state = settled_face(scn)
    return out, model, scn, sim, state


def test_the_file_holds_every_pan_and_support_and_the_shearer(exported):
    out, model, scn, _, _ = exported
    names = {model.body(i).name for i in range(model.nbody)}
    assert sum(n.endswith("_pan") for n in names) == scn.face.pan_count == 44
    assert sum(n.endswith("_support") for n in names) == support_count(scn)
    assert {"shearer_shearer", "shearer_ride", "floor"} <= names
    geoms = {model.geom(i).name for i in range(model.ngeom)}
    assert {"shearer_drum_head", "shearer_drum_tail", "shearer_arm_head", "shearer_arm_tail"} <= geoms
    assert "file=" not in out.read_text()  # the floor's heights inline: nothing to find beside it


def test_the_file_stands_as_the_faces_state(exported):
    """At qpos0 (where MuJoCo's viewer starts) each pan joint holds its state in F, so the bend angles are the face's,
    the pans stand where the state puts them, and the shearer stands on the pans mid-face."""
    _, model, scn, sim, state = exported
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    n = scn.face.pan_count
    qpos = np.array([[data.qpos[model.jnt_qposadr[model.joint(f"pan{i}_{j}").id]] for j in PAN_JOINTS]
                     for i in range(n)])
    np.testing.assert_allclose(qpos, state.pans, atol=1e-4)  # the file's 6 significant digits
    for ours, theirs in zip(bend_angles(qpos), bend_angles(state.pans)):
        np.testing.assert_allclose(ours, theirs, atol=2e-6)
    assert np.abs(np.diff(state.pans[:, 3])).max() > 1e-4  # the face is not straight: the check can fail
    mat_tf = FaceFrame(np.radians(scn.face.azimuth_deg)).mat_tf
    pan_t = data.xpos[[model.body(f"pan{i}_pan").id for i in range(n)]]
    np.testing.assert_allclose(pan_t @ mat_tf, state.pans[:, :3], atol=1e-4)
    pos_f, _ = target_pose_f(state.pans, np.array([0.5 * n * scn.face.pan_length_m]), scn)
    np.testing.assert_allclose(data.xpos[model.body("shearer_shearer").id] @ mat_tf, pos_f[0], atol=1e-4)
    legs = [data.qpos[model.jnt_qposadr[model.joint(f"sup{j}_leg").id]] for j in range(support_count(scn))]
    np.testing.assert_allclose(legs, state.sup_leg, atol=1e-4)


def test_the_floor_in_the_file_is_the_scenarios(exported):
    _, model, _, sim, _ = exported
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    hf = model.hfield("floor")
    nrow, ncol = int(model.hfield_nrow[hf.id]), int(model.hfield_ncol[hf.id])
    adr = int(model.hfield_adr[hf.id])
    heights = model.hfield_data[adr:adr + nrow * ncol].reshape(nrow, ncol)
    assert heights.min() == 0.0 and heights.max() == 1.0
    centre_f = sim.frame.mat_tf.T @ data.xpos[model.body("floor").id]
    half_x, half_y, elevation = model.hfield_size[hf.id, :3]
    x = centre_f[0] - half_x + np.arange(ncol) * 2 * half_x / (ncol - 1)
    y = centre_f[1] - half_y + np.arange(nrow) * 2 * half_y / (nrow - 1)
    np.testing.assert_allclose(centre_f[2] + heights * elevation, sim.floor.height(x[None, :], y[:, None]), atol=1e-4)


def test_the_saved_face_is_at_rest(exported):
    """Simulated from its initial state (the rams' and legs' actuator states count from the face as assembled), the
    face holds: a second moves no pan, support or canopy a millimetre (the actuators at 0 as MuJoCo starts them,
    uncounted, would pull the pans back a metre and drop the canopies)."""
    _, model, _, _, _ = exported
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    bodies = [i for i in range(model.nbody) if model.body(i).name.endswith(("_pan", "_support", "_canopy"))]
    before = data.xpos[bodies].copy()
    mujoco.mj_step(model, data, nstep=round(1.0 / model.opt.timestep))
    assert np.abs(data.xpos[bodies] - before).max() < 1e-3


def test_the_render_is_lit_and_as_wide_as_asked(tmp_path):
    """In a fresh process (MuJoCo picks its OpenGL backend when first imported), without a display: EGL."""
    png = tmp_path / "face.png"
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    done = subprocess.run([sys.executable, "-m", "twin.cli", "model", str(SCENARIO_DIR / "seed003.toml"), "--png",
                           str(png), "--width", "800"], capture_output=True, text=True, env=env, timeout=300)
    if done.returncode == 2 and "no OpenGL context" in done.stderr:
        pytest.skip(done.stderr.strip())
    assert done.returncode == 0, done.stderr
    image = matplotlib.image.imread(png)[..., :3] * 255
    assert image.shape == (450, 800, 3)
    assert image.mean() > 40 and image.std() > 10  # lit, and not one flat colour
