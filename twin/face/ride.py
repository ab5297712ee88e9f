"""The shearer's ride on the pans: shoe points on the bent pan line, mocap targets, MuJoCo rollout.

The target pose is the chord between the two shoes: the shoes sit on the running lines of the pans under
them (at arc lengths s -/+ shoe_spacing/2), the body y axis runs from the rear to the front shoe, x is the
mean pan x axis made orthogonal to y, and the body reference point is body_height above the chord's
middle. The shearer body follows that target through a soft weld (its suspension), simulated with
`mujoco.rollout` in chunks that start while the shearer stands at a face end (so each chunk starts at
rest).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco import rollout

from estimators.nav.rotations import mat_to_quat
from twin.config.scenario import Scenario
from twin.face.layout import FaceFrame, joint_ends, pan_axes
from twin.face.model import build_ride_spec


def shoe_pans(s: np.ndarray, scn: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """Pan index under the rear (headgate-side) and front shoe for body arc lengths s."""
    length, n = scn.face.pan_length_m, scn.face.pan_count
    half = scn.shearer.shoe_spacing_m / 2
    rear = np.clip(np.floor((s - half) / length), 0, n - 1).astype(np.int32)
    front = np.clip(np.floor((s + half) / length), 0, n - 1).astype(np.int32)
    return rear, front


def _along_joints(per_joint: np.ndarray, s_shoe: np.ndarray, scn: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation of per-joint vectors (N+1, 3) at arc lengths s_shoe, and the pan index there."""
    length, n = scn.face.pan_length_m, scn.face.pan_count
    pan = np.clip(np.floor(s_shoe / length), 0, n - 1).astype(np.int32)
    frac = (s_shoe - pan * length)[:, None] / length
    return per_joint[pan] + frac * (per_joint[pan + 1] - per_joint[pan]), pan


def shoe_frames_f(pans: np.ndarray, s_shoe: np.ndarray, scn: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """Shoe points on the running line at arc lengths s_shoe (F), and the pans' cross axis (x) there.

    The line runs through the pan joints (the mid-point of the two pans' rail ends, which the connect
    equalities hold within a millimetre) and the cross axis turns linearly from joint to joint, so a shoe
    crosses a bent joint without a jump in position or in the machine's attitude.
    """
    start, end = joint_ends(pans, scn.face.pan_length_m)
    joints = np.concatenate([start[:1], 0.5 * (end[:-1] + start[1:]), end[-1:]])
    x_axes = pan_axes(pans)[:, :, 0]
    x_joints = np.concatenate([x_axes[:1], 0.5 * (x_axes[:-1] + x_axes[1:]), x_axes[-1:]])
    point, _ = _along_joints(joints, s_shoe, scn)
    x_axis, _ = _along_joints(x_joints, s_shoe, scn)
    return point, x_axis


def target_pose_f(pans: np.ndarray, s: np.ndarray, scn: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """Body reference point (K, 3) and C_b^F (K, 3, 3) of the chord between the shoes at arc lengths s."""
    half = scn.shearer.shoe_spacing_m / 2
    rear, x_rear = shoe_frames_f(pans, s - half, scn)
    front, x_front = shoe_frames_f(pans, s + half, scn)
    y_b = front - rear
    y_b /= np.linalg.norm(y_b, axis=-1, keepdims=True)
    x_mean = 0.5 * (x_rear + x_front)
    x_b = x_mean - np.sum(x_mean * y_b, axis=-1, keepdims=True) * y_b
    x_b /= np.linalg.norm(x_b, axis=-1, keepdims=True)
    z_b = np.cross(x_b, y_b)
    mat_fb = np.stack([x_b, y_b, z_b], axis=-1)
    pos = 0.5 * (rear + front) + scn.shearer.body_height_m * z_b
    return pos, mat_fb


@dataclass(frozen=True)
class PanVersion:
    """The pan line as an event leaves it: the pans move from the previous version during [t_begin, t_end]."""

    t_begin: float
    t_end: float
    pans: np.ndarray


def smootherstep(x: np.ndarray) -> np.ndarray:
    """0 to 1 with zero first and second derivatives at both ends."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * x * (x * (6 * x - 15) + 10)


def ride_targets_t(versions: list[PanVersion], times: np.ndarray, s: np.ndarray,
                   scn: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """Mocap targets in t (positions (K, 3), quaternions q_tb (K, 4)) on the pan line at each time.

    While an event moves the pans (between a version's t_begin and t_end) the target passes smoothly from
    the pose on the previous line to the pose on the new one.
    """
    mat_tf = FaceFrame(np.radians(scn.face.azimuth_deg)).mat_tf
    begins = np.array([v.t_begin for v in versions])
    which = np.clip(np.searchsorted(begins, times, side="right") - 1, 0, len(versions) - 1)
    pos = np.empty((times.size, 3))
    quat = np.empty((times.size, 4))
    bounds = np.flatnonzero(np.diff(which)) + 1
    for lo, hi in zip(np.concatenate([[0], bounds]), np.concatenate([bounds, [times.size]])):
        k = which[lo]
        p_f, mat_fb = target_pose_f(versions[k].pans, s[lo:hi], scn)
        pos[lo:hi], quat[lo:hi] = p_f @ mat_tf.T, mat_to_quat(mat_tf @ mat_fb)
        moving = np.flatnonzero(times[lo:hi] < versions[k].t_end) if k > 0 else np.zeros(0, int)
        if moving.size:
            v = versions[k]
            alpha = smootherstep((times[lo:hi][moving] - v.t_begin) / max(v.t_end - v.t_begin, 1e-9))[:, None]
            p0_f, mat0_fb = target_pose_f(versions[k - 1].pans, s[lo:hi][moving], scn)
            q0 = mat_to_quat(mat_tf @ mat0_fb)
            q1 = quat[lo:hi][moving]
            q1 = np.where(np.sum(q0 * q1, axis=1, keepdims=True) < 0, -q1, q1)
            pos[lo + moving] = (1 - alpha) * (p0_f @ mat_tf.T) + alpha * pos[lo + moving]
            q = (1 - alpha) * q0 + alpha * q1
            quat[lo + moving] = q / np.linalg.norm(q, axis=1, keepdims=True)
    return pos, quat


def simulate_ride(scn: Scenario, target_pos: np.ndarray, target_quat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shearer body positions (K, 3) and q_tb (K, 4) at the ride rate, from mocap targets at the same rate.

    The shearer starts at rest on the first target; sample k's state is after the step that had target k
    as its mocap pose. One `mujoco.rollout` on one thread (callers run chunks in parallel).
    """
    model = build_ride_spec(scn).compile()
    # Its geoms are drawn only (contype and conaffinity 0): without the collision pass, the same steps 15 % faster.
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    data = mujoco.MjData(model)
    data.qpos[:3], data.qpos[3:7] = target_pos[0], target_quat[0]
    data.mocap_pos[0], data.mocap_quat[0] = target_pos[0], target_quat[0]
    mujoco.mj_forward(model, data)
    init = np.empty((1, mujoco.mj_stateSize(model, spec)))
    mujoco.mj_getState(model, data, init[0], spec)
    pos, quat = target_pos.copy(), target_quat.copy()
    nstep = target_pos.shape[0] - 1
    if nstep > 0:
        control = np.concatenate([target_pos[1:], target_quat[1:]], axis=1)[None]
        ctrl_spec = mujoco.mjtState.mjSTATE_MOCAP_POS | mujoco.mjtState.mjSTATE_MOCAP_QUAT
        state, _ = rollout.rollout(model, [data], init, control, control_spec=ctrl_spec, nstep=nstep)
        pos[1:], quat[1:] = state[0, :, 1:4], state[0, :, 4:8]
    quat *= np.where(quat[:, :1] < 0, -1.0, 1.0)
    return pos, quat
