"""002's turntable as a scenario file (top-level `kind = "support_turntable"`; scenarios/seed002_turntable.toml).

Every parameter is a required key; the motion, the readings and the filters are twin.papers.turntable's.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from pydantic import Field

from twin.config.imu_grades import GRADES
from twin.config.section import (
    Finite,
    NonNegativeFloat,
    PositiveFloat,
    ScenarioError,
    Section,
    validate,
)
from twin.config.tomlfile import file_kind, read_scenario

TURNTABLE_KIND = "support_turntable"

Pair = Annotated[list[Finite], Field(min_length=2, max_length=2)]
PositiveVector3 = Annotated[list[PositiveFloat], Field(min_length=3, max_length=3)]


class TurntableSite(Section):
    lat_deg: Annotated[float, Field(ge=-89, le=89, allow_inf_nan=False)]
    lon_deg: Annotated[float, Field(ge=-180, le=180, allow_inf_nan=False)]
    height_m: Finite
    mag_date: str


class Motion(Section):
    """002 section 4.1: each angle ramps from its first to its second value over its time pair."""

    duration_s: PositiveFloat
    pitch_deg: Pair
    pitch_s: Pair
    roll_deg: Pair
    roll_s: Pair
    heading_deg: Pair
    """002's yaw, clockwise from north."""
    heading_s: Pair


class Unit(Section):
    """The 9-axis unit: the grade's errors with the residuals of a factory calibration for its constant terms."""

    rate_hz: PositiveFloat
    grade: str
    accel_bias_mg: NonNegativeFloat
    accel_scale: NonNegativeFloat
    accel_nonorth_rad: NonNegativeFloat
    gyro_scale: NonNegativeFloat
    gyro_nonorth_rad: NonNegativeFloat
    mag_noise_t: PositiveFloat


class Disturbance(Section):
    peak_t: NonNegativeFloat
    pass_times_s: list[Finite]
    speed_m_s: PositiveFloat
    range_m: PositiveFloat


class PaperFilters(Section):
    """002's KF, UKF and GD-UKF."""

    untuned_var_deg2_s2: PositiveVector3
    sigma_alpha: PositiveFloat
    sigma_beta: NonNegativeFloat
    sigma_kappa: Finite
    p0_sigma: PositiveFloat
    gd_iterations: Annotated[int, Field(ge=0)]
    gd_reference_disturbed: bool
    """Whether the reference run for the tuning has the disturbance (false: a lab run, as 002's)."""
    gd_tol: PositiveFloat


class Ours(Section):
    update_hz: PositiveFloat
    gyro_arw_deg_sqrt_h: PositiveFloat
    gyro_bias_walk_deg_h_sqrt_h: PositiveFloat
    attitude_sigma0_deg: PositiveFloat
    gyro_bias_sigma0_deg_s: PositiveFloat
    accel_sigma_mg: PositiveFloat
    accel_gate_mg: PositiveFloat
    mag_sigma_t: PositiveFloat
    norm_tol_t: PositiveFloat
    dip_tol_deg: PositiveFloat
    gate_chi2: PositiveFloat
    relock_s: PositiveFloat


class Turntable(Section):
    kind: str
    name: str
    seed: int
    site: TurntableSite
    motion: Motion
    unit: Unit
    disturbance: Disturbance
    paper_filters: PaperFilters
    ours: Ours


def is_turntable(path: str | Path) -> bool:
    """Whether a scenario file is a support turntable (its top-level `kind`); unreadable files are not."""
    return file_kind(path) == TURNTABLE_KIND


def parse_turntable(data: dict, source: str = "<turntable>") -> Turntable:
    """Validate the file's data; a one-line ScenarioError naming `source` and the key."""
    if data.get("kind") != TURNTABLE_KIND:
        raise ScenarioError(f"{source}: kind: must be \"{TURNTABLE_KIND}\" (got {data.get('kind')!r})")
    tt = validate(Turntable, data, source, "scenarios/seed002_turntable.toml")
    if tt.unit.grade not in GRADES:
        raise ScenarioError(f"{source}: unit.grade: no IMU preset '{tt.unit.grade}' (presets: "
                            f"{', '.join(sorted(GRADES))})")
    return tt


def load_turntable(path: str | Path, seed: int | None = None) -> Turntable:
    """Read and validate a turntable file; `seed` overrides the file's seed."""
    return parse_turntable(read_scenario(path, seed), str(path))
