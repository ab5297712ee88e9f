"""Face mechanics: pans and supports moved by their rams, simulated window by window in MuJoCo.

The face is slow, local and event-driven: a push touches the pans of the snake and the supports behind it,
nothing else. `FaceSimulator` compiles one window model (a run of pans with their supports and two mocap
anchors standing in for the neighbours) and moves it along the face: for each push event it loads the
window's part of the global `FaceState`, places its floor (a height field of fixed size under the window only:
model.FloorBand) and the roof over its canopies (the legs' slide limits), lowers the supports that advance (their
legs' valves open), drives the rams to their new targets as the hydraulics would (each at its flow-limited speed up
to its force limit), sets the advanced supports against the roof to their set load, each phase in real time scaled
to a quasi-static speed and sampled as it goes (EventTrace), lets the window settle, and writes the result back.
Between events the set supports' legs are held closed while the roof converges on them (`hold_legs`, the same
hydraulics in closed form, which a test checks against MuJoCo). The window, the state and the trace are
twin.face.window's; the legs' lowering and setting twin.face.leg_phases'.
"""

from __future__ import annotations

import mujoco
import numpy as np

from twin.config.scenario import Scenario
from twin.face.connectors import connect_window
from twin.face.drift import stand_supports
from twin.face.hydraulics import CANOPY_CENTRE_X_M, CANOPY_TOP_M, VALVE_RAMP_S, SupportHydraulics
from twin.face.layout import FaceFrame, Floor, Roof, joint_ends, pan_axes, support_stations
from twin.face.leg_phases import drive_legs, leak, leg_valves
from twin.face.model import (
    RAM_DAMPING_N_S_M,
    RAM_GAIN_N_M,
    SUPPORT_FRICTION_LOWERED_N,
    SUPPORT_GRIP,
    place_floor,
)
from twin.face.window import (
    ARRIVED_M,
    RAM_SAMPLE_S,
    RAMP_FLOOR,
    STALL_S,
    VALVE_TIMEOUT_FACTOR,
    EventTrace,
    FaceState,
    RoofLimits,
    TraceBuilder,
    Window,
)

QS_RAM_SPEED_M_S = 1.2
"""Speed at which MuJoCo moves the fastest ram of an event (faster than the real rams, slow enough that inertia
neither drags nor overshoots the pans); the event's real time is its simulated time scaled by the ratio k. Inertia is
k^2 times the real one: accelerating a pan shows in its ram's force, so the pressure truth carries transients at the
start of a push (up to relief for a drive frame). At 0.6 m/s the default run's 99th percentile pressure was 9.8 MPa
against 31.5 here, but seed004's twin ran at 321x real time against 479x here (issue 2's target: 400x)."""
RELIEF_FRACTION = 0.99
"""A ram whose force is this fraction of its limit stands at its relief valve."""
STALL_SPEED_FRACTION = 0.1
"""A ram at its force limit moving slower than this fraction of its metered speed stands (faster, it is accelerating
its load: in the quasi-static time scale, inertia is k^2 times the real one)."""
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


class FaceSimulator:
    """Steps windows of the face model: compiled once per window size, moved along the face."""

    def __init__(self, scn: Scenario, floor: Floor, window_sizes: list[int]):
        self.scn = scn
        self.floor = floor
        self.roof = Roof.from_scenario(scn, floor)
        self.convergence_m_s = scn.roof.convergence_mm_h * 1e-3 / 3600.0
        self.frame = FaceFrame(np.radians(scn.face.azimuth_deg))
        self.stations = support_stations(scn)
        k, n = scn.supports.pans_per_support, scn.face.pan_count
        counts = sorted({min(n, int(np.ceil(c / k)) * k) for c in window_sizes})
        self.hydraulics = SupportHydraulics.from_scenario(scn.supports, scn.roof)
        self.windows = [Window.compile(scn, floor, c) for c in counts]
        model = self.windows[0].model
        self.ram_site_local = np.array(model.site("pan0_ram").pos)
        self.sup_site_local = np.array(model.site(f"sup{self.windows[0].index.supports[0]}_ram").pos)

    # -- geometry ---------------------------------------------------------------------------------------
    def initial_supports(self, pans: np.ndarray, ram_extension_m: float = 0.0) -> FaceState:
        """Supports set to their set load behind their pans, with the rams at their set length plus
        `ram_extension_m`, at time 0."""
        sup, legs = self.scn.supports, self.hydraulics.legs
        st = self.stations
        n = st.size
        sup_x = self._pan_ram_points(pans)[st, 0] - sup.ram_length_set_m - ram_extension_m
        zeros = np.zeros(n)
        state = FaceState(pans=pans.copy(), sup_x=sup_x, sup_z=zeros.copy(), sup_leg=zeros.copy(), ram=zeros.copy(),
                          ram_force=zeros.copy(), leg_oil=zeros.copy(), leg_force=np.full(n, legs.force_set_n),
                          leg_t=zeros.copy(), t_set=zeros.copy(), pan_wall_x=np.full(pans.shape[0], np.inf),
                          ram_speed_factor=np.ones(n), leg_leak_m_s=zeros.copy(),
                          set_force_n=np.full(n, legs.force_set_n), sup_y=zeros.copy())
        stand_supports(self.scn, self.ram_site_local, state, np.arange(n))
        state.sup_z = self.support_z(sup_x, state.sup_y)
        state.sup_leg = self.roof_clearance(state, np.arange(n), 0.0)
        state.leg_oil = state.sup_leg + legs.squeeze_set_m
        state.ram = self.ram_lengths(state, zeros, sup_x)
        return state

    def support_z(self, sup_x: np.ndarray, sup_y: np.ndarray) -> np.ndarray:
        """Height of supports standing with their bases at `sup_x`, `sup_y`: the floor under their skids."""
        return self.floor.height(sup_x + SKID_OFFSET_X_M, sup_y)

    def roof_clearance(self, state: FaceState, sups: np.ndarray, t: float, sup_x: np.ndarray | None = None,
                       sup_z: np.ndarray | None = None, t_set: np.ndarray | None = None) -> np.ndarray:
        """How far the legs of supports `sups` (with their bases at `sup_x`, `sup_z`, set at `t_set`; default: the
        state's) reach to the roof at time t: the roof over their canopies, converged since they were set."""
        x = state.sup_x[sups] if sup_x is None else sup_x
        z = state.sup_z[sups] if sup_z is None else sup_z
        since = t - (state.t_set[sups] if t_set is None else t_set)
        return (self.roof.height(x + CANOPY_CENTRE_X_M, state.sup_y[sups]) - self.convergence_m_s * np.maximum(since, 0.0) - z
                - CANOPY_TOP_M)

    def hold_legs(self, state: FaceState, t: float) -> None:
        """Bring the supports' legs whose state is older than t to t with their valves closed (LegHydraulics.hold):
        the roof converging squeezes them up to yield, a leak relieves them and lowers the canopy."""
        legs = self.hydraulics.legs
        sups = np.flatnonzero(state.leg_t < t)
        dt = t - state.leg_t[sups]
        # The roof where a loaded canopy stands (MuJoCo's limit with its fraction of a millimetre of give), or the
        # roof's surface over a canopy hanging below it; converging on since.
        loaded = state.leg_oil[sups] > state.sup_leg[sups]
        c_then = np.where(loaded, state.sup_leg[sups], self.roof_clearance(state, sups, state.leg_t[sups]))
        c_now = c_then - self.convergence_m_s * np.minimum(dt, np.maximum(t - state.t_set[sups], 0.0))
        g = legs.hold(state.leg_oil[sups] - c_then, dt, self.convergence_m_s, state.leg_leak_m_s[sups])
        state.leg_oil[sups] = c_now + g
        state.sup_leg[sups] = c_now + np.minimum(g, 0.0)
        state.leg_force[sups] = legs.force_n(g)
        state.leg_t[sups] = t

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
    def _window_for(self, lo: int, hi: int) -> tuple[Window, int]:
        """The smallest window covering pans lo..hi (inclusive) with margins, and its first pan."""
        n, k = self.scn.face.pan_count, self.scn.supports.pans_per_support
        need = hi - lo + 1 + 2 * WINDOW_MARGIN_PANS
        win = next((w for w in self.windows if w.count >= min(need, n)), None)
        if win is None:
            raise ValueError(f"event spans pans {lo}..{hi}, more than the largest window "
                             f"({self.windows[-1].count} pans)")
        first = int(np.clip((lo + hi) // 2 - win.count // 2, 0, n - win.count))
        return win, first - first % k

    def _load(self, win: Window, state: FaceState, first: int) -> tuple[np.ndarray, np.ndarray]:
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
        d.act[m.actuator_actadr[ix.leg_act]] = state.leg_oil[sups]
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
        mujoco.mj_forward(m, d)  # the rams' and legs' lengths and forces of the loaded state
        return pans, sups

    def _store(self, win: Window, state: FaceState, pans: np.ndarray, sups: np.ndarray, t: float) -> None:
        m, d, ix = win.model, win.data, win.index
        state.pans[pans] = d.qpos[ix.pan_qpos]
        state.sup_x[sups] = d.qpos[ix.sup_qpos[:, 0]]
        state.sup_leg[sups] = d.qpos[ix.sup_qpos[:, 1]]
        state.leg_oil[sups] = d.act[m.actuator_actadr[ix.leg_act]]
        state.ram[sups] = d.ten_length[ix.ram_tendon]
        state.ram_force[sups] = d.actuator_force[ix.ram_act]
        state.leg_force[sups] = win.leg_load()
        state.leg_t[sups] = t
        state.sup_z[sups] = self.support_z(state.sup_x[sups], state.sup_y[sups])

    def step_event(self, state: FaceState, moved: np.ndarray, target: np.ndarray, advancing: np.ndarray,
                   t_begin_s: float = 0.0, time_limit_s: float = np.inf
                   ) -> tuple[np.ndarray, np.ndarray, EventTrace]:
        """One push-advance event for the supports in `moved` (global per-support arrays), from `t_begin_s`, in
        real time.

        The supports flagged in `advancing` lower (their legs' valves release the load and the canopy drops
        supports.lower_m), their rams pull them up to their pans while the AFC is held, and they set again against
        the roof to their set load, each ram keeping the stroke it reached; the other moved rams push their pans,
        all at once. Every ram travels to its `target` length at its flow-limited speed (twin.face.hydraulics) and
        stops there, or where its load reaches its force limit (it stalls), or when the event's `time_limit_s` is up
        (its valve closes). A support that must push and then advance takes two events. The state's legs must hold
        at t_begin_s (hold_legs). Returns the pans and supports of the window that was simulated and the trace.
        """
        if np.any(advancing & ~moved):
            raise ValueError("an advancing support must be among the moved ones")
        moved_pans = self.stations[moved]
        win, first = self._window_for(int(moved_pans.min()), int(moved_pans.max()))
        m, d, ix = win.model, win.data, win.index
        pans, sups = self._load(win, state, first)
        roof = RoofLimits(self, win, state, sups, t_begin_s)
        adv = advancing[sups]
        act = d.act[m.actuator_actadr[ix.ram_act]]
        goal = np.where(moved[sups], target[sups], act)
        self._set_supports(win, adv, ~adv & (goal > act + ARRIVED_M))
        trace = TraceBuilder(win, sups, moved[sups])
        lower_m = self.scn.supports.lower_m
        legs = self.hydraulics.legs
        if adv.any():
            t = drive_legs(win, legs, state, sups, adv, roof, lower_m, False, 0.0, trace)
            set_s = legs.set_s(lower_m)
        else:
            t, set_s = 0.0, VALVE_RAMP_S  # the valves closed and the window at rest
        t = self._drive_rams(win, state, sups, goal, roof, t, time_limit_s - set_s, trace)
        if adv.any():
            mujoco.mj_step(m, d, nstep=SETTLE_STEPS)  # the released supports come up to their rams
            # Setting closes the ram valves: each ram holds the stroke it has, pulling no further.
            d.act[m.actuator_actadr[ix.ram_act]] = d.ten_length[ix.ram_tendon]
            roof.advance(adv, t_begin_s + t)  # on the floor and under fresh roof where they stand now
            t = drive_legs(win, legs, state, sups, adv, roof, lower_m, True, t, trace)
            state.t_set[sups[adv]] = t_begin_s + t
            self._set_supports(win, np.zeros_like(adv))
            t_legs = t
        else:
            t_legs = t
            t += set_s  # the valves closing: the legs' state holds at t_legs (hold_legs brings it on)
        mujoco.mj_step(m, d, nstep=SETTLE_STEPS)
        if adv.any():  # the setting valves close at the set load once the canopies have come to rest on the roof
            leg_valves(win, legs, np.where(adv, state.set_force_n[sups], legs.force_yield_n))
        self._store(win, state, pans, sups, t_begin_s + t_legs)
        return pans, sups, trace.build(t)

    def _drive_rams(self, win: Window, state: FaceState, sups: np.ndarray, goal: np.ndarray, roof: RoofLimits,
                    t0: float, t_limit: float, trace: TraceBuilder) -> float:
        """Meter every ram (window order) towards its `goal` length from real time t0; returns the real time
        when the last ram has arrived, stalled or timed out, or t_limit.

        MuJoCo steps the rams at their real speeds times one factor k (the fastest at the quasi-static
        QS_RAM_SPEED_M_S); real time is simulated time times k. Each ram's stroke leads its rod by the
        servo's compression under load; where that load reaches the cylinder's force limit the relief valve
        opens (the stroke is held at the limit, no wind-up), and a ram held there STALL_S has stalled. A sticking
        valve (state.ram_speed_factor) passes a fraction of the metered flow.
        """
        m, d, ix, hyd = win.model, win.data, win.index, self.hydraulics.ram
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
        speed *= state.ram_speed_factor[sups]
        k = QS_RAM_SPEED_M_S / speed[moving].max()
        nstep = max(1, round(RAM_SAMPLE_S / (k * m.opt.timestep)))
        seg_sim = nstep * m.opt.timestep
        seg_real = seg_sim * k
        travel_s = np.divide(np.abs(stroke), speed, out=np.zeros_like(stroke), where=moving)
        deadline = t0 + VALVE_RAMP_S + VALVE_TIMEOUT_FACTOR * travel_s + STALL_S
        held_s = np.zeros(goal.size)
        yield_cap = np.full(sups.size, self.hydraulics.legs.force_yield_n)
        t = t0
        while moving.any() and t < t_limit - 1e-9:
            roof.place(t + seg_real)  # the roof where it is at the end of the step
            # The valves open and close over VALVE_RAMP_S: the speed ramps up from the start and down towards the
            # goal (to a floor, so that the ram arrives).
            togo = np.abs(goal - d.act[adr])
            ramp = np.clip(np.minimum((t + seg_real - t0) / VALVE_RAMP_S, togo / (speed * VALVE_RAMP_S + 1e-12)),
                           RAMP_FLOOR, 1.0)
            reach = ramp * speed * k * seg_sim
            d.ctrl[ix.ram_act] = np.where(moving, np.clip(goal - d.act[adr], -reach, reach), 0.0) / seg_sim
            mujoco.mj_step(m, d, nstep=nstep)
            t += seg_real
            leak(win, state, sups, seg_real)
            leg_valves(win, self.hydraulics.legs, yield_cap)
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
            trace.sample(t)
        d.ctrl[ix.ram_act] = 0.0
        short = np.abs(goal - d.act[adr]) > ARRIVED_M
        d.act[adr[short]] = d.ten_length[ix.ram_tendon[short]]  # valves closed where the rams stand
        return t

    def _set_supports(self, win: Window, lowered: np.ndarray, pushing: np.ndarray | None = None) -> None:
        """Grip every support of the window by its legs' load (SUPPORT_GRIP), those `lowered` (window order) free;
        hold the AFC at their pans and their neighbours, but for the pans of the `pushing` supports (their rams
        move them)."""
        ix = win.index
        grip = SUPPORT_GRIP * np.maximum(win.leg_load(), 0.0)
        win.model.dof_frictionloss[ix.sup_dof[:, 0]] = np.where(lowered, SUPPORT_FRICTION_LOWERED_N,
                                                                np.maximum(grip, SUPPORT_FRICTION_LOWERED_N))
        at = np.zeros(ix.pans.size + 2, bool)  # padded by a pan each side
        at[self.stations[ix.supports[lowered]] - ix.pans[0] + 1] = True
        held = at[1:-1] | at[:-2] | at[2:]
        if pushing is not None:
            held[self.stations[ix.supports[pushing]] - ix.pans[0]] = False
        win.model.dof_frictionloss[ix.pan_dof[:, :2]] = np.where(held, AFC_HOLD_N, 0.0)[:, None]

    def load_at_rest(self, win: Window, state: FaceState, first: int) -> tuple[np.ndarray, np.ndarray]:
        """Load window `win` with the state's pans from `first` on and their supports, set against the roof at time 0
        and gripping the floor by their legs' load (nothing moving); returns the window's pans and supports."""
        pans, sups = self._load(win, state, first)
        RoofLimits(self, win, state, sups, 0.0)
        self._set_supports(win, np.zeros(win.index.supports.size, bool))
        return pans, sups

    def settle(self, state: FaceState) -> None:
        """Let the whole face come to rest on the floor at time 0, window by window from the headgate."""
        win = self.windows[-1]
        n = self.scn.face.pan_count
        starts = list(range(0, max(1, n - win.count + 1), max(1, win.count // 2))) + [n - win.count]
        for first in starts:
            pans, sups = self.load_at_rest(win, state, first)
            mujoco.mj_step(win.model, win.data, nstep=2 * SETTLE_STEPS)
            self._store(win, state, pans, sups, 0.0)


