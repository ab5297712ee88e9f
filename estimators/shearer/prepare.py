"""The sensor log prepared for the shearer filters (001, 003, 004): the IMU increments in the body frame and
coning/sculling-compensated at the mechanization rate, the filter epochs, the odometer at them, the straight
cuts and the segments (passes), and the start state.

Passes and face ends are found from the odometer alone: a straight cut is a run of travel in one direction
longer than STRAIGHT_CUT_FRACTION of the face (the distance between the two surveyed face-end points), which ends
where the travel turns (estimators.shearer.odometer_epochs); its pass ends a second into the stand after it. The
log can come in pieces (`Preparer`, for an online run): the epochs and passes are the ones the whole log gives. The first cycle has no CPOEM points; its face ends are surveyed (the survey
stream). The start pose comes from the survey (position, heading) and from levelling the accelerometers while the
shearer stands before the first cut (estimators.shearer.start_state).

The IMU increments are not held whole: `Prepared.mech(a, b)` compensates a pass's rows (epochs a..b) when a filter
runs it, read from the log's ImuRows, so the estimators' memory holds a pass of increments, not the run's.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from estimators.io.log import PERIOD_ROWS, ImuRows, Log
from estimators.kalman import error_state as es
from estimators.nav import earth
from estimators.nav.rotations import euler_to_mat
from estimators.shearer.config import Config, PositioningError
from estimators.shearer.cpoem import RamLog
from estimators.shearer.odometer_epochs import (
    ODO_PERIOD_ROWS,
    STRAIGHT_CUT_FRACTION,
    Growing,
    TravelRuns,
    odometer_at,
)
from estimators.shearer.odometer_filter import MODE_MOVING, MODE_STANDING
from estimators.shearer.start_state import initial_state
from estimators.sins.strapdown import compensated_increments


@dataclass(frozen=True)
class Mech:
    """The mechanization increments of epochs a..b (Prepared.mech): update times t (U + 1,), row 0 at epoch a, and
    the coning/sculling-compensated rotation vectors phi_b and velocity increments dv_b (U, 3) over
    (t[u], t[u + 1]], U = (b - a) * steps."""

    t: np.ndarray
    phi_b: np.ndarray
    dv_b: np.ndarray


@dataclass
class Prepared:
    """The log resampled for the filters: filter epochs, odometer, cuts, segments, start state, and the IMU
    increments of any epochs on demand (`mech`, `increments`).

    Epochs are numbered from the log's start (cuts, segments, fixes). t_kf, odo and mode hold epochs first_epoch..n_kf:
    an online run lets the epochs before the last pass go (Preparer.forget_before), a whole log holds them all
    (first_epoch 0). Read epochs a..b as t_kf[prep.span(a, b)], and epochs by number through `held`. What the
    whole run says of them is kept as it comes: odo0, odo_min, odo_max and the odometer's gaps."""

    imu: ImuRows
    mat_bs: np.ndarray
    imu_dt: float
    n_samples: int
    steps: int
    t_kf: np.ndarray
    odo: np.ndarray
    mode: np.ndarray
    cuts: list[tuple[int, int]]
    segments: list[tuple[int, int]]
    survey_epochs: np.ndarray
    rams: RamLog | None
    nav0: np.ndarray
    cal0: np.ndarray
    notes: list[str]
    first_epoch: int = 0
    """The epoch of t_kf[0], odo[0] and mode[0]."""
    odo0: float = np.nan
    """The odometer's distance at epoch 0: the face coordinate u of an epoch is odo - odo0."""
    odo_min: float = np.nan
    odo_max: float = np.nan
    """The odometer's extremes over the epochs known."""
    odo_gaps: int = 0
    """Epochs after the start without odometer data (mode < 0)."""
    t_first_gap: float = np.nan

    @property
    def n_kf(self) -> int:
        """The last filter epoch (epochs 0..n_kf)."""
        return self.first_epoch + self.t_kf.size - 1

    def held(self, epochs: int | np.ndarray) -> int | np.ndarray:
        """Where epochs (a number or an array of them) are in t_kf, odo and mode; ValueError for one let go."""
        if np.size(epochs) and np.min(epochs) < self.first_epoch:
            raise ValueError(f"filter epoch {np.min(epochs)} was let go (Preparer.forget_before); epochs from "
                             f"{self.first_epoch} are held")
        return epochs - self.first_epoch

    def span(self, a: int, b: int) -> slice:
        """The slice of t_kf, odo and mode holding epochs a..b."""
        return slice(self.held(a), b + 1 - self.first_epoch)

    @property
    def mech_dt(self) -> float:
        """The first mechanization interval [s]."""
        t = self.increments(0, self.n_samples)[0]
        return float(t[-1] - t[0])

    def increments(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The IMU increments (row k over (t[k-1], t[k]]) of samples i0+1..i1 turned into b, with row 0 at sample i0
        (its increments unused): sample 0 is the start, a period before the log's first row, with zero increments."""
        t, dtheta, dv = self.imu.read(max(i0 - 1, 0), i1)
        if i0 == 0:
            t = np.concatenate([[t[0] - 1.0 / (1.0 / self.imu_dt)], t])
            dtheta, dv = np.concatenate([np.zeros((1, 3)), dtheta]), np.concatenate([np.zeros((1, 3)), dv])
        return t, dtheta @ self.mat_bs.T, dv @ self.mat_bs.T

    def epoch_increments(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """`increments` of epochs a..b (row 0 at epoch a), and the log's row number of row 0 (-1: the start)."""
        per_epoch = self.steps * self.n_samples
        return *self.increments(a * per_epoch, b * per_epoch), a * per_epoch - 1

    def mech(self, a: int, b: int) -> Mech:
        """The mechanization increments of epochs a..b (Mech); PositioningError naming the log's first row that
        compensation refuses."""
        *increments, first_row = self.epoch_increments(a, b)
        try:
            return Mech(*compensated_increments(*increments, self.n_samples, first_row))
        except ValueError as err:
            raise PositioningError(f"imu: {err}") from None


def body_mounting(cfg: Config) -> np.ndarray:
    """C_s^b of the calibrated mounting: the IMU increments turned from the sensor axes into b."""
    return euler_to_mat(*cfg.imu_mounting_rad)


def _cat(old: np.ndarray, new: np.ndarray) -> np.ndarray:
    return np.concatenate([old, new]) if new.size else old


class Preparer:
    """`prepare` as the log comes: `update(part, final)` takes the rows of the odometer, survey, push-ram and face
    survey streams that came since the last call (part.imu is not read: the ImuRows given at the start has the IMU's
    rows) and returns the Prepared of the epochs known so far (None until the start can be prepared).

    An epoch is known once the odometer has reached stand_settle_s past it (its channel looks ahead that far), and a
    pass (a segment) once its straight cut has ended: the travel turned (a sump at the face end) and the pass's
    second of stand after it is known; the last pass ends with the log (`final`). Fed a whole log at once with
    final=True it is `prepare`. The odometer rows are kept from the last known epoch on, and `forget_before` lets an
    online run drop the epochs and push-ram rows its next passes do not read, so that its memory does not grow with
    the log."""

    def __init__(self, cfg: Config, imu: ImuRows):
        self.cfg, self.imu = cfg, imu
        z = np.zeros(0)
        self.log = Log(imu, z, z, np.zeros(0, np.int64), z, np.zeros((0, 3)), z, np.zeros((0, 3)))
        """The rows kept: odometer from the last known epoch on, survey and face survey whole, push rams since the
        last forget_before."""
        self.prep: Prepared | None = None
        self._t_kf, self._odo, self._mode = Growing(float), Growing(float), Growing(np.int8)
        self._odo_period = np.nan
        self._odo_first = np.nan
        self._prev_distance = np.nan  # the odometer reading before the kept rows
        self._active_before = -np.inf  # the last reading before the kept rows that showed motion
        self._runs = TravelRuns()
        self._cuts_seen = 0  # runs of _runs.closed looked at
        self._ends_seen = 0  # cuts whose pass end is placed
        self._face_travel: float | None = None
        self.started = False
        """The start state is known (Prepared.nav0, cal0)."""

    def _take(self, part: Log) -> None:
        """Append a part's rows to the kept ones."""
        log = self.log
        self.log = dataclasses.replace(
            log, odo_t=_cat(log.odo_t, part.odo_t), odo_distance=_cat(log.odo_distance, part.odo_distance),
            odo_direction=_cat(log.odo_direction, part.odo_direction),
            survey_t=_cat(log.survey_t, part.survey_t), survey_llh=_cat(log.survey_llh, part.survey_llh),
            survey_yaw=_cat(log.survey_yaw, part.survey_yaw), survey_sd=_cat(log.survey_sd, part.survey_sd),
            ram_t=_cat(log.ram_t, part.ram_t), ram_support=_cat(log.ram_support, part.ram_support),
            ram_extension=_cat(log.ram_extension, part.ram_extension), ram_valid=_cat(log.ram_valid, part.ram_valid),
            face_u=_cat(log.face_u, part.face_u), face_llh=_cat(log.face_llh, part.face_llh),
            face_sd=_cat(log.face_sd, part.face_sd))
        if np.isnan(self._odo_first) and self.log.odo_t.size:
            self._odo_first = float(self.log.odo_t[0])

    def update(self, part: Log, final: bool = False) -> Prepared | None:
        """The Prepared of the epochs known after `part` (module docstring); PositioningError names the stream a log
        cannot be used for."""
        self._take(part)
        log, cfg = self.log, self.cfg
        if np.isnan(self._odo_period) and (log.odo_t.size > ODO_PERIOD_ROWS or final) and log.odo_t.size > 1:
            self._odo_period = float(np.median(np.diff(log.odo_t[:ODO_PERIOD_ROWS + 1])))
        if self.prep is None and not self._start(final):
            return None
        prep = self.prep
        per_epoch = prep.steps * prep.n_samples
        n_imu = self.imu.size // per_epoch  # epochs the IMU has reached
        if n_imu > self._t_kf.n - 1:
            self._t_kf.extend(self.imu.times_at(np.arange(self._t_kf.n, n_imu + 1) * per_epoch - 1))
        t_kf, first = self._t_kf.data, self._t_kf.first
        if final:
            n_known = n_imu
        elif log.odo_t.size:
            n_known = first + int(np.searchsorted(t_kf, log.odo_t[-1] - cfg.stand_settle_s, side="right")) - 1
        else:
            n_known = -1
        if n_known > self._odo.n - 1 and log.odo_t.size and (final or not np.isnan(self._odo_period)):
            self._odometer(t_kf[max(self._odo.n - 1, 0) - first:n_known + 1 - first], final)
        self._hold()
        if prep.t_kf.size == 0:
            return prep
        if not self.started and not self._initial(final):
            return prep
        passes = len(prep.segments)
        self._segments(final)
        n_kf = prep.n_kf
        # A face end surveyed before the epochs held maps to the first held: no later pass has it.
        epochs = prep.first_epoch + np.searchsorted(prep.t_kf, log.survey_t[1:])
        prep.survey_epochs = np.minimum(epochs, n_kf) if final else epochs
        # The push-ram log is read by the passes just found (their fixes): made when there are some.
        if log.ram_t.size and len(cfg.support_u_m) >= 2 and len(prep.segments) > passes:
            prep.rams = RamLog.from_rows(log.ram_t, log.ram_support, log.ram_extension, log.ram_valid,
                                         cfg.support_u_m, cfg.ram_noise_sd)
        return prep

    def _start(self, final: bool) -> bool:
        """Make the Prepared once the IMU's period is known (PERIOD_ROWS rows, or the whole log); False before."""
        log, cfg = self.log, self.cfg
        if self.imu.size <= PERIOD_ROWS and not final:
            return False
        if log.survey_t.size == 0:
            if not final:
                return False
            raise PositioningError("survey: no rows; the start position and heading must be surveyed")
        imu_dt = self.imu.period()
        imu_rate = 1.0 / imu_dt
        steps_f = imu_rate / cfg.n_samples / cfg.filter_rate_hz
        if abs(steps_f - round(steps_f)) > 1e-6 or round(steps_f) < 1:
            raise PositioningError(f"imu: {imu_rate:.6g} Hz is not {cfg.n_samples} x {cfg.filter_rate_hz:g} Hz x an "
                                   f"integer; choose filter_rate_hz to divide the mechanization rate")
        steps = round(steps_f)
        per_epoch = steps * cfg.n_samples
        if self.imu.size // per_epoch < 1:
            raise PositioningError(f"imu: {self.imu.size} rows, fewer than one filter epoch ({per_epoch} rows)")
        self.prep = Prepared(self.imu, body_mounting(cfg), imu_dt, cfg.n_samples, steps, np.zeros(0), np.zeros(0),
                             np.zeros(0, np.int8), [], [], np.zeros(0, int), None, np.zeros(es.N_NAV),
                             np.zeros(es.N_CAL), [])
        self._t_kf.extend(self.prep.increments(0, 1)[0][:1])
        return True

    def _hold(self) -> None:
        """The Prepared's epochs: those known, from the first held."""
        prep = self.prep
        prep.first_epoch = self._odo.first
        known = self._odo.n - self._odo.first
        prep.t_kf, prep.odo, prep.mode = self._t_kf.data[:known], self._odo.data, self._mode.data

    def _odometer(self, t_kf: np.ndarray, final: bool) -> None:
        """Distance and channel of the epochs t_kf (the first already known, unless it is epoch 0), then the kept
        odometer rows cut to those from the last at or before the last known epoch."""
        log, prep = self.log, self.prep
        dist, mode = odometer_at(log.odo_t, log.odo_distance, log.odo_direction, self._prev_distance,
                                  self._active_before, t_kf, self.cfg.stand_settle_s, self._odo_period,
                                  self._odo_first, float(log.odo_t[-1]))
        first = self._odo.n == 0
        if first:
            prep.odo0 = prep.odo_min = prep.odo_max = float(dist[0])
        j0 = max(self._odo.n, 1)
        self._odo.extend(dist if first else dist[1:])
        self._mode.extend(np.concatenate([[MODE_STANDING], mode]) if first else mode)
        prep.odo_min, prep.odo_max = min(prep.odo_min, float(dist.min())), max(prep.odo_max, float(dist.max()))
        gaps = np.flatnonzero(mode < 0)
        if gaps.size and not prep.odo_gaps:
            prep.t_first_gap = float(t_kf[1 + gaps[0]])
        prep.odo_gaps += gaps.size
        k0 = j0 - self._odo.first
        u = self._odo.data
        self._runs.add(j0, u[k0:] - u[k0 - 1:-1], self._mode.data[k0:])
        if final:
            self._runs.finish()
        keep = max(int(np.searchsorted(log.odo_t, t_kf[-1], side="right")) - 1, 0)
        if keep:
            active = (log.odo_direction[:keep] != 0) | (
                np.diff(log.odo_distance[:keep], prepend=log.odo_distance[0] if np.isnan(self._prev_distance)
                        else self._prev_distance) != 0)
            if active.any():
                self._active_before = float(log.odo_t[:keep][active][-1])
            self._prev_distance = float(log.odo_distance[keep - 1])
            self.log = dataclasses.replace(log, odo_t=log.odo_t[keep:], odo_distance=log.odo_distance[keep:],
                                           odo_direction=log.odo_direction[keep:])

    def _initial(self, final: bool) -> bool:
        """The start state once the stand before the first move is known (estimators.shearer.start_state); False
        before."""
        prep = self.prep
        if not np.any(prep.mode == MODE_MOVING) and not final:
            return False
        prep.nav0, prep.cal0, prep.notes = initial_state(self.log, prep, self.cfg)
        self.started = True
        return True

    def _segments(self, final: bool) -> None:
        """The straight cuts among the runs that have ended, and the passes they end (one second of the stand after
        a cut belongs to its pass); with `final` the last pass, to the end of the log."""
        prep, log = self.prep, self.log
        n_kf = prep.n_kf
        if self._face_travel is None:
            if log.survey_t.size >= 2:
                d = earth.lla_to_enu(*log.survey_llh[1], *log.survey_llh[0])
                self._face_travel = float(np.hypot(d[0], d[1]))
            elif final:
                self._face_travel = prep.odo_max - prep.odo_min
                prep.notes.append("survey has no far face end: face length taken from the odometer")
            else:
                return  # the runs wait for the face's length
        u = prep.odo
        for first, last in self._runs.closed[self._cuts_seen:]:
            if abs(u[prep.held(last)] - u[prep.held(first - 1)]) > STRAIGHT_CUT_FRACTION * self._face_travel:
                prep.cuts.append((first, last))
        self._cuts_seen = len(self._runs.closed)
        settle = round(self.cfg.filter_rate_hz)
        start = prep.segments[-1][1] if prep.segments else 0
        for _, last in prep.cuts[self._ends_seen:]:
            end = last + 1 + settle
            if end >= n_kf and not final:
                break
            self._ends_seen += 1
            if start < end < n_kf:
                prep.segments.append((start, end))
                start = end
        if final and start < n_kf:
            prep.segments.append((start, n_kf))

    def forget_before(self, epoch: int) -> None:
        """Drop the epochs before `epoch` and the push-ram readings at or before it: the passes from it on read their
        own epochs and the travel run since it, and their CPOEM fixes strokes since their last pass's points (an
        online run, after each pass, with the last pass's first epoch)."""
        log = self.log
        keep = log.ram_t > self.prep.t_kf[self.prep.held(epoch)]
        self.log = dataclasses.replace(log, ram_t=log.ram_t[keep], ram_support=log.ram_support[keep],
                                       ram_extension=log.ram_extension[keep], ram_valid=log.ram_valid[keep])
        for epochs in (self._t_kf, self._odo, self._mode):
            epochs.drop_before(epoch)
        self._hold()


def prepare(log: Log, cfg: Config) -> Prepared:
    """The log resampled for the filters (Prepared) from the whole log at once (Preparer); PositioningError names
    the stream a log cannot be used for."""
    return Preparer(cfg, log.imu).update(log, final=True)
