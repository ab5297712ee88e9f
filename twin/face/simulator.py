"""Face mechanics: pans and supports moved by their rams, simulated window by window in MuJoCo.

The face is slow, local and event-driven: a push touches the pans of the snake and the supports behind it,
nothing else. `FaceSimulator` compiles one window model (a run of pans with their supports and two mocap
anchors standing in for the neighbours) and moves it along the face: for each push event it loads the
window's part of the global `FaceState`, places its floor (a height field of fixed size under the window only:
model.FloorBand), drives the rams to their new targets as the hydraulics would (each at its flow-limited speed up
to its force limit, in real time scaled to a quasi-static speed, sampled as it goes: EventTrace), then the supports
set and the window settles, and writes the result back.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from twin.config.scenario import Scenario
from twin.face.connectors import connect_window
from twin.face.drift import stand_supports
from twin.face.hydraulics import LOWER_S, SET_S, VALVE_RAMP_S, RamHydraulics
from twin.face.layout import FaceFrame, Floor, joint_ends, pan_axes, support_stations
from twin.face.model import (
    RAM_DAMPING_N_S_M,
    RAM_GAIN_N_M,
    SUPPORT_FRICTION_LOWERED_N,
    SUPPORT_FRICTION_SET_N,
    FaceIndex,
    FloorBand,
    build_face_spec,
    index_face_model,
    place_floor,
)

QS_RAM_SPEED_M_S = 1.2
"""Speed at which MuJoCo moves the fastest ram of an event (faster than the real rams, slow enough that inertia
neither drags nor overshoots the pans); the event's real time is its simulated time scaled by the ratio k. Inertia is
k^2 times the real one: accelerating a pan shows in its ram's force, so the pressure truth carries transients at the
start of a push (up to relief for a drive frame). At 0.6 m/s the default run's 99th percentile pressure was 9.8 MPa
against 31.5 here, but seed004's twin ran at 321x real time against 479x here (issue 2's target: 400x)."""
RAM_SAMPLE_S = 0.25
"""Real time between the samples of an event's trace (the supports' truth rows while the rams move)."""
RAMP_FLOOR = 0.2
"""Least fraction of its metered speed a ram moves at while its valve ramps."""
ARRIVED_M = 1e-6
"""A ram's metered stroke this close to its goal has arrived."""
RELIEF_FRACTION = 0.99
"""A ram whose force is this fraction of its limit stands at its relief valve."""
STALL_S = 1.0
"""A ram standing at its relief valve this long has stalled: its valve closes where it stands (the push falls short)."""
STALL_SPEED_FRACTION = 0.1
"""A ram at its force limit moving slower than this fraction of its metered speed stands (faster, it is accelerating
its load: in the quasi-static time scale, inertia is k^2 times the real one)."""
VALVE_TIMEOUT_FACTOR = 1.5
"""A valve closes after this many times its ram's travel time (plus STALL_S) whatever the ram has reached."""
SETTLE_STEPS = 20
"""Steps after the supports are set again, for the window to come to rest."""
WINDOW_MARGIN_PANS = 2
"""Pans kept dynamic on each side of the pans an event touches."""
AFC_HOLD_N = 3.0e5
"""While supports advance, the rest of the AFC is held by the set supports' rams; the window stands in for
that hold with a sliding resistance on every pan (so a support pulls itself up, not its pan back)."""
OPEN_WALL_M = 1.0e6
"""A pan slide's limits where nothing stands in its way."""
DRIVE_FRAME_MASS_SCALE = 6.0
"""The end pans are the drive frames (gearbox, motors, sprocket): several times a line pan's mass."""
SKID_OFFSET_X_M = -1.5
"""Where the support base rests on the floor, behind the ram connection (support.xml)."""


@dataclass
class FaceState:
    """The whole face in F: pan states (N, 6), support base x and z, canopy leg, ram length and ram force [N]
    (positive pushing)."""

    pans: np.ndarray
    sup_x: np.ndarray
    sup_z: np.ndarray
    sup_leg: np.ndarray
    ram: np.ndarray
    ram_force: np.ndarray
    pan_wall_x: np.ndarray
    """Per pan, the x of an obstacle in front of it (an obstruction fault), or inf."""
    sup_y: np.ndarray
    """Per support, the y of its base: behind its pan, following it along the face (twin.face.drift)."""


@dataclass
class EventTrace:
    """The moved supports of an event through it, sampled in real time while their rams move: one row per sample
    (t_s since the event began), one column per support of `supports` (global indices)."""

    supports: np.ndarray
    t_s: np.ndarray
    ram: np.ndarray
    sup_x: np.ndarray
    ram_force: np.ndarray
    """Ram force [N], positive pushing the pan (twin.face.hydraulics.RamHydraulics.pressure_mpa)."""
    duration_s: float
    """From the event's beginning to its supports set again."""


class _TraceBuilder:
    """Collects an event's samples of the moved supports of a window (window order)."""

    def __init__(self, sups: np.ndarray, moved: np.ndarray):
        self.sups, self.moved = sups, moved
        self.rows: list[tuple[float, np.ndarray, np.ndarray, np.ndarray]] = []

    def sample(self, t: float, ram: np.ndarray, sup_x: np.ndarray, force: np.ndarray) -> None:
        mv = self.moved
        self.rows.append((t, ram[mv].copy(), sup_x[mv].copy(), force[mv].copy()))

    def build(self, duration_s: float) -> EventTrace:
        t = np.array([r[0] for r in self.rows], float)
        ram, sup_x, force = (np.array([r[i] for r in self.rows], float).reshape(t.size, int(self.moved.sum()))
                             for i in (1, 2, 3))
        return EventTrace(self.sups[self.moved], t, ram, sup_x, force, duration_s)


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
        self.hydraulics = RamHydraulics.from_scenario(scn.supports.hydraulics)
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
        state = FaceState(pans.copy(), sup_x, np.zeros(st.size), np.full(st.size, sup.canopy_height_m),
                          np.zeros(st.size), np.zeros(st.size), np.full(pans.shape[0], np.inf), np.zeros(st.size))
        stand_supports(self.scn, self.ram_site_local, state, np.arange(st.size))
        state.sup_z = self.support_z(sup_x, state.sup_y)
        state.ram = self.ram_lengths(state, np.zeros(st.size), sup_x)
        return state

    def support_z(self, sup_x: np.ndarray, sup_y: np.ndarray) -> np.ndarray:
        """Height of supports standing with their bases at `sup_x`, `sup_y`: the floor under their skids."""
        return self.floor.height(sup_x + SKID_OFFSET_X_M, sup_y)

    def _pan_ram_points(self, pans: np.ndarray) -> np.ndarray:
        return pans[:, :3] + pan_axes(pans) @ self.ram_site_local

    def ram_lengths(self, state: FaceState, pan_shift: np.ndarray, sup_x: np.ndarray) -> np.ndarray:
        """Ram lengths (per support) that put each support's pan `pan_shift` further towards the coal wall
        with the support base at `sup_x` (on the floor there): the stroke a push or an advance commands."""
        pan_site = self._pan_ram_points(state.pans)[self.stations]
        pan_site[:, 0] += pan_shift
        sup_site = np.column_stack([sup_x, state.sup_y, self.support_z(sup_x, state.sup_y)]) + self.sup_site_local
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
        # An obstacle in front of a pan: its advance slide limited there.
        wall = state.pan_wall_x[pans]
        x_joint = m.dof_jntid[ix.pan_dof[:, 0]]
        m.jnt_limited[x_joint] = np.isfinite(wall)
        m.jnt_range[x_joint] = np.column_stack([np.full(wall.size, -OPEN_WALL_M), np.minimum(wall, OPEN_WALL_M)])
        scale = np.where((pans == 0) | (pans == n - 1), DRIVE_FRAME_MASS_SCALE, 1.0)
        m.body_mass[win.pan_body] = win.pan_mass * scale
        m.body_inertia[win.pan_body] = win.pan_inertia * scale[:, None]
        d.qpos[ix.sup_qpos[:, 0]] = state.sup_x[sups]
        d.qpos[ix.sup_qpos[:, 1]] = state.sup_leg[sups]
        d.act[m.actuator_actadr[ix.ram_act]] = state.ram[sups]
        d.ctrl[ix.leg_act] = state.sup_leg[sups]
        y = state.sup_y[sups]
        m.body_pos[win.sup_body] = np.column_stack([np.zeros_like(y), y, state.sup_z[sups]]) @ self.frame.mat_tf.T
        start, end = joint_ends(state.pans, length)
        for side, (other, point) in enumerate(((first - 1, end), (first + win.count, start))):
            active = 0 <= other < n
            d.eq_active[ix.anchor_eq[side]] = active
            if active:
                d.mocap_pos[ix.anchor_mocap[side]] = self.frame.mat_tf @ point[other]
        # The connectors to the neighbours beyond the window limited around them, the couplers at their play.
        connect_window(m, d, ix, state.pans, first, length)
        mujoco.mj_forward(m, d)  # the rams' lengths and forces of the loaded state
        return pans, sups

    def _store(self, win: _Window, state: FaceState, pans: np.ndarray, sups: np.ndarray) -> None:
        d, ix = win.data, win.index
        state.pans[pans] = d.qpos[ix.pan_qpos]
        state.sup_x[sups] = d.qpos[ix.sup_qpos[:, 0]]
        state.sup_leg[sups] = d.qpos[ix.sup_qpos[:, 1]]
        state.ram[sups] = d.ten_length[ix.ram_tendon]
        state.ram_force[sups] = d.actuator_force[ix.ram_act]
        state.sup_z[sups] = self.support_z(state.sup_x[sups], state.sup_y[sups])

    def step_event(self, state: FaceState, moved: np.ndarray, target: np.ndarray, advancing: np.ndarray,
                   time_limit_s: float = np.inf) -> tuple[np.ndarray, np.ndarray, EventTrace]:
        """One push-advance event for the supports in `moved` (global per-support arrays), in real time.

        The supports flagged in `advancing` lower (LOWER_S), their rams pull them up to their pans while the
        AFC is held, and they set again (SET_S), each ram keeping the stroke it reached; the other moved rams
        push their pans, all at once. Every ram travels to its `target` length at its flow-limited speed
        (twin.face.hydraulics) and stops there, or where its load reaches its force limit (it stalls), or
        when the event's `time_limit_s` is up (its valve closes). A support that must push and then advance
        takes two events. Returns the pans and supports of the window that was simulated and the trace.
        """
        if np.any(advancing & ~moved):
            raise ValueError("an advancing support must be among the moved ones")
        moved_pans = self.stations[moved]
        win, first = self._window_for(int(moved_pans.min()), int(moved_pans.max()))
        m, d, ix = win.model, win.data, win.index
        pans, sups = self._load(win, state, first)
        adv = advancing[sups]
        act = d.act[m.actuator_actadr[ix.ram_act]]
        goal = np.where(moved[sups], target[sups], act)
        self._set_supports(win, adv, ~adv & (goal > act + ARRIVED_M))
        set_s = SET_S if adv.any() else VALVE_RAMP_S  # set again, or the valves closed and the window at rest
        trace = _TraceBuilder(sups, moved[sups])
        t_rams = self._drive_rams(win, goal, LOWER_S if adv.any() else 0.0, time_limit_s - set_s, trace)
        if adv.any():
            mujoco.mj_step(m, d, nstep=SETTLE_STEPS)  # the released supports come up to their rams
            # Setting closes the ram valves: each ram holds the stroke it has, pulling no further.
            d.act[m.actuator_actadr[ix.ram_act]] = d.ten_length[ix.ram_tendon]
            self._set_supports(win, np.zeros_like(adv))
        mujoco.mj_step(m, d, nstep=SETTLE_STEPS)
        self._store(win, state, pans, sups)
        return pans, sups, trace.build(t_rams + set_s)

    def _drive_rams(self, win: _Window, goal: np.ndarray, t0: float, t_limit: float,
                    trace: _TraceBuilder) -> float:
        """Meter every ram (window order) towards its `goal` length from real time t0; returns the real time
        when the last ram has arrived, stalled or timed out, or t_limit.

        MuJoCo steps the rams at their real speeds times one factor k (the fastest at the quasi-static
        QS_RAM_SPEED_M_S); real time is simulated time times k. Each ram's stroke leads its rod by the
        servo's compression under load; where that load reaches the cylinder's force limit the relief valve
        opens (the stroke is held at the limit, no wind-up), and a ram held there STALL_S has stalled.
        """
        m, d, ix, hyd = win.model, win.data, win.index, self.hydraulics
        adr = m.actuator_actadr[ix.ram_act]
        stroke = goal - d.act[adr]
        moving = np.abs(stroke) > ARRIVED_M
        if not moving.any():
            return t0
        # The pushes of an event are one group, metered to finish together (the longest at the push speed), so
        # the pans move as the snake's shape and no pan is pushed ahead of its neighbours against its bend limit;
        # each advancing support pulls at the pull speed.
        pushes = moving & (stroke > 0.0)
        speed = hyd.speed(stroke)
        if pushes.any():
            speed[pushes] *= stroke[pushes] / stroke[pushes].max()
        k = QS_RAM_SPEED_M_S / speed[moving].max()
        nstep = max(1, round(RAM_SAMPLE_S / (k * m.opt.timestep)))
        seg_sim = nstep * m.opt.timestep
        seg_real = seg_sim * k
        travel_s = np.divide(np.abs(stroke), speed, out=np.zeros_like(stroke), where=moving)
        deadline = t0 + VALVE_TIMEOUT_FACTOR * travel_s + STALL_S
        held_s = np.zeros(goal.size)
        t = t0
        while moving.any() and t < t_limit - 1e-9:
            # The valves open and close over VALVE_RAMP_S: the speed ramps up from the start and down towards the
            # goal (to a floor, so that the ram arrives).
            togo = np.abs(goal - d.act[adr])
            ramp = np.clip(np.minimum((t + seg_real - t0) / VALVE_RAMP_S, togo / (speed * VALVE_RAMP_S + 1e-12)),
                           RAMP_FLOOR, 1.0)
            reach = ramp * speed * k * seg_sim
            d.ctrl[ix.ram_act] = np.where(moving, np.clip(goal - d.act[adr], -reach, reach), 0.0) / seg_sim
            mujoco.mj_step(m, d, nstep=nstep)
            t += seg_real
            rod, rod_v = d.ten_length[ix.ram_tendon], d.ten_velocity[ix.ram_tendon]
            force = d.actuator_force[ix.ram_act]
            at_limit = (force >= RELIEF_FRACTION * hyd.force_push_n) | (force <= -RELIEF_FRACTION * hyd.force_pull_n)
            standing = at_limit & (np.abs(rod_v) < STALL_SPEED_FRACTION * speed * k)
            # The relief valve passes the flow the load does not take: a ram's stroke leads its rod by at most the
            # servo's compression under the limit force at the metered speed (no wind-up, so a rod held back, or
            # lagging its inertia, does not catch up faster than its flow), and by the limit force alone where the
            # ram stands.
            lead = (np.where(standing, 0.0, RAM_DAMPING_N_S_M * speed * k) + hyd.force_push_n) / RAM_GAIN_N_M
            trail = (np.where(standing, 0.0, RAM_DAMPING_N_S_M * speed * k) + hyd.force_pull_n) / RAM_GAIN_N_M
            d.act[adr] = np.clip(d.act[adr], rod - trail, rod + lead)
            held_s = np.where(standing & moving, held_s + seg_real, 0.0)
            moving &= (np.abs(goal - d.act[adr]) > ARRIVED_M) & (held_s < STALL_S) & (t < deadline)
            trace.sample(t, rod, d.qpos[ix.sup_qpos[:, 0]], force)
        d.ctrl[ix.ram_act] = 0.0
        short = np.abs(goal - d.act[adr]) > ARRIVED_M
        d.act[adr[short]] = d.ten_length[ix.ram_tendon[short]]  # valves closed where the rams stand
        return t

    def _set_supports(self, win: _Window, lowered: np.ndarray, pushing: np.ndarray | None = None) -> None:
        """Set every support of the window but those `lowered` (window order); hold the AFC at their pans and
        their neighbours, but for the pans of the `pushing` supports (their rams move them)."""
        ix, sup = win.index, self.scn.supports
        win.model.dof_frictionloss[ix.sup_dof[:, 0]] = np.where(lowered, SUPPORT_FRICTION_LOWERED_N,
                                                                SUPPORT_FRICTION_SET_N)
        win.data.ctrl[ix.leg_act] = np.where(lowered, sup.canopy_height_m - sup.lower_m, sup.canopy_height_m)
        at = np.zeros(ix.pans.size + 2, bool)  # padded by a pan each side
        at[self.stations[ix.supports[lowered]] - ix.pans[0] + 1] = True
        held = at[1:-1] | at[:-2] | at[2:]
        if pushing is not None:
            held[self.stations[ix.supports[pushing]] - ix.pans[0]] = False
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
