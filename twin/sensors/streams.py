"""All sensor streams of a run from its truth: physics once, sensor errors redrawn per Monte Carlo trial.

The error-free IMU increments (with the lever arm, the mounting and the vibration, which are part of the
machine's motion) are computed once per run (`ImuTruth`); every trial then draws its own sensor errors and
fault realisations from a generator seeded by (scenario seed, trial, stream), so trial k is reproducible
on its own and adding a stream does not change the others.

The shearer's streams are drawn chunk by chunk as a streaming run hands over its truth (`ShearerSensors`,
twin.sensors.chunks); the whole run in one chunk gives the same numbers (`sensor_streams`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.config.imu_grades import grade
from twin.config.scenario import Scenario
from twin.sensors.chunks import TruthChunk, halo_rows, split_truth
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
from twin.sensors.pressure import pressure_stream
from twin.sensors.pushram import pushram_stream
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


def support_streams(scn: Scenario, truth: dict[str, dict[str, np.ndarray]], trial: int = 0
                    ) -> dict[str, dict[str, np.ndarray]]:
    """The streams of the supports (pushram, pressure, support_imu) and the fault schedule, from the whole run's truth
    (the shearer's truth is read for its position along the face)."""
    shearer, supports = truth["truth_shearer"], truth["truth_supports"]
    duration = float(shearer["t"][-1])
    faults = list(scn.faults)
    pushram = pushram_stream(scn, supports, duration, trial_rng(scn, trial, _PUSHRAM), faults, shearer)
    # A push shortfall happens at the pans, not in the sensors: the readings keep the commanded strokes.
    for fault in faults_of(faults, "push_shortfall"):
        short = shortfall_profile(fault, int(pushram["support"].max()) + 1)[pushram["support"]]
        pushram["extension"] = pushram["extension"] + np.where(window_mask(pushram["t"], fault), short, 0.0)
    streams = {"pushram": pushram, "pressure": pressure_stream(scn, supports, duration, trial_rng(scn, trial, _PRESSURE),
                                                               faults),
               "faults": faults_table(scn)}
    if scn.sensors.support_imu.supports:
        streams["support_imu"] = support_imu_stream(scn, supports, shearer, trial_rng(scn, trial, _SUPPORT_IMU),
                                                    faults)
    return streams


def sensor_streams(scn: Scenario, truth: dict[str, dict[str, np.ndarray]], ideal: ImuTruth,
                   trial: int = 0) -> dict[str, dict[str, np.ndarray]]:
    """The sensor streams (logformat names -> columns) of one trial, from the whole run's truth in memory."""
    shearer = truth["truth_shearer"]
    t_last = float(shearer["t"][-1])
    check_faults_in_run(scn, t_last)
    sensors = ShearerSensors(scn, trial, truth.get("truth_cycles"), t_last)
    streams = sensors.step(next(split_truth(shearer, [], halo_rows(scn))), ideal)
    return {**streams, **support_streams(scn, truth, trial)}
