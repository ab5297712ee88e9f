"""Scenario sections for the instruments and the injected faults (`[sensors.*]` and `[[faults]]`).

Units as written in the file (deg, Hz, T, m); the sensor models convert once. Every field has the default a
mining engineer would expect for a modern face; `grade` names a preset of twin.config.imu_grades.
"""
# ruff: noqa: RUF012 -- the list defaults are pydantic fields (Section is a BaseModel; pydantic copies defaults)

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from twin.config.section import (
    Finite,
    NonNegativeFloat,
    PositiveFloat,
    Section,
    Vector3,
)

Rate = Annotated[float, Field(gt=0, le=2000, allow_inf_nan=False)]


class Imu(Section):
    """The shearer's strapdown IMU."""

    grade: str = "mti-g-700"
    """A preset of twin.config.imu_grades (mti-g-700, par1 .. par12, nav-004, mti-30, icm-42605, ideal)."""
    rate_hz: Rate = 200.0
    lever_arm_m: Vector3 = [0.3, 0.5, 0.2]
    """IMU position relative to the body reference point, in the body frame b."""
    misalignment_deg: Vector3 = [0.05, -0.05, 0.1]
    """Small rotation of the IMU axes relative to b (about x, y, z): C_s^b = I + [m]x to first order."""


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
    metres_per_pulse: PositiveFloat = 0.002
    scale_error: Annotated[float, Field(ge=-0.1, le=0.1, allow_inf_nan=False)] = 0.003
    """Relative error of the nominal metres per pulse (0.003 = 3 per mille)."""
    mounting_deg: Vector3 = [0.2, 0.0, -0.3]
    """Angles of the encoder's axis relative to b (about x, y, z): the encoder counts travel along that axis, so
    they change its count by their cosine only. 001's mounting angles (eq. 10), between the IMU and the frame the
    machine moves in, are [sensors.imu] misalignment_deg here: the machine moves along b."""


class PushRam(Section):
    """Stroke sensors on the push rams."""

    rate_hz: Rate = 1.0
    noise_m: NonNegativeFloat = 1e-4
    """Standard deviation of the reading (0.02 m for the sensors of 004 Table 1)."""
    resolution_m: NonNegativeFloat = 1e-4


class Magnetometer(Section):
    """The shearer's three-axis magnetometer."""

    rate_hz: Rate = 50.0
    date: Annotated[str, Field(pattern=r"^\d{4}-\d{2}-\d{2}$")] = "2026-06-01"
    """Date for the geomagnetic model (declination, inclination, intensity at the site)."""
    noise_t: NonNegativeFloat = 1.0e-7
    hard_iron_t: Vector3 = [2.0e-6, -1.0e-6, 0.5e-6]
    soft_iron: Annotated[list[Vector3], Field(min_length=3, max_length=3)] = [[1.02, 0.01, 0.0], [0.01, 0.98, 0.0],
                                                                              [0.0, 0.0, 1.0]]
    """Soft-iron matrix applied to the Earth field in b (rows)."""
    motor_disturbance_t: Vector3 = [1.5e-6, 0.5e-6, -1.0e-6]
    """Field of the haulage and cutting motors in b while the shearer moves (scaled by speed / cutting speed)."""


class SupportImu(Section):
    """9-axis MEMS units on the canopies of selected supports (002 section 2)."""

    supports: list[Annotated[int, Field(ge=0)]] = []
    rate_hz: Rate = 50.0
    grade: str = "icm-42605"
    shearer_disturbance_t: NonNegativeFloat = 5.0e-6
    """Peak magnetic disturbance at a support while the shearer passes it (falls off over a pan length)."""


class Survey(Section):
    """Surveyed fixes of the shearer: the start pose at face end A and face end B of the first cut (001 section
    2.2: the face ends are measured in advance). Defaults are 001 Table 1's initial position and heading errors."""

    sd_horizontal_m: NonNegativeFloat = 0.05
    """One-sigma error of each horizontal coordinate (east, north) of a fix."""
    sd_vertical_m: NonNegativeFloat = 0.05
    """One-sigma error of the height of a fix."""
    sd_yaw_deg: NonNegativeFloat = 1.0
    """One-sigma error of the surveyed yaw of the start pose (the face-end fix B carries no heading)."""
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
    mag: Magnetometer = Magnetometer()
    support_imu: SupportImu = SupportImu()
    survey: Survey = Survey()


FaultKind = Literal["ram_stuck", "ram_offset", "ram_drift", "ram_scale", "ram_dropout", "ram_noise_burst",
                    "push_shortfall", "rail_deviation", "mag_interference", "odometer_slip"]


class Fault(Section):
    """A fault injected on a sensor (or, for push_shortfall and rail_deviation, on the face) in a window.

    value: ram_stuck (ignored: the reading freezes), ram_offset [m], ram_drift [m/s], ram_scale (relative
    error), ram_dropout (ignored: readings invalid), ram_noise_burst (standard deviation [m]), push_shortfall
    (metres the pan falls short while the sensor reads the full stroke), rail_deviation (horizontal angle
    [deg] per two chutes, 004 section V), mag_interference (field magnitude [T]), odometer_slip (fraction of
    travel the encoder misses).
    """

    kind: FaultKind
    t_start_s: NonNegativeFloat
    t_end_s: NonNegativeFloat
    target: Annotated[int, Field(ge=0)] | None = None
    """Support index for ram faults and push_shortfall; for mag_interference, a support whose canopy unit is
    disturbed (None: the shearer magnetometer); None for the others."""
    value: Finite = 0.0
