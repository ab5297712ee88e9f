"""Face scenarios (TOML in, validated `Scenario` out), and the one loader of every kind of scenario file.

A scenario file is the single description of a run. Units at this edge are the ones a mining engineer
writes (degrees, m/min, Hz); `Scenario` keeps them as written so the resolved file reads like the input,
and the `*_rad` / `*_m_s` properties convert once for the code. Any problem is a `ScenarioError` whose
message is one line naming the file and the key.

`load_scenario` reads any scenario file and dispatches on its top-level `kind`: absent for a face scenario,
"sins_experiment" for 000's experiments (twin.config.experiments), "support_turntable" for 002's turntable
(twin.config.turntable); `scenario_to_toml` writes any of them back.
"""
# ruff: noqa: RUF012 -- the list defaults are pydantic fields (Section is a BaseModel; pydantic copies defaults)

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, Field, model_validator

from twin.config.alignment import Alignment
from twin.config.experiments import EXPERIMENT_KIND, Experiment, parse_experiment
from twin.config.imu_grades import GRADES
from twin.config.push import check_scenario_offsets
from twin.config.section import (
    Duration,
    Finite,
    NonNegativeFloat,
    PositiveFloat,
    ScenarioError,
    Section,
    Site,
    between,
    validate,
    vector3,
)
from twin.config.sensors import (
    EARTH_FIELD_T,
    TARGETED,
    Fault,
    Sensors,
    SoftIron,
    check_soft_iron,
)
from twin.config.supports import Roof, Supports
from twin.config.tomlfile import read_scenario
from twin.config.turntable import TURNTABLE_KIND, Turntable, parse_turntable
from twin.face import snake
from twin.face.hydraulics import SupportHydraulics
from twin.face.layout import floor_pitch_change
from twin.face.suspension import ringing_hz

BendLimit = Annotated[float, Field(gt=0, le=10, allow_inf_nan=False)]
PAN_FLOOR_FRICTION = 0.35
"""Friction coefficient of a pan's feet on the floor (models/pan.xml, class pan_foot; a test keeps them equal)."""
MAX_FLOOR_TILT_DEG = math.degrees(math.atan(PAN_FLOOR_FRICTION))
"""Steepest floor the face stands on: a pan's friction angle, 19.3 deg. A pan at rest on a steeper floor slides down
it, and nothing in the twin holds the AFC against that (no anti-creep rams or anchored drive frames)."""


END_PUSH_MARGIN = 1.25
"""The end-push stop holds the end pans' push and their supports' advance with this margin (for the re-pushes)."""


class Face(Section):
    """The armoured face conveyor line, the floor it lies on and the coal to be cut."""

    azimuth_deg: Annotated[float, Field(ge=0, lt=360, allow_inf_nan=False)] = 0.0
    """Direction of the face line from headgate to tailgate, degrees clockwise from north.
    The face advances 90 deg clockwise from it (body x, towards the coal wall)."""
    pan_count: Annotated[int, Field(ge=8, le=400)] = 44
    pan_length_m: Annotated[float, Field(ge=1.5, le=2.05, allow_inf_nan=False)] = 1.75
    face_length_m: PositiveFloat | None = None
    """Optional check: must equal pan_count * pan_length_m within 1 mm when given."""
    bend_limit_horizontal_deg: BendLimit = 1.0
    bend_limit_vertical_deg: BendLimit = 3.0
    roll_limit_deg: BendLimit = 2.0
    """Relative roll a pan connector allows between neighbouring pans (twist about the face line), degrees."""
    axial_play_m: between(0, 0.05) = 0.004
    """Axial play of a pan connector: neighbouring pans' running lines part or close up by up to half of it each
    way from the nominal pitch pan_length_m (0: a rigid pin); at most 50 mm, a worn dogbone. Above about 5 mm the
    shearer's ride, which finds its pans at the nominal pitch (twin.face.ride), strays off the running line: at 10 mm
    the shoes of seed002_face ran 7 mm beside it against the 5 mm its test allows."""
    initial_bend_horizontal_deg: Literal["random"] | list[Finite] = "random"
    """Per-chute horizontal bend (pan i+1 yaw minus pan i yaw), pan_count - 1 values, or "random"."""
    initial_straightness_deg: between(0, 5) = 0.3
    """Standard deviation of the random initial pan yaw (smooth, AR(1) along the face); at most 5 deg (a face
    line more crooked cannot be pushed straight within any bend limit)."""
    seam_dip_deg: Annotated[float, Field(ge=-20, le=20, allow_inf_nan=False)] = 0.0
    """Floor slope along the face; positive rises towards the tailgate. With advance_dip_deg, the floor's tilt is at
    most MAX_FLOOR_TILT_DEG (the pans' friction angle, 19.3 deg)."""
    advance_dip_deg: Annotated[float, Field(ge=-20, le=20, allow_inf_nan=False)] = 0.0
    """Floor slope in the advance direction; positive rises towards the coal wall (tilt: see seam_dip_deg)."""
    undulation_amplitude_m: NonNegativeFloat = 0.1
    undulation_wavelength_m: between(5, 10000) = 30.0
    """Above 10 km the floor is a plane over any face and panel."""
    web_depth_m: Annotated[float, Field(ge=0.3, le=1.5, allow_inf_nan=False)] = 0.8
    panel_length_m: Annotated[float, Field(gt=0, le=6000, allow_inf_nan=False)] = 20.0
    """Extent of coal (and floor) in the advance direction; cycles * web_depth_m must fit in it. At most 6 km, the
    longest longwall panels (the floor's height field covers the panel: twin.config.resources counts it)."""

    @model_validator(mode="after")
    def _floor_holds_the_pans(self) -> Face:
        tilt = math.degrees(math.atan(math.hypot(math.tan(math.radians(self.seam_dip_deg)),
                                                 math.tan(math.radians(self.advance_dip_deg)))))
        if tilt > MAX_FLOOR_TILT_DEG:
            raise ValueError(f"seam_dip_deg: with advance_dip_deg the floor tilts {tilt:.1f} deg, steeper than the pans' "
                             f"friction angle atan({PAN_FLOOR_FRICTION}) = {MAX_FLOOR_TILT_DEG:.1f} deg: a pan at rest "
                             f"would slide down it, and nothing anchors the face")
        return self


class Shearer(Section):
    length_m: Annotated[float, Field(ge=3, le=20, allow_inf_nan=False)] = 8.0
    shoe_spacing_m: Annotated[float, Field(ge=1, le=15, allow_inf_nan=False)] = 5.0
    body_height_m: Annotated[float, Field(gt=0, le=3, allow_inf_nan=False)] = 0.9
    """Height of the body reference point above the running line."""
    suspension_frequency_hz: Annotated[float, Field(ge=1, le=100, allow_inf_nan=False)] = 10.0
    """Natural frequency of the body on its suspension (twin.face.suspension). Its ringing, frequency x
    sqrt(1 - suspension_damping_ratio^2), must stay below the ride's Nyquist frequency rates.ride_hz / 2."""
    suspension_damping_ratio: Annotated[float, Field(gt=0, le=2, allow_inf_nan=False)] = 1.0


class Stop(Section):
    """A scripted stop of the shearer during a straight cut."""

    cycle: Annotated[int, Field(ge=0)]
    at_m: NonNegativeFloat
    """Distance travelled into the cycle's straight cut where the shearer stops."""
    duration_s: Duration
    """At most a day (section.Duration)."""


class Haulage(Section):
    cutting_speed_m_min: Annotated[float, Field(ge=1, le=30, allow_inf_nan=False)] = 8.0
    return_speed_m_min: Annotated[float, Field(ge=1, le=40, allow_inf_nan=False)] = 18.0
    """Speed through coal already cut (the start of a pass over the previous sump)."""
    sump_speed_m_min: Annotated[float, Field(ge=1, le=30, allow_inf_nan=False)] = 6.0
    acceleration_m_s2: Annotated[float, Field(ge=0.005, le=2, allow_inf_nan=False)] = 0.05
    reversal_stop_s: between(0, 3600) = 10.0
    """Stand at each reversal; at most an hour (a longer stand is a scripted stop)."""
    end_push_stop_s: between(0, 3600) = 30.0
    """Stop while the end pans are pushed during snake sumping; at most an hour, as the reversal."""
    stops: list[Stop] = []


class Pattern(Section):
    kind: Literal["bidirectional"] = "bidirectional"
    snake_length_pans: Annotated[int, Field(ge=2, le=40)] = 12
    push_lag_pans: Annotated[int, Field(ge=0, le=20)] = 2
    """Pans between the shearer's trailing end and the first pan of the snake."""
    push_step_pans: Annotated[int, Field(ge=1, le=4)] = 1
    """The push-advance controller acts each time the shearer has travelled this many pans."""


class Rates(Section):
    truth_hz: Annotated[float, Field(ge=50, le=2000, allow_inf_nan=False)] = 200.0
    """Rate of the published shearer truth (samples of the truth splines)."""
    ride_hz: Annotated[float, Field(ge=50, le=2000, allow_inf_nan=False)] = 100.0
    """Step rate of the shearer's MuJoCo ride (suspension); the truth splines pass through its samples."""
    face_timestep_s: Annotated[float, Field(ge=0.001, le=0.02, allow_inf_nan=False)] = 0.01


class ShearerPositioning(Section):
    """The shearer positioning estimators of 001 that `longwall run` / `longwall estimate` run on the log."""

    methods: list[Literal["dr", "dr_compensated", "kf", "kf_rts", "kf_cpoem", "kf_cpoem_rts", "rts_offline",
                          "ckf_mag", "afkf", "fkf_rail"]] = [
        "dr", "dr_compensated", "kf", "kf_cpoem", "kf_cpoem_rts", "rts_offline"]
    """estimators.shearer.positioning METHODS; an empty list runs none."""
    tuning: Literal["ours", "appendix_a"] = "ours"
    """ours: P0 and Q from the IMU grade and the survey; appendix_a: 001 Appendix A (Table 1 x 3, noise x 5)."""
    filter_rate_hz: Annotated[float, Field(gt=0, le=50, allow_inf_nan=False)] = 10.0
    n_samples: Annotated[int, Field(ge=1, le=5)] = 4
    """Coning/sculling sub-samples per mechanization update."""
    cpoem_spacing_m: Annotated[float, Field(ge=0.2, le=50, allow_inf_nan=False)] = 2.0
    """Delta of 001 section 2.2: the distance between CPOEM points (001 uses 2, 6 and 10 m)."""
    mag_extra_sigma_deg: Annotated[float, Field(ge=0, le=30, allow_inf_nan=False)] = 0.5
    """Magnetic yaw error the magnetometer's white noise does not cover (calibration residual, motor field) [deg]."""
    mag_field_check: bool = True
    """afkf: leave out magnetometer readings whose strength or dip disagrees with the geomagnetic model."""
    mag_hard_iron_t: vector3(2 * EARTH_FIELD_T) = [0.0, 0.0, 0.0]
    """Hard-iron offset [T] of the magnetometer's calibration (estimators.nav.geomagnetic.fit_ellipsoid), removed from
    the readings before use; within twice the Earth's field (twin.config.sensors.EARTH_FIELD_T)."""
    mag_soft_iron_correction: SoftIron = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    """The calibration's S^-1 (rows): calibrated field = S^-1 (reading - hard iron); not singular."""

    @model_validator(mode="after")
    def _invertible(self) -> ShearerPositioning:
        check_soft_iron(self.mag_soft_iron_correction, "mag_soft_iron_correction")
        return self


class Estimators(Section):
    shearer: ShearerPositioning = ShearerPositioning()


class Scenario(Section):
    name: Annotated[str, Field(min_length=1)]
    seed: Annotated[int, Field(ge=0)] = 0
    cycles: Annotated[int, Field(ge=1)] = 1
    """Cutting cycles of the run. No cap of its own: the panel bounds it (cycles * face.web_depth_m <=
    face.panel_length_m) and the resource estimate (twin.config.resources) refuses a run this machine cannot hold."""
    site: Site = Site()
    face: Face = Face()
    supports: Supports = Supports()
    roof: Roof = Roof()
    shearer: Shearer = Shearer()
    haulage: Haulage = Haulage()
    pattern: Pattern = Pattern()
    rates: Rates = Rates()
    sensors: Sensors = Sensors()
    faults: list[Fault] = []
    estimators: Estimators = Estimators()
    alignment: Alignment = Alignment()

    @model_validator(mode="after")
    def _consistent(self) -> Scenario:
        f, sh, p = self.face, self.shearer, self.pattern
        length = f.pan_count * f.pan_length_m
        if f.face_length_m is not None and abs(f.face_length_m - length) > 1e-3:
            raise ValueError(
                f"face.face_length_m: {f.face_length_m} m differs from pan_count * pan_length_m = {length:.3f} m")
        if isinstance(f.initial_bend_horizontal_deg, list):
            bends = f.initial_bend_horizontal_deg
            if len(bends) != f.pan_count - 1:
                raise ValueError(f"face.initial_bend_horizontal_deg: {len(bends)} values, need pan_count - 1 = "
                                 f"{f.pan_count - 1}")
            worst = max(abs(b) for b in bends)
            if worst > f.bend_limit_horizontal_deg:
                raise ValueError(f"face.initial_bend_horizontal_deg: {worst} deg exceeds "
                                 f"bend_limit_horizontal_deg = {f.bend_limit_horizontal_deg}")
        if sh.shoe_spacing_m >= sh.length_m:
            raise ValueError(f"shearer.shoe_spacing_m: {sh.shoe_spacing_m} m must be shorter than "
                             f"shearer.length_m = {sh.length_m} m")
        ringing = ringing_hz(sh.suspension_frequency_hz, sh.suspension_damping_ratio)
        if ringing >= self.rates.ride_hz / 2:
            raise ValueError(f"shearer.suspension_frequency_hz: {sh.suspension_frequency_hz} Hz at damping ratio "
                             f"{sh.suspension_damping_ratio} rings at {ringing:.1f} Hz, at or above the ride's Nyquist "
                             f"frequency rates.ride_hz / 2 = {self.rates.ride_hz / 2:g} Hz; raise rates.ride_hz above "
                             f"{2 * ringing:.1f} Hz, lower the frequency or raise suspension_damping_ratio")
        end_zone = sump_length_m(self)
        if 2 * end_zone > length:
            raise ValueError(f"face.pan_count: a {length:.1f} m face is too short for the shearer and the snake "
                             f"at both ends (needs > {2 * end_zone:.1f} m); add pans or shorten the snake")
        bend = floor_pitch_change(f.undulation_amplitude_m, f.undulation_wavelength_m, f.pan_length_m)
        if bend > 0.8 * math.radians(f.bend_limit_vertical_deg):
            raise ValueError(f"face.undulation_amplitude_m: the floor bends up to {math.degrees(bend):.2f} deg per pan, "
                             f"more than 80 % of bend_limit_vertical_deg = {f.bend_limit_vertical_deg}; flatten the "
                             f"floor or lengthen undulation_wavelength_m")
        if self.cycles * f.web_depth_m > f.panel_length_m:
            raise ValueError(f"cycles: {self.cycles} cycles of {f.web_depth_m} m exceed face.panel_length_m = "
                             f"{f.panel_length_m} m; lengthen the panel or run fewer cycles")
        # A full web over the snake must fit the horizontal bend limit (see twin.face.snake).
        max_push = snake.capacity_m(p.snake_length_pans, f.pan_length_m, math.radians(f.bend_limit_horizontal_deg))
        if f.web_depth_m > max_push:
            raise ValueError(f"pattern.snake_length_pans: {p.snake_length_pans} pans bend at most {max_push:.2f} m "
                             f"within bend_limit_horizontal_deg; web_depth_m {f.web_depth_m} m needs a longer snake")
        need = SupportHydraulics.from_scenario(self.supports, self.roof).end_push_s(
            f.web_depth_m, self.supports.lower_m) * END_PUSH_MARGIN
        if self.haulage.end_push_stop_s < need:
            raise ValueError(f"haulage.end_push_stop_s: {self.haulage.end_push_stop_s:g} s is too short for the rams "
                             f"to push the end pans a {f.web_depth_m} m web and advance their supports ({need:.1f} s "
                             f"with supports.hydraulics); lengthen the stop or raise the rams' flows")
        n_supports = support_count(self)
        check_scenario_offsets(self, n_supports)
        for k, fault in enumerate(self.faults):
            _check_fault_target(self, k, fault, n_supports)
        for where, name in (("sensors.imu.grade", self.sensors.imu.grade),
                            ("sensors.support_imu.grade", self.sensors.support_imu.grade)):
            if name not in GRADES:
                raise ValueError(f"{where}: no IMU preset '{name}' (presets: {', '.join(sorted(GRADES))})")
        ratio = self.rates.truth_hz / self.sensors.imu.rate_hz
        if abs(ratio - round(ratio)) > 1e-9:
            raise ValueError(f"sensors.imu.rate_hz: {self.sensors.imu.rate_hz} Hz must divide rates.truth_hz = "
                             f"{self.rates.truth_hz} Hz (IMU increments are sums of truth intervals)")
        bad = [j for j in self.sensors.support_imu.supports if j >= n_supports]
        if bad:
            raise ValueError(f"sensors.support_imu.supports: no support {bad[0]} (supports 0..{n_supports - 1})")
        for a, b in self.sensors.vibration.rock_zones_m:
            if not a < b <= length:
                raise ValueError(f"sensors.vibration.rock_zones_m: [{a}, {b}] must be an interval within the "
                                 f"{length:.1f} m face (from < to <= pan_count * pan_length_m)")
        for stop in self.haulage.stops:
            if stop.cycle >= self.cycles:
                raise ValueError(f"haulage.stops: stop in cycle {stop.cycle} but the run has {self.cycles} cycles")
            if stop.at_m > travel_length_m(self):
                raise ValueError(f"haulage.stops: stop at {stop.at_m} m is beyond the "
                                 f"{travel_length_m(self):.1f} m of travel")
        if self.alignment.mode != "none" and self.haulage.reversal_stop_s < 1.0:
            raise ValueError(f"alignment.mode: {self.alignment.mode} needs each shear's path as the shear ends, which "
                             f"the twin hands over at the reversal stops; set haulage.reversal_stop_s to at least 1 s")
        return self


def support_count(scn: Scenario) -> int:
    """Number of roof supports: one per pans_per_support pans, the first at pan pans_per_support // 2."""
    return len(range(scn.supports.pans_per_support // 2, scn.face.pan_count, scn.supports.pans_per_support))


def _check_fault_target(scn: Scenario, k: int, fault: Fault, n_supports: int) -> None:
    """ValueError unless the fault acts on a unit the face has (and a push shortfall within the web)."""
    units = scn.sensors.support_imu.supports
    if fault.kind in TARGETED and (fault.target is None or fault.target >= n_supports):
        raise ValueError(f"faults[{k}]: {fault.kind} needs a target support 0..{n_supports - 1} (got {fault.target})")
    if fault.kind == "mag_interference" and fault.target is not None and fault.target not in units:
        raise ValueError(f"faults[{k}]: mag_interference target {fault.target} has no canopy unit (units on "
                         f"supports {units} of sensors.support_imu.supports; no target: the shearer's magnetometer)")
    if fault.kind not in (*TARGETED, "mag_interference") and fault.target is not None:
        raise ValueError(f"faults[{k}]: {fault.kind} takes no target (got {fault.target}); remove the key")
    if fault.kind == "failed_set" and fault.value >= scn.supports.legs.set_pressure_mpa:
        raise ValueError(f"faults[{k}]: failed_set value {fault.value:g} MPa is not below supports.legs.set_pressure_mpa "
                         f"= {scn.supports.legs.set_pressure_mpa:g} MPa (a set that fails stops short of it)")
    if fault.kind == "push_shortfall" and fault.value > scn.face.web_depth_m:
        raise ValueError(f"faults[{k}]: push_shortfall value {fault.value:g} m exceeds face.web_depth_m = "
                         f"{scn.face.web_depth_m} m (a pan cannot fall short by more than its push)")


def sump_length_m(scn: Scenario) -> float:
    """How far the shearer backs into the snake at a face end: past the snake, its lag and one more pan."""
    p = scn.pattern
    return scn.shearer.length_m + (p.push_lag_pans + p.snake_length_pans + 2) * scn.face.pan_length_m


def travel_length_m(scn: Scenario) -> float:
    """Arc length the shearer centre travels in a straight cut (face end to face end)."""
    return scn.face.pan_count * scn.face.pan_length_m - scn.shearer.length_m


def parse_scenario(data: dict, source: str = "<scenario>") -> Scenario:
    """Validate a face scenario's data (the TOML as a dict); one-line ScenarioError naming `source` and the key."""
    return validate(Scenario, data, source)


SCENARIO_KINDS = {None: parse_scenario, EXPERIMENT_KIND: parse_experiment, TURNTABLE_KIND: parse_turntable}
"""The parser of each kind of scenario file, by its top-level `kind` (None: absent, a face scenario)."""


def parse_any(data: dict, source: str = "<scenario>") -> Scenario | Experiment | Turntable:
    """Validate a scenario file's data of any kind (its top-level `kind`)."""
    kind = data.get("kind")
    if kind not in SCENARIO_KINDS:
        raise ScenarioError(f"{source}: kind: must be one of {', '.join(k for k in SCENARIO_KINDS if k)} or absent "
                            f"(a face scenario); got {kind!r}")
    return SCENARIO_KINDS[kind](data, source)


def load_scenario(path: str | Path, seed: int | None = None) -> Scenario | Experiment | Turntable:
    """Read and validate a scenario file of any kind (face scenario, SINS experiment, turntable); `seed`
    overrides the file's seed."""
    return parse_any(read_scenario(path, seed), str(path))


def load_face_scenario(path: str | Path, seed: int | None = None) -> Scenario:
    """`load_scenario` where only a face scenario will do (estimating or reporting a face run)."""
    data = read_scenario(path, seed)
    if "kind" in data:
        raise ScenarioError(f"{path}: kind: a face scenario is needed here, not a {data['kind']!r} file")
    return parse_scenario(data, str(path))


def scenario_to_toml(scn: BaseModel) -> str:
    """A resolved scenario of any kind (every default made visible) as TOML text."""
    data = scn.model_dump(exclude_none=True)
    lines: list[str] = []

    def value(v) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace('"', '\\"') + '"'
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)

    def table(prefix: str, d: dict) -> None:
        scalars = {k: v for k, v in d.items() if not isinstance(v, dict) and not _is_table_list(v)}
        if prefix:
            lines.append(f"\n[{prefix}]")
        lines.extend(f"{k} = {value(v)}" for k, v in scalars.items())
        for k, v in d.items():
            if _is_table_list(v):
                for item in v:
                    lines.append(f"\n[[{prefix + '.' if prefix else ''}{k}]]")
                    lines.extend(f"{kk} = {value(vv)}" for kk, vv in item.items())
        for k, v in d.items():
            if isinstance(v, dict):
                table(f"{prefix}.{k}" if prefix else k, v)

    table("", data)
    return "\n".join(lines).lstrip() + "\n"


def _is_table_list(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)
