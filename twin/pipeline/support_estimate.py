"""Canopy attitude of every instrumented support in a face run (issue 8): 002's KF, UKF and GD-UKF and ours, each
method one batched call over all supports (estimators.support.batch.support_batch), scored against the
support truth; run by twin.pipeline.estimate.run_estimators, drawn by twin.view.estimate_recording."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from estimators.io.logformat import (
    ESTIMATE_SUPPORT_ATTITUDE,
    STREAMS,
    SUPPORT_IMU,
    TRUTH_SUPPORTS,
    LogError,
    Stream,
    read_stream,
    write_estimate,
)
from estimators.nav import earth
from estimators.nav.rotations_scalar import quat_euler
from estimators.support.batch import SupportBatch, support_batch
from estimators.support.error_state import (
    FLAG_ACCEL,
    FLAG_DIP,
    FLAG_GATE,
    FLAG_NORM,
    OursSettings,
    ours,
)
from estimators.support.filters_002 import kf, ukf
from estimators.support.tuning import tune_q
from estimators.support.unit_model import UnitModel, wrap
from twin.config.imu_grades import G0, grade
from twin.config.scenario import Scenario
from twin.face.layout import support_stations
from twin.pipeline.rundir import write_timing
from twin.sensors.magnetometer import site_field_n
from twin.sensors.support_imu import canopy_attitude_n, shearer_disturbance

SUPPORT_ATTITUDE = "support_attitude"
"""Key of the canopy attitude results in twin.pipeline.estimate.run_estimators' dict and in metrics.json."""
METHODS = ("kf", "ukf", "gd_ukf", "ours")
UNTUNED_VAR_DEG2_S2 = 0.01
"""Q of 002's KF and UKF: 002 Table 1's "inherent" rate variance of the dynamic test, (deg/s)^2 per axis."""
TUNING_WINDOW_S = 120.0
"""The GD-UKF's reference segment (002 step 1.1): this long, centred on the reference support's first advance."""
TUNING_ITERATIONS = 25
"""Largest number of gradient-descent steps of the tuning."""
OURS_UPDATE_HZ = 10.0
"""Rate of ours' gravity, magnetometer and zero-rate updates."""
NEAR_FRACTION = 0.1
"""A unit counts as disturbed while the shearer's field there exceeds this fraction of its peak."""
FLAGS_MAG = FLAG_NORM | FLAG_DIP | FLAG_GATE
FLAG_NAMES = (("norm", FLAG_NORM), ("dip", FLAG_DIP), ("gate", FLAG_GATE), ("accelerating", FLAG_ACCEL))
"""Ours' flag bits by name: counted in the metrics, drawn in the recording."""
ANGLES = ("pitch", "roll", "yaw")
CLASSES = {"face_end": "face ends", "mid_face": "mid-face"}


def unit_model(scn: Scenario, rate_hz: float) -> UnitModel:
    """What the filters know of the canopy units at `rate_hz` and of the site: per-sample white-noise variances
    of the grade's accelerometer and of `sensors.mag.noise_t`, the WMM field and the Earth rate at the site."""
    g = grade(scn.sensors.support_imu.grade)
    return UnitModel(np.full(3, max(g.accel_vrw ** 2 * rate_hz, 1e-8)),
                     np.full(3, max(scn.sensors.mag.noise_t, 1e-9) ** 2), site_field_n(scn),
                     earth.earth_rate_n(np.radians(scn.site.lat_deg)))


def ours_settings(scn: Scenario, rate_hz: float) -> OursSettings:
    """Ours for the scenario's canopy units, from the grade's figures as a user would enter them: twice the gyro's
    ARW (its scale and non-orthogonality on the canopy's motion), the Gauss-Markov bias drive sigma sqrt(2 / tau),
    twice the turn-on bias as the start's bias sigma, a dip tolerance of three times the tilt the accelerometer's
    bias and non-orthogonality cause (the dip is taken in the estimated frame), and zero-rate updates (a set
    canopy is static; its advances move it too fast to pass their gate once the bias is known)."""
    g = grade(scn.sensors.support_imu.grade)
    mag_noise = scn.sensors.mag.noise_t
    tilt_budget = np.hypot(g.accel_bias / G0, g.accel_nonorth)
    return OursSettings(
        samples_per_update=max(1, round(rate_hz / OURS_UPDATE_HZ)), gyro_arw=max(2 * g.gyro_arw, 1e-5),
        gyro_bias_walk=max(g.gyro_bias_instability * np.sqrt(2 / g.gyro_bias_tau) if g.gyro_bias_tau > 0 else 0.0,
                           1e-6),
        attitude_sigma0=np.radians(3.0), gyro_bias_sigma0=max(2 * g.gyro_bias, 1e-3),
        accel_sigma=max(g.accel_vrw * np.sqrt(rate_hz), 1e-3 * G0), accel_gate=50e-3 * G0,
        mag_sigma=max(2 * mag_noise, 1e-7), norm_tol=max(2e-7, 2 * mag_noise),
        dip_tol=max(np.radians(0.25), 3 * tilt_budget), gate=10.83, relock_updates=round(3.0 * OURS_UPDATE_HZ),
        zaru_gate=16.27)


def support_class(scn: Scenario, support: int) -> str:
    """"face_end" for a support within the shearer's length plus the snake and push lag of a face end (where the
    shearer reverses, sumps and stands while the end pans are pushed: passed twice, disturbed for longer), else
    "mid_face"."""
    f, p = scn.face, scn.pattern
    y = f.pan_length_m * (support_stations(scn)[support] + 0.5)
    reach = scn.shearer.length_m + (p.snake_length_pans + p.push_lag_pans) * f.pan_length_m
    return "face_end" if min(y, f.pan_count * f.pan_length_m - y) < reach else "mid_face"


@dataclass
class SupportAttitude:
    """Every method's canopy attitude for the instrumented supports: what twin.pipeline.estimate.run_estimators returns
    (`metrics`) and twin.view.estimate_recording draws."""

    metrics: dict
    supports: np.ndarray  # (N,) support indices
    t: dict[str, np.ndarray]  # method -> (K_m,) output times [s]
    euler: dict[str, np.ndarray]  # method -> (N, K_m, 3) pitch, roll, yaw [rad]
    truth_euler: dict[str, np.ndarray]  # method -> (N, K_m, 3) of the truth; empty without truth_supports
    flags: np.ndarray  # (N, U) ours' FLAG_* bits at t["ours"]
    near: np.ndarray | None  # (N, U) shearer's field at the unit over its peak at t["ours"]; None without truth
    objective: list[float]  # the GD-UKF's objective per iteration [rad]; empty without tuning


def _columns(run_dir: Path, stream: Stream) -> dict[str, np.ndarray] | None:
    path = Path(run_dir) / stream.filename
    if not path.is_file():
        return None
    table = read_stream(run_dir, stream)
    return {c: table.column(c).to_numpy() for c in table.column_names}


def _estimate_columns(batch: SupportBatch, t: np.ndarray, q: np.ndarray, euler: np.ndarray, bias=None, sigma=None,
                      flags=None) -> dict:
    """ESTIMATE_SUPPORT_ATTITUDE columns from (N, K_m, ...) arrays: rows by time, then support."""
    n, k = q.shape[:2]

    def rows(a: np.ndarray) -> np.ndarray:
        return np.swapaxes(a, 0, 1).reshape((n * k,) + a.shape[2:])

    nan3 = np.full((n * k, 3), np.nan)
    out = {"t": np.repeat(t, n), "support": np.tile(batch.supports, k).astype(np.int32),
           "flags": np.zeros(n * k, np.int32) if flags is None else rows(flags).astype(np.int32)}
    for i, a in enumerate("wxyz"):
        out[f"q_nc_{a}"] = rows(q[..., i])
    for i, name in enumerate(ANGLES):
        out[name] = rows(euler[..., i])
    for i, a in enumerate("xyz"):
        out[f"gyro_bias_{a}"] = nan3[:, i] if bias is None else rows(bias[..., i])
        out[f"sd_att_{a}"] = nan3[:, i] if sigma is None else rows(sigma[..., i])
    return out


def _tune(batch: SupportBatch, model: UnitModel, truth: dict, q_true: np.ndarray, var0: np.ndarray):
    """002's gradient descent of Q (eq. 35) on the reference segment of the first support: (Tuning, its metrics)."""
    i, j = 0, int(batch.supports[0])
    ids = np.asarray(truth["support"])
    lowered = np.flatnonzero((ids == j) & (np.asarray(truth["set"]) == 0))
    centre = float(np.min(np.asarray(truth["t"], float)[lowered])) if lowered.size else batch.t[0] + TUNING_WINDOW_S / 2
    start = min(max(centre - TUNING_WINDOW_S / 2, batch.t[0]), max(batch.t[-1] - TUNING_WINDOW_S, batch.t[0]))
    sel = (batch.t >= start) & (batch.t <= start + TUNING_WINDOW_S)
    tuning = tune_q(batch.gyro[i, sel], batch.accel[i, sel], batch.mag[i, sel], batch.dt, model, q_true[i, sel],
                    var0, iterations=TUNING_ITERATIONS)
    return tuning, {"reference_support": j, "window_s": [float(batch.t[sel][0]), float(batch.t[sel][-1])],
                    "objective_deg": [float(np.degrees(f)) for f in tuning.objective],
                    "var_deg2_s2": [(v / np.radians(1.0) ** 2).tolist() for v in tuning.history],
                    "converged": tuning.converged}


def _error_stats(err: np.ndarray, near: np.ndarray | None) -> dict:
    """RMSE and max |error| [deg] per angle of errors (..., K, 3) [rad], and the yaw RMSE where `near`."""
    e = np.degrees(err.reshape(-1, 3))
    out = {"rmse_deg": dict(zip(ANGLES, np.sqrt(np.mean(e ** 2, axis=0)).tolist())),
           "max_deg": dict(zip(ANGLES, np.abs(e).max(axis=0).tolist()))}
    if near is not None:
        sel = near.reshape(-1)
        out["yaw_near_rmse_deg"] = float(np.sqrt(np.mean(e[sel, 2] ** 2))) if sel.any() else None
    return out


def _own(batch: SupportBatch, euler: dict[str, np.ndarray], res) -> dict:
    """What needs no truth: per support each method's final pitch, roll, yaw and ours' final attitude one-sigma
    [deg]; ours' flag counts (FLAG_NAMES) over its updates."""
    final = {int(j): {name: dict(zip(ANGLES, np.degrees(e[i, -1]).tolist())) for name, e in euler.items()}
             for i, j in enumerate(batch.supports)}
    sd = {int(j): dict(zip("xyz", np.degrees(res.sigma[i, -1, :3]).tolist())) for i, j in enumerate(batch.supports)}
    return {"final_deg": final, "ours_final_sd_deg": sd, "ours_updates": int(res.flags.size),
            "ours_flags": {name: int(np.count_nonzero(res.flags & bit)) for name, bit in FLAG_NAMES}}


def support_attitude(run_dir: Path, scn: Scenario) -> SupportAttitude | None:
    """KF, UKF, GD-UKF and ours on the run's support_imu stream; None when the scenario names no instrumented
    support. Writes estimates/METHOD_support_attitude.parquet (estimators.io.logformat.ESTIMATE_SUPPORT_ATTITUDE).

    The filters read only the stream and the scenario (unit_model, ours_settings). The truth, where the run has it,
    tunes the GD-UKF's Q on a reference segment (002 step 1: truth_supports) and scores every method against the
    true canopy attitude, with the shearer's proximity (truth_shearer) marking the disturbed samples; without it
    the GD-UKF and the scores are left out with a note. The metrics hold "truth" (whether truth_supports was
    there) and, needing no truth, each method's final angles and ours' final one-sigma [deg] and flag counts
    ("own"). Supports the filters cannot use are skipped with their reason (estimators.support.batch.support_batch);
    a stream with none left raises LogError (one line).
    """
    if not scn.sensors.support_imu.supports:
        return None
    path = Path(run_dir) / SUPPORT_IMU.filename
    columns = _columns(run_dir, SUPPORT_IMU)
    if columns is None:
        raise LogError(f"{path}: stream file not found (the scenario names instrumented supports)")
    try:
        batch = support_batch(columns, scn.sensors.support_imu.supports)
    except ValueError as err:
        raise LogError(f"{path}: {err}") from None
    model = unit_model(scn, 1.0 / batch.dt)
    var0 = np.full(3, UNTUNED_VAR_DEG2_S2 * np.radians(1.0) ** 2)
    truth, shearer = _columns(run_dir, TRUTH_SUPPORTS), _columns(run_dir, STREAMS["truth_shearer"])
    notes = [f"support {j} skipped: {why}" for j, why in batch.skipped.items()]
    q_true = None
    if truth is None:
        notes.append("no truth_supports: the GD-UKF (tuned against the truth, 002 step 1) and the scores are left out")
    else:
        q_true = np.stack([canopy_attitude_n(scn, truth, int(j), batch.t) for j in batch.supports])
    scale = None if shearer is None else np.stack([shearer_disturbance(scn, shearer, int(j), batch.t)
                                                   for j in batch.supports])
    seconds: dict[str, float] = {}

    def timed(name: str, fn):
        start = time.perf_counter()
        out = fn()
        seconds[name] = time.perf_counter() - start
        return out

    args = (batch.gyro, batch.accel, batch.mag, batch.dt, model)
    q = {"kf": timed("kf", lambda: kf(*args, var0)), "ukf": timed("ukf", lambda: ukf(*args, var0))}
    tuning: dict = {}
    if q_true is not None:
        tuned, tuning = timed("gd_tuning", lambda: _tune(batch, model, truth, q_true, var0))
        q["gd_ukf"] = timed("gd_ukf", lambda: ukf(*args, tuned.var_w))
    res = timed("ours", lambda: ours(*args, ours_settings(scn, 1.0 / batch.dt)))
    q["ours"] = res.q_nb
    sub = {name: res.sample if name == "ours" else slice(None) for name in q}  # each method's output samples
    t_out = {name: batch.t[sub[name]] for name in q}
    euler = {name: np.stack(quat_euler(*np.moveaxis(q_nc, -1, 0)), axis=-1) for name, q_nc in q.items()}
    for name, q_nc in q.items():
        extra = (res.gyro_bias, res.sigma[..., :3], res.flags) if name == "ours" else ()
        write_estimate(run_dir, name, _estimate_columns(batch, t_out[name], q_nc, euler[name], *extra),
                       ESTIMATE_SUPPORT_ATTITUDE)

    write_timing(run_dir, support_attitude_s=seconds)  # wall clock: not in metrics.json
    classes = {int(j): support_class(scn, int(j)) for j in batch.supports}
    metrics = {"truth": q_true is not None, "methods": list(q), "supports": batch.supports.tolist(),
               "skipped": batch.skipped, "classes": classes, "tuning": tuning, "notes": notes,
               "own": _own(batch, euler, res)}
    near = None if scale is None else scale > NEAR_FRACTION
    if near is not None:
        flagged, near_ours = (res.flags & FLAGS_MAG) > 0, near[:, res.sample]
        metrics["detection"] = {
            "near_updates": int(near_ours.sum()), "flagged_near": int((flagged & near_ours).sum()),
            "far_updates": int((~near_ours).sum()), "flagged_far": int((flagged & ~near_ours).sum())}
    truth_euler = {}
    if q_true is not None:
        truth_all = np.stack(quat_euler(*np.moveaxis(q_true, -1, 0)), axis=-1)
        truth_euler = {name: truth_all[:, sub[name]] for name in q}
        errors = {name: wrap(euler[name] - truth_euler[name]) for name in q}  # euler_errors

        def stats(name: str, rows) -> dict:
            return _error_stats(errors[name][rows], None if near is None else near[:, sub[name]][rows])

        metrics["per_support"] = {int(j): {name: stats(name, i) for name in q} for i, j in enumerate(batch.supports)}
        metrics["by_class"] = {}
        for cls in CLASSES:
            rows = np.flatnonzero([classes[int(j)] == cls for j in batch.supports])
            if rows.size:
                metrics["by_class"][cls] = {"supports": batch.supports[rows].tolist(),
                                            **{name: stats(name, rows) for name in q}}
    return SupportAttitude(metrics, batch.supports, t_out, euler, truth_euler, res.flags,
                           None if scale is None else scale[:, res.sample],
                           [float(np.radians(f)) for f in tuning.get("objective_deg", [])])


def format_support_attitude(metrics: dict | None) -> str:
    """The canopy attitude summary: RMSE [deg] of pitch, roll, yaw, of the yaw while the shearer passes, and the
    largest |yaw error| per support class and method; ours' disturbance flags; the GD objective; what was left out."""
    if not metrics:
        return ""
    scored = ": RMSE [deg]" if metrics.get("by_class") else ""  # else a note says why
    lines = ["", f"support canopy attitude (002's KF, UKF, GD-UKF and ours){scored}"]
    for cls, label in CLASSES.items():
        entry = metrics.get("by_class", {}).get(cls)
        if entry is None:
            continue
        lines.append(f"  {label} ({', '.join(map(str, entry['supports']))}){'':4s}"
                     f"{'pitch':>8s}{'roll':>8s}{'yaw':>8s}{'yaw near':>10s}{'yaw max':>9s}")
        for name in metrics["methods"]:
            e = entry[name]
            near = e.get("yaw_near_rmse_deg")
            lines.append(f"    {name:10s}" + "".join(f"{e['rmse_deg'][a]:8.3f}" for a in ANGLES)
                         + (f"{near:10.3f}" if near is not None else f"{'-':>10s}") + f"{e['max_deg']['yaw']:9.3f}")
    d = metrics.get("detection")
    if d:
        lines.append(f"  ours: magnetometer updates flagged {d['flagged_near']}/{d['near_updates']} while the shearer "
                     f"is near (field > {NEAR_FRACTION:.0%} of its peak), {d['flagged_far']}/{d['far_updates']} otherwise")
    own = metrics.get("own")
    if own and not metrics.get("by_class"):
        counts = ", ".join(f"{name} {n}" for name, n in own["ours_flags"].items())
        lines.append(f"  ours: flags over {own['ours_updates']} unit updates: {counts}")
    tu = metrics.get("tuning")
    if tu:
        obj = tu["objective_deg"]
        lines.append(f"  GD-UKF objective [deg]: {obj[0]:.4f} -> {obj[-1]:.4f} in {len(obj) - 1} steps (converged "
                     f"{tu['converged']}; reference support {tu['reference_support']}, "
                     f"{tu['window_s'][0]:.0f}-{tu['window_s'][1]:.0f} s)")
    lines += [f"  {note}" for note in metrics["notes"]]
    return "\n".join(lines)
