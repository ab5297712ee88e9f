"""All sensor streams of a run from its truth: physics once, sensor errors redrawn per Monte Carlo trial.

The error-free IMU increments (with the lever arm, the mounting and the vibration, which are part of the
machine's motion) are computed once per run (`ImuTruth`); every trial then draws its own sensor errors and
fault realisations from a generator seeded by (scenario seed, trial, stream), so trial k is reproducible
on its own and adding a stream does not change the others.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.config.imu_grades import grade
from twin.config.scenario import Scenario
from twin.sensors.faults import (
    check_faults_in_run,
    faults_of,
    faults_table,
    shortfall_profile,
    window_mask,
)
from twin.sensors.imu import ideal_increments
from twin.sensors.imu_errors import apply_imu_errors
from twin.sensors.magnetometer import mag_stream
from twin.sensors.odometer import odometer_stream
from twin.sensors.pushram import pushram_stream
from twin.sensors.support_imu import support_imu_stream
from twin.sensors.survey import face_survey_stream, survey_stream

# Stream keys of the per-trial generators (fixed, so streams do not shift each other).
_IMU, _ODOMETER, _PUSHRAM, _MAG, _SUPPORT_IMU = range(5)
_SURVEY, _FACE_SURVEY = 5, 6
_VIBRATION = 1000  # the vibration phases belong to the machine's motion: drawn once per run, not per trial


@dataclass(frozen=True)
class ImuTruth:
    """Error-free increments at the IMU rate: t (K,), dtheta (K, 3), dv (K, 3); row 0 is the start."""

    t: np.ndarray
    dtheta: np.ndarray
    dv: np.ndarray


def imu_truth(scn: Scenario, shearer: dict[str, np.ndarray]) -> ImuTruth:
    """Ideal increments at the truth rate summed to the IMU rate (increments add exactly)."""
    inc = ideal_increments(scn, shearer, np.random.default_rng([scn.seed, _VIBRATION]))
    step = int(round(scn.rates.truth_hz / scn.sensors.imu.rate_hz))
    dtheta = np.column_stack([inc[f"dtheta_{a}"] for a in "xyz"])
    dv = np.column_stack([inc[f"dv_{a}"] for a in "xyz"])
    if step > 1:
        n = (dtheta.shape[0] - 1) // step
        dtheta = np.concatenate([dtheta[:1], dtheta[1:1 + n * step].reshape(n, step, 3).sum(axis=1)])
        dv = np.concatenate([dv[:1], dv[1:1 + n * step].reshape(n, step, 3).sum(axis=1)])
    t = inc["t"][::step][: dtheta.shape[0]]
    return ImuTruth(t, dtheta, dv)


def trial_rng(scn: Scenario, trial: int, stream: int) -> np.random.Generator:
    return np.random.default_rng([scn.seed, trial, stream])


def sensor_streams(scn: Scenario, truth: dict[str, dict[str, np.ndarray]], ideal: ImuTruth,
                   trial: int = 0) -> dict[str, dict[str, np.ndarray]]:
    """The sensor streams (logformat names → columns) of one trial."""
    shearer, supports = truth["truth_shearer"], truth["truth_supports"]
    duration = float(shearer["t"][-1])
    check_faults_in_run(scn, duration)
    faults = list(scn.faults)
    dt = 1.0 / scn.sensors.imu.rate_hz
    dtheta, dv, _ = apply_imu_errors(ideal.dtheta[1:], ideal.dv[1:], dt, grade(scn.sensors.imu.grade),
                                     trial_rng(scn, trial, _IMU))
    imu = {"t": ideal.t[1:], **{f"dtheta_{a}": dtheta[:, i] for i, a in enumerate("xyz")},
           **{f"dv_{a}": dv[:, i] for i, a in enumerate("xyz")}}
    pushram = pushram_stream(scn, supports, duration, trial_rng(scn, trial, _PUSHRAM), faults, shearer)
    # A push shortfall happens at the pans, not in the sensors: the readings keep the commanded strokes.
    for fault in faults_of(faults, "push_shortfall"):
        short = shortfall_profile(fault, int(pushram["support"].max()) + 1)[pushram["support"]]
        pushram["extension"] = pushram["extension"] + np.where(window_mask(pushram["t"], fault), short, 0.0)
    streams = {
        "imu": imu,
        "odometer": odometer_stream(scn, shearer, trial_rng(scn, trial, _ODOMETER), faults),
        "pushram": pushram,
        "mag": mag_stream(scn, shearer, trial_rng(scn, trial, _MAG), faults),
        "faults": faults_table(scn),
        "survey": survey_stream(scn, shearer, truth.get("truth_cycles"), trial_rng(scn, trial, _SURVEY)),
        "face_survey": face_survey_stream(scn, shearer, truth.get("truth_cycles"),
                                          trial_rng(scn, trial, _FACE_SURVEY)),
    }
    if scn.sensors.support_imu.supports:
        streams["support_imu"] = support_imu_stream(scn, supports, shearer, trial_rng(scn, trial, _SUPPORT_IMU),
                                                    faults)
    return streams
