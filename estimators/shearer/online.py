"""Shearer positioning online: 001's filter run as the log comes, a pass at a time (issue 26's estimator-fed face
alignment, issue 24's streaming estimators).

`OnlinePositioning.feed` takes the rows of the IMU, odometer, survey and push-ram streams made since its last call
(any cut of the log into consecutive pieces) and returns the passes that have ended, each filtered once, with the
filter's state carried to the next: estimators.shearer.prepare.Preparer finds the epochs and passes as the odometer
reaches them (a pass ends a second after its straight cut, once the travel has turned), and
estimators.shearer.positioning.KfPasses filters them. A pass's rows are the batch method's rows over it, bit for bit
(tests/estimators/shearer/test_online.py), so a log fed in pieces gives what the whole log gives. What is held: the IMU
rows of the pass under way, the odometer from the last known epoch, the push-ram readings since the last pass's points,
and the epochs' times, distance and channel from the last pass's first: a run's memory does not grow with the log.

Methods: ``kf_cpoem_rts`` and ``kf_rts`` (each pass smoothed at its end, the output; with a PassStore each pass kept for
rts_offline), ``kf_cpoem`` and ``kf`` (the forward filter), ``dr`` and ``dr_compensated`` (the dead reckoning, the
latter with a filter's final calibration) of 001, and 004's ``fkf_rail`` (estimators.shearer.rail_kinematics.RailPasses;
it reads the face survey stream too).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from estimators.io.log import ImuBuffer, log_from_columns
from estimators.io.logformat import FLAG_SMOOTHED, IMU, ODOMETER, SURVEY
from estimators.shearer.config import DEAD_RECKONING, Config, PositioningError
from estimators.shearer.health import filter_lost, track_lost
from estimators.shearer.dead_reckoning import DeadReckoningPasses
from estimators.shearer.positioning import KfPass, KfPasses, PassStore
from estimators.shearer.prepare import Preparer
from estimators.shearer.rail_kinematics import RailPasses
from estimators.shearer.solution import Solution, make_solution, rows_of

ONLINE_METHODS = ("kf_cpoem_rts", "kf_cpoem", "kf_rts", "kf", "fkf_rail", "dr", "dr_compensated")
"""The methods that run online."""

_EMPTY = {stream.name: {c.name: np.zeros(0, c.dtype) for c in stream.columns} for stream in (IMU, ODOMETER, SURVEY)}
"""No new rows of a stream."""


@dataclass(frozen=True)
class PassEstimate:
    """One pass of an online run: its epochs' solution (the method's rows over epochs a + 1..b), the rows of its
    straight cut in it (from the epoch before the cut's first move to its last; None for a pass without one, the
    log's last), and whether the filter kept track over it (estimators.shearer.health.filter_lost)."""

    solution: Solution
    cut: slice | None
    healthy: bool


class OnlinePositioning:
    """One method of ONLINE_METHODS run online (module docstring)."""

    def __init__(self, cfg: Config, method: str = "kf_cpoem_rts", store: PassStore | None = None,
                 cal: np.ndarray | None = None):
        """`store`: where a kf_cpoem_rts run keeps its passes for rts_offline; `cal`: dr_compensated's calibration
        (estimators.shearer.odometer_filter's vector, a filter's last row)."""
        if method not in ONLINE_METHODS:
            raise PositioningError(f"{method}: not a method that runs online; choose one of {', '.join(ONLINE_METHODS)}")
        if (cal is not None) != (method == "dr_compensated"):
            raise ValueError(f"{method}: a calibration goes with dr_compensated, and only with it")
        self.cfg, self.method, self.store, self.cal = cfg, method, store, cal
        self.imu = ImuBuffer()
        self.preparer = Preparer(cfg, self.imu)
        self.passes: KfPasses | RailPasses | DeadReckoningPasses | None = None
        self.done = 0
        """Passes run."""
        self.initial: Solution | None = None
        """Epoch 0's row of the batch method (the start state), once the first pass runs."""

    def feed(self, streams: Mapping[str, Mapping[str, np.ndarray]], final: bool = False) -> list[PassEstimate]:
        """The passes that end with these rows (stream name -> columns as in estimators.io.logformat: imu, odometer,
        survey, pushram, face_survey; missing streams have no new rows); `final`: the log ends here."""
        part = log_from_columns(*(streams.get(k, _EMPTY[k]) for k in ("imu", "odometer", "survey")),
                                pushram=streams.get("pushram"), face_survey=streams.get("face_survey"))
        imu = part.imu
        self.imu.append(imu.t, imu.dtheta, imu.dv)
        prep = self.preparer.update(part, final)
        if prep is None or not self.preparer.started:
            return []
        log = self.preparer.log
        if self.passes is None and prep.segments[self.done:]:
            if self.method == "fkf_rail":
                self.passes = RailPasses(log, self.cfg, prep, self.cfg.isolate_by, whole=False)
                self.initial = self.passes.first_row(prep)
            elif self.method in DEAD_RECKONING:
                self.passes = DeadReckoningPasses(self.cfg, prep, log.survey_llh[0], self.cal)
            else:
                self.passes = KfPasses(log, self.cfg, prep, cpoem=self.method.startswith("kf_cpoem"),
                                       smooth=self.method.endswith("_rts"), keep=self.store)
                self.initial = self.passes.first_row(prep)
                self.initial.flags |= FLAG_SMOOTHED if self.method.endswith("_rts") else 0
                if self.store is not None:
                    self.store.start(self.passes, prep)
        out = []
        per_epoch = prep.steps * prep.n_samples
        for a, b in prep.segments[self.done:]:
            t = prep.t_kf[prep.span(a + 1, b)]
            if isinstance(self.passes, DeadReckoningPasses):
                rows = self.passes.run(prep, a, b)
                if self.initial is None:
                    self.initial = rows_of(rows, slice(0, 1))
                solution = rows_of(rows, slice(1, None))
                lost = track_lost(solution, self.cfg, has_sd=False)
            else:
                one = self.passes.run(prep, log, a, b)
                smoothed = isinstance(one, KfPass) and one.nav_s is not None
                nav, sd = (one.nav_s, one.sd_s) if smoothed else (one.nav, one.sd)
                if isinstance(self.passes, RailPasses):
                    solution = self.passes.pass_solution(prep, a, one)
                else:
                    flags = one.flags[1:] | (FLAG_SMOOTHED if smoothed else 0)
                    solution = make_solution(t, self.cfg, nav[1:], sd[1:], flags, one.cal[1:], [])
                lost = filter_lost(t, nav[1:], sd[1:], self.cfg)
            cut = next((slice(max(first - 1 - (a + 1), 0), last - a) for first, last in prep.cuts
                        if a < first and last <= b), None)
            out.append(PassEstimate(solution, cut, not lost.any()))
            self.done += 1
            self.imu.forget_before(b * per_epoch - 1)
            self.preparer.forget_before(a)
        return out

    def finish(self) -> list[str]:
        """The notes of the batch method once the log has ended (KfPasses.finish: the fixes gated, the odometer's
        gaps; RailPasses.finish: the fusion's)."""
        return [] if self.passes is None else self.passes.finish(self.preparer.prep)

    @property
    def notes(self) -> list[str]:
        """What the run has said so far (the start's alignment, fixes left out, a pass that lost track)."""
        return [] if self.passes is None else self.passes.notes
