"""002's turntable scenario (twin.papers.turntable): the readings, a shortened `longwall run` (the file's loading and
bad input: tests/twin/config/test_turntable.py)."""

from __future__ import annotations

import json
import tomllib

import numpy as np
import pytest

from estimators.nav.rotations_scalar import quat_euler
from estimators.support.unit_model import accel_pitch_roll, mag_yaw
from tests.conftest import SCENARIO_DIR
from twin.cli import main
from twin.config.turntable import load_turntable, parse_turntable
from twin.papers.turntable import readings, unit_model

FILE = SCENARIO_DIR / "seed002_turntable.toml"


def short(**motion) -> dict:
    data = tomllib.loads(FILE.read_text())
    # The ramps and the shearer's passes scaled into the shortened motion (they must lie within it).
    data["motion"].update(duration_s=40.0, pitch_s=[0.0, 16.0], roll_s=[0.0, 20.0], heading_s=[0.0, 20.0], **motion)
    data["disturbance"]["pass_times_s"] = [12.0, 30.0]
    data["paper_filters"]["gd_iterations"] = 2
    return data


def test_motion_and_error_free_readings():
    """The ramps of 002 section 4.1, and with the ideal grade the sensors give back the truth exactly."""
    tt = load_turntable(FILE)
    data = tt.model_dump()
    data["unit"]["grade"] = "ideal"
    data["unit"].update(accel_bias_mg=0.0, accel_scale=0.0, accel_nonorth_rad=0.0, gyro_scale=0.0,
                        gyro_nonorth_rad=0.0, mag_noise_t=1e-15)
    data["disturbance"]["peak_t"] = 0.0
    tt = parse_turntable(data)
    r = readings(tt, np.random.default_rng(0))
    pitch, roll, yaw = (np.degrees(a) for a in quat_euler(*r.q_true.T))
    i200, i250 = 200 * 100 - 1, 250 * 100 - 1
    assert pitch[i200] == pytest.approx(15.0) and pitch[-1] == pytest.approx(15.0)
    assert roll[i250] == pytest.approx(40.0) and yaw[i250] == pytest.approx(-10.0)  # heading +10 deg clockwise
    model, _ = unit_model(tt)
    p, rl = accel_pitch_roll(*r.accel.T)
    y = mag_yaw(*r.mag.T, p, rl, model.declination)
    np.testing.assert_allclose(np.degrees(p), pitch, atol=1e-9)
    np.testing.assert_allclose(np.degrees(y), yaw, atol=1e-6)


def test_longwall_run_writes_metrics(tmp_path, capsys):
    src = tmp_path / "tt.toml"
    data = short()
    lines = []
    for key in ("kind", "name", "seed"):
        lines.append(f"{key} = {json.dumps(data[key])}")
    for sec, body in data.items():
        if isinstance(body, dict):
            lines.append(f"[{sec}]")
            lines += [f"{k} = {json.dumps(v)}" for k, v in body.items()]
    src.write_text("\n".join(lines) + "\n")
    out = tmp_path / "run"
    assert main(["run", str(src), "--out", str(out)]) in (0, None)
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["ours"]) == {"kf", "ukf", "gd_ukf", "ours"}
    obj = metrics["tuning"]["objective_deg"]
    assert np.all(np.diff(obj) < 0)
    assert (out / "errors.parquet").exists() and (out / "ours_states.parquet").exists()
    assert "GD objective" in capsys.readouterr().out
