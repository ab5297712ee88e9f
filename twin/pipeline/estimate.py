"""Run the shearer positioning estimators on a run directory: estimates Parquet, metrics, estimates.rrd.

The estimators read only the log (estimators.io.log.load_log); what they are told about the machine
(IMU error budget, lever arm, odometer pulse length, where the supports sit along the face) comes from the
scenario, as a mining engineer would enter it from the datasheets and the face layout. The truth is used only to
score the result (estimators.io.metrics) and to give the true sensor states beside the estimated ones: a log without
it (a real face's, imported) gets every estimate, the recording and what the estimates say of themselves, unscored.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np

from estimators.faults.hydraulic_checks import HydraulicLayout
from estimators.faults.ram_checks import RamLayout
from estimators.io import metrics
from estimators.io.log import load_log, log_pieces
from estimators.io.logformat import (
    ESTIMATE,
    ESTIMATE_DETECTORS,
    ESTIMATE_FUSION,
    ESTIMATE_STATES,
    STREAMS,
    Stream,
    StreamAppender,
    StreamBlocks,
    estimate_file,
    make_table,
    read_stream,
)
from estimators.io.self_assessment import SelfAssessment
from estimators.kalman.error_state import CAL_MOUNT, CAL_SCALE
from estimators.shearer.config import STREAMED, Config, ImuNoise, MagSettings
from estimators.shearer.methods import estimate
from estimators.shearer.rail_kinematics import detector_chi2
from estimators.shearer.solution import Solution, estimate_columns, state_columns
from twin.config.imu_grades import grade
from twin.config.scenario import Scenario
from twin.face.layout import support_stations
from twin.view.record_rate import RECORD_RATE_HZ


def positioning_config(scn: Scenario) -> Config:
    """The filter configuration a user would write for this face and machine."""
    est = scn.estimators.shearer
    g = grade(scn.sensors.imu.grade)
    ram = scn.sensors.pushram
    # The IMU's pitch and roll mounting come from the static calibration (000 section 6.1-6.2, taken as exact
    # here); its yaw mounting is not found statically and is left to the filter (inside the survey's heading).
    mount = np.radians(scn.sensors.imu.misalignment_deg)
    kw = {"lever_arm_m": tuple(scn.sensors.imu.lever_arm_m), "imu_mounting_rad": (float(mount[0]), float(mount[1]), 0.0),
          "metres_per_pulse": scn.sensors.odometer.metres_per_pulse,
          "support_u_m": tuple((support_stations(scn) + 0.5) * scn.face.pan_length_m - scn.shearer.length_m / 2),
          "n_samples": est.n_samples, "filter_rate_hz": est.filter_rate_hz, "cpoem_spacing_m": est.cpoem_spacing_m,
          "ram_noise_sd": max(ram.noise_m, ram.resolution_m), "advance_sd": max(5 * ram.noise_m, 0.003),
          "rail_advance_sd": max(1.5 * ram.noise_m, 0.003),
          "chute_length_m": scn.face.pan_length_m,
          "end_zone_m": scn.shearer.length_m + (scn.pattern.push_lag_pans + scn.pattern.snake_length_pans + 2)
          * scn.face.pan_length_m,
          "mag": MagSettings(date=scn.sensors.mag.date, noise_t=max(scn.sensors.mag.noise_t, 1e-9),
                             extra_sigma=math.radians(est.mag_extra_sigma_deg), field_check=est.mag_field_check,
                             hard_iron_t=tuple(est.mag_hard_iron_t),
                             soft_iron_correction=tuple(map(tuple, est.mag_soft_iron_correction)))}
    if est.tuning == "appendix_a":
        return Config.appendix_a(**kw)
    imu = ImuNoise(gyro_arw=max(g.gyro_arw, 1e-6), accel_vrw=max(g.accel_vrw, 1e-5),
                   gyro_bias=max(g.gyro_bias, g.gyro_bias_instability, 1e-7),
                   accel_bias=max(g.accel_bias, g.accel_bias_instability, 1e-5),
                   gyro_bias_psd=g.gyro_bias_psd,
                   accel_bias_psd=g.accel_bias_psd,
                   accel_nonorth=max(g.accel_nonorth, 1e-6))
    return Config(imu=imu, **kw)


def ram_layout(scn: Scenario) -> RamLayout:
    """What a user knows of the scenario's face and its push-ram sensors (estimators.faults.ram_checks)."""
    k = scn.supports.pans_per_support
    return RamLayout(n_supports=support_stations(scn).size, spacing_m=k * scn.face.pan_length_m,
                     stroke_m=scn.face.web_depth_m, noise_m=scn.sensors.pushram.noise_m,
                     resolution_m=scn.sensors.pushram.resolution_m, pan_length_m=scn.face.pan_length_m,
                     bend_limit_deg=scn.face.bend_limit_horizontal_deg)


def hydraulic_layout(scn: Scenario) -> HydraulicLayout:
    """What a user knows of the scenario's supports' hydraulics and transducers (estimators.faults.hydraulic_checks)."""
    return HydraulicLayout(n_supports=support_stations(scn).size,
                           relief_mpa=scn.supports.hydraulics.pump_pressure_mpa,
                           set_mpa=scn.supports.legs.set_pressure_mpa, noise_mpa=scn.sensors.pressure.noise_mpa,
                           ram_noise_m=scn.sensors.pushram.noise_m)


def true_states(scn: Scenario) -> dict[str, float]:
    """True odometer scale-factor error (twin.sensors.odometer: dk_D = 1 / (1 + e) - 1) and odometer mounting angles as
    the filter holds them: the rotation vector of C_m^b' from the frame m in which the machine moves along y
    (001 eqs. 1-4, the non-holonomic frame) to the frame b' the filter's increments are in.

    The shearer moves along its body y (it rides the pan rails), so m is the body frame b. positioning_config
    turns the IMU axes into b with the calibrated pitch and roll mounting only, so b' is b turned back by the
    IMU's yaw mounting m_z: C_m^b' = Rz(-m_z), and the true angles are (0, 0, -m_z). The twin's
    [sensors.odometer] mounting_deg turns the encoder's axis, which changes its count only by the cosine of the
    angle (1.4e-5 at 0.3 deg) and is not a mounting the motion constraints can see."""
    return {"odo_scale": 1.0 / (1.0 + scn.sensors.odometer.scale_error) - 1.0, "odo_mount_x": 0.0,
            "odo_mount_y": 0.0, "odo_mount_z": -math.radians(scn.sensors.imu.misalignment_deg[2])}


def detector_thresholds(scn: Scenario) -> dict[str, float]:
    """Thresholds of the rail model's detectors as the filter runs them: the residual and dual-state chi-square
    tests at the false-alarm probability (estimators.shearer.rail_kinematics.detector_chi2), T1/T0 of the fading
    SPRT."""
    detector = positioning_config(scn).detector
    residual, dual = detector_chi2(detector)
    return {"residual": residual, "dual_state": dual, "t_on": detector.t_on, "t_off": detector.t_off}


NO_CYCLES = {key: np.empty(0) for key in ("cycle", "t", "t_cut_end", "t_end")}
"""truth_cycles with no cycle: errors scored over the whole run only (estimators.io.metrics.cycle_metrics)."""


def _optional(run_dir: Path, name: str, columns: tuple[str, ...] | None = None):
    """Stream `name` of run_dir (only `columns` when given), None when its file is absent."""
    path = Path(run_dir) / STREAMS[name].filename
    return read_stream(run_dir, STREAMS[name], columns) if path.is_file() else None


def _calibration(sol: Solution, states_truth: dict[str, float] | None) -> dict:
    """The final odometer scale and mounting [deg] with their one-sigma, and the true values with truth."""
    def state(i: int, key: str, deg: bool) -> dict:
        out = {"estimate": float(np.degrees(sol.cal[-1, i]) if deg else sol.cal[-1, i]),
               "sd": float(np.degrees(sol.sd_cal[-1, i]) if deg else sol.sd_cal[-1, i])}
        if states_truth:
            out["truth"] = math.degrees(states_truth[key]) if deg else states_truth[key]
        return out
    return {"odo_scale": state(CAL_SCALE, "odo_scale", False),
            "odo_mount_deg": {a: state(CAL_MOUNT.start + i, f"odo_mount_{a}", True) for i, a in enumerate("xyz")}}


def solution_columns(sol: Solution, scn: Scenario) -> dict[str, np.ndarray]:
    """A shearer estimate's ESTIMATE columns in the scenario's frames: the tangent plane at its site (the truth's t)
    and its face frame F."""
    origin = np.array([np.radians(scn.site.lat_deg), np.radians(scn.site.lon_deg), scn.site.height_m])
    return estimate_columns(sol, origin, np.radians(scn.face.azimuth_deg))


def _truth_track(run_dir: Path) -> metrics.TruthTrack | None:
    """The run's truth_shearer read a row group at a time, once for every method's epochs
    (estimators.io.metrics.TruthTrack); None without it."""
    if not (Path(run_dir) / STREAMS["truth_shearer"].filename).is_file():
        return None
    return metrics.TruthTrack(StreamBlocks(run_dir, STREAMS["truth_shearer"], metrics.SCORED_TRUTH))


class EstimateWriter:
    """The sink of estimators.shearer.methods.estimate for a run directory: each method's rows appended to its
    estimate files as they come (a pass at a time from an online method), the method scored once it is done
    (estimators.io.metrics against the truth, read a row group at a time), all in the process that runs it."""

    def __init__(self, run_dir: Path, scn: Scenario):
        self.run_dir, self.scn = Path(run_dir), scn
        self.truth = _truth_track(run_dir)
        self.survey = read_stream(run_dir, STREAMS["survey"])
        self.cycles = _optional(run_dir, "truth_cycles") if self.truth is not None else None
        self.states_truth = true_states(scn) if self.truth is not None else None
        self.open: dict[str, dict[str, StreamAppender]] = {}
        self.last: dict[str, Solution] = {}

    def rows(self, name: str, sol: Solution) -> None:
        appenders = self.open.setdefault(name, {})
        for stream, columns in ((ESTIMATE, solution_columns(sol, self.scn)),
                                (ESTIMATE_STATES, state_columns(sol) if sol.cal is not None else None),
                                (ESTIMATE_FUSION, sol.fusion), (ESTIMATE_DETECTORS, sol.detectors)):
            if columns is not None:
                if stream.name not in appenders:
                    folder, named = estimate_file(self.run_dir, name, stream)
                    folder.mkdir(parents=True, exist_ok=True)
                    appenders[stream.name] = StreamAppender(folder, named)
                appenders[stream.name].append(make_table(stream, columns))
        self.last[name] = sol

    def done(self, name: str, notes: list[str]) -> tuple[dict, list[str]]:
        """(The method's metrics entry, the estimate streams written)."""
        appenders = self.open.pop(name)
        for appender in appenders.values():
            appender.close()
        last = self.last.pop(name)
        own = SelfAssessment(self.survey)
        score = None if self.truth is None else metrics.CycleScore(NO_CYCLES if self.cycles is None else self.cycles)
        for block in StreamBlocks(*estimate_file(self.run_dir, name), metrics.SCORED_ESTIMATE):
            own.push(block)
            if score is not None:
                score.push(*metrics.position_errors(block, self.truth))
        entry = {"truth": self.truth is not None}
        if score is not None:
            entry["cycles"] = score.rows()
        entry |= {"notes": notes, "self": own.result()}
        return entry | (_calibration(last, self.states_truth) if last.cal is not None else {}), list(appenders)


def _shearer_methods(run_dir: Path, scn: Scenario, methods: tuple[str, ...], workers: int
                     ) -> dict[str, tuple[dict, list[str]]]:
    """Run `methods` on run_dir's log on `workers` processes, each solution written to estimates/ and scored in
    the process that made it (none is held by the parent; 001's filters run online over the log read a row group
    at a time, estimators.shearer.config.STREAMED): method -> (its metrics entry, the streams written)."""
    log = load_log(run_dir) if any(m not in STREAMED for m in methods) else None
    return estimate(log, positioning_config(scn), methods, workers, EstimateWriter(run_dir, scn),
                    lambda: log_pieces(run_dir))


def run_estimators(run_dir: Path, scn: Scenario, recording: bool = True, workers: int = 1,
                   record_rate_hz: float | None = RECORD_RATE_HZ) -> dict:
    """Run the scenario's shearer estimators on run_dir; writes estimates/, estimates.rrd (with `recording`, at
    `record_rate_hz`: Hz, or None for every row; twin.view.record_rate) and returns the metrics. A log the
    estimators cannot use raises PositioningError (one line). With instrumented supports the metrics also hold their
    canopy attitude under SUPPORT_ATTITUDE (twin.pipeline.support_estimate).
    The shearer's methods run on `workers` processes (estimators.shearer.methods.estimate), forked before the
    supports' parallel kernels start their threads.

    Each method's entry holds "truth" (whether truth_shearer was there to score against), its notes, what it says
    of itself (estimators.io.self_assessment, under "self") and, for the filters, the final odometer
    calibration; with truth_shearer also the errors ("cycles": estimators.io.metrics.cycle_metrics) and the true
    calibration. Partial truth: without truth_cycles the errors are scored over the whole run only (the "all" row);
    truth_cycles without truth_shearer scores nothing. The truth never reaches an estimator."""
    # The canopy attitude of the instrumented supports (issue 8), under the key SUPPORT_ATTITUDE.
    from twin.pipeline.support_estimate import SUPPORT_ATTITUDE, support_attitude
    from twin.view.estimate_recording import write_estimate_recording
    methods = tuple(scn.estimators.shearer.methods)
    finished = _shearer_methods(run_dir, scn, methods, workers) if methods else {}
    supports = support_attitude(run_dir, scn)
    out = {} if supports is None else {SUPPORT_ATTITUDE: supports.metrics}
    if recording and supports is not None and not methods:
        write_estimate_recording(Path(run_dir) / "estimates.rrd", scn, None, {}, {}, supports=supports,
                                 rate_hz=record_rate_hz)
    if not methods:
        return out
    written = {stream.name: [name for name in methods if stream.name in finished[name][1]]
               for stream in (ESTIMATE, ESTIMATE_STATES, ESTIMATE_FUSION, ESTIMATE_DETECTORS)}
    out |= {name: entry for name, (entry, _) in finished.items()}
    truth = _truth_track(run_dir)
    states_truth = true_states(scn) if truth is not None else None
    if recording:
        def tables(stream: Stream) -> EstimateTables:
            return EstimateTables(run_dir, stream, written[stream.name])

        thresholds = detector_thresholds(scn)
        detectors = {name: (StreamBlocks(*estimate_file(run_dir, name, ESTIMATE_DETECTORS)), thresholds)
                     for name in written[ESTIMATE_DETECTORS.name]}
        write_estimate_recording(Path(run_dir) / "estimates.rrd", scn, truth, tables(ESTIMATE), tables(ESTIMATE_STATES),
                                 states_truth, rate_hz=record_rate_hz, fusion=tables(ESTIMATE_FUSION),
                                 detectors=detectors, supports=supports)
    return out


class EstimateTables(Mapping):
    """A run's estimate files of one kind (ESTIMATE, ESTIMATE_STATES, ...) by method, each read a row group at a time
    (StreamBlocks) when it is iterated: a recording holds a block of one method at a time."""

    def __init__(self, run_dir: Path, stream: Stream, methods: list[str]):
        self.run_dir, self.stream, self.methods = Path(run_dir), stream, methods

    def __getitem__(self, method: str) -> StreamBlocks:
        if method not in self.methods:
            raise KeyError(method)
        return StreamBlocks(*estimate_file(self.run_dir, method, self.stream))

    def __iter__(self) -> Iterator[str]:
        return iter(self.methods)

    def __len__(self) -> int:
        return len(self.methods)


PAPER_FIGURES = {
    "seed001": ("sep", "001 Table 3, KF + CPOEM + RTS: 0.50 0.32 0.13 0.17"),
    "seed003": ("max", "003 Table 2: SINS/OD 0.901 E 1.249 N, SINS/OD/MAG 0.220 E 0.325 N"),
    "seed003_interference": ("max", "003 section 5.2: CKF 3.827 E 1.942 N, FKF 1.545 E 1.942 N"),
}
"""The paper figures a scenario reproduces, printed beside the table they belong to."""


SELF_COLUMNS = ("sd h. [m]", "max sd h. [m]", "path [m]", "fixes", "ZUPTs", "survey [m]", "scale [1e-3]")
"""Headings of `self_assessment_rows`' columns."""


def self_assessment_rows(estimators: dict) -> list[list]:
    """Per method what its estimate says of itself (metrics.json's "self"): final and largest horizontal one-sigma,
    distance along its path, fixes and ZUPTs applied, the largest horizontal residual against the survey's fixes,
    the final odometer scale error [1e-3]; None where a method has none."""
    rows = []
    for name, e in estimators.items():
        own = e["self"]
        if not own["samples"]:
            rows.append([name] + [None] * len(SELF_COLUMNS))
            continue
        scale = e["odo_scale"]["estimate"] * 1e3 if "odo_scale" in e else None
        rows.append([name, own["final_sd_horizontal_m"], own["max_sd_horizontal_m"], own["distance_m"],
                     own["flags"]["position_fixes"], own["flags"]["zupts"],
                     max((r["horizontal"] for r in own.get("survey_residuals", [])), default=None), scale])
    return rows


def format_self_assessment(estimators: dict) -> str:
    """One line saying the run has no truth, so no errors are scored, then `self_assessment_rows` as a table."""
    formats = (".3f", ".3f", ".1f", "d", "d", ".3f", ".3f")
    lines = ["", "no truth in this run (no truth_shearer.parquet): no errors are scored; each estimate on its own:",
             f"{'method':16s}" + "".join(f"{h:>13s}" for h in SELF_COLUMNS)]
    for name, *cells in self_assessment_rows(estimators):
        lines.append(f"{name:16s}" + "".join(f"{'-' if c is None else format(c, f):>13s}"
                                             for c, f in zip(cells, formats)))
    return "\n".join(lines)


def format_estimators(estimators: dict, scenario: str = "") -> str:
    """Per-method SEP per cutting cycle and maximum |east|, |north| error over the run [m] as tables, with the
    paper's figures for the scenarios that reproduce one (PAPER_FIGURES); a run without truth gets one line saying
    so and format_self_assessment's table. A method that lost track (estimators.shearer.health) says so after them."""
    # The supports' canopy attitude (twin.pipeline.support_estimate) has its own table, after the shearer's.
    from twin.pipeline.support_estimate import SUPPORT_ATTITUDE, format_support_attitude
    supports = format_support_attitude(estimators.get(SUPPORT_ATTITUDE))
    estimators = {name: e for name, e in estimators.items() if name != SUPPORT_ATTITUDE}
    if not estimators:
        return supports
    health = "".join(f"\n{note}" for e in estimators.values() for note in e.get("notes", [])
                     if note.startswith("health:"))
    if not all("cycles" in e for e in estimators.values()):
        return format_self_assessment(estimators) + health + supports
    table, paper = PAPER_FIGURES.get(scenario, ("", ""))
    n = max(len(e["cycles"]) - 1 for e in estimators.values())
    lines = ["", "shearer position, SEP per cutting cycle [m]" + (f" ({paper})" if table == "sep" else "")
             + ("" if n else " (no truth_cycles.parquet: over the whole run only)"),
             f"{'method':16s}" + "".join(f"{metrics.cycle_label(k):>8s}" for k in range(n)) + f"{'all':>8s}"]
    for name, e in estimators.items():
        lines.append(f"{name:16s}" + "".join(f"{c['sep']:8.3f}" for c in e["cycles"]))
    lines += ["", "shearer position, maximum error over the run [m]" + (f" ({paper})" if table == "max" else ""),
              f"{'method':16s}{'east':>8s}{'north':>8s}{'horiz.':>8s}"]
    for name, e in estimators.items():
        run = e["cycles"][-1]
        lines.append(f"{name:16s}{run['max_e']:8.3f}{run['max_n']:8.3f}{run['max_horizontal']:8.3f}")
    return "\n".join(lines) + health + supports


def write_metrics(run_dir: Path, estimators: dict) -> None:
    path = Path(run_dir) / "metrics.json"
    data = json.loads(path.read_text()) if path.is_file() else {}
    data["estimators"] = estimators
    path.write_text(json.dumps(data, indent=2) + "\n")
