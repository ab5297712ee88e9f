"""Orchestration: scenario in, truth tables out.

Multi-rate (DESIGN "Simulation strategy"): the haulage timeline gives the shearer's arc length s(t); the
push-advance controller turns each pan crossing of the shearer's trailing end into ram targets, and the face
simulator moves the window of pans and supports that event touches; the shearer then rides the resulting
pan line at the truth rate in one batched rollout, and the truth splines are fitted through its samples.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from estimators.face.alignment import ShearOffsets
from estimators.io import logformat as lf
from estimators.nav.rotations import mat_to_quat
from twin.config.scenario import Scenario
from twin.face.drift import SUPPORT_DEADBAND_M, OffsetSource, StrokeControl, cycle_offsets, stand_supports
from twin.face.haulage import Timeline
from twin.face.layout import FaceFrame, Floor, initial_pans
from twin.face.model import FloorGrid
from twin.face.pushadvance import PushAdvanceController
from twin.face.ride import PanVersion, ride_targets_t, shoe_pans, simulate_ride
from twin.face.simulator import WINDOW_MARGIN_PANS, FaceSimulator
from twin.face.truth import shearer_truth
from twin.face.window import FaceState
from twin.pipeline.alignment_loop import AlignmentLoop
from twin.pipeline.face_recorder import FaceRecorder, split_columns
from twin.sensors.clock import sample_times
from twin.sensors.faults import faults_of, shortfall_profile

MIN_EVENT_S = 2.0
"""Shortest time an event takes (valves, a small correction push)."""

LEG_TICK_S = 10.0
"""Between events the set supports' legs are brought forward (the roof converging, a leak) every this many seconds."""

RAM_DEADBAND_M = 1e-3
"""A ram whose target moves less than this is left alone in an event."""

MAX_REPUSHES = 8
"""Most times the end pans are pushed again after the snake sumping (each only where still off target)."""

Progress = Callable[[str, float], None]
"""Callback (stage, fraction done in 0..1)."""
ShearerSink = Callable[[dict[str, np.ndarray]], None]
"""Takes the truth_shearer columns of the next stretch of the run, in time order (a streaming run's consumer)."""


SensorSink = Callable[[str, dict[str, np.ndarray], float], None]
"""Takes a sensor stream's next rows as they are drawn: (logformat stream name, columns, the time before which the
stream's rows are all drawn now; inf at its end)."""


@dataclass(frozen=True)
class LiveTaps:
    """What a live consumer (twin.opcua.server) sees of a run as the twin makes it: the truth_shearer chunks as they
    are handed over; after each cycle's face events the truth_supports rows recorded since the last (a row per move)
    and the time before which no more rows will come (the last event's start: later rows are all at or after it);
    and, from a streaming run with sensors (twin.pipeline.twin_stream), sensor trial 0's rows as they are drawn, the
    rows its Parquet files get. With taps, every finished chunk is handed over before a cycle's offsets are asked
    for, so that a consumer that steers the face has seen the shear before it."""

    shearer: ShearerSink
    supports: Callable[[dict[str, np.ndarray], float], None]
    sensors: SensorSink | None = None


@dataclass
class SimResult:
    """The truth tables (logformat stream name -> columns; truth_shearer only from `simulate`, a streaming run's
    sink takes it), the floor, the face frame, the simulated time, the number of push-advance events and the
    per-support offsets [m] each cycle's shear applied (cycles, supports), what the face alignment system
    published after each shear (twin.pipeline.alignment_loop; none in open loop) and, fed by an estimator, the errors
    of each shear's estimated path (AlignmentLoop.path_errors)."""

    tables: dict[str, dict[str, np.ndarray]]
    floor_grid: FloorGrid
    frame: FaceFrame
    duration_s: float
    events: int
    offsets: np.ndarray
    alignment: list[ShearOffsets]
    path_errors: list[dict[str, float]]
    support_advance: np.ndarray | None = None
    """A streaming run (twin.pipeline.twin_stream): each support's advance [m] at each cycle's end (cycles x
    supports), what the summary reads of the supports' truth, which is on disk."""


def window_sizes(scn: Scenario) -> list[int]:
    """Window sizes (pans) for the events: one over the snake and the advancing supports during the cut,
    one over the snake, the lags and the shearer's length at a face end; both with margins."""
    p = scn.pattern
    cut = p.snake_length_pans + p.push_step_pans + scn.supports.advance_lag_pans + 1
    end = p.snake_length_pans + p.push_lag_pans + scn.supports.advance_lag_pans + int(
        np.ceil(scn.shearer.length_m / scn.face.pan_length_m)) + 2
    return [min(scn.face.pan_count, w + 2 * WINDOW_MARGIN_PANS) for w in (cut, end)]


def shearer_chunks(scn: Scenario, timeline: Timeline) -> np.ndarray:
    """Chunk boundaries [s] of the shearer's ride: the middle of each reversal stop, where it stands still."""
    stop = scn.haulage.reversal_stop_s
    # On the ride clock, so that a chunk's ride ends exactly where the next begins and no truth sample between
    # them is lost.
    ride_hz = scn.rates.ride_hz
    inner = [round((p.t_start + stop / 2) * ride_hz) / ride_hz for p in timeline.cycles[1:]] if stop >= 1.0 else []
    return np.array([0.0, *inner, timeline.duration])


def _truth_times(scn: Scenario, t0: float, t1: float, last: bool) -> np.ndarray:
    """The truth clock over a ride chunk [t0, t1) ([t0, t1] for the last), within the ride's samples."""
    t_ride_end = sample_times(t0, t1, scn.rates.ride_hz)[-1]
    t = sample_times(t0, t1, scn.rates.truth_hz)
    return t[(t <= t_ride_end) & ((t < t1) | last)]


def last_truth_time(scn: Scenario, timeline: Timeline) -> float:
    """The time of the run's last truth_shearer row, known before the run."""
    bounds = shearer_chunks(scn, timeline)
    return float(_truth_times(scn, bounds[-2], bounds[-1], True)[-1])


def shearer_chunk(scn: Scenario, timeline: Timeline, versions: list[PanVersion], t0: float, t1: float,
                  last: bool) -> dict[str, np.ndarray]:
    """Ride and truth columns for times in [t0, t1) ([t0, t1] for the last chunk)."""
    t_ride = sample_times(t0, t1, scn.rates.ride_hz)
    pos, quat = simulate_ride(scn, *ride_targets_t(versions, t_ride, timeline.sample(t_ride)["s"], scn))
    t = _truth_times(scn, t0, t1, last)
    haul = timeline.sample(t)
    site, frame = scn.site, FaceFrame(np.radians(scn.face.azimuth_deg))
    truth = shearer_truth(t_ride, pos, quat, t, mat_to_quat(frame.mat_tf), np.radians(site.lat_deg),
                          np.radians(site.lon_deg), site.height_m)
    rear, front = shoe_pans(haul["s"], scn)
    return {
        "t": t, "lat": truth.lat, "lon": truth.lon, "h": truth.h, **split_columns(truth.p_t, "p_t", "enu"),
        **split_columns(truth.v_n, "v_n", "enu"), **split_columns(truth.q_nb, "q_nb", "wxyz"),
        **split_columns(truth.w_ib_b, "w_ib_b", "xyz"), **split_columns(truth.w_nb_b, "w_nb_b", "xyz"),
        **split_columns(truth.f_b, "f_b", "xyz"), "s": haul["s"], "pan_rear": rear, "pan_front": front,
        "cycle": haul["cycle"], "phase": haul["phase"]}


def cycles_table(timeline: Timeline) -> dict[str, np.ndarray]:
    """The truth_cycles columns: the haulage timeline's cycles, known before the face is simulated."""
    plans = timeline.cycles
    return {"cycle": np.array([p.cycle for p in plans]), "direction": np.array([p.direction for p in plans]),
            "t": np.array([p.t_start for p in plans], float),
            **{key: np.array([getattr(p, key) for p in plans], float)
               for key in ("t_cut_end", "t_sump_end", "t_push_end", "t_end", "s_sump")}}


def settled_face(scn: Scenario) -> tuple[FaceSimulator, FaceState]:
    """The face a run starts from: the face simulator over the run's windows (on the scenario's floor) and the pans
    laid on the floor with their supports set behind them, settled."""
    rng = np.random.default_rng(scn.seed)
    floor = Floor.from_scenario(scn, rng)
    sim = FaceSimulator(scn, floor, window_sizes(scn))
    state = sim.initial_supports(initial_pans(scn, floor, rng), PushAdvanceController(scn).support_lag_m())
    sim.settle(state)
    return sim, state


def simulate(scn: Scenario, progress: Progress | None = None, offsets: OffsetSource | None = None) -> SimResult:
    """Run the twin for a scenario: the face events, the shearer ride and the truth, all tables in memory."""
    pieces: list[dict[str, np.ndarray]] = []
    result = simulate_stream(scn, pieces.append, progress, offsets)
    result.tables[lf.TRUTH_SHEARER.name] = {key: np.concatenate([p[key] for p in pieces]) for key in pieces[0]}
    return result


def simulate_stream(scn: Scenario, shearer_sink: ShearerSink, progress: Progress | None = None,
                    offsets: OffsetSource | None = None, live: LiveTaps | None = None,
                    supports_sink: Callable[[dict[str, np.ndarray], float], None] | None = None) -> SimResult:
    """Run the twin for a scenario, handing the shearer truth to `shearer_sink` a ride chunk (a cycle) at a time as
    it is made; the result holds the other truth tables. At most two chunks of the shearer's truth exist at once.
    `offsets` is the roof support system's per-cycle input (twin.face.drift.OffsetSource), added to the scenario's;
    `live` taps the run as it goes (LiveTaps). `supports_sink` takes the truth_supports rows as LiveTaps.supports
    does, after each cycle's events and the rest at the end (time inf), and the rows are then let go (the result has
    no truth_supports), unless an estimator-fed face alignment reads them (they are kept)."""
    report = progress or (lambda stage, frac: None)
    frame = FaceFrame(np.radians(scn.face.azimuth_deg))
    timeline = Timeline(scn)
    sim, state = settled_face(scn)
    ctrl = PushAdvanceController(scn)
    pan_x0, sup_x0 = state.pans[sim.stations, 0].copy(), state.sup_x.copy()
    strokes = StrokeControl(scn, state.ram) if scn.supports.push.control == "stroke" else None
    applied: list[np.ndarray] = []
    recorder = FaceRecorder(scn, frame, state, sim)
    loop = (AlignmentLoop(scn, cycles_table(timeline), recorder, last_truth_time(scn, timeline))
            if scn.alignment.mode != "none" else None)
    length = scn.face.pan_length_m
    events = 0
    hydraulics_free = 0.0  # when the last event's rams are done and its supports set

    last_target = np.zeros(sim.stations.size)
    last_moved = np.zeros(sim.stations.size, bool)
    legs = sim.hydraulics.legs
    hydraulic_faults = faults_of(scn.faults, "leg_leak", "failed_set", "sticking_valve")
    fault_edges = np.unique([e for f in hydraulic_faults for e in (f.t_start_s, f.t_end_s)])
    legs_t = 0.0  # the time the supports' legs are brought to

    def hydraulic_faults_at(t: float) -> None:
        """The faults of the supports' hydraulics in force at t (a leaking leg, a failed set, a sticking valve)."""
        state.leg_leak_m_s[:] = 0.0
        state.set_force_n[:] = legs.force_set_n
        state.ram_speed_factor[:] = 1.0
        for f in hydraulic_faults:
            if f.t_start_s <= t < f.t_end_s:
                if f.kind == "leg_leak":
                    state.leg_leak_m_s[f.target] += f.value / 6e4 / legs.area_m2
                elif f.kind == "failed_set":
                    state.set_force_n[f.target] = min(state.set_force_n[f.target], f.value * 1e6 * legs.area_m2)
                else:
                    state.ram_speed_factor[f.target] = min(state.ram_speed_factor[f.target], f.value)

    hydraulic_faults_at(0.0)

    def legs_until(t: float) -> None:
        """Bring the set supports' legs to t (the roof converging, leaks), with rows every LEG_TICK_S and at the
        edges of the hydraulic faults' windows on the way."""
        nonlocal legs_t
        grid = np.arange(np.floor(legs_t / LEG_TICK_S) + 1, np.ceil(t / LEG_TICK_S)) * LEG_TICK_S
        ticks = np.union1d(grid, fault_edges[(fault_edges > legs_t) & (fault_edges < t)])
        for tick in (*ticks, t):
            sim.hold_legs(state, float(tick))
            hydraulic_faults_at(float(tick))
            if tick < t:
                recorder.record_legs(float(tick), state)
        legs_t = max(legs_t, t)

    shortfalls = faults_of(scn.faults, "push_shortfall")
    obstructions = faults_of(scn.faults, "obstruction")
    walls: dict[int, float] = {}  # obstruction -> the x of its obstacle, placed when it begins

    def obstruct(t: float) -> None:
        """Place (and clear) the obstacles of the obstruction faults in force at t, in front of their pans."""
        state.pan_wall_x[:] = np.inf
        for k, f in enumerate(obstructions):
            pan = sim.stations[f.target]
            if f.t_start_s <= t < f.t_end_s:
                walls.setdefault(k, float(state.pans[pan, 0]) + f.value)
                state.pan_wall_x[pan] = min(state.pan_wall_x[pan], walls[k])

    def shortfall_at(t: float) -> np.ndarray:
        return sum((shortfall_profile(f, sim.stations.size) for f in shortfalls if f.t_start_s <= t < f.t_end_s),
                   np.zeros(sim.stations.size))

    def event(t: float, s_trail: float | None, t_limit: float, repush: bool = False) -> bool:
        """One push-advance event, due at t, its rams stopped at t_limit; `repush` pushes the last event's pans
        again to their targets. It begins when the last event's hydraulics are done, if that is later.

        Returns whether any ram moved."""
        nonlocal events, last_target, last_moved
        sup_before = ctrl.sup_target.copy()
        pan_target, advancing = ctrl.update(s_trail)
        new_target = pan_target != last_target
        region = new_target | advancing | (last_moved & repush)
        last_target = pan_target
        # A push shortfall (a fault of the face, not of the sensors): the pans stop short while it lasts,
        # and their supports, which follow them, with them.
        short = shortfall_at(t)
        pan_target = pan_target - short
        sup_goal = ctrl.sup_target - short
        if strokes is not None:
            # By stroke from where each support stands (twin.face.drift): the errors stay in the face.
            push, advance, behind = strokes.goals(state.ram, pan_target, sup_before, sup_goal, new_target)
        else:
            # Strokes that take each pan from where it is to its absolute target, from where its support stands;
            # an advancing support then pulls itself up to its own target.
            shift = pan_target - (state.pans[sim.stations, 0] - pan_x0)
            push = sim.ram_lengths(state, shift, state.sup_x)
            advance = sim.ram_lengths(state, shift, sup_x0 + sup_goal)
            behind = sup_goal - (state.sup_x - sup_x0) > SUPPORT_DEADBAND_M
        if region.any():
            # A support near the action that is short of its advance (it stuck, or its pan was pulled
            # back) advances again.
            near = np.zeros_like(region)
            near[np.flatnonzero(region).min():np.flatnonzero(region).max() + 1] = True
            advancing |= near & behind
        target = np.where(advancing, advance, push)
        moved = (region | advancing) & ((np.abs(push - state.ram) > RAM_DEADBAND_M) | advancing)
        last_moved = moved
        if not moved.any():
            return False
        advancing &= moved
        if strokes is not None:
            strokes.commanded(moved, advancing, target)
        t_begin = max(t, hydraulics_free)
        obstruct(t_begin)
        if np.any(advancing & (np.abs(push - state.ram) > RAM_DEADBAND_M)):
            # Push and advance of one support (the end push of snake sumping): the rams extend first, then the
            # supports pull themselves up.
            t_begin = hydraulic_event(t_begin, t_limit, moved, push, np.zeros_like(advancing))
        hydraulic_event(t_begin, t_limit, moved, target, advancing)
        events += 1
        return True

    def hydraulic_event(t_begin: float, t_limit: float, moved: np.ndarray, target: np.ndarray,
                        advancing: np.ndarray) -> float:
        """Rams of `moved` to `target` from t_begin, the `advancing` supports lowered first and set after; the
        supports' rows through it and the pans' new line, in force from t_begin to its end (returned)."""
        nonlocal hydraulics_free
        legs_until(t_begin)
        lowered = np.flatnonzero(advancing)
        if lowered.size:
            # Lowered, the supports come up behind their pans along the face as their rams pull them.
            stand_supports(scn, sim.ram_site_local, state, lowered)
            state.sup_z[lowered] = sim.support_z(state.sup_x[lowered], state.sup_y[lowered])
            recorder.record(t_begin, state, np.zeros(0, int), lowered, lowered)
        pans, sups, trace = sim.step_event(state, moved, target, advancing, t_begin, t_limit - t_begin)
        recorder.record_trace(t_begin, trace, state, lowered)
        t_done = t_begin + max(MIN_EVENT_S, trace.duration_s)
        recorder.record(t_done, state, pans, sups, t_begin=t_begin)
        hydraulics_free = t_done
        return t_done

    # The shearer's ride and truth run chunk by chunk on the other core while the face simulates on:
    # a chunk needs only the pan line up to its end, and each starts with the shearer at rest.
    bounds = shearer_chunks(scn, timeline)
    pending: list[Future] = []
    taking: list[Future] = []  # the chunks the sink is taking on its own thread, oldest first
    handed = [0]

    def hand_over(keep: int) -> None:
        """Hand the finished chunks, oldest first, to the sink (on a thread of its own while the face simulates on;
        taken() waits for it) until at most `keep` are pending; live taps see each chunk after its readings."""
        while len(pending) > keep:
            chunk = pending.pop(0).result()
            if loop is not None:
                loop.observe(chunk)
            taking.append(sinking.submit(shearer_sink, chunk))
            handed[0] += 1
            if live is not None:
                taken()
                live.shearer(chunk)

    def taken() -> None:
        """Wait for the sink to have taken every chunk handed over (the support rows' sink reads what it holds)."""
        while taking:
            taking.pop(0).result()
            report("shearer", (handed[0] - len(taking)) / (len(bounds) - 1))

    half = scn.shearer.length_m / 2
    supports_told = 0  # the recorder's support row blocks the live taps have seen
    # The support rows are let go once the sink has them, unless the alignment system's estimator reads them.
    release = supports_sink is not None and (loop is None or not loop.reads_support_rows)
    with ThreadPoolExecutor(max_workers=1) as pool, ThreadPoolExecutor(max_workers=1) as sinking:
        for plan in timeline.cycles:
            if loop is not None:  # the shears whose paths this cycle's offsets come from, handed over
                hand_over(keep=max(0, len(pending) - max(0, loop.shears_needed(plan.cycle) - handed[0])))
            elif live is not None:
                hand_over(keep=0)
            applied.append(cycle_offsets(scn, plan.cycle, state.pans, offsets, None if loop is None else loop.offsets))
            ctrl.begin_cycle(plan.direction, applied[-1])
            step = length * scn.pattern.push_step_pans
            times, marks = timeline.crossings(plan.cycle, -plan.direction * half, step)
            for t, mark in zip(times, marks):
                event(float(t), float(mark), plan.t_push_end)
            # Snake sumping: the end pans are pushed while the shearer stands at C, then pushed again where
            # the end supports' advance pulled them back; all before the shearer moves on.
            for k in range(1 + MAX_REPUSHES):
                t_due = max(plan.t_sump_end, hydraulics_free)
                if t_due >= plan.t_push_end - MIN_EVENT_S or not event(t_due, None, plan.t_push_end, repush=k > 0):
                    break
            report("face", (plan.cycle + 1) / len(timeline.cycles))
            taken()
            if live is not None or supports_sink is not None:
                rows = recorder.support_rows(supports_told)
                for tap in (live.supports if live is not None else None, supports_sink):
                    if tap is not None:
                        tap(rows, legs_t)
                supports_told = recorder.sup_released + len(recorder.sup_rows)
                if release:
                    recorder.release_support_rows(supports_told)
            last = plan.cycle == len(timeline.cycles) - 1
            # Chunk k ends in the reversal stop after cycle k, before cycle k+1's first push.
            ready = [plan.cycle] if len(bounds) - 1 == len(timeline.cycles) else (
                range(len(bounds) - 1) if last else [])
            for c in ready:
                pending.append(pool.submit(shearer_chunk, scn, timeline, list(recorder.versions), bounds[c],
                                           bounds[c + 1], c == len(bounds) - 2))
                recorder.forget_before(bounds[c + 1])
            # The face runs at most one chunk ahead of the ride: memory stays that of two chunks.
            hand_over(keep=1)
        hand_over(keep=0)
        taken()
    if loop is not None:
        loop.finish()
    legs_until(timeline.duration)
    recorder.record_legs(timeline.duration, state)
    pans_tab, sups_tab = recorder.tables()
    tables = {lf.TRUTH_PANS.name: pans_tab, lf.TRUTH_CYCLES.name: cycles_table(timeline)}
    if supports_sink is not None:
        supports_sink(recorder.support_rows(supports_told), np.inf)
    if not release:
        tables[lf.TRUTH_SUPPORTS.name] = sups_tab
    return SimResult(tables, FloorGrid.from_scenario(scn, sim.floor), frame, timeline.duration, events, np.array(applied),
                     [] if loop is None else loop.published, [] if loop is None else loop.path_errors)
