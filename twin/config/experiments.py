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
    Finite,
    NonNegativeFloat,
    PositiveFloat,
    ScenarioError,
    Section,
    Site,
    Vector3,
    validate,
)
from twin.config.tomlfile import file_kind, read_scenario

EXPERIMENT_KIND = "sins_experiment"

Samples = Annotated[int, Field(ge=1, le=5)]


class AlignmentParams(Section):
    """000 section 5.3: a standing IMU, fine alignment by each filter on each grade."""

    rate_hz: PositiveFloat
    duration_s: PositiveFloat
    pitch_deg: Finite
    roll_deg: Finite
    yaw_deg: Finite
    """000's heading angle: counter-clockwise from north (000's convention), 270 deg."""
    initial_error_deg: Vector3
    """phi_E, phi_N, phi_U of the start attitude (and the filter's initial sigma)."""
    grades: Annotated[list[str], Field(min_length=1)]
    methods: Annotated[list[Literal["ekf", "ukf", "optimized_ukf"]], Field(min_length=1)]
    update_hz: PositiveFloat
    velocity_sigma_m_s: PositiveFloat
    """Noise of the zero-velocity observation."""


class SwayParams(Section):
    """000 eq. 54: theta = theta_m sin(2 pi t / T_theta), likewise roll and yaw."""

    amplitude_deg: Vector3
    """Pitch, roll, yaw amplitudes."""
    period_s: Annotated[list[PositiveFloat], Field(min_length=3, max_length=3)]


class LeverArmParams(Section):
    """000 section 6.4, part 1: an error-free sensor mechanized with and without the compensation."""

    rate_hz: PositiveFloat
    duration_s: PositiveFloat
    samples: Samples
    """Increments per mechanization update (even: the two-sample compensation works on pairs)."""
    lever_arms_m: Annotated[list[Vector3], Field(min_length=1)]
    hold_height: bool


class ClosedLoopParams(Section):
    """000 section 6.4, part 2: closed-loop fine alignment with the paper's sensor errors."""

    enabled: bool
    gyro_bias_deg_h: NonNegativeFloat
    gyro_random_deg_h: NonNegativeFloat
    """Random drift: the sigma of white noise on each gyro sample's rate."""
    accel_bias_g: NonNegativeFloat
    accel_random_g: NonNegativeFloat
    initial_error_deg: Vector3
    update_hz: PositiveFloat
    velocity_sigma_m_s: PositiveFloat


class ConingParams(Section):
    """000 section 7.2, eq. 55."""

    half_cone_deg: PositiveFloat
    cone_rate_rad_s: PositiveFloat
    step_s: PositiveFloat
    """h: the gyro sample interval."""
    duration_s: PositiveFloat
    samples: Samples


class ScullingParams(Section):
    """000 section 7.4, eq. 71."""

    frequency_hz: PositiveFloat
    angular_amplitude_deg: PositiveFloat
    """B."""
    specific_force_amplitude_g: PositiveFloat
    """C."""
    step_s: PositiveFloat
    """Sub-sample interval; the velocity period is T = samples * step_s (000: 4 x 6 ms = 0.024 s)."""
    duration_s: PositiveFloat
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
    if isinstance(exp, LeverArmExperiment) and exp.lever_arm.samples % 2:
        raise ScenarioError(f"{source}: lever_arm.samples: must be even (the two-sample compensation works on "
                            f"pairs of increments; got {exp.lever_arm.samples})")
    return exp


def load_experiment(path: str | Path, seed: int | None = None) -> Experiment:
    """Read and validate an experiment file; `seed` overrides the file's seed."""
    return parse_experiment(read_scenario(path, seed), str(path))
