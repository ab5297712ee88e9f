"""Pan connectors (issue 25 item 4): a pin on a coupler with axial play, limited in horizontal bend, vertical bend
and relative roll, between neighbouring pans of a face model and from a window's edge pans to the mocap anchors
standing in for the pans beyond it (add_connectors); connect_window ties a loaded window to the rest of the face."""

from __future__ import annotations

from typing import TYPE_CHECKING

import mujoco
import numpy as np

from twin.config.scenario import Scenario
from twin.face.layout import joint_ends, pan_axes

if TYPE_CHECKING:
    from twin.face.model import FaceIndex

CONNECTOR_KINDS = ("yaw", "pitch", "roll")
"""The pan joints whose differences a connector limits: horizontal bend, vertical bend, relative roll."""
CONNECTOR_SOLREF = (0.02, 1.0)
CONNECTOR_SOLIMP = (0.999, 0.9999, 0.001, 0.5, 2.0)
"""Softness of the connectors' pins and limits: the shortest time constant MuJoCo takes at the face's 10 ms step
(twice the step) and an impedance of 0.999-0.9999 within a milliradian or millimetre. At 0.99-0.999 (the pins' old
values) a 0.3 m push shortfall on the default face bent a connector 1.14 deg against its 1 deg limit and opened one
6.2 mm against its 5 mm; at these, 1.04 deg and 5.2 mm."""
COUPLER_MASS_KG = 50.0
"""Mass of a connector's sliding part (a dogbone and its pins)."""
COUPLER_ARMATURE_KG = 5000.0
"""Inertia added to a coupler's slide alone, about a pan's mass. A limit's stiffness in MuJoCo scales with the
inertia it acts on: on the 50 kg slide alone the ends of a 10 mm play gave way by over 3 mm under the chain's pull
(joints 8.2 mm open on the default face); with a pan's inertia, by under 1 mm. The armature adds no weight and moves
nothing but the slide. A heavy coupler needs connect_window: a window reloaded with its couplers mid-play would move
the pans, not the couplers, to take up the difference."""
COUPLER_DAMPING_N_S_M = 1.0e4
UNLIMITED_RAD = 1.0e3
"""An anchor limit's half range while no neighbour stands beyond it (a face end, or before connect_window)."""


def connector_limits_rad(scn: Scenario) -> np.ndarray:
    """Half ranges of a pan connector [rad]: horizontal bend, vertical bend, relative roll (CONNECTOR_KINDS)."""
    f = scn.face
    return np.radians([f.bend_limit_horizontal_deg, f.bend_limit_vertical_deg, f.roll_limit_deg])


def _coupler(pan: mujoco.MjsBody, prefix: str, end: str, y: float, play: float) -> str:
    """The sliding part of a connector at one end ("start" or "end") of a pan's running line (at y in the pan): a
    light body on a slide along the pan's axis within +-play/2. Returns its site, the connector's pin."""
    body = pan.add_body(name=f"{prefix}coupler_{end}", pos=[0.0, y, 0.0])
    body.explicitinertial = True
    body.mass = COUPLER_MASS_KG
    body.inertia = [1.0, 1.0, 1.0]
    body.add_joint(name=f"{prefix}play_{end}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0.0, 1.0, 0.0],
                   limited=mujoco.mjtLimited.mjLIMITED_TRUE, range=[-play / 2, play / 2],
                   damping=COUPLER_DAMPING_N_S_M, armature=COUPLER_ARMATURE_KG,
                   solref_limit=list(CONNECTOR_SOLREF), solimp_limit=list(CONNECTOR_SOLIMP))
    body.add_site(name=f"{prefix}coupler_{end}")
    return f"{prefix}coupler_{end}"


def _pin(spec: mujoco.MjSpec, name: str, site1: str, site2: str) -> None:
    spec.add_equality(name=name, type=mujoco.mjtEq.mjEQ_CONNECT, objtype=mujoco.mjtObj.mjOBJ_SITE, name1=site1,
                      name2=site2, solref=list(CONNECTOR_SOLREF), solimp=list(CONNECTOR_SOLIMP))


def _limit(spec: mujoco.MjSpec, name: str, half_range: float, joints: tuple[tuple[str, float], ...]) -> None:
    ten = spec.add_tendon(name=name, limited=mujoco.mjtLimited.mjLIMITED_TRUE, range=[-half_range, half_range],
                          solref_limit=list(CONNECTOR_SOLREF), solimp_limit=list(CONNECTOR_SOLIMP))
    for joint, coef in joints:
        ten.wrap_joint(joint, coef)


def add_connectors(spec: mujoco.MjSpec, scn: Scenario, pans: dict[int, mujoco.MjsBody], anchors: bool) -> None:
    """The connectors between the pans `pans` (pan index -> body, a contiguous range, in the spec); with `anchors`,
    the connectors to the mocap anchors.

    A connector is a pin (a connect equality, a ball joint) at the running line's end, limited in horizontal bend,
    vertical bend and relative roll by fixed tendons on the yaw, pitch and roll differences (the relative roll
    limit is what keeps a ram's pull below the running line from rolling a pan over: before it, a 0.3 m push
    shortfall rolled pans 111-165 deg), with axial play: the pin sits on a coupler, a light body sliding along the
    pan's axis within +-axial_play_m / 2 (a slide joint with a range). A coupler costs one degree of freedom per pan
    and a constraint row only while it is at an end of its play; the pin keeps the running lines together across
    and up and down, as a dogbone does. (A spatial tendon of limited length between the rail ends would need no
    state, but would let the ends part sideways as far as along the face, and pass each other closing up.) A
    window does not load its couplers' slides (mj_resetData puts them mid-play): connect_window sets them from the
    loaded pans; without it the light coupler, not the pans, takes up the difference in the first steps. With no
    play the pin sits on the rail end itself.

    The anchor connectors (to the mocap anchors standing in for the pans beyond a window) are pins on couplers too,
    and carry the same three limits as tendons on the edge pan's own joints, their ranges set around the
    neighbour's state by connect_window (a pin alone is a ball joint: the edge pan bent up to 2.5 deg against the
    neighbour it could not see).
    """
    f = scn.face
    play, half = f.axial_play_m, f.pan_length_m / 2
    limits = connector_limits_rad(scn)
    first, last = min(pans), max(pans)
    pins: dict[tuple[int, str], str] = {}
    for i, body in pans.items():
        prefix = f"pan{i}_"
        for end, y, needed in (("start", -half, anchors and i == first), ("end", half, i < last or anchors)):
            if needed:
                pins[i, end] = _coupler(body, prefix, end, y, play) if play > 0 else f"{prefix}rail_{end}"
    for i in range(first, last):
        _pin(spec, f"joint{i}", pins[i, "end"], f"pan{i + 1}_rail_start")
        for kind, lim in zip(CONNECTOR_KINDS, limits):
            _limit(spec, f"bend_{kind}{i}", float(lim), ((f"pan{i + 1}_{kind}", 1.0), (f"pan{i}_{kind}", -1.0)))
    if anchors:
        for side, (pan, end) in enumerate(((first, "start"), (last, "end"))):
            spec.worldbody.add_body(name=f"anchor{side}", mocap=True).add_site(name=f"anchor{side}")
            _pin(spec, f"anchor{side}", pins[pan, end], f"anchor{side}")
            for kind in CONNECTOR_KINDS:
                _limit(spec, f"anchor{side}_{kind}", UNLIMITED_RAD, ((f"pan{pan}_{kind}", 1.0),))


def connect_window(model: mujoco.MjModel, data: mujoco.MjData, index: FaceIndex, pans: np.ndarray, first: int,
                   pan_length_m: float) -> None:
    """Tie a window model loaded with the face's pans first..first+count-1 (their states already in data.qpos) to
    the rest of the face, whose pan states (N, 6) are `pans`: each anchor connector's limits around the neighbour
    beyond it (lifted at a face end), and each coupler at the play its joint has in `pans`. Call after loading a
    window, before stepping it; calling it twice changes nothing."""
    count, n = index.pan_qpos.shape[0], pans.shape[0]
    for side, other in enumerate((first - 1, first + count)):
        if 0 <= other < n:
            centre = pans[other, 3:6]
            model.tendon_range[index.anchor_tendon[side]] = np.column_stack(
                [centre - index.connector_limit, centre + index.connector_limit])
        else:
            model.tendon_range[index.anchor_tendon[side]] = [-UNLIMITED_RAD, UNLIMITED_RAD]
    if index.coupler_qpos.size:
        start, end = joint_ends(pans, pan_length_m)
        axis = pan_axes(pans)[:, :, 1]
        # A tail coupler sits at pan i's end and slides along pan i's axis to pan i + 1's start; the head coupler
        # at the window's first pan's start, to the end of the pan before it.
        tail = np.zeros(count)
        inner = np.arange(first, min(first + count, n - 1))
        tail[inner - first] = np.einsum("ij,ij->i", start[inner + 1] - end[inner], axis[inner])
        head = float((end[first - 1] - start[first]) @ axis[first]) if first > 0 else 0.0
        lim = model.jnt_range[index.coupler_jnt]
        data.qpos[index.coupler_qpos] = np.clip(np.append(tail, head)[index.coupler_pan], lim[:, 0], lim[:, 1])
