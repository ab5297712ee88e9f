"""A window of the face model (twin.face.simulator) and what it holds and records: the face's state, the compiled
window, the trace of an event's samples, and the roof over the window's canopies through an event.

Also the valves' timing the rams and the legs share: a valve meters its flow up to its goal, ramps over its last
stretch to RAMP_FLOOR of it, and closes after VALVE_TIMEOUT_FACTOR times its travel time plus STALL_S.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from twin.config.scenario import Scenario
from twin.face.layout import Floor
from twin.face.model import FaceIndex, FloorBand, build_face_spec, index_face_model

if TYPE_CHECKING:
    from twin.face.simulator import FaceSimulator

RAM_SAMPLE_S = 0.25
"""Real time between the samples of an event's trace (the supports' truth rows while the rams and legs move)."""
ROOF_CONTACT_M = 1e-5
"""A canopy at the roof is loaded this far into its slide's limit, so that the limit holds from the first step (a
limit at exactly zero distance is not active yet): 1.3 kN of the legs' 7.9 MN."""
RAMP_FLOOR = 0.2
"""Least fraction of its metered speed a ram moves at while its valve ramps."""
ARRIVED_M = 1e-6
"""A ram's metered stroke this close to its goal has arrived."""
STALL_S = 1.0
"""A ram standing at its relief valve this long has stalled: its valve closes where it stands (the push falls short)."""
VALVE_TIMEOUT_FACTOR = 1.5
"""A valve closes after this many times its ram's travel time (plus STALL_S) whatever the ram has reached."""


@dataclass
class FaceState:
    """The whole face in F: pan states (N, 6); per support its base x and z, canopy height (the leg joint), ram
    length and force [N] (positive pushing), legs' oil column [m] and load [N], and the times its legs' state holds
    at and it was last set [s]; the faults of the face in force."""

    pans: np.ndarray
    sup_x: np.ndarray
    sup_z: np.ndarray
    sup_leg: np.ndarray
    ram: np.ndarray
    ram_force: np.ndarray
    leg_oil: np.ndarray
    leg_force: np.ndarray
    leg_t: np.ndarray
    t_set: np.ndarray
    pan_wall_x: np.ndarray
    """Per pan, the x of an obstacle in front of it (an obstruction fault), or inf."""
    ram_speed_factor: np.ndarray
    """Per support, the fraction of its metered speed its ram's valve passes (below 1: a sticking valve)."""
    leg_leak_m_s: np.ndarray
    """Per support, the oil its legs lose [m of the column per s] (a leaking leg)."""
    set_force_n: np.ndarray
    """Per support, the load at which its setting valve closes (below the set load: a failed set)."""
    sup_y: np.ndarray
    """Per support, the y of its base: behind its pan, following it along the face (twin.face.drift)."""


@dataclass
class EventTrace:
    """The moved supports of an event through it, sampled in real time while their rams and legs move: one row per
    sample (t_s since the event began), one column per support of `supports` (global indices)."""

    supports: np.ndarray
    t_s: np.ndarray
    ram: np.ndarray
    sup_x: np.ndarray
    ram_force: np.ndarray
    """Ram force [N], positive pushing the pan (twin.face.hydraulics.RamHydraulics.pressure_mpa)."""
    leg: np.ndarray
    """Canopy height above the base [m]."""
    leg_force: np.ndarray
    """The legs' load [N] (twin.face.hydraulics.LegHydraulics.pressure_mpa)."""
    duration_s: float
    """From the event's beginning to its supports set again."""

    FIELDS = ("ram", "sup_x", "ram_force", "leg", "leg_force")


class TraceBuilder:
    """Collects an event's samples of the moved supports of a window (window order; `sups` their global indices)."""

    def __init__(self, win: Window, sups: np.ndarray, moved: np.ndarray):
        self.win, self.sups, self.moved = win, sups, moved
        self.t: list[float] = []
        self.rows: list[np.ndarray] = []

    def sample(self, t: float) -> None:
        d, ix, mv = self.win.data, self.win.index, self.moved
        self.t.append(t)
        self.rows.append(np.stack([d.ten_length[ix.ram_tendon[mv]], d.qpos[ix.sup_qpos[mv, 0]],
                                   d.actuator_force[ix.ram_act[mv]], d.qpos[ix.sup_qpos[mv, 1]],
                                   self.win.leg_load()[mv]]))

    def build(self, duration_s: float) -> EventTrace:
        cols = np.array(self.rows, float).reshape(len(self.t), len(EventTrace.FIELDS), int(self.moved.sum()))
        return EventTrace(self.sups[self.moved], np.array(self.t, float),
                          *(cols[:, i] for i in range(len(EventTrace.FIELDS))), duration_s)


@dataclass
class Window:
    """One compiled window model of `count` pans, its index and data, moved along the face."""

    count: int
    band: FloorBand
    model: mujoco.MjModel
    data: mujoco.MjData
    index: FaceIndex
    pan_body: np.ndarray
    pan_mass: np.ndarray
    pan_inertia: np.ndarray
    sup_body: np.ndarray

    def leg_load(self) -> np.ndarray:
        """The legs' load [N] per support: their oil column's squeeze less the flow's resistance while the canopy moves
        (the servo's damping: a canopy rising freely carries next to nothing), within the actuator's range."""
        m, d, ix = self.model, self.data, self.index
        squeeze = d.act[m.actuator_actadr[ix.leg_act]] - d.qpos[ix.sup_qpos[:, 1]]
        force = m.actuator_gainprm[ix.leg_act, 0] * squeeze + m.actuator_biasprm[ix.leg_act, 2] * d.qvel[ix.sup_dof[:, 1]]
        rng = m.actuator_forcerange[ix.leg_act]
        return np.clip(force, rng[:, 0], rng[:, 1])

    @classmethod
    def compile(cls, scn: Scenario, floor: Floor, count: int) -> "Window":
        band = FloorBand.for_window(scn, floor, count)
        return cls.of_spec(scn, band, count, build_face_spec(scn, band, 0, count, anchors=True))

    @classmethod
    def of_spec(cls, scn: Scenario, band: FloorBand, count: int, spec: mujoco.MjSpec) -> "Window":
        """The window compiled from `spec`: build_face_spec's of `count` pans on `band`, with anchors, and whatever
        a caller added to it (twin.face.export: the shearer, lights and a camera)."""
        model = spec.compile()
        index = index_face_model(model, scn, 0, count)
        pan_body = np.array([model.body(f"pan{i}_pan").id for i in index.pans], int)
        sup_body = np.array([model.body(f"sup{j}_support").id for j in index.supports], int)
        return cls(count, band, model, mujoco.MjData(model), index, pan_body, model.body_mass[pan_body].copy(),
                   model.body_inertia[pan_body].copy(), sup_body)


class RoofLimits:
    """The roof over a window's canopies through an event: the upper limits of their leg slides, converging from the
    event's beginning t_begin (real time t since it began); `advance` puts advanced supports on the floor and under
    fresh roof where they stand."""

    def __init__(self, sim: FaceSimulator, win: Window, state: FaceState, sups: np.ndarray, t_begin: float):
        self.sim, self.win, self.state, self.sups, self.t_begin = sim, win, state, sups, t_begin
        self.t_set = state.t_set[sups].copy()
        self.sup_z = state.sup_z[sups].copy()
        self.leg_jnt = win.model.dof_jntid[win.index.sup_dof[:, 1]]
        self.clearance = np.zeros(sups.size)
        self.place(0.0)
        q_leg = win.data.qpos[win.index.sup_qpos[:, 1]]
        at_roof = q_leg >= self.clearance - ROOF_CONTACT_M
        q_leg[at_roof] = np.maximum(q_leg[at_roof], self.clearance[at_roof] + ROOF_CONTACT_M)
        win.data.qpos[win.index.sup_qpos[:, 1]] = q_leg

    def advance(self, which: np.ndarray, t_abs: float) -> None:
        """Supports `which` (lowered) set from t_abs where they stand: their bases lifted onto the floor there."""
        m, d, ix = self.win.model, self.win.data, self.win.index
        x = d.qpos[ix.sup_qpos[which, 0]]
        self.sup_z[which] = self.sim.support_z(x, self.state.sup_y[self.sups[which]])
        pos_t = m.body_pos[self.win.sup_body[which]]
        pos_t += np.outer(self.sup_z[which] - self.state.sup_z[self.sups[which]], self.sim.frame.mat_tf[:, 2])
        m.body_pos[self.win.sup_body[which]] = pos_t
        self.t_set[which] = t_abs
        mujoco.mj_forward(m, d)

    def place(self, t: float) -> None:
        d, ix = self.win.data, self.win.index
        self.clearance = self.sim.roof_clearance(self.state, self.sups, self.t_begin + t, d.qpos[ix.sup_qpos[:, 0]],
                                                 self.sup_z, self.t_set)
        self.win.model.jnt_range[self.leg_jnt, 1] = self.clearance
