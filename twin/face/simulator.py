"""Face mechanics: pans and supports moved by their rams, simulated window by window in MuJoCo.

The face is slow, local and event-driven: a push touches the pans of the snake and the supports behind it,
nothing else. `FaceSimulator` compiles one window model (a run of pans with their supports and two mocap
anchors standing in for the neighbours) and moves it along the face: for each push event it loads the
window's part of the global `FaceState`, places its floor (a height field of fixed size under the window only:
model.FloorBand), drives the rams to their new targets (quasi-static: the rams move over a fixed number of steps,
then the supports set and the window settles) and writes the result back.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from twin.config.scenario import Scenario
from twin.face.connectors import connect_window
from twin.face.layout import FaceFrame, Floor, joint_ends, pan_axes, support_stations
from twin.face.model import (
    SUPPORT_FRICTION_LOWERED_N,
    SUPPORT_FRICTION_SET_N,
    FaceIndex,
    FloorBand,
    build_face_spec,
    index_face_model,
    place_floor,
)

QS_RAM_SPEED_M_S = 1.2
"""Ram speed of the quasi-static event simulation (faster than the real rams, slow enough that inertia
neither drags nor overshoots the pans)."""
MIN_MOVE_STEPS = 10
"""Fewest steps of a ram move."""
RAM_STILL_M = 1e-4
"""A ram commanded less than this is not pushing."""
SETTLE_STEPS = 20
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
    """The whole face in F: pan states (N, 6), support base x and z, canopy leg and ram length."""

    pans: np.ndarray
    sup_x: np.ndarray
    sup_z: np.ndarray
    sup_leg: np.ndarray
    ram: np.ndarray


@dataclass
class _Window:
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

    @classmethod
    def compile(cls, scn: Scenario, floor: Floor, count: int) -> "_Window":
        band = FloorBand.for_window(scn, floor, count)
        model = build_face_spec(scn, band, 0, count, anchors=True).compile()
        index = index_face_model(model, scn, 0, count)
        pan_body = np.array([model.body(f"pan{i}_pan").id for i in index.pans], int)
        sup_body = np.array([model.body(f"sup{j}_support").id for j in index.supports], int)
        return cls(count, band, model, mujoco.MjData(model), index, pan_body, model.body_mass[pan_body].copy(),
                   model.body_inertia[pan_body].copy(), sup_body)


class FaceSimulator:
    """Steps windows of the face model: compiled once per window size, moved along the face."""

    def __init__(self, scn: Scenario, floor: Floor, window_sizes: list[int]):
        self.scn = scn
        self.floor = floor
        self.frame = FaceFrame(np.radians(scn.face.azimuth_deg))
        self.stations = support_stations(scn)
        k, n = scn.supports.pans_per_support, scn.face.pan_count
        counts = sorted({min(n, int(np.ceil(c / k)) * k) for c in window_sizes})
        self.windows = [_Window.compile(scn, floor, c) for c in counts]
        model = self.windows[0].model
        self.ram_site_local = np.array(model.site("pan0_ram").pos)
        self.sup_site_local = np.array(model.site(f"sup{self.windows[0].index.supports[0]}_ram").pos)

    # -- geometry ---------------------------------------------------------------------------------------
    def initial_supports(self, pans: np.ndarray, ram_extension_m: float = 0.0) -> FaceState:
        """Supports set behind their pans with the rams at their set length plus `ram_extension_m`."""
        sup = self.scn.supports
        st = self.stations
        sup_x = self._pan_ram_points(pans)[st, 0] - sup.ram_length_set_m - ram_extension_m
        y = (st + 0.5) * self.scn.face.pan_length_m
        sup_z = self.floor.height(sup_x + SKID_OFFSET_X_M, y)
        state = FaceState(pans.copy(), sup_x, sup_z, np.full(st.size, sup.canopy_height_m), np.zeros(st.size))
        state.ram = self.ram_lengths(state, np.zeros(st.size), sup_x)
        return state

    def _pan_ram_points(self, pans: np.ndarray) -> np.ndarray:
        return pans[:, :3] + pan_axes(pans) @ self.ram_site_local

    def ram_lengths(self, state: FaceState, pan_shift: np.ndarray, sup_x: np.ndarray) -> np.ndarray:
        """Ram lengths (per support) that put each support's pan `pan_shift` further towards the coal wall
        with the support base at `sup_x` (on the floor there): the stroke a push or an advance commands."""
        y = (self.stations + 0.5) * self.scn.face.pan_length_m
        pan_site = self._pan_ram_points(state.pans)[self.stations]
        pan_site[:, 0] += pan_shift
        sup_z = self.floor.height(sup_x + SKID_OFFSET_X_M, y)
        sup_site = np.column_stack([sup_x, y, sup_z]) + self.sup_site_local
        return np.linalg.norm(pan_site - sup_site, axis=1)

    # -- window stepping --------------------------------------------------------------------------------
    def _window_for(self, lo: int, hi: int) -> tuple[_Window, int]:
        """The smallest window covering pans lo..hi (inclusive) with margins, and its first pan."""
        n, k = self.scn.face.pan_count, self.scn.supports.pans_per_support
        need = hi - lo + 1 + 2 * WINDOW_MARGIN_PANS
        win = next((w for w in self.windows if w.count >= min(need, n)), None)
        if win is None:
            raise ValueError(f"event spans pans {lo}..{hi}, more than the largest window "
                             f"({self.windows[-1].count} pans)")
        first = int(np.clip((lo + hi) // 2 - win.count // 2, 0, n - win.count))
        return win, first - first % k

    def _load(self, win: _Window, state: FaceState, first: int) -> tuple[np.ndarray, np.ndarray]:
        m, d, ix = win.model, win.data, win.index
        n, length = self.scn.face.pan_count, self.scn.face.pan_length_m
        pans = np.arange(first, first + win.count)
        sups = np.flatnonzero((self.stations >= first) & (self.stations < first + win.count))
        mujoco.mj_resetData(m, d)
        place_floor(m, d, *win.band.place(self.floor, float(state.pans[pans, 0].min()), first * length),
                    self.frame.mat_tf)
        d.qpos[ix.pan_qpos] = state.pans[pans]
        scale = np.where((pans == 0) | (pans == n - 1), DRIVE_FRAME_MASS_SCALE, 1.0)
        m.body_mass[win.pan_body] = win.pan_mass * scale
        m.body_inertia[win.pan_body] = win.pan_inertia * scale[:, None]
        d.qpos[ix.sup_qpos[:, 0]] = state.sup_x[sups]
        d.qpos[ix.sup_qpos[:, 1]] = state.sup_leg[sups]
        d.act[m.actuator_actadr[ix.ram_act]] = state.ram[sups]
        d.ctrl[ix.leg_act] = state.sup_leg[sups]
        y = (self.stations[sups] + 0.5) * length
        m.body_pos[win.sup_body] = np.column_stack([np.zeros_like(y), y, state.sup_z[sups]]) @ self.frame.mat_tf.T
        start, end = joint_ends(state.pans, length)
        for side, (other, point) in enumerate(((first - 1, end), (first + win.count, start))):
            active = 0 <= other < n
            d.eq_active[ix.anchor_eq[side]] = active
            if active:
                d.mocap_pos[ix.anchor_mocap[side]] = self.frame.mat_tf @ point[other]
        # The connectors to the neighbours beyond the window limited around them, the couplers at their play.
        connect_window(m, d, ix, state.pans, first, length)
        return pans, sups

    def _store(self, win: _Window, state: FaceState, pans: np.ndarray, sups: np.ndarray) -> None:
        d, ix = win.data, win.index
        state.pans[pans] = d.qpos[ix.pan_qpos]
        state.sup_x[sups] = d.qpos[ix.sup_qpos[:, 0]]
        state.sup_leg[sups] = d.qpos[ix.sup_qpos[:, 1]]
        state.ram[sups] = d.ten_length[ix.ram_tendon]
        y = (self.stations[sups] + 0.5) * self.scn.face.pan_length_m
        state.sup_z[sups] = self.floor.height(state.sup_x[sups] + SKID_OFFSET_X_M, y)

    def step_event(self, state: FaceState, moved: np.ndarray, push_target: np.ndarray,
                   final_target: np.ndarray, advancing: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One push-advance event for the supports in `moved` (global per-support arrays).

        Push: every support set, the rams travel to `push_target`, pushing their pans. Advance: supports
        flagged in `advancing` are lowered and released, their rams travel to `final_target` pulling them
        up to their pans while the AFC is held, and then set, each ram keeping the stroke it reached.
        Rams move over a fixed number of steps (quasi-static); the caller times the event from the ram
        speed. Returns the pans and supports of the window that was simulated.
        """
        moved_pans = self.stations[moved]
        win, first = self._window_for(int(moved_pans.min()), int(moved_pans.max()))
        m, d, ix = win.model, win.data, win.index
        pans, sups = self._load(win, state, first)
        push = np.where(moved[sups], push_target[sups] - state.ram[sups], 0.0)
        pull = np.where(advancing[sups] & moved[sups], final_target[sups] - push_target[sups], 0.0)
        adv = pull != 0.0
        # A support that is pushed and advanced in one event pushes first; otherwise pushes and advances
        # run together (the advancing supports' pans are already home, and only they are held).
        together = not np.any(adv & (np.abs(push) > RAM_STILL_M))
        self._set_supports(win, adv if together else np.zeros_like(adv))
        self._move_rams(win, push + pull if together else push)
        if adv.any():
            if not together:
                self._set_supports(win, adv)
                self._move_rams(win, pull)
            mujoco.mj_step(m, d, nstep=SETTLE_STEPS)  # the released supports come up to their rams
            # Setting closes the ram valves: each ram holds the stroke it has, pulling no further.
            d.act[m.actuator_actadr[ix.ram_act]] = d.ten_length[ix.ram_tendon]
            self._set_supports(win, np.zeros_like(adv))
        mujoco.mj_step(m, d, nstep=SETTLE_STEPS)
        self._store(win, state, pans, sups)
        return pans, sups

    @staticmethod
    def _move_rams(win: _Window, travel: np.ndarray) -> None:
        """Drive the rams by `travel` (window order) at the quasi-static ram speed, then hold."""
        m, d, ix = win.model, win.data, win.index
        longest = np.abs(travel).max(initial=0.0)
        steps = max(MIN_MOVE_STEPS, int(np.ceil(longest / (QS_RAM_SPEED_M_S * m.opt.timestep))))
        d.ctrl[ix.ram_act] = travel / (steps * m.opt.timestep)
        mujoco.mj_step(m, d, nstep=steps)
        d.ctrl[ix.ram_act] = 0.0

    def _set_supports(self, win: _Window, lowered: np.ndarray) -> None:
        """Set every support of the window but those `lowered` (window order); hold their pans' AFC."""
        ix, sup = win.index, self.scn.supports
        win.model.dof_frictionloss[ix.sup_dof[:, 0]] = np.where(lowered, SUPPORT_FRICTION_LOWERED_N,
                                                                SUPPORT_FRICTION_SET_N)
        win.data.ctrl[ix.leg_act] = np.where(lowered, sup.canopy_height_m - sup.lower_m, sup.canopy_height_m)
        held = np.zeros(ix.pans.size, bool)
        held[self.stations[ix.supports[lowered]] - ix.pans[0]] = True
        held |= np.roll(held, 1) | np.roll(held, -1)
        win.model.dof_frictionloss[ix.pan_dof[:, :2]] = np.where(held, AFC_HOLD_N, 0.0)[:, None]

    def settle(self, state: FaceState) -> None:
        """Let the whole face come to rest on the floor, window by window from the headgate."""
        win = self.windows[-1]
        n = self.scn.face.pan_count
        starts = list(range(0, max(1, n - win.count + 1), max(1, win.count // 2))) + [n - win.count]
        for first in starts:
            pans, sups = self._load(win, state, first)
            self._set_supports(win, np.zeros(win.index.supports.size, bool))
            mujoco.mj_step(win.model, win.data, nstep=2 * SETTLE_STEPS)
            self._store(win, state, pans, sups)
