"""SINS experiments: the simulations of 000 as scenario files, run beside the paper's figures.

A second kind of scenario file, marked by the top-level key `kind = "sins_experiment"`; `experiment` names one
of the four simulations of 000_78d1df35b229913e.txt and a section of the same name holds all its parameters
(no hidden defaults: every parameter is a required key, in the units the paper writes):

* ``alignment`` (000 section 5.3, Table 1): a standing IMU at 34.27 deg, 36 m, 000's heading angle 270 deg,
  initial attitude errors 3, 3, 5 deg, 200 Hz; `estimators.sins.fine_alignment.fine_align` with each filter
  (EKF, UKF, optimized UKF) on each IMU grade named (twin.config.imu_grades, errors drawn by twin.sensors.imu_errors).
* ``lever_arm`` (000 section 6.4, Tables 2-3): the sway of 000 eq. 54 (pitch, roll, yaw 10 deg, periods 6, 8,
  10 s) of a body whose reference point rests at the site, the sensor at lever arms r_p = [1, 1, 1] and
  [1.5, 1.5, 1] m. Part 1 mechanizes an error-free sensor (twin.sensors.imu's exact increments) for 400 s with and
  without the two-sample compensation (estimators.sins.installation.compensate_lever_arm, eqs. 48-53); part 2
  (``[closed_loop]``) runs the paper's own setting as far as it is specified: a 15-state closed-loop fine
  alignment with zero-velocity observations and the paper's sensor errors (see `_closed_loop`).
* ``coning`` (000 section 7.2): the cone of eq. 55 (alpha = 1 deg, omega = 2 pi rad/s, h = 10 ms, 3 samples,
  40 s; twin.papers.motions.coning): the N-sample rotation vector (estimators.sins.strapdown.compensate) against the
  exact one, and the body attitude integrated from either against the true cone.
* ``sculling`` (000 section 7.4): eq. 71 (f = 1 Hz, B = 0.1 deg, C = 0.01 g, 4 samples of 6 ms, 30 s;
  twin.papers.motions.sculling): the velocity integrated from plain sums and from the N-sample sculling
  compensation against the true vibration.

Each run gives our figures, the paper's, a table of both, and error time series against the truth: quantity
"attitude" [rad] (error angles phi with C_true = Exp(phi) C_est, E/N/U), "velocity" [m/s], "position" [m]
(E/N/U), and where the experiment has them "coning" (the per-update coning error [rad], body axes) and
"sigma" (a filter's one-sigma attitude uncertainty [rad]). In coning and sculling the body rests level with
b = n (twin.papers.motions), so their axes are E, N, U too.

Errors in a file are a `ScenarioError` of one line naming the file and the key, as for face scenarios.
"""

from __future__ import annotations

import json
import time
import tomllib
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from estimators.nav import earth
from estimators.nav.rotations import (
    euler_to_mat,
    euler_to_quat,
    mat_to_euler,
    mat_to_quat,
    quat_conj,
    quat_mul,
    quat_rotate,
    quat_to_mat,
    quat_to_rotvec,
    rotvec_to_quat,
)
from estimators.sins import error_model
from estimators.sins.fine_alignment import alignment_floors, fine_align
from estimators.sins.installation import compensate_lever_arm
from estimators.sins.strapdown import body_attitude, compensate, mechanize
from twin.config.imu_grades import GRADES, grade
from twin.config.scenario import ScenarioError, Site, _format_error, scenario_to_toml
from twin.papers.motions import G0, coning, sculling
from twin.sensors.imu import VibrationTones, sensor_increments
from twin.sensors.imu_errors import apply_imu_errors

EXPERIMENT_KIND = "sins_experiment"
DEG = np.pi / 180

PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegativeFloat = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
Vector3 = Annotated[list[Finite], Field(min_length=3, max_length=3)]
Samples = Annotated[int, Field(ge=1, le=5)]


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


class AlignmentParams(_Section):
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


class SwayParams(_Section):
    """000 eq. 54: theta = theta_m sin(2 pi t / T_theta), likewise roll and yaw."""

    amplitude_deg: Vector3
    """Pitch, roll, yaw amplitudes."""
    period_s: Annotated[list[PositiveFloat], Field(min_length=3, max_length=3)]


class LeverArmParams(_Section):
    """000 section 6.4, part 1: an error-free sensor mechanized with and without the compensation."""

    rate_hz: PositiveFloat
    duration_s: PositiveFloat
    samples: Samples
    """Increments per mechanization update (even: the two-sample compensation works on pairs)."""
    lever_arms_m: Annotated[list[Vector3], Field(min_length=1)]
    hold_height: bool


class ClosedLoopParams(_Section):
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


class ConingParams(_Section):
    """000 section 7.2, eq. 55."""

    half_cone_deg: PositiveFloat
    cone_rate_rad_s: PositiveFloat
    step_s: PositiveFloat
    """h: the gyro sample interval."""
    duration_s: PositiveFloat
    samples: Samples


class ScullingParams(_Section):
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


class _Experiment(_Section):
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


# --------------------------------------------------------------------------------------------------------------
# Files


def _read_toml(path: Path) -> dict:
    if not path.is_file():
        raise ScenarioError(f"{path}: scenario file not found")
    try:
        return tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ScenarioError(f"{path}: not valid TOML: {err}") from None


def is_experiment(path: str | Path) -> bool:
    """Whether a scenario file is a SINS experiment (its top-level `kind`); unreadable files are not."""
    try:
        data = _read_toml(Path(path))
    except ScenarioError:
        return False
    return data.get("kind") == EXPERIMENT_KIND


def parse_experiment(data: dict, source: str = "<experiment>") -> Experiment:
    """Validate an experiment's data (the TOML as a dict); one-line ScenarioError naming `source` and the key."""
    if data.get("kind") != EXPERIMENT_KIND:
        raise ScenarioError(f"{source}: kind: must be \"{EXPERIMENT_KIND}\" for an experiment (got "
                            f"{data.get('kind')!r})")
    name = data.get("experiment")
    if name not in MODELS:
        raise ScenarioError(f"{source}: experiment: must be one of {', '.join(MODELS)} (got {name!r})")
    try:
        exp = MODELS[name].model_validate(data)
    except ValidationError as err:
        if err.errors()[0]["type"] == "extra_forbidden":
            loc = ".".join(str(x) for x in err.errors()[0]["loc"])
            raise ScenarioError(f"{source}: {loc}: unknown key (check the spelling; see "
                                f"scenarios/seed000_{name}.toml for the keys)") from None
        raise ScenarioError(_format_error(source, err)) from None
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
    data = _read_toml(Path(path))
    if seed is not None:
        data["seed"] = seed
    return parse_experiment(data, str(path))


def experiment_to_toml(exp: Experiment) -> str:
    """The resolved experiment as TOML text (every default made visible)."""
    return scenario_to_toml(exp)


# --------------------------------------------------------------------------------------------------------------
# Results


@dataclass
class Series:
    """One error time series: quantity (attitude, velocity, position, coning, sigma) of a case, (K, 3) in SI.

    group: the sub-experiment ("" when there is one; "table2", "mti-g-700/ekf", ...); variant: what is compared
    within it ("uncompensated", "compensated"; "" when nothing is)."""

    group: str
    quantity: str
    variant: str
    t: np.ndarray
    values: np.ndarray


@dataclass
class ExperimentResult:
    name: str
    experiment: str
    ours: dict
    paper: dict
    table: list[str]
    series: list[Series] = field(default_factory=list)


def attitude_error(q_true: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    """Error angles phi (K, 3) [rad] in n with C_true = Exp(phi) C_est (to first order C_est = (I - [phi x]) C_true)."""
    return quat_to_rotvec(quat_mul(q_true, quat_conj(q_est)))


def reduction_pct(uncompensated, compensated) -> np.ndarray:
    return 100.0 * (1.0 - np.asarray(compensated) / np.asarray(uncompensated))


def _row(label: str, values, fmt: str | list[str], width: int = 12) -> str:
    """One table row; fmt is a format spec for all values or one per value."""
    fmts = [fmt] * len(values) if isinstance(fmt, str) else fmt
    return f"  {label:34s}" + "".join(f"{v:{width}{f}}" for v, f in zip(values, fmts))


def _header(names) -> str:
    return f"  {'':34s}" + "".join(f"{n:>12s}" for n in names)


def _compensation_table(title: str, axes: list[str], paper: tuple, ours: tuple, reduction: str) -> list[str]:
    """Largest errors per axis, uncompensated and compensated, the paper's above ours."""
    rows = [_row(f"{who}, {variant}", values, ".3g") for who, pair in (("paper", paper), ("ours", ours))
            for variant, values in zip(("uncompensated", "compensated"), pair)]
    return [title, _header(axes), *rows, f"  reduction of the largest error: {reduction}"]


def _plain_sums(a: np.ndarray, n: int, updates: int) -> np.ndarray:
    """Sums of the increments of each update (rows 1.., grouped by n): no coning or sculling terms."""
    return a[1:1 + updates * n].reshape(updates, n, 3).sum(axis=1)


# --------------------------------------------------------------------------------------------------------------
# Coning (000 section 7.2)

PAPER_CONING = {
    "axes": "x, y, z as printed in 000 section 7.2; its cone axis is z (ours: x, eq. 55)",
    "max_error_rad": {"uncompensated": [4.2e-6, 7.7e-6, 1.95e-8], "compensated": [1.5e-6, 2.8e-6, 0.98e-8]},
    "reduction_pct": [64.3, 63.6, 49.7],
}


def run_coning(exp: ConingExperiment) -> ExperimentResult:
    """Largest per-update coning error (algorithm rotation vector minus the exact one), and the attitude drift
    of the body attitude integrated from them, without and with the N-sample compensation."""
    p = exp.coning
    alpha, psi, n = p.half_cone_deg * DEG, p.cone_rate_rad_s, p.samples
    t, dtheta, dv = coning(alpha, psi, dt=p.step_s, duration_s=p.duration_s, earth_rate=False, gravity=False)
    tt = t[::n]
    q_true = rotvec_to_quat(alpha * np.column_stack([0 * tt, np.cos(psi * tt), np.sin(psi * tt)]))
    exact = quat_to_rotvec(quat_mul(quat_conj(q_true[:-1]), q_true[1:]))
    phi, _ = compensate(dtheta, dv, n)
    u = phi.shape[0]
    ours, series = {"samples": n}, []
    for variant, rotvec in (("uncompensated", _plain_sums(dtheta, n, u)), ("compensated", phi)):
        err = rotvec - exact[:u]
        att = attitude_error(q_true[:u + 1], body_attitude(q_true[0], rotvec))
        ours.setdefault("max_error_rad", {})[variant] = np.abs(err).max(axis=0).tolist()
        ours.setdefault("drift_rad", {})[variant] = float(np.linalg.norm(att[-1]))
        series += [Series("", "coning", variant, tt[1:u + 1], err), Series("", "attitude", variant, tt[:u + 1], att)]
    raw, comp = (np.array(ours["max_error_rad"][v]) for v in ("uncompensated", "compensated"))
    ours["reduction_pct"] = float(reduction_pct(raw.max(), comp.max()))
    ours["drift_reduction_pct"] = float(reduction_pct(*(ours["drift_rad"][v] for v in ("uncompensated",
                                                                                         "compensated"))))
    pr, pc = (PAPER_CONING["max_error_rad"][v][::-1] for v in ("uncompensated", "compensated"))
    table = _compensation_table(
        f"000 section 7.2, coning ({p.half_cone_deg:g} deg, {psi:.4g} rad/s, h = {p.step_s * 1e3:g} ms, {n} samples, "
        f"{p.duration_s:g} s): largest coning error per axis [rad]", ["x (cone)", "y", "z"], (pr, pc), (raw, comp),
        f"paper {max(PAPER_CONING['reduction_pct']):.1f} %, ours {ours['reduction_pct']:.4f} %")
    table += [(f"  attitude drift after {tt[u]:g} s [rad]: uncompensated {ours['drift_rad']['uncompensated']:.3g}, "
              f"compensated {ours['drift_rad']['compensated']:.3g} ({ours['drift_reduction_pct']:.4f} % less)"),
              "  (the paper's axes put the cone axis on z; ours follow eq. 55 with it on x; paper columns reordered)"]
    return ExperimentResult(exp.name, exp.experiment, ours, PAPER_CONING, table, series)


# --------------------------------------------------------------------------------------------------------------
# Sculling (000 section 7.4)

PAPER_SCULLING = {
    "largest_uncompensated_error_m_s": 0.145,
    "max_error_m_s": {"uncompensated": [0.055, 0.58, 0.038], "compensated": [0.013, 0.18, 0.014]},
    "reduction_pct": [76.4, 70.0, 63.2],
}


def run_sculling(exp: ScullingExperiment) -> ExperimentResult:
    """Largest velocity error against the true vibration, from plain sums of the increments and from the
    N-sample sculling compensation; the position error is the velocity error integrated (trapezoid)."""
    p = exp.sculling
    b, c, n = p.angular_amplitude_deg * DEG, p.specific_force_amplitude_g * G0, p.samples
    om = 2 * np.pi * p.frequency_hz
    t, dtheta, dv = sculling(p.frequency_hz, b, c, dt=p.step_s, duration_s=p.duration_s)
    tt = t[::n]
    # The sensor's displacement u_y = -C / Omega^2 sin(Omega t) and its angle B sin(Omega t) (twin.papers.motions).
    v_true = np.column_stack([0 * tt, -c / om * np.cos(om * tt), 0 * tt])
    q_true = rotvec_to_quat(np.column_stack([b * np.sin(om * tt), 0 * tt, 0 * tt]))
    phi, dv_b = compensate(dtheta, dv, n)
    u = phi.shape[0]
    ours, series = {"samples": n, "velocity_period_s": n * p.step_s}, []
    for variant, (rotvec, dvel) in (("uncompensated", (_plain_sums(dtheta, n, u), _plain_sums(dv, n, u))),
                                    ("compensated", (phi, dv_b))):
        q = body_attitude(q_true[0], rotvec)
        v = v_true[0] + np.concatenate([[np.zeros(3)], np.cumsum(quat_rotate(q[:-1], dvel), axis=0)])
        dv_err = v - v_true[:u + 1]
        steps = 0.5 * (dv_err[1:] + dv_err[:-1]) * np.diff(tt[:u + 1])[:, None]
        dp_err = np.concatenate([[np.zeros(3)], np.cumsum(steps, axis=0)])
        ours.setdefault("max_error_m_s", {})[variant] = np.abs(dv_err).max(axis=0).tolist()
        ours.setdefault("max_position_error_m", {})[variant] = np.abs(dp_err).max(axis=0).tolist()
        series += [Series("", "attitude", variant, tt[:u + 1], attitude_error(q_true[:u + 1], q)),
                   Series("", "velocity", variant, tt[:u + 1], dv_err),
                   Series("", "position", variant, tt[:u + 1], dp_err)]
    raw, comp = (np.array(ours["max_error_m_s"][v]) for v in ("uncompensated", "compensated"))
    ours["reduction_pct"] = float(reduction_pct(raw.max(), comp.max()))
    pr, pc = (PAPER_SCULLING["max_error_m_s"][v] for v in ("uncompensated", "compensated"))
    table = _compensation_table(
        f"000 section 7.4, sculling ({p.frequency_hz:g} Hz, B = {p.angular_amplitude_deg:g} deg, "
        f"C = {p.specific_force_amplitude_g:g} g, {n} x {p.step_s * 1e3:g} ms, {p.duration_s:g} s): largest velocity "
        "error per axis [m/s]", ["x", "y", "z"], (pr, pc), (raw, comp),
        f"paper {PAPER_SCULLING['reduction_pct'][1]:.1f} % (Y), ours {ours['reduction_pct']:.4f} %")
    table.append(f"  (paper: largest uncompensated sculling error {PAPER_SCULLING['largest_uncompensated_error_m_s']}"
                 " m/s on Y, its Figure 17)")
    return ExperimentResult(exp.name, exp.experiment, ours, PAPER_SCULLING, table, series)


# --------------------------------------------------------------------------------------------------------------
# Lever arm (000 section 6.4, eq. 54, Tables 2-3)

PAPER_LEVER_ARM = {  # maximum attitude errors [deg] (E, N, U) and reductions [%] per lever arm
    (1.0, 1.0, 1.0): {"table": 2, "uncompensated_deg": [0.45, 0.25, 0.35], "compensated_deg": [0.12, 0.10, 0.05],
                      "reduction_pct": [73.3, 60.0, 85.7]},
    (1.5, 1.5, 1.0): {"table": 3, "uncompensated_deg": [0.90, 0.70, 0.70], "compensated_deg": [0.20, 0.15, 0.08],
                      "reduction_pct": [77.8, 78.6, 88.6]},
}


def sway(t: np.ndarray, amplitude_rad, period_s, lat: float, h: float) -> tuple[np.ndarray, ...]:
    """000 eq. 54 at a point fixed on the Earth: C_b^n (K, 3, 3), w_ib^b (K, 3), f^b (K, 3), analytic.

    C_b^n = Rz(y) Rx(p) Ry(r) gives w_nb^b = [cr p' - sr cp y', r' + sp y', sr p' + cr cp y']; the body rate adds
    the Earth rate C_n^b w_ie^n (no transport rate at rest), and f^b = C_n^b [0, 0, gamma]."""
    t = np.asarray(t, float)
    om = 2 * np.pi / np.asarray(period_s, float)
    p, r, y = (a * np.sin(o * t) for a, o in zip(amplitude_rad, om))
    pd, rd, yd = (a * o * np.cos(o * t) for a, o in zip(amplitude_rad, om))
    c = euler_to_mat(p, r, y)
    sp, cp, sr, cr = np.sin(p), np.cos(p), np.sin(r), np.cos(r)
    w_nb = np.stack([cr * pd - sr * cp * yd, rd + sp * yd, sr * pd + cr * cp * yd], axis=-1)
    w_ib = w_nb + np.einsum("...ji,j->...i", c, earth.earth_rate_n(lat))
    f_b = earth.normal_gravity(lat, h) * c[..., 2, :]
    return c, w_ib, f_b


def _sway_increments(t: np.ndarray, w_ib: np.ndarray, f_b: np.ndarray, lever_arm_b) -> tuple[np.ndarray, ...]:
    """Exact increments of an error-free sensor at lever_arm_b on the swaying body (twin IMU, no vibration)."""
    still = VibrationTones(freq_hz=np.ones((1, 1)), ang_amp=np.zeros((1, 1, 3)), lin_amp=np.zeros((1, 1, 3)),
                           phase_ang=np.zeros((3, 1)), phase_lin=np.zeros((3, 1)))
    return sensor_increments(t, w_ib, f_b, np.zeros((t.size, 1)), still, np.asarray(lever_arm_b, float), np.eye(3))


def _closed_loop(exp: LeverArmExperiment, t, c, dth, dv, r_p, compensated: bool) -> tuple[np.ndarray, np.ndarray]:
    """000 section 6.4's setting: closed-loop fine alignment over the sway with the paper's sensor errors.

    A 15-state error-state Kalman filter on estimators.sins.error_model (attitude, velocity, position, gyro drift,
    accelerometer bias) with zero-velocity observations of the resting reference point at `update_hz`.
    Uncompensated, the sensor's lever-arm velocity enters the observations and is taken for tilt. The paper
    gives no filter tuning; the observation noise is `velocity_sigma_m_s` and the absolute errors depend on it.
    Returns the update times and the attitude errors (E, N, U) [rad] after each update."""
    cl, site = exp.closed_loop, exp.site
    rng = np.random.default_rng(exp.seed)
    h = float(t[1] - t[0])
    gyro_bias, gyro_random = cl.gyro_bias_deg_h * DEG / 3600, cl.gyro_random_deg_h * DEG / 3600
    accel_bias, accel_random = cl.accel_bias_g * G0, cl.accel_random_g * G0
    phi0 = np.asarray(cl.initial_error_deg) * DEG
    dth = dth + gyro_bias * h + rng.normal(0, gyro_random * h, dth.shape)
    dv = dv + accel_bias * h + rng.normal(0, accel_random * h, dv.shape)
    dth[0] = dv[0] = 0.0
    if compensated:
        dv = compensate_lever_arm(dth, dv, r_p, h=h)
    chunk = max(1, round(1.0 / (cl.update_hz * h)))
    q = quat_mul(rotvec_to_quat(-phi0), mat_to_quat(c[0]))  # C_est = (I - [phi x]) C_true
    lat, lon, hgt, v = site.lat_deg * DEG, site.lon_deg * DEG, site.height_m, np.zeros(3)
    n = 15
    p = np.diag(np.r_[phi0 ** 2, [0.01 ** 2] * 3, [1e-14, 1e-14, 1e-2], [gyro_bias ** 2] * 3, [accel_bias ** 2] * 3])
    hm = np.zeros((3, n))
    hm[:, 3:6] = np.eye(3)
    r = np.eye(3) * cl.velocity_sigma_m_s ** 2
    dt = chunk * h
    qn = np.diag(np.r_[[gyro_random ** 2 * dt * 1e3] * 3, [accel_random ** 2 * dt * 1e3] * 3])
    bg, ba = np.zeros(3), np.zeros(3)
    t_out, q_out = [], []
    for k0 in range(0, t.size - chunk, chunk):
        sl = slice(k0, k0 + chunk + 1)
        nav = mechanize(t[sl], dth[sl] - bg * h, dv[sl] - ba * h, lat, lon, hgt, v, q, n_samples=2)
        lat, lon, hgt, v, q = nav.lat[-1], nav.lon[-1], nav.h[-1], nav.v_n[-1], nav.q_nb[-1]
        f_n = quat_to_mat(q) @ (dv[sl][1:].sum(axis=0) / dt - ba)
        gg, ga = error_model.sensor_input(q)
        f = np.zeros((n, n))
        f[:9, :9] = error_model.system_matrix(lat, hgt, v, f_n)
        f[:9, 9:12], f[:9, 12:15] = gg, ga
        phi = np.eye(n) + f * dt + f @ f * dt * dt / 2
        g = np.zeros((n, 6))
        g[:9, :3], g[:9, 3:] = gg, ga
        p = phi @ p @ phi.T + g @ qn @ g.T
        gain = p @ hm.T @ np.linalg.inv(hm @ p @ hm.T + r)
        x = gain @ v  # observation: computed velocity minus the zero of the resting reference point
        p = (np.eye(n) - gain @ hm) @ p
        p = 0.5 * (p + p.T)
        q = quat_mul(rotvec_to_quat(x[:3]), q)
        q = q / np.linalg.norm(q)
        v = v - x[3:6]
        lat, lon, hgt = lat - x[6], lon - x[7], hgt - x[8]
        bg, ba = bg + x[9:12], ba + x[12:15]
        t_out.append(t[k0 + chunk])
        q_out.append(q)
    k = np.arange(chunk, chunk * (len(t_out) + 1), chunk)
    return np.array(t_out), attitude_error(mat_to_quat(c[k]), np.array(q_out))


def _lever_arm_group(r_p) -> str:
    paper = PAPER_LEVER_ARM.get(tuple(float(x) for x in r_p))
    return f"table{paper['table']}" if paper else "r_p_" + "_".join(f"{x:g}" for x in r_p)


def run_lever_arm(exp: LeverArmExperiment) -> ExperimentResult:
    """Per lever arm: the maximum attitude errors (E, N, U) of the mechanization of an error-free sensor,
    uncompensated and compensated, and (closed_loop.enabled) those of the closed-loop fine alignment over its
    second half (the steady state the paper describes; the initial heading error would dominate otherwise).

    The paper's figures come from its fine-alignment filter, where the lever-arm acceleration is mistaken for
    tilt; in part 1 the sensor is error-free, so the attitude errors are those of the lever arm alone (through
    the velocity error and the transport rate): their size is not comparable with the paper's, the reductions
    are."""
    la, sw, site = exp.lever_arm, exp.sway, exp.site
    lat, lon, hgt = site.lat_deg * DEG, site.lon_deg * DEG, site.height_m
    t = np.arange(round(la.duration_s * la.rate_hz) + 1) / la.rate_hz
    c, w_ib, f_b = sway(t, np.asarray(sw.amplitude_deg) * DEG, sw.period_s, lat, hgt)
    q_true = mat_to_quat(c[::la.samples])
    ours, paper, series = {}, {}, []
    table = [(f"000 section 6.4, lever arm: eq. 54 sway ({', '.join(f'{a:g}' for a in sw.amplitude_deg)} deg, "
             f"periods {', '.join(f'{p:g}' for p in sw.period_s)} s), {la.duration_s:g} s at {la.rate_hz:g} Hz; "
             "maximum attitude errors (E, N, U)")]
    for r_p in la.lever_arms_m:
        group = _lever_arm_group(r_p)
        p_ref = PAPER_LEVER_ARM.get(tuple(float(x) for x in r_p))
        dtheta, dv = _sway_increments(t, w_ib, f_b, r_p)
        res = {"lever_arm_m": list(r_p)}
        for variant, dv_used in (("uncompensated", dv), ("compensated", compensate_lever_arm(dtheta, dv, r_p, t=t))):
            nav = mechanize(t, dtheta, dv_used, lat, lon, hgt, np.zeros(3), q_true[0], n_samples=la.samples,
                            hold_height=la.hold_height)
            att = attitude_error(q_true[:nav.t.size], nav.q_nb)
            pos = earth.lla_to_enu(nav.lat, nav.lon, nav.h, lat, lon, hgt)
            res[f"{variant}_deg"] = np.degrees(np.abs(att).max(axis=0)).tolist()
            res[f"{variant}_velocity_m_s"] = np.abs(nav.v_n).max(axis=0).tolist()
            res[f"{variant}_position_m"] = np.abs(pos).max(axis=0).tolist()
            series += [Series(group, "attitude", variant, nav.t, att),
                       Series(group, "velocity", variant, nav.t, nav.v_n),
                       Series(group, "position", variant, nav.t, pos)]
        res["reduction_pct"] = reduction_pct(res["uncompensated_deg"], res["compensated_deg"]).tolist()
        table += [f"r_p = {list(r_p)} m" + (f" (paper Table {p_ref['table']})" if p_ref else ""),
                  _header(["dphi_E", "dphi_N", "dphi_U"]),
                  _row("ours uncompensated [deg]", res["uncompensated_deg"], ".3e"),
                  _row("ours compensated [deg]", res["compensated_deg"], ".3e"),
                  _row("ours reduction [%]", res["reduction_pct"], ".2f")]
        if exp.closed_loop.enabled:
            loop = {}
            for variant in ("uncompensated", "compensated"):
                tk, att = _closed_loop(exp, t, c, dtheta, dv, r_p, variant == "compensated")
                loop[f"{variant}_deg"] = np.degrees(np.abs(att[att.shape[0] // 2:]).max(axis=0)).tolist()
                loop[f"{variant}_final_deg"] = np.degrees(att[-1]).tolist()
                series.append(Series(f"closed_loop/{group}", "attitude", variant, tk, att))
            loop["reduction_pct"] = reduction_pct(loop["uncompensated_deg"], loop["compensated_deg"]).tolist()
            res["closed_loop"] = loop
            table += [_row("closed loop uncompensated [deg]", loop["uncompensated_deg"], ".4f"),
                      _row("closed loop compensated [deg]", loop["compensated_deg"], ".4f"),
                      _row("closed loop reduction [%]", loop["reduction_pct"], ".2f")]
        if p_ref:
            paper[group] = {"lever_arm_m": list(r_p), **{k: v for k, v in p_ref.items() if k != "table"}}
            table += [_row("paper uncompensated [deg]", p_ref["uncompensated_deg"], ".2f"),
                      _row("paper compensated [deg]", p_ref["compensated_deg"], ".2f"),
                      _row("paper reduction [%]", p_ref["reduction_pct"], ".1f")]
            line = "  reductions >= paper's: mechanization "
            for part in (res, res.get("closed_loop")):
                if part is not None:
                    part["meets_paper"] = bool(np.all(np.array(part["reduction_pct"]) >= p_ref["reduction_pct"]))
                    line += f"{'yes' if part['meets_paper'] else 'no'}{', closed loop ' if part is res else ''}"
            table.append(line.removesuffix(", closed loop "))
        ours[group] = res
    if exp.closed_loop.enabled:
        cl = exp.closed_loop
        table.append(f"  closed loop: the paper's sensor errors, R = ({cl.velocity_sigma_m_s:g} m/s)^2, maximum over "
                     f"the second half ({la.duration_s / 2:g}-{la.duration_s:g} s)")
    return ExperimentResult(exp.name, exp.experiment, ours, paper, table, series)


# --------------------------------------------------------------------------------------------------------------
# Fine alignment (000 section 5.3, Table 1)

PAPER_TABLE1 = {  # "Filtering Results of error angle" (units not stated in 000): error, variance per angle
    "units": "not stated in 000; copied as written",
    "ekf": {"error": [-0.510, 0.325, -18.478], "variance": [0.0103, 0.0056, 9.4679]},
    "ukf": {"error": [0.302, -0.253, 8.935], "variance": [0.0118, 0.0068, 7.6143]},
    "optimized_ukf": {"error": [-0.123, 0.102, -4.239], "variance": [0.0127, 0.0059, 4.8291]},
}


def _bias_psd(sigma: float, tau: float) -> float:
    """Random-walk PSD for the bias states matching a Gauss-Markov in-run bias: 2 sigma^2 / tau."""
    return 2 * sigma ** 2 / tau if sigma > 0 else 0.0


ALIGN_WINDOW_S = 10.0
"""Window of the mean attitude reported as a fine alignment's result [s]."""


def _fine_align(p: AlignmentParams, g, dtheta, dv, lat: float, h: float, q0, method: str):
    """The one call of estimators.sins.fine_alignment.fine_align (the grade's noise and bias priors)."""
    return fine_align(dtheta, dv, 1 / p.rate_hz, lat, q0, (g.gyro_arw, g.accel_vrw),
                      np.asarray(p.initial_error_deg) * DEG, method, h=h, gyro_bias_sigma=g.gyro_bias,
                      accel_bias_sigma=g.accel_bias, velocity_sigma=p.velocity_sigma_m_s, update_rate=p.update_hz,
                      gyro_bias_psd=_bias_psd(g.gyro_bias_instability, g.gyro_bias_tau),
                      accel_bias_psd=_bias_psd(g.accel_bias_instability, g.accel_bias_tau))


def run_alignment(exp: AlignmentExperiment) -> ExperimentResult:
    """Per grade and filter: the final attitude errors and the filter's sigma, with their convergence."""
    p, site = exp.alignment, exp.site
    lat, h = site.lat_deg * DEG, site.height_m
    q_true = euler_to_quat(p.pitch_deg * DEG, p.roll_deg * DEG, p.yaw_deg * DEG)
    c_true = quat_to_mat(q_true)
    n = round(p.duration_s * p.rate_hz)
    w_b = quat_rotate(quat_conj(q_true), earth.earth_rate_n(lat))
    f_b = quat_rotate(quat_conj(q_true), np.array([0.0, 0.0, earth.normal_gravity(lat, h)]))
    q0 = quat_mul(rotvec_to_quat(-np.asarray(p.initial_error_deg) * DEG), q_true)
    ours, series = {}, []
    table = [(f"000 section 5.3 / Table 1: L = {site.lat_deg:g} deg, h = {h:g} m, yaw {p.yaw_deg:g} deg, initial "
             f"errors {', '.join(f'{e:g}' for e in p.initial_error_deg)} deg, {p.rate_hz:g} Hz, {p.duration_s:g} s "
             f"stationary, seed {exp.seed}"),
             "  000 Table 1 (units not stated):  error and variance of phi_E, phi_N, phi_U",
             _header(["phi_E", "var", "phi_N", "var", "phi_U", "var"])]
    for m in p.methods:
        ref = PAPER_TABLE1[m]
        table.append(_row(f"paper {m}", [x for pair in zip(ref["error"], ref["variance"]) for x in pair],
                          [".4f", ".4g"] * 3))
    for gname in p.grades:
        g = grade(gname)
        dtheta, dv, info = apply_imu_errors(np.tile(w_b / p.rate_hz, (n, 1)), np.tile(f_b / p.rate_hz, (n, 1)),
                                            1 / p.rate_hz, g, np.random.default_rng(exp.seed))
        # Effective biases (turn-on bias and non-orthogonality times what the sensors see) and the floors of an
        # ideal stationary alignment for this draw (estimators.sins.fine_alignment.alignment_floors).
        acc = info.accel_bias + (info.accel_matrix - np.eye(3)) @ f_b
        gyr = info.gyro_bias + (info.gyro_matrix - np.eye(3)) @ w_b
        acc_sigma = float(np.hypot(g.accel_bias, np.linalg.norm(f_b) * g.accel_nonorth))
        start = np.asarray(p.initial_error_deg) * DEG
        fl, _ = alignment_floors(c_true, acc, gyr, lat, acc_sigma, g.gyro_bias, h, arw=g.gyro_arw,
                                 seconds=p.duration_s, start_error=start, start_sigma=start)
        floors = {"level_deg": float(np.degrees(np.hypot(fl[0], fl[1]))), "heading_deg": float(np.degrees(abs(fl[2]))),
                  "phi_deg": np.degrees(fl).tolist()}
        ours[gname] = {"floors": floors}
        table += [(f"{gname}: floors of this draw: level {floors['level_deg']:.4f} deg, heading "
                   f"{floors['heading_deg']:.4f} deg; ours [deg, deg^2]: final error and variance (sigma^2) of phi_E, "
                   "phi_N, phi_U"),
                  _header(["phi_E", "var", "phi_N", "var", "phi_U", "var", "time [s]"])]
        for m in p.methods:
            start = time.perf_counter()
            res = _fine_align(p, g, dtheta, dv, lat, h, q0, m)
            elapsed = time.perf_counter() - start
            # phi of the filter's convention (C_true = E(phi) C_est, estimators.sins.fine_alignment) at every update.
            phi = np.stack(mat_to_euler(c_true @ np.swapaxes(quat_to_mat(res.q_nb), -1, -2)), axis=-1)
            # The final estimate is the mean over the last ALIGN_WINDOW_S (the update-to-update tracking noise
            # removed, FineAlignment.attitude).
            d, phi_end = res.errors(q_true, window_s=ALIGN_WINDOW_S)
            err, var = np.degrees(phi_end), np.degrees(res.attitude_sigma[-1]) ** 2
            ours[gname][m] = {"error_deg": err.tolist(), "variance_deg2": var.tolist(),
                              "sigma_deg": np.sqrt(var).tolist(), "pitch_roll_yaw_error_deg": np.degrees(d).tolist(),
                              "seconds": elapsed}
            series += [Series(f"{gname}/{m}", "attitude", "", res.t, phi),
                       Series(f"{gname}/{m}", "sigma", "", res.t, res.attitude_sigma)]
            table.append(_row(f"ours {m}", [*[x for pair in zip(err, var) for x in pair], elapsed],
                              [".4f", ".4g"] * 3 + [".2f"]))
    paper = {k: v for k, v in PAPER_TABLE1.items() if k == "units" or k in p.methods}
    return ExperimentResult(exp.name, exp.experiment, ours, paper, table, series)


# --------------------------------------------------------------------------------------------------------------
# Running and writing

RUNNERS = {"alignment": run_alignment, "lever_arm": run_lever_arm, "coning": run_coning, "sculling": run_sculling}
UNITS = {"attitude": ("deg", np.degrees), "sigma": ("deg", np.degrees), "coning": ("rad", np.asarray),
         "velocity": ("m/s", np.asarray), "position": ("m", np.asarray)}
"""Units of the Rerun plots (SI in the Parquet file; degrees for angles at this edge)."""


def run_experiment(exp: Experiment) -> ExperimentResult:
    return RUNNERS[exp.experiment](exp)


def series_table(series: list[Series]) -> pa.Table:
    """The error time series as one long table: group, quantity, variant, t [s], e, n, u (SI)."""
    sizes = [s.t.size for s in series]
    cols = {"group": pa.array(np.repeat([s.group for s in series], sizes).astype(str)),
            "quantity": pa.array(np.repeat([s.quantity for s in series], sizes).astype(str)),
            "variant": pa.array(np.repeat([s.variant for s in series], sizes).astype(str)),
            "t": pa.array(np.concatenate([s.t for s in series]).astype(float))}
    values = np.concatenate([s.values for s in series]).astype(float)
    for k, axis in enumerate("enu"):
        cols[axis] = pa.array(values[:, k])
    meta = {"units": "attitude, coning, sigma [rad]; velocity [m/s]; position [m]",
            "axes": "e, n, u of the navigation frame (coning: body axes)"}
    return pa.table(cols, metadata=meta)


def entity_path(s: Series) -> str:
    return "/".join(x for x in ("errors", s.group, s.quantity, s.variant) if x)


def write_experiment_recording(path: Path, result: ExperimentResult, rate_hz: float = 20.0) -> None:
    """The error time series as Rerun Scalars (one send_columns per entity `errors/[group/]quantity[/variant]`,
    decimated to about `rate_hz`; errors.parquet keeps every sample), with a blueprint of one time-series view per
    group and quantity (compensated beside uncompensated; for the alignment, the attitude errors and the filter's
    sigma of each filter)."""
    import rerun as rr
    import rerun.blueprint as rrb

    from twin.view.recording import APPLICATION_ID, _series, decimate

    views: dict[str, str] = {}
    for s in result.series:
        origin = "/".join(x for x in ("errors", s.group, s.quantity if result.experiment != "alignment" else "") if x)
        views.setdefault(origin, f"{s.group + ' ' if s.group else ''}"
                                 f"{s.quantity if result.experiment != 'alignment' else 'attitude error and sigma'}")
    blueprint = rrb.Blueprint(rrb.Grid(*[rrb.TimeSeriesView(name=name, origin=origin)
                                         for origin, name in views.items()]), collapse_panels=True)
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4())
    rec.save(path, default_blueprint=blueprint)
    try:
        rec.send_recording_name(result.name)
        for s in result.series:
            unit, convert = UNITS[s.quantity]
            label = f"{s.quantity}{' ' + s.variant if s.variant else ''}"
            keep = decimate(s.t, rate_hz)
            _series(rec, entity_path(s), s.t[keep], convert(s.values[keep]), [f"{label} {a} [{unit}]" for a in "ENU"])
        rec.flush()
    finally:
        rec.disconnect()


def _json_ready(obj):
    if isinstance(obj, dict):
        return {str(k): _json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_ready(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def write_run(staging: Path, exp: Experiment, result: ExperimentResult) -> None:
    """metrics.json {"experiment", "ours", "paper"}, errors.parquet, run.rrd and the resolved scenario.toml."""
    (staging / "scenario.toml").write_text(experiment_to_toml(exp))
    metrics = {"experiment": {"name": exp.name, "kind": EXPERIMENT_KIND, "experiment": exp.experiment,
                              "seed": exp.seed}, "ours": result.ours, "paper": result.paper}
    (staging / "metrics.json").write_text(json.dumps(_json_ready(metrics), indent=2) + "\n")
    pq.write_table(series_table(result.series), staging / "errors.parquet")
    write_experiment_recording(staging / "run.rrd", result)


def run_experiment_file(scenario: Path, out: Path | None, seed: int | None, force: bool,
                        quiet: bool = False) -> Path:
    """`longwall run` for an experiment file: run it, write the run directory, print ours beside the paper's."""
    from twin.pipeline.rundir import atomic_run_dir, check_target

    exp = load_experiment(scenario, seed)
    out = Path(out) if out is not None else Path("runs") / f"{exp.name}-seed{exp.seed}"
    check_target(out, force)
    start = time.perf_counter()
    result = run_experiment(exp)
    with atomic_run_dir(out, force) as staging:
        write_run(staging, exp, result)
    if not quiet:
        print("\n".join(result.table))
        print(f"\n{time.perf_counter() - start:.1f} s; run directory: {out}")
    return out


def run_shipped(name: str, seed: int | None = None) -> ExperimentResult:
    """Run the shipped experiment file scenarios/NAME.toml (its seed, or `seed`): ours and the paper's figures."""
    from importlib import resources

    return run_experiment(load_experiment(Path(str(resources.files("twin.scenarios") / f"{name}.toml")), seed))


def benchmark(names: list[str]) -> None:
    """Run shipped experiment files (scenarios/NAME.toml) and print ours beside the paper's with run times: the
    benchmarks' entry point (benchmarks/bench_coning_sculling.py, bench_lever_arm.py)."""
    for name in names:
        start = time.perf_counter()
        result = run_shipped(name)
        print("\n".join(result.table))
        print(f"({name}: {time.perf_counter() - start:.1f} s)\n")
