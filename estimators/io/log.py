"""The sensor log as the estimators read it: the streams of a run directory (estimators.io.logformat) as arrays,
loaded and checked, or put together from stream columns."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from estimators.io.logformat import (
    FACE_SURVEY,
    IMU,
    MAG,
    ODOMETER,
    PUSHRAM,
    SURVEY,
    LogError,
    read_stream,
)


@dataclass(frozen=True)
class Log:
    """The streams the positioning reads (columns as in estimators.io.logformat)."""

    imu_t: np.ndarray
    dtheta: np.ndarray
    dv: np.ndarray
    odo_t: np.ndarray
    odo_distance: np.ndarray
    odo_direction: np.ndarray
    survey_t: np.ndarray
    survey_llh: np.ndarray  # (S, 3)
    survey_yaw: np.ndarray
    survey_sd: np.ndarray  # (S, 3): horizontal, vertical [m], yaw [rad]
    ram_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ram_support: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    ram_extension: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ram_valid: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    mag_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mag_b: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (M, 3) [T]
    face_u: np.ndarray = field(default_factory=lambda: np.zeros(0))  # FACE_SURVEY: distance from the start pose
    face_llh: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    face_sd: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # horizontal, vertical [m]


def log_from_columns(imu, odometer, survey, pushram=None, mag=None, face_survey=None) -> Log:
    """A Log from stream columns (pyarrow tables or mappings of arrays, logformat column names)."""
    def col(table, name):
        c = table[name] if isinstance(table, dict) else table.column(name)
        return np.asarray(c if isinstance(c, np.ndarray) else c.to_numpy())

    optional = {}
    if pushram is not None:
        optional.update(ram_t=col(pushram, "t"), ram_support=col(pushram, "support"),
                        ram_extension=col(pushram, "extension"), ram_valid=col(pushram, "valid"))
    if mag is not None:
        optional.update(mag_t=col(mag, "t"), mag_b=np.column_stack([col(mag, f"b_{a}") for a in "xyz"]))
    if face_survey is not None:
        optional.update(face_u=col(face_survey, "u"),
                        face_llh=np.column_stack([col(face_survey, k) for k in ("lat", "lon", "h")]),
                        face_sd=np.column_stack([col(face_survey, k) for k in ("sd_horizontal", "sd_vertical")]))
    return Log(imu_t=col(imu, "t"), dtheta=np.column_stack([col(imu, f"dtheta_{a}") for a in "xyz"]),
               dv=np.column_stack([col(imu, f"dv_{a}") for a in "xyz"]), odo_t=col(odometer, "t"),
               odo_distance=col(odometer, "distance"), odo_direction=col(odometer, "direction"),
               survey_t=col(survey, "t"), survey_llh=np.column_stack([col(survey, k) for k in ("lat", "lon", "h")]),
               survey_yaw=col(survey, "yaw"),
               survey_sd=np.column_stack([col(survey, k) for k in ("sd_horizontal", "sd_vertical", "sd_yaw")]),
               **optional)


MIN_ROWS = {IMU.name: (2, "two IMU samples give the first sample interval"),
            ODOMETER.name: (1, "one odometer sample"), SURVEY.name: (1, "the surveyed start pose")}
"""Fewest rows of the streams the positioning needs, and why."""


def load_log(run_dir: Path) -> Log:
    """The streams of a run directory the positioning reads (push rams, magnetometer and face survey optional),
    checked on load."""
    def optional(stream):
        return read_stream(run_dir, stream) if (Path(run_dir) / stream.filename).is_file() else None

    def required(stream):
        table = read_stream(run_dir, stream)
        least, why = MIN_ROWS[stream.name]
        if table.num_rows < least:
            raise LogError(f"{Path(run_dir) / stream.filename}: {table.num_rows} rows, the positioning needs at least "
                           f"{least} ({why}); import a recording that has them")
        return table

    return log_from_columns(required(IMU), required(ODOMETER), required(SURVEY),
                            optional(PUSHRAM), optional(MAG), optional(FACE_SURVEY))

