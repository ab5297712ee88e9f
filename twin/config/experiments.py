"""SINS experiment files: the simulations of 000 as scenario files (top-level `kind = "sins_experiment"`).

`experiment` names one of 000_78d1df35b229913e.txt's four simulations and a section of the same name holds all
its parameters, in the units the paper writes (no hidden defaults: every parameter is a required key); the runs
are twin.papers.sins_experiments'. The shipped files are scenarios/seed000_{alignment,lever_arm,coning,sculling}.toml.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field

from twin.config.imu_grades import GRADES
from twin.config.section import (
    Duration,
    Rate,
    ScenarioError,
    Section,
    Site,
    between,
    validate,
    vector3,
)
from twin.config.tomlfile import file_kind, read_scenario

EXPERIMENT_KIND = "sins_experiment"

Samples = Annotated[int, Field(ge=1, le=5)]
Angle = between(-360, 360)
"""An attitude angle [deg]: one turn either way."""
SmallAngles = vector3(30)
"""Attitude errors phi_E, phi_N, phi_U [deg]: the fine-alignment filters' error models are small-angle ones."""
VelocitySigma = Annotated[float, Field(gt=0, le=10, allow_inf_nan=False)]
"""Noise of a zero-velocity observation [m/s]: above 10 m/s it observes nothing at a standstill."""
Step = Annotated[float, Field(gt=0, le=1, allow_inf_nan=False)]
"""A sample interval [s]: at most a second (the paper's are 6 and 10 ms; twin.config.resources counts the steps)."""


class AlignmentParams(Section):
    """000 section 5.3: a standing IMU, fine alignment by each filter on each grade."""

    rate_hz: Rate
    duration_s: Duration
    pitch_deg: between(-90, 90)
    roll_deg: Angle
    yaw_deg: Angle
    """000's heading angle: counter-clockwise from north (000's convention), 270 deg."""
    initial_error_deg: SmallAngles
    """phi_E, phi_N, phi_U of the start attitude (and the filter's initial sigma)."""
    grades: Annotated[list[str], Field(min_length=1)]
    methods: Annotated[list[Literal["ekf", "ukf", "optimized_ukf"]], Field(min_length=1)]
    update_hz: Rate
    velocity_sigma_m_s: VelocitySigma
    """Noise of the zero-velocity observation."""


class SwayParams(Section):
    """000 eq. 54: theta = theta_m sin(2 pi t / T_theta), likewise roll and yaw."""

    amplitude_deg: vector3(90)
    """Pitch, roll, yaw amplitudes; at most 90 deg (the pitch would pass the vertical)."""
    period_s: Annotated[list[Duration], Field(min_length=3, max_length=3)]


class LeverArmParams(Section):
    """000 section 6.4, part 1: an error-free sensor mechanized with and without the compensation."""

    rate_hz: Rate
    duration_s: Duration
    samples: Samples
    """Increments per mechanization update (even: the two-sample compensation works on pairs)."""
    lever_arms_m: Annotated[list[vector3(100)], Field(min_length=1, max_length=10)]
    """Within 100 m per axis (000's are 1.5 m; a longer arm is another body)."""
    hold_height: bool


class ClosedLoopParams(Section):
    """000 section 6.4, part 2: closed-loop fine alignment with the paper's sensor errors."""

    enabled: bool
    gyro_bias_deg_h: between(0, 3600)
    """At most 1 deg/s, a consumer MEMS gyro's turn-on bias."""
    gyro_random_deg_h: between(0, 3600)
    """Random drift: the sigma of white noise on each gyro sample's rate; at most 1 deg/s, as the bias."""
    accel_bias_g: between(0, 0.1)
    """At most 0.1 g (an uncalibrated MEMS accelerometer reaches 0.05 g)."""
    accel_random_g: between(0, 0.1)
    initial_error_deg: SmallAngles
    update_hz: Rate
    velocity_sigma_m_s: VelocitySigma


class ConingParams(Section):
    """000 section 7.2, eq. 55."""

    half_cone_deg: Annotated[float, Field(gt=0, le=90, allow_inf_nan=False)]
    cone_rate_rad_s: Annotated[float, Field(gt=0, le=1000, allow_inf_nan=False)]
    """At most 1000 rad/s (160 turns a second; the paper's is one)."""
    step_s: Step
    """h: the gyro sample interval."""
    duration_s: Duration
    samples: Samples


class ScullingParams(Section):
    """000 section 7.4, eq. 71."""

    frequency_hz: Annotated[float, Field(gt=0, le=1000, allow_inf_nan=False)]
    angular_amplitude_deg: Annotated[float, Field(gt=0, le=90, allow_inf_nan=False)]
    """B."""
    specific_force_amplitude_g: Annotated[float, Field(gt=0, le=50, allow_inf_nan=False)]
    """C; at most 50 g (no IMU of a face reads more)."""
    step_s: Step
    """Sub-sample interval; the velocity period is T = samples * step_s (000: 4 x 6 ms = 0.024 s)."""
    duration_s: Duration
    samples: Samples


class _Experiment(Section):
    kind: Literal["sins_experiment"]
    name: Annotated[str, Field(min_length=1)]
    seed: Annotated[int, Field(ge=0)] = 0
    site: Site = Site()


class AlignmentExperiment(_Experiment):
    experiment: Literal["alignment"]
    alignment: AlignmentParams


class LeverArmExperiment(_Experiment):
    experiment: Literal["lever_arm"]
    sway: SwayParams
    lever_arm: LeverArmParams
    closed_loop: ClosedLoopParams


class ConingExperiment(_Experiment):
    experiment: Literal["coning"]
    coning: ConingParams


class ScullingExperiment(_Experiment):
    experiment: Literal["sculling"]
    sculling: ScullingParams


Experiment = AlignmentExperiment | LeverArmExperiment | ConingExperiment | ScullingExperiment
MODELS: dict[str, type[_Experiment]] = {"alignment": AlignmentExperiment, "lever_arm": LeverArmExperiment,
                                        "coning": ConingExperiment, "sculling": ScullingExperiment}


def is_experiment(path: str | Path) -> bool:
    """Whether a scenario file is a SINS experiment (its top-level `kind`); unreadable files are not."""
    return file_kind(path) == EXPERIMENT_KIND


def parse_experiment(data: dict, source: str = "<experiment>") -> Experiment:
    """Validate an experiment's data (the TOML as a dict); one-line ScenarioError naming `source` and the key."""
    if data.get("kind") != EXPERIMENT_KIND:
        raise ScenarioError(f"{source}: kind: must be \"{EXPERIMENT_KIND}\" for an experiment (got "
                            f"{data.get('kind')!r})")
    name = data.get("experiment")
    if name not in MODELS:
        raise ScenarioError(f"{source}: experiment: must be one of {', '.join(MODELS)} (got {name!r})")
    exp = validate(MODELS[name], data, source, f"scenarios/seed000_{name}.toml")
    if isinstance(exp, AlignmentExperiment):
        for k, g in enumerate(exp.alignment.grades):
            if g not in GRADES:
                raise ScenarioError(f"{source}: alignment.grades[{k}]: no IMU preset '{g}' (presets: "
                                    f"{', '.join(sorted(GRADES))})")
    if isinstance(exp, AlignmentExperiment) and exp.alignment.update_hz > exp.alignment.rate_hz:
        raise ScenarioError(f"{source}: alignment.update_hz: {exp.alignment.update_hz} Hz exceeds rate_hz = "
                            f"{exp.alignment.rate_hz} Hz (an update needs a new sample)")
    if isinstance(exp, LeverArmExperiment) and exp.lever_arm.samples % 2:
        raise ScenarioError(f"{source}: lever_arm.samples: must be even (the two-sample compensation works on "
                            f"pairs of increments; got {exp.lever_arm.samples})")
    return exp


def load_experiment(path: str | Path, seed: int | None = None) -> Experiment:
    """Read and validate an experiment file; `seed` overrides the file's seed."""
    return parse_experiment(read_scenario(path, seed), str(path))
