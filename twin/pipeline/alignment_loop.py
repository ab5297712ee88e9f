"""The face alignment loop in the twin (OPC 40561, use case 4.2.6): the face alignment system
(estimators.face.alignment) reads each shear's shearer path as the shear ends and publishes offsets with a sequence
number; the roof support system applies the latest set on a later shear (scenario section [alignment]).

The twin hands the shearer's truth over a cycle at a time (twin.pipeline.simulate: a ride chunk ends in the reversal
stop after each cycle), so the loop sees shear k's path once cycle k's chunk is done: with delay_shears = d, the
offsets of cycle k come from shear k - 1 - d (none before the first). Mode truth feeds the system the true path of
the body reference point over each straight cut (truth_cycles' t to t_cut_end).

An estimator mode (kf_cpoem_rts, kf_cpoem, kf, fkf_rail) feeds it what the machine itself would know (`EstimatedShears`): trial
0's shearer and push-ram readings, drawn from the truth as the twin makes it (the numbers the run's files hold), go to
the method online (estimators.shearer.online), and each pass's straight cut, as the filter estimated it, is the shear
of the cycle it lies in; a cycle that ends without one, or whose pass the filter lost track over, leaves the last
offsets in force (the system's note says why). The same readings from a saved run directory give the same offsets
(`AlignmentLoop.replay`).
"""

from __future__ import annotations

import math

import numpy as np

from estimators.face.alignment import AlignmentConfig, FaceAlignmentSystem, ShearOffsets, path_in_face_frame
from estimators.io.metrics import error_stats
from estimators.nav import earth
from estimators.shearer.online import OnlinePositioning, PassEstimate
from twin.config.push import MAX_OFFSET_WEB_FRACTION
from twin.config.scenario import Scenario
from twin.face import snake
from twin.face.layout import support_stations
from twin.pipeline.estimate import positioning_config
from twin.pipeline.face_recorder import FaceRecorder, concat_rows
from twin.sensors.chunks import ChunkAssembler, halo_rows
from twin.sensors.faults import faults_of
from twin.sensors.streams import ShearerSensors, SupportSensors


def alignment_config(scn: Scenario) -> AlignmentConfig:
    """The alignment system's figures for a scenario's face: the shields' push points along the face, the stroke
    and bend limits twin.config.push.check_offsets holds offsets to, and the [alignment] section's settings; the path
    is the body point's in truth mode, an estimator's otherwise (estimators.face.alignment's path models)."""
    f, a, p = scn.face, scn.alignment, scn.pattern
    bend = math.radians(f.bend_limit_horizontal_deg)
    return AlignmentConfig(
        station_y_m=(support_stations(scn) + 0.5) * f.pan_length_m,
        spacing_m=scn.supports.pans_per_support * f.pan_length_m,
        azimuth_rad=math.radians(f.azimuth_deg),
        max_offset_m=MAX_OFFSET_WEB_FRACTION * f.web_depth_m,
        max_extra_push_m=snake.capacity_m(p.snake_length_pans, f.pan_length_m, bend) - f.web_depth_m,
        curvature_limit_rad=(1 - snake.BEND_FRACTION) * bend,
        gain=a.gain, smoothing_shields=a.smoothing_shields,
        planned_slope=0.0 if a.target == "square" else None, max_turn_rad=math.radians(a.max_turn_deg),
        min_coverage=a.min_coverage,
        end_zone_m=scn.shearer.length_m + (p.push_lag_pans + p.snake_length_pans + 2) * f.pan_length_m,
        shoe_spacing_m=scn.shearer.shoe_spacing_m, path_model="shoes" if a.mode == "truth" else "heading",
        path_ends_m=(scn.shearer.length_m / 2, f.pan_count * f.pan_length_m - scn.shearer.length_m / 2),
    )


class _SupportRows:
    """The truth_supports rows a push-ram reading from a time on reads, taken from the face recorder as it records:
    each support's latest row at or before that time and every row after it (twin.sensors.clock.true_at)."""

    def __init__(self, recorder: FaceRecorder):
        self.recorder, self.taken = recorder, 0
        self.rows: dict[str, np.ndarray] | None = None

    def since(self, t0: float) -> dict[str, np.ndarray]:
        blocks = self.recorder.sup_rows
        new, self.taken = blocks[self.taken:], len(blocks)
        rows = concat_rows(([self.rows] if self.rows is not None else []) + new)
        support, t = rows["support"], rows["t"]
        later = t > t0
        # each support's last row at or before t0 (rows are in time order, the later of equal times last)
        early = np.flatnonzero(~later)
        last = np.zeros(t.size, bool)
        if early.size:
            _, k = np.unique(support[early][::-1], return_index=True)
            last[early[::-1][k]] = True
        self.rows = {key: v[last | later] for key, v in rows.items()}
        return self.rows


class EstimatedShears:
    """An estimator mode's shear paths: trial 0's shearer streams (twin.sensors.streams.ShearerSensors) and push-ram
    readings (SupportSensors, from the face recorder's rows) drawn from each truth chunk as the twin hands it over,
    fed to the method online; `feed` returns the passes that ended. A chunk goes to the sensors as two pieces, its
    last halo of rows apart, so that its readings up to a halo before its end come out with it (ChunkAssembler holds
    a piece until the halo after it is known)."""

    def __init__(self, scn: Scenario, cycles: dict[str, np.ndarray], recorder: FaceRecorder, t_last: float):
        self.halo = halo_rows(scn)
        self.assembler = ChunkAssembler(self.halo)
        self.shearer = ShearerSensors(scn, 0, cycles, t_last)
        self.support = SupportSensors(scn, 0)
        self.support_rows = _SupportRows(recorder)
        self.online = OnlinePositioning(positioning_config(scn), scn.alignment.mode)
        self.rail = bool(faults_of(list(scn.faults), "rail_deviation"))
        self.path_ts: list[dict[str, np.ndarray]] = []  # the shearer's (t, s): rail_deviation reads it from its start
        self.t_drawn = 0.0
        """Readings are drawn up to this time."""

    def feed(self, truth: dict[str, np.ndarray] | None, last: bool = False) -> list[PassEstimate]:
        """The passes that end with the readings of the next truth chunk (None: no more truth), `last`: the run
        ends with it."""
        chunks = []
        if truth is not None:
            n = truth["t"].size
            for piece in (slice(0, max(n - self.halo, 0)), slice(max(n - self.halo, 0), n)):
                chunks += self.assembler.push({k: v[piece] for k, v in truth.items()})
        if last:
            chunks += self.assembler.finish()
        if not chunks:
            return []
        parts = [self.shearer.step(chunk) for chunk in chunks]
        path = {k: np.concatenate([c.rows[k] for c in chunks]) for k in ("t", "s")}
        if self.rail:
            self.path_ts.append(path)
            path = {k: np.concatenate([p[k] for p in self.path_ts]) for k in ("t", "s")}
        t1 = float(chunks[-1].rows["t"][-1]) if last else float(chunks[-1].after["t"][0])
        readings = self.support.step(self.t_drawn, t1, last, self.support_rows.since(self.t_drawn), path)
        self.t_drawn = t1
        streams = {name: {k: np.concatenate([p[name][k] for p in parts]) for k in parts[0][name]}
                   for name in ("imu", "odometer", "survey", "face_survey")}
        return self.online.feed({**streams, "pushram": readings["pushram"]}, final=last)


class AlignmentLoop:
    """The loop of one run: `observe` takes the shearer's truth chunks as the twin makes them, `offsets` is the
    roof support system's input for each cycle (twin.face.drift.OffsetSource). Fed a saved run's whole
    truth_shearer table at once (mode truth) or its readings (`replay`, an estimator mode), it gives the offsets the
    twin applied (no simulation)."""

    def __init__(self, scn: Scenario, cycles: dict[str, np.ndarray], recorder: FaceRecorder | None = None,
                 t_last: float = np.inf):
        """`cycles`: the truth_cycles columns (twin.pipeline.simulate.cycles_table); an estimator mode draws its
        push-ram readings from `recorder`'s rows, and t_last is the run's last truth time."""
        self.scn = scn
        self.cfg = alignment_config(scn)
        self.system = FaceAlignmentSystem(self.cfg)
        self.delay = scn.alignment.delay_shears
        self.cuts = list(zip(cycles["t"], cycles["t_cut_end"]))
        self.cycle_end = np.asarray(cycles["t_end"], float)
        self.estimated = (EstimatedShears(scn, cycles, recorder, t_last)
                          if scn.alignment.mode != "truth" and recorder is not None else None)
        self.passes: dict[int, PassEstimate] = {}  # estimated passes by the cycle their cut lies in, not yet used
        self.truth: dict[str, np.ndarray] | None = None  # the last two chunks' true path (an estimator mode)
        self.last_chunk_t0 = -np.inf
        self.path_errors: list[dict[str, float]] = []
        """An estimator mode fed by the twin: per shear, its estimated cut's position errors against the truth: SEP
        (estimators.io.metrics.error_stats) and the RMS of the error across the face about its best-fit line along it
        (what the target line does not take out) [m]."""
        self.published: list[ShearOffsets] = []
        """The system's output after each shear, in shear order."""

    @property
    def reads_support_rows(self) -> bool:
        """An estimator mode fed by the twin reads the face recorder's support rows as they come (_SupportRows)."""
        return self.estimated is not None

    def observe(self, chunk: dict[str, np.ndarray]) -> None:
        """Read a truth_shearer chunk: every straight cut that ends in it gives the system a shear."""
        if self.estimated is not None:
            path = {k: chunk[k] for k in ("t", "p_t_e", "p_t_n", "p_t_u")}
            self.truth = path if self.truth is None else {
                k: np.concatenate([self.truth[k][self.truth["t"] >= self.last_chunk_t0], v]) for k, v in path.items()}
            self.last_chunk_t0 = float(chunk["t"][0])
            self._take(self.estimated.feed(chunk), self.estimated.t_drawn)
            return
        t = chunk["t"]
        for t0, t1 in self.cuts[len(self.published):]:
            if t1 > t[-1]:
                break
            rows = (t >= t0) & (t <= t1)
            p_t = np.column_stack([chunk["p_t_e"][rows], chunk["p_t_n"][rows], chunk["p_t_u"][rows]])
            p_f, _ = path_in_face_frame(p_t, None, self.cfg.azimuth_rad)
            self.published.append(self.system.shear(p_f, np.zeros(p_f.shape[0]), label=f"shear {len(self.published)}"))

    def replay(self, streams: dict[str, dict[str, np.ndarray]]) -> list[ShearOffsets]:
        """An estimator mode on a saved run's readings (imu, odometer, survey, pushram, face_survey columns): what
        the system published after each shear."""
        online = OnlinePositioning(positioning_config(self.scn), self.scn.alignment.mode)
        self._take(online.feed(streams, final=True), np.inf)
        return self.published

    def _take(self, passes: list[PassEstimate], t_known: float) -> None:
        """Give the system the shears of the estimated passes, in cycle order, up to the last cycle that ended by
        t_known (one without a pass gives an empty path: the last offsets are held)."""
        starts = np.array([c[0] for c in self.cuts])
        for one in passes:
            if one.cut is None:
                continue
            t = one.solution.t[one.cut]
            k = int(np.searchsorted(starts, t.mean(), side="right")) - 1
            if k >= 0 and t.mean() <= self.cuts[k][1]:
                self.passes[k] = one
        site = self.scn.site
        origin = (np.radians(site.lat_deg), np.radians(site.lon_deg), site.height_m)
        while len(self.published) < len(self.cuts):
            k = len(self.published)
            one = self.passes.pop(k, None)
            if one is None and self.cycle_end[k] > t_known:
                break
            p_f, sd_x, healthy = np.zeros((0, 3)), np.zeros(0), True
            if one is not None:
                llh, sd = one.solution.llh[one.cut], one.solution.sd[one.cut]
                p_t = earth.lla_to_enu(llh[:, 0], llh[:, 1], llh[:, 2], *origin)
                p_f, sd_x = path_in_face_frame(p_t, sd[:, :2], self.cfg.azimuth_rad)
                healthy = one.healthy
                self._path_error(k, one.solution.t[one.cut], p_t)
            self.published.append(self.system.shear(p_f, sd_x, healthy, label=f"shear {k}"))

    def _path_error(self, shear: int, t: np.ndarray, p_t: np.ndarray) -> None:
        """Record a shear's estimated path's errors against the true path (path_errors), if the truth held covers it."""
        if self.truth is None or t[0] < self.truth["t"][0] or t[-1] > self.truth["t"][-1]:
            return
        err = p_t - np.column_stack([np.interp(t, self.truth["t"], self.truth[f"p_t_{a}"]) for a in "enu"])
        e_f, _ = path_in_face_frame(err, None, self.cfg.azimuth_rad)
        y, _ = path_in_face_frame(p_t, None, self.cfg.azimuth_rad)
        across = e_f[:, 0] - np.polyval(np.polyfit(y[:, 1], e_f[:, 0], 1), y[:, 1])
        self.path_errors.append({"shear": shear, "sep_m": error_stats(err)["sep"],
                                 "x_rms_m": float(np.sqrt(np.mean(across ** 2)))})

    def finish(self) -> None:
        """The run has ended: the shears still to come from the estimator (the last cycle's)."""
        if self.estimated is not None:
            self._take(self.estimated.feed(None, last=True), np.inf)

    def shears_needed(self, cycle: int) -> int:
        """Shears whose paths the offsets of `cycle` depend on."""
        return max(cycle - self.delay, 0)

    def offsets(self, cycle: int, pans: np.ndarray) -> np.ndarray | None:
        """The latest offsets published from shear cycle - 1 - delay or earlier (None before any)."""
        k = cycle - 1 - self.delay
        if k < 0:
            return None
        if k >= len(self.published):
            raise RuntimeError(f"face alignment: shear {k}'s path was not handed over before cycle {cycle}")
        return self.published[k].offsets_m


def alignment_table(scn: Scenario, cycle_start_s: np.ndarray, offsets_m: np.ndarray,
                    published: list[ShearOffsets]) -> dict[str, np.ndarray]:
    """The alignment stream's columns (estimators.io.logformat.ALIGNMENT) of a run: per cycle (starting at
    `cycle_start_s`) and support, the offset applied (`offsets_m`, cycles x supports) and the alignment system's set
    among it (published[k - 1 - delay] for cycle k: its sequence number and one-sigma)."""
    n_cyc, n_sup = offsets_m.shape
    delay = scn.alignment.delay_shears
    seq = np.zeros((n_cyc, n_sup), np.int32)
    sd = np.full((n_cyc, n_sup), np.nan)
    for k in range(n_cyc):
        if published and 0 <= k - 1 - delay < len(published):
            shear = published[k - 1 - delay]
            seq[k], sd[k] = shear.sequence, shear.sd_m
    cycle = np.repeat(np.arange(n_cyc, dtype=np.int32), n_sup)
    return {"t": np.asarray(cycle_start_s, float)[cycle], "cycle": cycle,
            "support": np.tile(np.arange(n_sup, dtype=np.int32), n_cyc), "offset": offsets_m.ravel(),
            "sd": sd.ravel(), "sequence": seq.ravel()}
