"""The shearer's ride on the pans: shoe points on the bent pan line, mocap targets, MuJoCo rollout.

The target pose is the chord between the two shoes: the shoes sit on the running lines of the pans under
them (at arc lengths s -/+ shoe_spacing/2), the body y axis runs from the rear to the front shoe, x is the
mean pan x axis made orthogonal to y, and the body reference point is body_height above the chord's
middle. The shearer body follows that target through a soft weld (its suspension), simulated with
`mujoco.rollout` in chunks that start while the shearer stands at a face end (so each chunk starts at
rest), run in parallel threads.
"""

from __future__ import annotations

import os

import mujoco
import numpy as np
from mujoco import rollout

from estimators.rotations import mat_to_quat
from twin.layout import FaceFrame, pan_axes, running_line_points
from twin.model import build_ride_spec
from twin.scenario import Scenario


def shoe_pans(s: np.ndarray, scn: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """Pan index under the rear (headgate-side) and front shoe for body arc lengths s."""
    length, n = scn.face.pan_length_m, scn.face.pan_count
    half = scn.shearer.shoe_spacing_m / 2
    rear = np.clip(np.floor((s - half) / length), 0, n - 1).astype(np.int32)
    front = np.clip(np.floor((s + half) / length), 0, n - 1).astype(np.int32)
    return rear, front


def shoe_points_f(pans: np.ndarray, s_shoe: np.ndarray, scn: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """Points on the running line at arc lengths s_shoe (F) and the pan each lies on."""
    length, n = scn.face.pan_length_m, scn.face.pan_count
    pan = np.clip(np.floor(s_shoe / length), 0, n - 1).astype(np.int32)
    y_local = s_shoe - (pan + 0.5) * length
    return running_line_points(pans, pan, y_local), pan


def target_pose_f(pans: np.ndarray, s: np.ndarray, scn: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """Body reference point (K, 3) and C_b^F (K, 3, 3) of the chord between the shoes at arc lengths s."""
    half = scn.shearer.shoe_spacing_m / 2
    rear, pan_r = shoe_points_f(pans, s - half, scn)
    front, pan_f = shoe_points_f(pans, s + half, scn)
    y_b = front - rear
    y_b /= np.linalg.norm(y_b, axis=-1, keepdims=True)
    axes = pan_axes(pans)
    x_mean = 0.5 * (axes[pan_r, :, 0] + axes[pan_f, :, 0])
    x_b = x_mean - np.sum(x_mean * y_b, axis=-1, keepdims=True) * y_b
    x_b /= np.linalg.norm(x_b, axis=-1, keepdims=True)
    z_b = np.cross(x_b, y_b)
    mat_fb = np.stack([x_b, y_b, z_b], axis=-1)
    pos = 0.5 * (rear + front) + scn.shearer.body_height_m * z_b
    return pos, mat_fb


def ride_targets_t(versions: list[tuple[float, np.ndarray]], times: np.ndarray, s: np.ndarray,
                   scn: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """Mocap targets in t (positions (K, 3), quaternions q_tb (K, 4)) using the pan line valid at each time.

    `versions` lists (time from which valid, pan states) in time order.
    """
    mat_tf = FaceFrame(np.radians(scn.face.azimuth_deg)).mat_tf
    starts = np.array([v[0] for v in versions])
    which = np.clip(np.searchsorted(starts, times, side="right") - 1, 0, len(versions) - 1)
    pos = np.empty((times.size, 3))
    mat = np.empty((times.size, 3, 3))
    bounds = np.flatnonzero(np.diff(which)) + 1
    for lo, hi in zip(np.concatenate([[0], bounds]), np.concatenate([bounds, [times.size]])):
        pos[lo:hi], mat[lo:hi] = target_pose_f(versions[which[lo]][1], s[lo:hi], scn)
    return pos @ mat_tf.T, mat_to_quat(mat_tf @ mat)


def simulate_ride(scn: Scenario, target_pos: np.ndarray, target_quat: np.ndarray,
                  chunk_starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shearer body positions (K, 3) and q_tb (K, 4) at the ride rate, from mocap targets at the same rate.

    Sample k's state is after the step that had the target of sample k as its mocap pose; each chunk
    (sample indices `chunk_starts`) starts at rest on its first target.
    """
    model = build_ride_spec(scn).compile()
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    nstate = mujoco.mj_stateSize(model, spec)
    data = mujoco.MjData(model)
    bounds = np.concatenate([chunk_starts, [target_pos.shape[0]]])
    lengths = np.diff(bounds)
    nstep = int(lengths.max()) - 1
    init = np.empty((lengths.size, nstate))
    control = np.empty((lengths.size, max(nstep, 1), 7))
    for c, (lo, hi) in enumerate(zip(bounds[:-1], bounds[1:])):
        data.qpos[:3], data.qpos[3:7] = target_pos[lo], target_quat[lo]
        data.qvel[:] = 0.0
        data.mocap_pos[0], data.mocap_quat[0] = target_pos[lo], target_quat[lo]
        mujoco.mj_forward(model, data)
        mujoco.mj_getState(model, data, init[c], spec)
        idx = np.minimum(np.arange(lo + 1, lo + 1 + max(nstep, 1)), hi - 1)
        control[c, :, :3] = target_pos[idx]
        control[c, :, 3:] = target_quat[idx]
    ctrl_spec = mujoco.mjtState.mjSTATE_MOCAP_POS | mujoco.mjtState.mjSTATE_MOCAP_QUAT
    threads = [mujoco.MjData(model) for _ in range(min(os.cpu_count() or 1, lengths.size))]
    pos = np.empty_like(target_pos)
    quat = np.empty_like(target_quat)
    if nstep > 0:
        state, _ = rollout.rollout(model, threads, init, control, control_spec=ctrl_spec, nstep=nstep)
    for c, (lo, hi) in enumerate(zip(bounds[:-1], bounds[1:])):
        pos[lo], quat[lo] = target_pos[lo], target_quat[lo]
        if hi - lo > 1:
            qpos = state[c, : hi - lo - 1, 1:8]
            pos[lo + 1:hi], quat[lo + 1:hi] = qpos[:, :3], qpos[:, 3:7]
    quat *= np.sign(quat[:, :1] + (quat[:, :1] == 0))
    return pos, quat
