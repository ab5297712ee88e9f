"""The assembled face as one MuJoCo model to save, open in MuJoCo's viewer and render: the whole face's pans and
supports (twin.face.model.build_face_spec) on its floor, with the shearer of the ride model (build_ride_spec) standing
on the pans, lit, with a camera on the face.

The face is loaded into the compiled model as the simulator loads a window (FaceSimulator.load_at_rest), and that
state is made the model's initial one, which MuJoCo's viewer resets to: every body placed where it stands, every
joint's qpos0 (its `ref`) its position (a pan joint's qpos is its state in F, twin.face.layout), the floor's heights in
the height field, the roof in the legs' limits, and each ram's and leg's actuator state counted from its oil column as
assembled. So the model as saved stands at rest; simulated, it holds (a pan moves under a millimetre in a second).
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from estimators.nav.rotations import mat_to_quat
from twin.face.export_target import ExportError
from twin.face.layout import FaceFrame
from twin.face.model import FloorBand, build_face_spec, build_ride_spec
from twin.face.ride import target_pose_f
from twin.face.simulator import FaceSimulator
from twin.face.window import FaceState, Window

SHEARER_PREFIX = "shearer_"
"""Of the ride model's names in the face's (its body "shearer_shearer", its mocap target "shearer_ride", its drums
and ranging arms "shearer_drum_head", "shearer_arm_head", ...), as pans' are "pan{i}_"."""
CAMERA = "face"
"""The camera a render looks through (the viewer's too: visual/global cameraid)."""
OFFSCREEN_PX = (1920, 1080)
"""The saved model's offscreen buffer: the largest image a render of the file can have (MuJoCo's default: 640 x 480)."""
CAMERA_SPAN_M = 40.0
"""Length of face the camera frames around the shearer (the whole face if shorter)."""
SKY_TOP, SKY_BOTTOM = (0.55, 0.65, 0.75), (0.25, 0.27, 0.3)


def assembled_face_spec(sim: FaceSimulator, state: FaceState, s_shearer_m: float | None = None) -> mujoco.MjSpec:
    """The spec of the whole face in `state` (every pan and support of sim's scenario, on sim's floor) with the
    shearer standing on the pans with its body reference point at arc length `s_shearer_m` (default mid-face)."""
    scn = sim.scn
    n, length = scn.face.pan_count, scn.face.pan_length_m
    s = 0.5 * n * length if s_shearer_m is None else s_shearer_m
    band = FloorBand.for_window(scn, sim.floor, n)
    spec = build_face_spec(scn, band, 0, n, anchors=True)
    spec.modelname = f"{scn.name}_face"
    ride = build_ride_spec(scn)
    ride.option.timestep = spec.option.timestep  # the face's (the options are the parent's; it warns otherwise)
    spec.attach(ride, prefix=SHEARER_PREFIX, frame=spec.worldbody.add_frame())
    pos_f, mat_fb = target_pose_f(state.pans, np.array([s]), scn)
    mat_tf = FaceFrame(np.radians(scn.face.azimuth_deg)).mat_tf
    pos_t, quat_tb = mat_tf @ pos_f[0], mat_to_quat(mat_tf @ mat_fb[0])
    _add_view(spec, pos_t, mat_tf, min(CAMERA_SPAN_M, n * length))
    win = Window.of_spec(scn, band, n, spec)
    m, d = win.model, win.data
    sim.load_at_rest(win, state, 0)
    free = m.jnt_qposadr[m.joint(f"{SHEARER_PREFIX}free").id]
    d.qpos[free:free + 3], d.qpos[free + 3:free + 7] = pos_t, quat_tb
    target = m.body_mocapid[m.body(f"{SHEARER_PREFIX}ride").id]
    d.mocap_pos[target], d.mocap_quat[target] = pos_t, quat_tb
    _floor_in_unit_range(spec, m, d)
    mujoco.mj_forward(m, d)
    _stand_as(m, d)
    _actuators_from_zero(m, d)
    spec.copy_back(m)
    _give_inertial_frames(spec, m)
    for side in (0, 1):  # no neighbours beyond the face's ends
        spec.equality(f"anchor{side}").active = False
    return spec


def _floor_in_unit_range(spec: mujoco.MjSpec, model: mujoco.MjModel, data: mujoco.MjData) -> None:
    """The same floor with its height field's samples from 0 to 1, as a model file holds them (compilation scales
    elevation data so; place_floor's start above 0): its elevation scale (in the model and the spec: MjSpec.copy_back
    copies samples, not sizes) and the floor's height changed to match."""
    hf = model.hfield("floor")
    adr, size = int(model.hfield_adr[hf.id]), int(model.hfield_nrow[hf.id] * model.hfield_ncol[hf.id])
    heights = model.hfield_data[adr:adr + size]
    low, span = heights.min(), np.ptp(heights)
    data.mocap_pos[model.body_mocapid[model.body("floor").id], 2] += low * model.hfield_size[hf.id, 2]
    if span > 0:  # a flat floor stays all zeros
        model.hfield_data[adr:adr + size] = (heights - low) / span
        model.hfield_size[hf.id, 2] *= span
    else:
        model.hfield_data[adr:adr + size] = 0.0
    spec.hfield("floor").size = model.hfield_size[hf.id]


def _stand_as(model: mujoco.MjModel, data: mujoco.MjData) -> None:
    """Make data's configuration the model's reference one: each body placed where data has it relative to its
    parent, each joint's qpos0 its position in data (a hinge's or slide's qpos0 is its `ref`)."""
    parent = model.body_parentid[1:]
    mat_parent = data.xmat[parent].reshape(-1, 3, 3)
    model.body_pos[1:] = np.einsum("kji,kj->ki", mat_parent, data.xpos[1:] - data.xpos[parent])
    model.body_quat[1:] = mat_to_quat(np.swapaxes(mat_parent, 1, 2) @ data.xmat[1:].reshape(-1, 3, 3))
    model.qpos0[:] = data.qpos


def _actuators_from_zero(model: mujoco.MjModel, data: mujoco.MjData) -> None:
    """Count each integrator actuator's state (a ram's metered stroke, the legs' oil column) from its value in data, as
    a model starts its actuators at 0: gain x act moves into the bias's constant term and the act range shifts with it
    (twin.face.model's actuators: fixed gain, affine bias), so the forces are the same."""
    ids = np.flatnonzero(model.actuator_dyntype == mujoco.mjtDyn.mjDYN_INTEGRATOR)
    adr = model.actuator_actadr[ids]
    model.actuator_biasprm[ids, 0] += model.actuator_gainprm[ids, 0] * data.act[adr]
    model.actuator_actrange[ids] -= data.act[adr, None]
    data.act[adr] = 0.0


def _give_inertial_frames(spec: mujoco.MjSpec, model: mujoco.MjModel) -> None:
    """Each explicit inertial without a frame given (the connectors' couplers) at the frame it compiled to:
    MjSpec.to_xml leaves such an inertial out, and the file's body would be massless."""
    for body in spec.bodies[1:]:
        if body.explicitinertial and np.isnan(body.ipos[0]):
            body.ipos, body.iquat = model.body_ipos[body.id], model.body_iquat[body.id]


def _look_at_quat(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Orientation of a camera at `eye` looking at `target` with z up (a MuJoCo camera looks along its -z, y up)."""
    back = (eye - target) / np.linalg.norm(eye - target)
    right = np.cross([0.0, 0.0, 1.0], back)
    right /= np.linalg.norm(right)
    return mat_to_quat(np.column_stack([right, np.cross(back, right), back]))


def _add_view(spec: mujoco.MjSpec, target_t: np.ndarray, mat_tf: np.ndarray, span_m: float) -> None:
    """Light (a headlight, the sun from above the goaf, a sky) and the camera CAMERA: from the coal side (no coal wall
    stands there), ahead of the shearer at `target_t` and a little above it, looking at it over `span_m` of face: the
    drums, the pans, the supports' bases and rams under their canopies."""
    vis = spec.visual
    vis.global_.offwidth, vis.global_.offheight = OFFSCREEN_PX
    vis.headlight.ambient, vis.headlight.diffuse, vis.headlight.specular = [0.35] * 3, [0.45] * 3, [0.1] * 3
    spec.worldbody.add_light(name="sun", type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
                             dir=mat_tf @ np.array([0.5, 0.3, -1.0]), diffuse=[0.5] * 3, specular=[0.1] * 3,
                             castshadow=False)
    spec.add_texture(name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX, builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
                     rgb1=list(SKY_TOP), rgb2=list(SKY_BOTTOM), width=64, height=64)
    eye_t = target_t + mat_tf @ (span_m * np.array([0.3, -0.45, 0.12]))
    spec.worldbody.add_camera(name=CAMERA, pos=eye_t, quat=_look_at_quat(eye_t, target_t), fovy=45.0)
    vis.global_.cameraid = len(spec.cameras) - 1


def write_mjcf(spec: mujoco.MjSpec, path: Path) -> int:
    """Write the spec as one MJCF file (the floor's heights inline: no files beside it); returns its size [bytes]."""
    text = spec.to_xml()
    try:
        path.write_text(text)
    except OSError as err:
        raise ExportError(f"{path}: cannot write the model ({err.strerror}); choose a writable path") from None
    return len(text.encode())


def compiled_at_rest(spec: mujoco.MjSpec) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """The spec compiled, and its initial data (an assembled face's spec: the face as assembled)."""
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return model, data
