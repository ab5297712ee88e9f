"""All sensor streams of a run from its truth: physics once, sensor errors redrawn per Monte Carlo trial.

The error-free IMU increments (with the lever arm, the mounting and the vibration, which are part of the
machine's motion) are computed once per run (`ImuTruth`); every trial then draws its own sensor errors and
fault realisations from a generator seeded by (scenario seed, trial, stream), so trial k is reproducible
on its own and adding a stream does not change the others.

The shearer's streams are drawn chunk by chunk as a streaming run hands over its truth (`ShearerSensors`,
twin.sensors.chunks); the whole run in one chunk gives the same numbers (`sensor_streams`).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from twin.config.imu_grades import grade
from twin.config.scenario import Scenario
from twin.sensors.chunks import TruthChunk, halo_rows, split_truth
from twin.sensors.clock import sample_times
from twin.sensors.faults import (
    check_faults_in_run,
    faults_of,
    faults_table,
    shortfall_profile,
    window_mask,
)
from twin.sensors.imu import IdealImu
from twin.sensors.imu_errors import ImuErrorModel
from twin.sensors.magnetometer import Magnetometer
from twin.sensors.odometer import Odometer
from twin.sensors.pressure import Pressures
from twin.sensors.pushram import PushRams
from twin.sensors.support_imu import support_imu_stream
from twin.sensors.survey import FaceSurvey, Survey

# Stream keys of the per-trial generators (fixed, so streams do not shift each other).
_IMU, _ODOMETER, _PUSHRAM, _MAG, _SUPPORT_IMU = range(5)
_SURVEY, _FACE_SURVEY, _PRESSURE = 5, 6, 7


@dataclass(frozen=True)
class ImuTruth:
    """Error-free increments at the IMU rate: t (K,), dtheta (K, 3) [rad], dv (K, 3) [m/s], each over (t - dt, t]."""

    t: np.ndarray
    dtheta: np.ndarray
    dv: np.ndarray


def imu_truth(scn: Scenario, shearer: dict[str, np.ndarray]) -> ImuTruth:
    """The error-free increments of a whole run's truth (twin.sensors.imu.IdealImu over one chunk)."""
    return ImuTruth(*IdealImu(scn).step(next(split_truth(shearer, [], halo_rows(scn)))))


def trial_rng(scn: Scenario, trial: int, stream: int) -> np.random.Generator:
    return np.random.default_rng([scn.seed, trial, stream])


class ShearerSensors:
    """The shearer's streams of one trial (imu, odometer, mag, survey, face_survey), drawn chunk by chunk: `step`
    takes the next TruthChunk (and, when they were computed once for several trials, its error-free IMU
    increments) and returns the readings the chunk owns, stream name -> columns. `truth_cycles` is known before
    the run (twin.pipeline.simulate.cycles_table) and `t_last` is the run's last truth time."""

    def __init__(self, scn: Scenario, trial: int, truth_cycles: dict[str, np.ndarray] | None, t_last: float):
        faults = list(scn.faults)
        self.ideal = IdealImu(scn)
        self.imu = ImuErrorModel(1.0 / scn.sensors.imu.rate_hz, grade(scn.sensors.imu.grade),
                                 trial_rng(scn, trial, _IMU))
        self.odometer = Odometer(scn, trial_rng(scn, trial, _ODOMETER), faults)
        self.mag = Magnetometer(scn, trial_rng(scn, trial, _MAG), faults)
        self.survey = Survey(scn, truth_cycles, trial_rng(scn, trial, _SURVEY), t_last)
        self.face_survey = FaceSurvey(scn, truth_cycles, trial_rng(scn, trial, _FACE_SURVEY))

    def step(self, chunk: TruthChunk, ideal: ImuTruth | None = None) -> dict[str, dict[str, np.ndarray]]:
        t, dtheta_ideal, dv_ideal = (ideal.t, ideal.dtheta, ideal.dv) if ideal else self.ideal.step(chunk)
        dtheta, dv = self.imu.step(dtheta_ideal, dv_ideal)
        return {"imu": {"t": t, **{f"dtheta_{a}": dtheta[:, i] for i, a in enumerate("xyz")},
                        **{f"dv_{a}": dv[:, i] for i, a in enumerate("xyz")}},
                "odometer": self.odometer.step(chunk), "mag": self.mag.step(chunk),
                "survey": self.survey.step(chunk), "face_survey": self.face_survey.step(chunk)}


SUPPORT_BLOCK_S = 900.0
"""A run's support streams are drawn this much time at a time (SupportSensors.step)."""


class SupportSensors:
    """The supports' push-ram and pressure streams of one trial, drawn a span of time at a time: `step(t0, t1, last)`
    gives the readings of every sensor clock time in [t0, t1) ([t0, t1] for the last span) from the run's truth_supports
    rows (in memory: a row per move) and the shearer's (t, s) (for rail_deviation). Any partition of the run into spans
    gives the streams of one step (twin.sensors.pushram.PushRams, twin.sensors.pressure.Pressures)."""

    def __init__(self, scn: Scenario, trial: int):
        faults = list(scn.faults)
        self.scn, self.shortfalls = scn, faults_of(faults, "push_shortfall")
        self.pushram = PushRams(scn, trial_rng(scn, trial, _PUSHRAM), faults)
        self.pressure = Pressures(scn, trial_rng(scn, trial, _PRESSURE), faults)

    def step(self, t0: float, t1: float, last: bool, supports: dict[str, np.ndarray],
             shearer: dict[str, np.ndarray]) -> dict[str, dict[str, np.ndarray]]:
        def clock(rate_hz: float) -> np.ndarray:
            t = sample_times(t0, t1, rate_hz)
            return t if last else t[t < t1]

        pushram = self.pushram.step(clock(self.scn.sensors.pushram.rate_hz), supports, shearer)
        # A push shortfall happens at the pans, not in the sensors: the readings keep the commanded strokes.
        for fault in self.shortfalls:
            short = shortfall_profile(fault, self.pushram.stations.size)[pushram["support"]]
            pushram["extension"] = pushram["extension"] + np.where(window_mask(pushram["t"], fault), short, 0.0)
        return {"pushram": pushram, "pressure": self.pressure.step(clock(self.scn.sensors.pressure.rate_hz), supports)}

    def spans(self, t_end: float, t_start: float = 0.0, last: bool = True) -> list[tuple[float, float, bool]]:
        """The spans (t0, t1, last) of at most SUPPORT_BLOCK_S, on its grid, the run from t_start to t_end is drawn
        in; `last`: t_end is the run's end (its last span holds it)."""
        edges = [t_start, *np.arange(SUPPORT_BLOCK_S * (np.floor(t_start / SUPPORT_BLOCK_S) + 1), t_end,
                                     SUPPORT_BLOCK_S), t_end]
        return [(a, b, last and k == len(edges) - 2) for k, (a, b) in enumerate(itertools.pairwise(edges))]


def support_streams(scn: Scenario, truth: dict[str, dict[str, np.ndarray]], trial: int = 0
                    ) -> dict[str, dict[str, np.ndarray]]:
    """The streams of the supports (pushram, pressure, support_imu) and the fault schedule, from the whole run's truth
    (the shearer's truth is read for its position along the face) in one SupportSensors step."""
    shearer, supports = truth["truth_shearer"], truth["truth_supports"]
    streams = {**SupportSensors(scn, trial).step(0.0, float(shearer["t"][-1]), True, supports, shearer),
               "faults": faults_table(scn)}
    imu = support_imu_readings(scn, supports, shearer, trial)
    return streams | ({"support_imu": imu} if imu is not None else {})


def support_imu_readings(scn: Scenario, supports: dict[str, np.ndarray], shearer: dict[str, np.ndarray],
                         trial: int) -> dict[str, np.ndarray] | None:
    """The SUPPORT_IMU stream of one trial from the whole run's truth_supports and shearer (t, s) (drawn at once);
    None without instrumented supports."""
    if not scn.sensors.support_imu.supports:
        return None
    return support_imu_stream(scn, supports, shearer, trial_rng(scn, trial, _SUPPORT_IMU), list(scn.faults))


def sensor_streams(scn: Scenario, truth: dict[str, dict[str, np.ndarray]], ideal: ImuTruth,
                   trial: int = 0) -> dict[str, dict[str, np.ndarray]]:
    """The sensor streams (logformat names -> columns) of one trial, from the whole run's truth in memory."""
    shearer = truth["truth_shearer"]
    t_last = float(shearer["t"][-1])
    check_faults_in_run(scn, t_last)
    sensors = ShearerSensors(scn, trial, truth.get("truth_cycles"), t_last)
    streams = sensors.step(next(split_truth(shearer, [], halo_rows(scn))), ideal)
    return {**streams, **support_streams(scn, truth, trial)}
