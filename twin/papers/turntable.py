"""002 section 4.1's two-axis turntable as a scenario file: the support attitude unit's filters beside 002's figures.

A third kind of scenario file, marked by the top-level key `kind = "support_turntable"` (scenarios/
seed002_turntable.toml, read by twin.config.turntable); `longwall run FILE` dispatches it here (twin.cli). Every
parameter is a key of the file.

Motion (002 section 4.1): each angle ramps linearly from its first to its second value between the two times
of its `*_s` pair and is held outside them. The file gives 002's angles: pitch (nose up), roll (left side up)
and heading (clockwise from north); the project's yaw is -heading. The unit sits at the turntable's centre, so it
feels gravity only.

Readings, sampled from the analytic motion at `rate_hz` (002 gives no rate)
    gyro  = Log(q_{k-1}^* q_k) / dt + C_n^b(t_k) w_ie^n      (the exact rotation of each interval, as a rate)
    accel = C_n^b(t_k) [0, 0, gamma]                          (normal gravity at the site)
    mag   = C_n^b(t_k) (B^n + d(t) u_n) + noise               (B^n the WMM field on `mag_date`)
with the inertial errors of `grade` applied as for the canopy units (twin.sensors.support_imu: twin.sensors.imu_errors on
rate * dt), except that the constant terms a factory calibration removes are replaced by the `[unit]`
residuals. The disturbance is the shearer's (twin.sensors.support_imu) passing at `speed_m_s`: peak `peak_t` in a
fixed random direction u_n, scaled by (1 - (d / range_m)^2)^3 with d = speed (t - t_pass) for each pass time.

Filters: 002's linear KF and UKF with the untuned rate variances (002 Table 1's "inherent" value; 002 gives no
unit: read as (deg/s)^2), the GD-UKF with Q tuned by gradient descent on a reference run (the same motion, an
independent error draw) and evaluated on the test run (held out), and ours (estimators.support.error_state).
Metrics: RMSE of pitch, roll and yaw [deg] over each angle's dynamic (ramp) and static (held) segment.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from estimators.nav import earth
from estimators.nav.rotations import (
    euler_to_quat,
    quat_conj,
    quat_mul,
    quat_rotate,
    quat_to_rotvec,
)
from estimators.support.error_state import OursSettings, ours
from estimators.support.filters_002 import SigmaSettings, kf, ukf
from estimators.support.tuning import tune_q
from estimators.support.unit_model import UnitModel, euler_errors
from twin.config.scenario import scenario_to_toml
from twin.config.turntable import (
    TURNTABLE_KIND,
    Motion,
    Turntable,
    is_turntable,
)
from twin.pipeline.rundir import write_timing

__all__ = [
    "FILTERS",
    "PAPER",
    "TARGETS",
    "Readings",
    "is_turntable",
    "ours_settings",
    "ramp",
    "readings",
    "run_filters",
    "run_turntable",
    "segment_rmse",
    "table",
    "truth_attitude",
    "unit_grade",
    "unit_model",
    "write_run",
]

DEG = np.pi / 180


# --------------------------------------------------------------------------------------------------------------
# Motion and readings


def ramp(t: np.ndarray, values: list[float], times: list[float]) -> np.ndarray:
    """Linear ramp from values[0] at times[0] to values[1] at times[1], held outside."""
    tau = np.clip((t - times[0]) / (times[1] - times[0]), 0.0, 1.0)
    return values[0] + (values[1] - values[0]) * tau


def truth_attitude(m: Motion, t: np.ndarray) -> np.ndarray:
    """q_nb (K, 4) of the turntable at times t (project convention; yaw = -heading)."""
    return euler_to_quat(ramp(t, m.pitch_deg, m.pitch_s) * DEG, ramp(t, m.roll_deg, m.roll_s) * DEG,
                         -ramp(t, m.heading_deg, m.heading_s) * DEG)


@dataclasses.dataclass
class Readings:
    t: np.ndarray  # (K,) sample times t_k = k dt, k = 1..K
    q_true: np.ndarray  # (K, 4)
    gyro: np.ndarray  # (K, 3) [rad/s]
    accel: np.ndarray  # (K, 3) [m/s^2]
    mag: np.ndarray  # (K, 3) [T]
    disturbance: np.ndarray  # (K,) [T] magnitude of the disturbing field


def unit_model(tt: Turntable):
    """(UnitModel, gravity [m/s^2], Earth rate in n) of the site; the filters' sensor variances per sample."""
    from twin.config.imu_grades import grade
    from twin.sensors.magnetometer import earth_field_n

    s = tt.site
    lat, h = np.radians(s.lat_deg), s.height_m
    g = float(-earth.gravity_n(lat, h)[2])
    w_ie = earth.earth_rate_n(lat)
    b_n = earth_field_n(s.lat_deg, s.lon_deg, s.height_m, s.mag_date)
    gr = grade(tt.unit.grade)
    var_a = np.full(3, gr.accel_vrw ** 2 * tt.unit.rate_hz)
    var_m = np.full(3, tt.unit.mag_noise_t ** 2)
    return UnitModel(var_a, var_m, b_n, w_ie), g


def unit_grade(tt: Turntable):
    """The grade with the calibration residuals of `[unit]` for its constant terms."""
    from twin.config.imu_grades import G0, grade

    u = tt.unit
    return dataclasses.replace(grade(u.grade), accel_bias=u.accel_bias_mg * 1e-3 * G0, accel_scale=u.accel_scale,
                               accel_nonorth=u.accel_nonorth_rad, gyro_scale=u.gyro_scale,
                               gyro_nonorth=u.gyro_nonorth_rad)


def readings(tt: Turntable, rng: np.random.Generator, disturbed: bool = True) -> Readings:
    """The unit's readings for one error draw from `rng` (inertial errors, magnetometer noise, field direction)."""
    from twin.sensors.imu_errors import apply_imu_errors

    model, g = unit_model(tt)
    dt = 1.0 / tt.unit.rate_hz
    k = round(tt.motion.duration_s * tt.unit.rate_hz)
    t = np.arange(k + 1) * dt
    q = truth_attitude(tt.motion, t)
    q_bn = quat_conj(q[1:])
    gyro = quat_to_rotvec(quat_mul(quat_conj(q[:-1]), q[1:])) / dt + quat_rotate(q_bn, model.earth_rate_n)
    accel = quat_rotate(q_bn, np.array([0.0, 0.0, g]))
    dtheta, dv, _ = apply_imu_errors(gyro * dt, accel * dt, dt, unit_grade(tt), rng)
    d = tt.disturbance
    scale = np.zeros(k)
    for tp in d.pass_times_s:
        scale += np.clip(1.0 - (d.speed_m_s * (t[1:] - tp) / d.range_m) ** 2, 0.0, None) ** 3
    noise = rng.normal(0.0, tt.unit.mag_noise_t, (k, 3))
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    peak = d.peak_t if disturbed else 0.0
    mag = quat_rotate(q_bn, model.field_n + (peak * scale)[:, None] * u) + noise
    return Readings(t[1:], q[1:], dtheta / dt, dv / dt, mag, peak * scale)


# --------------------------------------------------------------------------------------------------------------
# Filters and metrics

PAPER = {
    "source": "002_5cc0b59ad045ffaa.txt section 4.2 (turntable) and section 5 (industrial yaw)",
    "gd_ukf_static_deg": {"pitch": 0.5, "roll": 0.5, "bound": "less than"},
    "gd_ukf_dynamic_deg": {"pitch": 1.0, "roll": 1.0, "bound": "less than"},
    "kf_max_error_deg": {"pitch": 3.0, "roll": 3.0, "yaw": 1.8, "bound": "greater than (pitch, roll)"},
    "ukf_max_error_deg": {"pitch": 2.4, "roll": 2.4, "yaw": 1.3},
    "gd_ukf_yaw_disturbed_deg": 2.0,
    "table1_var": {"static": {"inherent": [0.0025] * 3, "gd": [0.0046, 0.0053, 0.0032]},
                   "dynamic": {"inherent": [0.01] * 3, "gd": [0.0196, 0.0182, 0.0134]}},
}
TARGETS = {"static_deg": 0.1, "dynamic_deg": 0.3, "yaw_deg": 1.0}
FILTERS = ("kf", "ukf", "gd_ukf", "ours")


def ours_settings(tt: Turntable) -> OursSettings:
    o = tt.ours
    m = max(1, round(tt.unit.rate_hz / o.update_hz))
    from twin.config.imu_grades import G0
    return OursSettings(
        samples_per_update=m, gyro_arw=o.gyro_arw_deg_sqrt_h * DEG / 60.0,
        gyro_bias_walk=o.gyro_bias_walk_deg_h_sqrt_h * DEG / 3600.0 / 60.0,
        attitude_sigma0=o.attitude_sigma0_deg * DEG, gyro_bias_sigma0=o.gyro_bias_sigma0_deg_s * DEG,
        accel_sigma=o.accel_sigma_mg * 1e-3 * G0, accel_gate=o.accel_gate_mg * 1e-3 * G0, mag_sigma=o.mag_sigma_t,
        norm_tol=o.norm_tol_t, dip_tol=o.dip_tol_deg * DEG, gate=o.gate_chi2,
        relock_updates=round(o.relock_s * o.update_hz))


def segment_rmse(tt: Turntable, t: np.ndarray, err: np.ndarray) -> dict:
    """RMSE [deg] of the pitch, roll and yaw errors (K, 3) [rad] over each angle's dynamic and static segment."""
    m = tt.motion
    out: dict = {"dynamic": {}, "static": {}, "max": {}}
    for a, (name, times) in enumerate((("pitch", m.pitch_s), ("roll", m.roll_s), ("yaw", m.heading_s))):
        dyn = (t > times[0]) & (t <= times[1])
        for seg, sel in (("dynamic", dyn), ("static", ~dyn)):
            out[seg][name] = float(np.degrees(np.sqrt(np.mean(err[sel, a] ** 2)))) if sel.any() else None
        out["max"][name] = float(np.degrees(np.abs(err[:, a]).max()))
    return out


def run_filters(tt: Turntable, test: Readings, reference: Readings) -> dict:
    """KF, UKF (untuned), GD-UKF (Q tuned on `reference`), ours on `test`; errors, metrics, tuning log, timings."""
    model, _ = unit_model(tt)
    dt = 1.0 / tt.unit.rate_hz
    pf = tt.paper_filters
    sig = SigmaSettings(pf.sigma_alpha, pf.sigma_beta, pf.sigma_kappa)
    var0 = np.asarray(pf.untuned_var_deg2_s2) * DEG ** 2
    args = (test.gyro, test.accel, test.mag, dt, model)
    out: dict = {"errors": {}, "metrics": {}, "seconds": {}}
    start = time.perf_counter()
    tuning = tune_q(reference.gyro, reference.accel, reference.mag, dt, model, reference.q_true, var0,
                    sigma=sig, iterations=pf.gd_iterations, tol=pf.gd_tol)
    out["seconds"]["gd_tuning"] = time.perf_counter() - start
    out["tuning"] = {"objective_deg": [float(np.degrees(f)) for f in tuning.objective],
                     "var_deg2_s2": [(v / DEG ** 2).tolist() for v in tuning.history],
                     "converged": tuning.converged}
    for name, var in (("kf", var0), ("ukf", var0), ("gd_ukf", tuning.var_w)):
        start = time.perf_counter()
        fn = kf if name == "kf" else ukf
        q = fn(*args, var, p0_sigma=pf.p0_sigma) if name == "kf" else fn(*args, var, p0_sigma=pf.p0_sigma,
                                                                          sigma=sig)
        out["seconds"][name] = time.perf_counter() - start
        out["errors"][name] = (test.t, euler_errors(test.q_true, q[0]))
    start = time.perf_counter()
    res = ours(*args, ours_settings(tt))
    out["seconds"]["ours"] = time.perf_counter() - start
    out["errors"]["ours"] = (test.t[res.sample], euler_errors(test.q_true[res.sample], res.q_nb[0]))
    out["ours_flags"] = (test.t[res.sample], res.flags[0])
    out["ours_bias"] = res.gyro_bias[0]
    for name, (t, e) in out["errors"].items():
        out["metrics"][name] = segment_rmse(tt, t, e)
    disturbed = np.interp(out["ours_flags"][0], test.t, test.disturbance) > 0.1 * max(tt.disturbance.peak_t, 1e-30)
    flagged = (out["ours_flags"][1] & 7) > 0
    out["detection"] = {"disturbed_updates": int(disturbed.sum()), "flagged_disturbed": int((flagged & disturbed).sum()),
                        "flagged_clean": int((flagged & ~disturbed).sum()), "clean_updates": int((~disturbed).sum())}
    return out


def table(tt: Turntable, res: dict) -> list[str]:
    """Ours beside 002's figures (RMSE [deg])."""
    rows = [(f"002 section 4.1 turntable ({tt.motion.duration_s:g} s, {tt.unit.rate_hz:g} Hz, {tt.unit.grade}, "
            f"disturbance {tt.disturbance.peak_t * 1e6:g} uT): RMSE [deg] dynamic / static, yaw with disturbance"),
            (f"  {'':10s}{'pitch dyn':>10s}{'pitch st':>10s}{'roll dyn':>10s}{'roll st':>10s}{'yaw dyn':>10s}"
            f"{'yaw st':>10s}{'yaw max':>10s}")]
    for name in FILTERS:
        m = res["metrics"][name]
        vals = [m["dynamic"]["pitch"], m["static"]["pitch"], m["dynamic"]["roll"], m["static"]["roll"],
                m["dynamic"]["yaw"], m["static"]["yaw"], m["max"]["yaw"]]
        rows.append(f"  {name:10s}" + "".join(f"{v:10.3f}" if v is not None else f"{'-':>10s}" for v in vals))
    rows.append(f"  {'002 GD-UKF':10s}{'< 1':>10s}{'< 0.5':>10s}{'< 1':>10s}{'< 0.5':>10s}{'':>10s}{'':>10s}"
                f"{'< 2':>10s}   (yaw: 002 section 5, in the face)")
    rows.append(f"  {'targets':10s}{'<= 0.3':>10s}{'<= 0.1':>10s}{'<= 0.3':>10s}{'<= 0.1':>10s}{'':>10s}{'':>10s}"
                f"{'<= 1':>10s}")
    tu = res["tuning"]
    rows.append(f"  GD objective [deg]: {' -> '.join(f'{f:.4f}' for f in tu['objective_deg'])}"
                f" ({len(tu['objective_deg']) - 1} steps, converged {tu['converged']})")
    rows.append("  GD variances [(deg/s)^2]: untuned " + ", ".join(f"{v:.4g}" for v in tu["var_deg2_s2"][0])
                + "; tuned " + ", ".join(f"{v:.4g}" for v in tu["var_deg2_s2"][-1]))
    d = res["detection"]
    rows.append(f"  ours: magnetometer updates flagged {d['flagged_disturbed']}/{d['disturbed_updates']} disturbed "
                f"(> 10 % of peak), {d['flagged_clean']}/{d['clean_updates']} clean")
    rows.append("  run time [s]: " + ", ".join(f"{k} {v:.2f}" for k, v in res["seconds"].items()))
    return rows


def run_turntable(tt: Turntable) -> tuple[dict, list[str]]:
    """The reference draw (child 0 of the seed, for the GD tuning; disturbed or not as the file says) and the test
    draw (child 1); all filters."""
    ref_rng, test_rng = np.random.default_rng(tt.seed).spawn(2)
    res = run_filters(tt, readings(tt, test_rng), readings(tt, ref_rng, tt.paper_filters.gd_reference_disturbed))
    return res, table(tt, res)


def _errors_table(res: dict) -> pa.Table:
    parts = {"filter": [], "t": [], "pitch": [], "roll": [], "yaw": []}
    for name, (t, e) in res["errors"].items():
        parts["filter"].append(np.full(t.size, name))
        parts["t"].append(t)
        for a, col in enumerate(("pitch", "roll", "yaw")):
            parts[col].append(e[:, a])
    cols = {k: pa.array(np.concatenate(v)) for k, v in parts.items()}
    return pa.table(cols, metadata={"units": "t [s]; pitch, roll, yaw errors [rad] (estimate - truth)"})


def write_run(staging: Path, tt: Turntable, res: dict) -> None:
    """The turntable's run directory: scenario.toml, metrics.json (ours and 002's), errors.parquet, the states of
    ours (flags, gyro bias), and the methods' run times in timing.json."""
    (staging / "scenario.toml").write_text(scenario_to_toml(tt))
    metrics = {"experiment": {"name": tt.name, "kind": TURNTABLE_KIND, "seed": tt.seed}, "ours": res["metrics"],
               "tuning": res["tuning"], "detection": res["detection"],
               "paper": PAPER, "targets": TARGETS}
    (staging / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    write_timing(staging, seconds=res["seconds"])
    pq.write_table(_errors_table(res), staging / "errors.parquet")
    t, flags = res["ours_flags"]
    pq.write_table(pa.table({"t": t, "flags": flags.astype(np.int8),
                             **{f"gyro_bias_{a}": res["ours_bias"][:, i] for i, a in enumerate("xyz")}}),
                   staging / "ours_states.parquet")
