"""Face mechanics: pans and supports moved by their rams, simulated window by window in MuJoCo.

The face is slow, local and event-driven: a push touches the pans of the snake and the supports behind it,
nothing else. `FaceSimulator` compiles one window model (a run of pans with their supports and two mocap
anchors standing in for the neighbours) and moves it along the face: for each push event it loads the
window's part of the global `FaceState`, drives the rams to their new targets (quasi-static: the rams move
over a fixed number of steps, then the supports set and the window settles) and writes the result back.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from twin.layout import PAN_WIDTH_M, FaceFrame, Floor, joint_ends, support_stations
from twin.model import (SUPPORT_FRICTION_LOWERED_N, SUPPORT_FRICTION_SET_N, FloorGrid, build_face_spec,
                        index_face_model)
from twin.scenario import Scenario

MOVE_STEPS = 40
"""Steps over which the rams travel to their targets in one event (quasi-static)."""
MAX_PUSH_PER_PHASE_M = 0.15
"""A longer push (the end pans during snake sumping) is spread over several move phases."""
SETTLE_STEPS = 40
"""Steps after the supports are set again, for the window to come to rest."""
WINDOW_MARGIN_PANS = 2
"""Pans kept dynamic on each side of the pans an event touches."""
AFC_HOLD_N = 3.0e5
"""While supports advance, the rest of the AFC is held by the set supports' rams; the window stands in for
that hold with a sliding resistance on every pan (so a support pulls itself up, not its pan back)."""
DRIVE_FRAME_MASS_SCALE = 6.0
"""The end pans are the drive frames (gearbox, motors, sprocket): several times a line pan's mass."""
SKID_OFFSET_X_M = -1.5
"""Where the support base rests on the floor, behind the ram connection (support.xml)."""


@dataclass
class FaceState:
    """The whole face in F: pan states (N, 6), support base x and z, canopy leg, ram length and target."""

    pans: np.ndarray
    sup_x: np.ndarray
    sup_z: np.ndarray
    sup_leg: np.ndarray
    ram: np.ndarray
    ram_target: np.ndarray
    sup_set: np.ndarray = field(default=None)

    def copy(self) -> "FaceState":
        return FaceState(*(np.array(getattr(self, k)) for k in
                           ("pans", "sup_x", "sup_z", "sup_leg", "ram", "ram_target", "sup_set")))


class FaceSimulator:
    """Steps windows of the face model; one compiled model moved along the face."""

    def __init__(self, scn: Scenario, floor: Floor, window_pans: int):
        self.scn = scn
        self.floor = floor
        self.frame = FaceFrame(np.radians(scn.face.azimuth_deg))
        self.grid = FloorGrid.from_scenario(scn, floor)
        self.stations = support_stations(scn)
        k = scn.supports.pans_per_support
        n = scn.face.pan_count
        count = min(n, int(np.ceil(window_pans / k)) * k)
        self.count = count
        first = 0
        self.model = build_face_spec(scn, self.grid, first, count, anchors=True).compile()
        self.index = index_face_model(self.model, scn, first, count)
        self.data = mujoco.MjData(self.model)
        self.pan_body = np.array([self.model.body(f"pan{i}_pan").id for i in self.index.pans], int)
        self.pan_mass = self.model.body_mass[self.pan_body].copy()
        self.pan_inertia = self.model.body_inertia[self.pan_body].copy()
        self.sup_body = np.array([self.model.body(f"sup{j}_support").id for j in self.index.supports], int)
        self.ram_site_local = np.array(self.model.site("pan0_ram").pos)
        self.sup_site_local = np.array(self.model.site(f"sup{self.index.supports[0]}_ram").pos)

    # -- geometry helpers -------------------------------------------------------------------------------
    def initial_supports(self, pans: np.ndarray) -> FaceState:
        """Supports set behind their pans with the rams at their set length, skids on the floor."""
        sup = self.scn.supports
        st = self.stations
        ram_pan = self._pan_ram_points(pans)[st]
        # Ram from the support site (base x, z + site height) to the pan's ram site, horizontal in x.
        sup_x = ram_pan[:, 0] - sup.ram_length_set_m
        y = (st + 0.5) * self.scn.face.pan_length_m
        sup_z = self.floor.height(sup_x + SKID_OFFSET_X_M, y)
        ram = np.linalg.norm(ram_pan - np.column_stack([sup_x, y, sup_z + self.sup_site_local[2]]), axis=1)
        leg = np.full(st.size, sup.canopy_height_m)
        return FaceState(pans.copy(), sup_x, sup_z, leg, ram, ram.copy(), np.ones(st.size, bool))

    def _pan_ram_points(self, pans: np.ndarray) -> np.ndarray:
        from twin.layout import pan_axes
        return pans[:, :3] + pan_axes(pans) @ self.ram_site_local

    # -- window stepping --------------------------------------------------------------------------------
    def window_start(self, lo: int, hi: int) -> int:
        """First pan of a window covering pans lo..hi (inclusive) with margins, on a support boundary."""
        n, k = self.scn.face.pan_count, self.scn.supports.pans_per_support
        if hi - lo + 1 + 2 * WINDOW_MARGIN_PANS > self.count and self.count < n:
            raise ValueError(f"event spans pans {lo}..{hi}, more than the {self.count}-pan window")
        centre = (lo + hi) // 2
        first = int(np.clip(centre - self.count // 2, 0, n - self.count))
        return first - first % k

    def _load(self, state: FaceState, first: int) -> np.ndarray:
        m, d, ix = self.model, self.data, self.index
        n, length = self.scn.face.pan_count, self.scn.face.pan_length_m
        pans = np.arange(first, first + self.count)
        sups = np.flatnonzero((self.stations >= first) & (self.stations < first + self.count))
        mujoco.mj_resetData(m, d)
        d.qpos[ix.pan_qpos] = state.pans[pans]
        scale = np.where((pans == 0) | (pans == n - 1), DRIVE_FRAME_MASS_SCALE, 1.0)
        m.body_mass[self.pan_body] = self.pan_mass * scale
        m.body_inertia[self.pan_body] = self.pan_inertia * scale[:, None]
        d.qpos[ix.sup_qpos[:, 0]] = state.sup_x[sups]
        d.qpos[ix.sup_qpos[:, 1]] = state.sup_leg[sups]
        d.act[m.actuator_actadr[ix.ram_act]] = state.ram[sups]
        d.ctrl[ix.leg_act] = state.sup_leg[sups]
        y = (self.stations[sups] + 0.5) * length
        z = state.sup_z[sups]
        m.body_pos[self.sup_body] = np.column_stack([np.zeros_like(y), y, z]) @ self.frame.mat_tf.T
        start, end = joint_ends(state.pans, length)
        for side, (other, point) in enumerate(((first - 1, end), (first + self.count, start))):
            active = 0 <= other < n
            d.eq_active[ix.anchor_eq[side]] = active
            if active:
                d.mocap_pos[ix.anchor_mocap[side]] = self.frame.mat_tf @ point[other]
        return sups

    def _store(self, state: FaceState, first: int, sups: np.ndarray) -> None:
        d, ix = self.data, self.index
        pans = np.arange(first, first + self.count)
        state.pans[pans] = d.qpos[ix.pan_qpos]
        state.sup_x[sups] = d.qpos[ix.sup_qpos[:, 0]]
        state.sup_leg[sups] = d.qpos[ix.sup_qpos[:, 1]]
        state.ram[sups] = d.ten_length[ix.ram_tendon]

    def step_event(self, state: FaceState, first: int, push_target: np.ndarray, final_target: np.ndarray,
                   advancing: np.ndarray) -> None:
        """One push-advance event on the window starting at pan `first` (targets are global, per support).

        Push: every support set, the rams travel to `push_target`, pushing their pans. Advance: supports
        flagged in `advancing` are lowered and released and their rams travel to `final_target`, pulling
        them up to their pans. Then every support sets and the window settles. Rams move over a fixed
        number of steps (quasi-static); the caller times the event from the ram speed.
        """
        m, d, ix = self.model, self.data, self.index
        sups = self._load(state, first)
        sup = self.scn.supports
        dofs = ix.sup_dof[:, 0]
        duration = MOVE_STEPS * m.opt.timestep
        m.dof_frictionloss[dofs] = SUPPORT_FRICTION_SET_N
        push = push_target[sups] - state.ram[sups]
        phases = max(1, int(np.ceil(np.abs(push).max(initial=0.0) / MAX_PUSH_PER_PHASE_M)))
        d.ctrl[ix.ram_act] = push / (phases * duration)
        for _ in range(phases):
            mujoco.mj_step(m, d, nstep=MOVE_STEPS)
        adv = advancing[sups]
        if adv.any():
            m.dof_frictionloss[dofs] = np.where(adv, SUPPORT_FRICTION_LOWERED_N, SUPPORT_FRICTION_SET_N)
            m.dof_frictionloss[ix.pan_dof[:, :2]] = AFC_HOLD_N
            d.ctrl[ix.leg_act] = np.where(adv, sup.canopy_height_m - sup.lower_m, sup.canopy_height_m)
            d.ctrl[ix.ram_act] = (final_target[sups] - push_target[sups]) / duration
            mujoco.mj_step(m, d, nstep=MOVE_STEPS)
            d.ctrl[ix.ram_act] = 0.0
            mujoco.mj_step(m, d, nstep=SETTLE_STEPS)  # the released supports come up to their rams
            m.dof_frictionloss[dofs] = SUPPORT_FRICTION_SET_N
            m.dof_frictionloss[ix.pan_dof[:, :2]] = 0.0
            d.ctrl[ix.leg_act] = sup.canopy_height_m
        d.ctrl[ix.ram_act] = 0.0
        mujoco.mj_step(m, d, nstep=SETTLE_STEPS)
        self._store(state, first, sups)
        state.ram_target[sups] = final_target[sups]
        y = (self.stations[sups] + 0.5) * self.scn.face.pan_length_m
        state.sup_z[sups] = self.floor.height(state.sup_x[sups] + SKID_OFFSET_X_M, y)

    def settle(self, state: FaceState) -> None:
        """Let the whole face come to rest on the floor, window by window from the headgate."""
        n = self.scn.face.pan_count
        starts = range(0, max(1, n - self.count + 1), max(1, self.count // 2))
        for first in list(starts) + [n - self.count]:
            self.step_event(state, first, state.ram_target, state.ram_target, np.zeros(self.stations.size, bool))
        state.ram_target[:] = state.ram
