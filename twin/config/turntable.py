"""002's turntable as a scenario file (top-level `kind = "support_turntable"`; scenarios/seed002_turntable.toml).

Every parameter is a required key; the motion, the readings and the filters are twin.papers.turntable's.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from pydantic import Field

from twin.config.imu_grades import GRADES
from twin.config.section import (
    Duration,
    NonNegativeFloat,
    PositiveFloat,
    Rate,
    ScenarioError,
    Section,
    WmmDate,
    between,
    validate,
)
from twin.config.sensors import EARTH_FIELD_T
from twin.config.tomlfile import file_kind, read_scenario

TURNTABLE_KIND = "support_turntable"

Pair = Annotated[list[between(-360, 360)], Field(min_length=2, max_length=2)]
"""Two angles [deg] within a turn either way, or two times [s] within the motion (parse_turntable)."""


def upto(hi: float):
    """A positive finite float at most `hi`."""
    return Annotated[float, Field(gt=0, le=hi, allow_inf_nan=False)]
PositiveVector3 = Annotated[list[PositiveFloat], Field(min_length=3, max_length=3)]


class TurntableSite(Section):
    lat_deg: Annotated[float, Field(ge=-89, le=89, allow_inf_nan=False)]
    lon_deg: Annotated[float, Field(ge=-180, le=180, allow_inf_nan=False)]
    height_m: between(-5000, 9000)
    """As the face scenarios' site (twin.config.section.Site)."""
    mag_date: WmmDate


class Motion(Section):
    """002 section 4.1: each angle ramps from its first to its second value over its time pair."""

    duration_s: Duration
    pitch_deg: Pair
    pitch_s: Pair
    roll_deg: Pair
    roll_s: Pair
    heading_deg: Pair
    """002's yaw, clockwise from north."""
    heading_s: Pair


class Unit(Section):
    """The 9-axis unit: the grade's errors with the residuals of a factory calibration for its constant terms."""

    rate_hz: Rate
    grade: str
    accel_bias_mg: between(0, 100)
    """At most 100 mg (an uncalibrated MEMS accelerometer's 20 mg, five times)."""
    accel_scale: between(0, 0.1)
    """Relative; at most 10 % (factory units are within 3 %), as the other calibration residuals."""
    accel_nonorth_rad: between(0, 0.1)
    gyro_scale: between(0, 0.1)
    gyro_nonorth_rad: between(0, 0.1)
    mag_noise_t: Annotated[float, Field(gt=0, le=0.2 * EARTH_FIELD_T, allow_inf_nan=False)]
    """At most a fifth of the Earth's field (twin.config.sensors.EARTH_FIELD_T)."""


class Disturbance(Section):
    peak_t: between(0, 2 * EARTH_FIELD_T)
    pass_times_s: Annotated[list[NonNegativeFloat], Field(max_length=100)]
    """Within the motion's duration (checked by parse_turntable)."""
    speed_m_s: Annotated[float, Field(gt=0, le=1, allow_inf_nan=False)]
    """The shearer's speed past the unit; at most 1 m/s (60 m/min, beyond any haulage)."""
    range_m: Annotated[float, Field(gt=0, le=100, allow_inf_nan=False)]


class PaperFilters(Section):
    """002's KF, UKF and GD-UKF."""

    untuned_var_deg2_s2: Annotated[list[upto(100)], Field(min_length=3, max_length=3)]
    """At most 100 (deg/s)^2 (002's are 0.0025; a gyro noisier than 10 deg/s measures nothing)."""
    sigma_alpha: upto(1)
    """The sigma-point spread of filterpy's MerweScaledSigmaPoints: 0 < alpha <= 1."""
    sigma_beta: between(0, 10)
    sigma_kappa: between(-10, 10)
    p0_sigma: upto(1)
    """Per quaternion component: at most 1, a unit quaternion's."""
    gd_iterations: Annotated[int, Field(ge=0, le=1000)]
    """At most 1000 (002 needs 25; each is a run of the filters, twin.config.resources counts them)."""
    gd_reference_disturbed: bool
    """Whether the reference run for the tuning has the disturbance (false: a lab run, as 002's)."""
    gd_tol: upto(1)


class Ours(Section):
    """The filter's tuning, bounded by what a 9-axis MEMS unit can be: noises within ten times the worst grade's,
    angles within a half turn, fields within twice the Earth's (twin.config.sensors.EARTH_FIELD_T)."""

    update_hz: Rate
    gyro_arw_deg_sqrt_h: upto(100)
    gyro_bias_walk_deg_h_sqrt_h: upto(3600)
    attitude_sigma0_deg: upto(180)
    gyro_bias_sigma0_deg_s: upto(10)
    accel_sigma_mg: upto(1000)
    accel_gate_mg: upto(1000)
    mag_sigma_t: upto(2 * EARTH_FIELD_T)
    norm_tol_t: upto(2 * EARTH_FIELD_T)
    dip_tol_deg: upto(90)
    gate_chi2: upto(1000)
    relock_s: Duration


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
    m = tt.motion
    for key in ("pitch_s", "roll_s", "heading_s"):
        t0, t1 = getattr(m, key)
        if not 0 <= t0 <= t1 <= m.duration_s:
            raise ScenarioError(f"{source}: motion.{key}: [{t0}, {t1}] must be times 0 <= from <= to <= "
                                f"motion.duration_s = {m.duration_s} s")
    late = [t for t in tt.disturbance.pass_times_s if t > tt.motion.duration_s]
    if late:
        raise ScenarioError(f"{source}: disturbance.pass_times_s: {late[0]} s is after motion.duration_s = "
                            f"{tt.motion.duration_s} s")
    if tt.unit.grade not in GRADES:
        raise ScenarioError(f"{source}: unit.grade: no IMU preset '{tt.unit.grade}' (presets: "
                            f"{', '.join(sorted(GRADES))})")
    return tt


def load_turntable(path: str | Path, seed: int | None = None) -> Turntable:
    """Read and validate a turntable file; `seed` overrides the file's seed."""
    return parse_turntable(read_scenario(path, seed), str(path))
