"""Scenario sections for the instruments and the injected faults (`[sensors.*]` and `[[faults]]`).

Units as written in the file (deg, Hz, T, m); the sensor models convert once. Every field has the default a
mining engineer would expect for a modern face; `grade` names a preset of twin.config.imu_grades.
"""
# ruff: noqa: RUF012 -- the list defaults are pydantic fields (Section is a BaseModel; pydantic copies defaults)

from __future__ import annotations

import math
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator

from twin.config.section import (
    Finite,
    NonNegativeFloat,
    Rate,
    Section,
    WmmDate,
    between,
    vector3,
)

EARTH_FIELD_T = 6.6e-5
"""The strongest geomagnetic field anywhere (near the south magnetic pole) [T]; fields and noises are bounded by a
multiple of it (a magnetometer noise of more than a fifth of it leaves no heading; a fault or calibration term of
more than twice it saturates the magnetometers of a face, +-0.8 mT being the widest range sold and 1e-4 T already
a welding cable at a metre)."""
SoftIron = Annotated[list[vector3(2.0)], Field(min_length=3, max_length=3)]
"""A 3 x 3 soft-iron matrix (rows), entries within +-2 (a real one is near the identity, within a few per cent)."""


def check_soft_iron(rows: list[list[float]], key: str) -> None:
    """ValueError when a soft-iron matrix is (nearly) singular: it would leave no heading to compute."""
    det = float(np.linalg.det(np.array(rows)))
    if abs(det) < 0.1:
        raise ValueError(f"{key}: determinant {det:.3g} is (nearly) singular; a soft-iron matrix is near the "
                         f"identity (|det| >= 0.1)")


class Imu(Section):
    """The shearer's strapdown IMU."""

    grade: str = "mti-g-700"
    """A preset of twin.config.imu_grades (mti-g-700, par1 .. par12, nav-004, mti-30, icm-42605, ideal)."""
    rate_hz: Rate = 200.0
    lever_arm_m: vector3(10.0) = [0.3, 0.5, 0.2]
    """IMU position relative to the body reference point, in the body frame b; within +-10 m per axis (the IMU is
    on the machine, at most 20 m long)."""
    misalignment_deg: vector3(5.0) = [0.05, -0.05, 0.1]
    """Small rotation of the IMU axes relative to b (about x, y, z): C_s^b = I + [m]x to first order, so within
    +-5 deg per axis (beyond, the first-order model is wrong by more than the sensors' errors)."""


class VibrationState(Section):
    """Vibration of the IMU in one machine state: a drum-rotation tone and a pick-impact band, with phase.

    The drum tone is slow (the drums turn at 0.5-1 Hz), so it is specified by how far it moves the machine:
    millimetres and hundredths of a degree, not g (0.3 g at 0.6 Hz would swing the shearer by 20 cm). The pick
    band carries the RMS acceleration and angular rate that accelerometers on a cutting shearer report."""

    drum_hz: Annotated[float, Field(ge=0, le=5, allow_inf_nan=False)] = 0.6
    drum_displacement_mm: Annotated[float, Field(ge=0, le=20, allow_inf_nan=False)] = 0.0
    """Amplitude of the drum tone's displacement of the IMU, per axis."""
    drum_angle_deg: Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)] = 0.0
    """Amplitude of the drum tone's rocking of the IMU, per axis."""
    pick_hz: Annotated[float, Field(ge=0, le=200, allow_inf_nan=False)] = 30.0
    accel_rms_g: Annotated[float, Field(ge=0, le=5, allow_inf_nan=False)] = 0.0
    """RMS acceleration of the pick band, per axis."""
    angular_rms_deg_s: Annotated[float, Field(ge=0, le=10, allow_inf_nan=False)] = 0.0
    """RMS angular rate of the pick band, per axis."""


class Vibration(Section):
    enabled: bool = True
    idle: VibrationState = VibrationState(drum_displacement_mm=0.1, drum_angle_deg=0.001, accel_rms_g=0.02,
                                          angular_rms_deg_s=0.02)
    cutting_coal: VibrationState = VibrationState(drum_displacement_mm=1.0, drum_angle_deg=0.01, accel_rms_g=0.3,
                                                  angular_rms_deg_s=0.3)
    cutting_rock: VibrationState = VibrationState(drum_displacement_mm=2.0, drum_angle_deg=0.02, accel_rms_g=0.8,
                                                  angular_rms_deg_s=0.8, pick_hz=38.0)
    rock_zones_m: list[Annotated[list[NonNegativeFloat], Field(min_length=2, max_length=2)]] = []
    """Arc-length intervals [from, to] along the face where the drums cut rock (floor or roof bands)."""


class Odometer(Section):
    """The haulage encoder: pulses of the drive sprocket on the rack."""

    rate_hz: Rate = 50.0
    metres_per_pulse: between(1e-5, 0.1) = 0.002
    """Travel per pulse: 10 um to 10 cm (finer than any rack encoder; coarser is not an odometer)."""
    scale_error: Annotated[float, Field(ge=-0.1, le=0.1, allow_inf_nan=False)] = 0.003
    """Relative error of the nominal metres per pulse (0.003 = 3 per mille)."""
    mounting_deg: vector3(10.0) = [0.2, 0.0, -0.3]
    """Within +-10 deg per axis (an encoder bolted to the haulage, off by more, is not mounted). Angles of the encoder's axis relative to b (about x, y, z): the encoder counts travel along that axis, so
    they change its count by their cosine only. 001's mounting angles (eq. 10), between the IMU and the frame the
    machine moves in, are [sensors.imu] misalignment_deg here: the machine moves along b."""


class PushRam(Section):
    """Stroke sensors on the push rams."""

    rate_hz: Rate = 1.0
    noise_m: between(0, 0.1) = 1e-4
    """Standard deviation of the reading (0.02 m for the sensors of 004 Table 1); at most 0.1 m, an eighth of a web
    (a noisier stroke sensor cannot tell a push from none)."""
    resolution_m: between(0, 0.1) = 1e-4
    """Reading step; at most 0.1 m, as the noise."""


class Pressure(Section):
    """Pressure transducers on every support's legs and push ram (0-60 MPa)."""

    rate_hz: Rate = 1.0
    noise_mpa: between(0, 5.0) = 0.05
    """Standard deviation of a reading; at most 5 MPa (a tenth of the range: noisier tells no set from a yield)."""
    resolution_mpa: between(0, 5.0) = 0.1
    """Reading step; at most 5 MPa, as the noise."""


class Magnetometer(Section):
    """The shearer's three-axis magnetometer."""

    rate_hz: Rate = 50.0
    date: WmmDate = "2026-06-01"
    """Date for the geomagnetic model (declination, inclination, intensity at the site): a real date within the
    model's years (section.WMM_YEARS)."""
    noise_t: between(0, 0.2 * EARTH_FIELD_T) = 1.0e-7
    """White noise per axis and sample; at most a fifth of the Earth's field (EARTH_FIELD_T)."""
    hard_iron_t: vector3(2 * EARTH_FIELD_T) = [2.0e-6, -1.0e-6, 0.5e-6]
    """Constant field of the machine's magnetised iron in b; within twice the Earth's field (EARTH_FIELD_T)."""
    soft_iron: SoftIron = [[1.02, 0.01, 0.0], [0.01, 0.98, 0.0], [0.0, 0.0, 1.0]]
    """Soft-iron matrix applied to the Earth field in b (rows); not singular (check_soft_iron)."""
    motor_disturbance_t: vector3(2 * EARTH_FIELD_T) = [1.5e-6, 0.5e-6, -1.0e-6]
    """Field of the haulage and cutting motors in b while the shearer moves (scaled by speed / cutting speed);
    within twice the Earth's field."""

    @model_validator(mode="after")
    def _invertible(self) -> Magnetometer:
        check_soft_iron(self.soft_iron, "soft_iron")
        return self


class SupportImu(Section):
    """9-axis MEMS units on the canopies of selected supports (002 section 2)."""

    supports: list[Annotated[int, Field(ge=0)]] = []
    rate_hz: Rate = 50.0
    grade: str = "icm-42605"
    shearer_disturbance_t: between(0, 2 * EARTH_FIELD_T) = 5.0e-6
    """Peak magnetic disturbance at a support while the shearer passes it (falls off over a pan length); within
    twice the Earth's field."""


class Survey(Section):
    """Surveyed fixes of the shearer: the start pose at face end A and face end B of the first cut (001 section
    2.2: the face ends are measured in advance). Defaults are 001 Table 1's initial position and heading errors."""

    sd_horizontal_m: between(0, 2.0) = 0.05
    """One-sigma error of each horizontal coordinate (east, north) of a fix; at most 2 m, about a pan length (a
    fix that cannot tell the chute is not a survey)."""
    sd_vertical_m: between(0, 2.0) = 0.05
    """One-sigma error of the height of a fix; at most 2 m, as the horizontal."""
    sd_yaw_deg: between(0, 10.0) = 1.0
    """One-sigma error of the surveyed yaw of the start pose (the face-end fix B carries no heading); at most 10
    deg (the filters' attitude errors are small angles)."""
    face_ends: Literal["first_cut", "every_cut"] = "every_cut"
    """first_cut: only the ends of the first straight cut are fixed (001's experiment); every_cut: both ends of
    every straight cut, as the gate-road survey marks them ahead of each advance."""
    face_line: bool = True
    """Survey the installed face line before the first cut (the FACE_SURVEY stream: one point per chute)."""


class Sensors(Section):
    imu: Imu = Imu()
    vibration: Vibration = Vibration()
    odometer: Odometer = Odometer()
    pushram: PushRam = PushRam()
    pressure: Pressure = Pressure()
    mag: Magnetometer = Magnetometer()
    support_imu: SupportImu = SupportImu()
    survey: Survey = Survey()


FaultKind = Literal["ram_stuck", "ram_offset", "ram_drift", "ram_scale", "ram_dropout", "ram_noise_burst",
                    "leg_pressure_stuck", "leg_pressure_offset", "leg_pressure_drift", "leg_pressure_scale",
                    "leg_pressure_dropout", "leg_pressure_noise_burst", "ram_pressure_stuck", "ram_pressure_offset",
                    "ram_pressure_drift", "ram_pressure_scale", "ram_pressure_dropout", "ram_pressure_noise_burst",
                    "push_shortfall", "obstruction", "leg_leak", "failed_set", "sticking_valve", "rail_deviation",
                    "mag_interference", "odometer_slip"]


class Fault(Section):
    """A fault injected on a sensor (or, for push_shortfall, obstruction and rail_deviation, on the face) in a window.

    value: ram_stuck (ignored: the reading freezes), ram_offset [m], ram_drift [m/s], ram_scale (relative
    error), ram_dropout (ignored: readings invalid), ram_noise_burst (standard deviation [m]); the same six on the
    pressure transducers of the legs (leg_pressure_*) and of the push ram (ram_pressure_*) in MPa and MPa/s; push_shortfall
    (metres the pan falls short while the sensor reads the full stroke), obstruction (metres the target's pan can
    still advance from where it stands at t_start before it meets an obstacle: its ram stalls at its relief
    pressure, the push falls short and the sensor reads it, until t_end clears it), leg_leak (oil the target's legs lose
    [L/min]: their pressure decays and the canopy comes off the roof), failed_set (pressure [MPa] at which the target's
    setting valve closes when it sets inside the window, short of the set pressure), sticking_valve (fraction of the
    metered flow the target's ram valve passes: a slow ram), rail_deviation (horizontal angle
    [deg] per two chutes, 004 section V), mag_interference (field magnitude [T]), odometer_slip (fraction of
    travel the encoder misses).
    """

    kind: FaultKind
    t_start_s: NonNegativeFloat
    t_end_s: NonNegativeFloat
    target: Annotated[int, Field(ge=0)] | None = None
    """Support index for ram faults, push_shortfall and obstruction; for mag_interference, a support whose canopy unit is
    disturbed (None: the shearer magnetometer); None for the others (the scenario checks that it exists)."""
    value: Finite = 0.0
    """Within FAULT_VALUES[kind]."""

    @model_validator(mode="after")
    def _in_range(self) -> Fault:
        lo, hi, why = FAULT_VALUES[self.kind]
        if not lo <= self.value <= hi:
            raise ValueError(f"value: {self.value:g} is outside {lo:g} .. {hi:g} for {self.kind} ({why})")
        if self.t_end_s <= self.t_start_s:
            raise ValueError(f"t_end_s {self.t_end_s:g} must be after t_start_s {self.t_start_s:g}")
        return self


READING_FAULTS = ("stuck", "offset", "drift", "scale", "dropout", "noise_burst")
"""The sensor faults of a support's readings, each kind `<sensor>_<fault>` (twin.sensors.faults: apply_gain_faults, ReadingFaults)."""
SUPPORT_SENSORS = ("ram", "leg_pressure", "ram_pressure")
"""The support sensors the reading faults act on: the ram's stroke, the legs' and the ram's pressure transducers."""
TARGETED = (*(f"{sensor}_{fault}" for sensor in SUPPORT_SENSORS for fault in READING_FAULTS), "push_shortfall",
            "obstruction", "leg_leak", "failed_set", "sticking_valve")
"""The fault kinds that need a target support."""
FAULT_VALUES: dict[str, tuple[float, float, str]] = {
    "ram_stuck": (-math.inf, math.inf, "ignored"),
    "ram_offset": (-3.0, 3.0, "metres; a ram is at most 3 m long"),
    "ram_drift": (-0.1, 0.1, "m/s; a tenth of the fastest ram, and a drift that fast is an offset"),
    "ram_scale": (-1.0, 1.0, "relative error; -1 reads zero"),
    "ram_dropout": (-math.inf, math.inf, "ignored"),
    "ram_noise_burst": (0.0, 1.0, "standard deviation [m]; more than a metre is no reading"),
    **{f"{sensor}_{kind}": limits for sensor in ("leg_pressure", "ram_pressure") for kind, limits in {
        "stuck": (-math.inf, math.inf, "ignored"), "offset": (-60.0, 60.0, "MPa; the transducer's range"),
        "drift": (-0.1, 0.1, "MPa/s; faster is an offset"), "scale": (-1.0, 1.0, "relative error; -1 reads zero"),
        "dropout": (-math.inf, math.inf, "ignored"),
        "noise_burst": (0.0, 20.0, "standard deviation [MPa]; a third of the range is no reading")}.items()},
    "push_shortfall": (0.0, 1.5, "metres; the scenario also keeps it within face.web_depth_m"),
    "obstruction": (0.0, 1.5, "metres of free advance; beyond a web the obstacle is never met"),
    "leg_leak": (0.0, 100.0, "L/min; a burst hose loses 100"),
    "failed_set": (0.0, 45.0, "MPa; at most the highest set pressure"),
    "sticking_valve": (0.05, 1.0, "fraction of the metered flow; below 5 % the valve is shut, not sticking"),
    "rail_deviation": (-10.0, 10.0, "deg per two chutes; the largest face.bend_limit_horizontal_deg"),
    "mag_interference": (-2 * EARTH_FIELD_T, 2 * EARTH_FIELD_T, "tesla; twice the Earth's field saturates"),
    "odometer_slip": (0.0, 1.0, "fraction of the travel missed; 1 misses all of it"),
}
"""Each fault kind's range of `value` (lo, hi, why)."""
