"""The face's truth as it is made: pan and support rows whenever they change (twin.pipeline.simulate's events, the
supports' traces through them, and the legs between them), and the pan-line versions the shearer's ride needs."""

from __future__ import annotations

import numpy as np

from estimators.nav.rotations import euler_to_quat, mat_to_quat, quat_mul
from twin.config.scenario import Scenario
from twin.face.layout import FaceFrame, bend_angles
from twin.face.ride import PanVersion
from twin.face.simulator import FaceSimulator
from twin.face.window import EventTrace, FaceState

LEG_ROW_MPA = 0.1
"""A support gets a truth row between events when its legs' pressure has moved this much since its last row (a
pressure transducer's step), or its canopy a millimetre (LEG_ROW_M)."""
LEG_ROW_M = 1e-3


class FaceRecorder:
    """Collects pan and support rows whenever they change, and the pan-line versions for the ride."""

    def __init__(self, scn: Scenario, frame: FaceFrame, state: FaceState, sim: FaceSimulator):
        self.scn, self.frame = scn, frame
        self.hydraulics, self.support_z = sim.hydraulics, sim.support_z
        self.pans0 = state.pans.copy()
        self.sup_x0 = state.sup_x.copy()
        self.last_leg_mpa = np.full(state.sup_x.size, np.nan)  # each support's latest row's leg pressure and canopy
        self.last_canopy = np.full(state.sup_x.size, np.nan)
        self.pan_rows: list[dict[str, np.ndarray]] = []
        self.sup_rows: list[dict[str, np.ndarray]] = []
        self.sup_released = 0  # support row blocks let go (release_support_rows)
        self.sup_first: dict[str, np.ndarray] | None = None  # the first block: the columns of an empty one
        self.versions: list[PanVersion] = []
        self.record(0.0, state, np.arange(state.pans.shape[0]), np.arange(state.sup_x.size))

    def record(self, t: float, state: FaceState, pans: np.ndarray, sups: np.ndarray,
               lowered: np.ndarray | None = None, t_begin: float | None = None) -> None:
        """Rows for `pans` and `sups` at time t; supports in `lowered` are logged lowered (canopy down).

        Pans that moved started moving at `t_begin` (default t)."""
        mat_tf = self.frame.mat_tf
        st = state.pans[pans]
        bend_h, bend_v = bend_angles(state.pans)
        pad = np.append(bend_h, np.nan), np.append(bend_v, np.nan)
        q_fp = euler_to_quat(st[:, 4], st[:, 5], st[:, 3])
        q_tp = quat_mul(np.broadcast_to(mat_to_quat(mat_tf), q_fp.shape), q_fp)
        p_t = st[:, :3] @ mat_tf.T
        self.pan_rows.append({
            "t": np.full(pans.size, t), "pan": pans, **split_columns(p_t, "p_t", "enu"), **split_columns(q_tp, "q_tp", "wxyz"),
            "bend_h": pad[0][pans], "bend_v": pad[1][pans], "advance": st[:, 0] - self.pans0[pans, 0]})
        is_lowered = np.zeros(sups.size, bool) if lowered is None else np.isin(sups, lowered)
        self._support_rows(np.full(sups.size, t), sups, state.sup_x[sups], state.sup_y[sups], state.sup_z[sups],
                           state.ram[sups], state.ram_force[sups], state.sup_leg[sups], state.leg_force[sups],
                           is_lowered)
        if pans.size:
            self.versions.append(PanVersion(t if t_begin is None else t_begin, t, state.pans.copy()))

    def record_trace(self, t0: float, trace: EventTrace, state: FaceState, lowered: np.ndarray) -> None:
        """Rows of the supports an event moved at every sample of its trace (the event began at t0); supports in
        `lowered` are logged lowered."""
        m, sups = trace.t_s.size, trace.supports
        if not m:
            return
        every = np.tile(sups, m)
        self._support_rows(np.repeat(t0 + trace.t_s, sups.size), every, trace.sup_x.ravel(), state.sup_y[every],
                           self.support_z(trace.sup_x.ravel(), state.sup_y[every]), trace.ram.ravel(),
                           trace.ram_force.ravel(), trace.leg.ravel(), trace.leg_force.ravel(), np.isin(every, lowered))

    def record_legs(self, t: float, state: FaceState) -> None:
        """Rows at t (between events) for the supports whose legs' pressure or canopy has moved since their last
        row (LEG_ROW_MPA, LEG_ROW_M): the roof converging on them, a leak."""
        moved = ((np.abs(self.hydraulics.legs.pressure_mpa(state.leg_force) - self.last_leg_mpa) >= LEG_ROW_MPA)
                 | (np.abs(state.sup_leg - self.last_canopy) >= LEG_ROW_M))
        sups = np.flatnonzero(moved)
        if sups.size:
            self._support_rows(np.full(sups.size, t), sups, state.sup_x[sups], state.sup_y[sups], state.sup_z[sups],
                               state.ram[sups], state.ram_force[sups], state.sup_leg[sups], state.leg_force[sups],
                               np.zeros(sups.size, bool))

    def _support_rows(self, t: np.ndarray, sups: np.ndarray, sup_x: np.ndarray, sup_y: np.ndarray, sup_z: np.ndarray,
                      ram: np.ndarray, ram_force: np.ndarray, leg: np.ndarray, leg_force: np.ndarray,
                      is_lowered: np.ndarray) -> None:
        p_f = np.column_stack([sup_x, sup_y, sup_z])
        leg_mpa = self.hydraulics.legs.pressure_mpa(leg_force)
        self.sup_rows.append({
            "t": t, "support": sups, **split_columns(p_f @ self.frame.mat_tf.T, "p_t", "enu"),
            "advance": sup_x - self.sup_x0[sups], "ram": ram,
            "ram_pressure": self.hydraulics.ram.pressure_mpa(ram_force), "canopy": leg, "leg_pressure": leg_mpa,
            "set": (~is_lowered).astype(np.int8)})
        if self.sup_first is None:
            self.sup_first = self.sup_rows[0]
        self.last_leg_mpa[sups] = leg_mpa  # rows come in time order: the last of a support's is its latest
        self.last_canopy[sups] = leg

    def forget_before(self, t: float) -> None:
        """Drop the pan-line versions no ride from time t on needs (the one in force at t and its predecessor,
        which a ride blends from while an event moves the pans, stay)."""
        begins = np.array([v.t_begin for v in self.versions])
        keep = max(0, int(np.searchsorted(begins, t, side="right")) - 2)
        del self.versions[:keep]

    def release_support_rows(self, upto: int) -> int:
        """Let the support row blocks before block `upto` go (a streaming run has written them); returns `upto`.
        Blocks keep their numbers: `sup_rows` holds the blocks from `sup_released` on."""
        del self.sup_rows[:upto - self.sup_released]
        self.sup_released = upto
        return upto

    def support_rows(self, since: int = 0) -> dict[str, np.ndarray]:
        """The support rows of the blocks from block `since` on (all kept ones by default) in time order."""
        blocks = self.sup_rows[max(since - self.sup_released, 0):]
        return concat_rows(blocks) if blocks else {k: v[:0] for k, v in self.sup_first.items()}

    def tables(self) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        return concat_rows(self.pan_rows), self.support_rows()


def split_columns(arr: np.ndarray, prefix: str, axes: str) -> dict[str, np.ndarray]:
    return {f"{prefix}_{a}": arr[:, i] for i, a in enumerate(axes)}


def concat_rows(rows: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    out = {k: np.concatenate([r[k] for r in rows]) for k in rows[0]}
    order = np.lexsort((out[next(k for k in out if k in ("pan", "support"))], out["t"]))
    return {k: v[order] for k, v in out.items()}


class FinalRows:
    """Support rows given in blocks as a run records them, handed out in time order once final: `split(rows,
    t_final)` returns the rows held and given with t < t_final in time order (no row recorded later comes before
    t_final: twin.pipeline.simulate's taps) and holds the rest. The blocks handed out, joined, are the whole run's
    rows as concat_rows orders them (equal times in the order recorded)."""

    def __init__(self):
        self.held: dict[str, np.ndarray] | None = None

    def split(self, rows: dict[str, np.ndarray], t_final: float) -> dict[str, np.ndarray]:
        rows = rows if self.held is None else concat_rows([self.held, rows])
        final = rows["t"] < t_final
        self.held = {k: v[~final] for k, v in rows.items()}
        return {k: v[final] for k, v in rows.items()}
