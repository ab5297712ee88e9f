"""SINS experiments (twin.papers.sins_experiments): the simulations of 000 beside the paper's figures.

The figures are checked on the shipped files at full length where that is quick (coning, sculling, the lever-arm
mechanization); the command-line runs use shortened copies (durations overridden) to check the run directory
and the recording. The files themselves (loading, bad input) are tests/twin/config/test_experiments.py's.
"""

from __future__ import annotations

import filecmp
import json
import tomllib

import numpy as np
import pyarrow.parquet as pq
import pytest
from rerun.chunk import RrdReader

from tests.conftest import EXPERIMENTS, SCENARIO_DIR, SCENARIOS
from twin.cli import main
from twin.config.experiments import is_experiment, load_experiment, parse_experiment
from twin.config.scenario import scenario_to_toml
from twin.papers.sins_experiments import run_experiment

SHORT = {  # per shipped experiment: section overrides for a quick command-line run, and its entities
    "seed000_alignment": ({"alignment": {"duration_s": 10.0, "grades": ["nav-004"]}},
                          [f"/errors/nav-004/{m}/{q}" for m in ("ekf", "ukf", "optimized_ukf")
                           for q in ("attitude", "sigma")]),
    "seed000_lever_arm": ({"lever_arm": {"duration_s": 6.0}},
                          [f"/errors/{g}/{q}/{v}" for g in ("table2", "table3") for q in ("attitude", "velocity",
                                                                                             "position")
                           for v in ("uncompensated", "compensated")]
                          + [f"/errors/closed_loop/table2/attitude/{v}" for v in ("uncompensated", "compensated")]),
    "seed000_coning": ({"coning": {"duration_s": 3.0}},
                       [f"/errors/{q}/{v}" for q in ("attitude", "coning") for v in ("uncompensated", "compensated")]),
    "seed000_sculling": ({"sculling": {"duration_s": 3.0}},
                         [f"/errors/{q}/{v}" for q in ("attitude", "velocity", "position")
                          for v in ("uncompensated", "compensated")]),
}


def shortened(name: str, tmp_path, **extra) -> tuple:
    """A copy of a shipped experiment with SHORT's overrides (and `extra` section overrides) in tmp_path."""
    data = tomllib.loads((SCENARIO_DIR / f"{name}.toml").read_text())
    for section, values in {**SHORT[name][0], **extra}.items():
        data[section].update(values)
    path = tmp_path / f"{name}.toml"
    path.write_text(scenario_to_toml(parse_experiment(data, name)))
    return path, SHORT[name][1]


def test_experiment_files_are_apart_from_face_scenarios():
    assert sorted(EXPERIMENTS) == sorted(SHORT)
    assert not set(EXPERIMENTS) & set(SCENARIOS)
    assert "default" in SCENARIOS
    assert all(is_experiment(SCENARIO_DIR / f"{n}.toml") for n in EXPERIMENTS)
    assert not is_experiment(SCENARIO_DIR / "default.toml")


def test_coning_figures():
    """000 section 7.2 reduces the coning error by 64 %; the exact 3-sample coefficients by > 99 %."""
    res = run_experiment(load_experiment(SCENARIO_DIR / "seed000_coning.toml"))
    assert res.ours["reduction_pct"] >= 99.0
    assert res.ours["drift_reduction_pct"] >= 99.0
    assert max(res.paper["reduction_pct"]) == pytest.approx(64.3)
    # The uncompensated drift is the coning rate of eq. 55 on the cone axis, integrated over 40 s.
    assert res.ours["drift_rad"]["uncompensated"] > 1e-4


def test_sculling_figures():
    """000 section 7.4 reduces the largest sculling error by 70 %; the 4-sample algorithm by > 99 %."""
    res = run_experiment(load_experiment(SCENARIO_DIR / "seed000_sculling.toml"))
    assert res.ours["reduction_pct"] >= 99.0
    assert res.paper["reduction_pct"][1] == pytest.approx(70.0)
    raw = res.ours["max_error_m_s"]["uncompensated"]
    assert raw[2] == max(raw)  # the sculling drift is on the third axis (z, normal to x and y)


def test_lever_arm_reductions_meet_the_paper():
    """Tables 2-3: the reductions of the maximum attitude errors are at least the paper's, on every axis."""
    exp = load_experiment(SCENARIO_DIR / "seed000_lever_arm.toml")
    exp = exp.model_copy(update={"closed_loop": exp.closed_loop.model_copy(update={"enabled": False})})
    res = run_experiment(exp)
    assert set(res.ours) == {"table2", "table3"}
    for group, ours in res.ours.items():
        assert np.all(np.array(ours["reduction_pct"]) >= res.paper[group]["reduction_pct"]), (group, ours)
        assert ours["meets_paper"]
        assert max(ours["compensated_velocity_m_s"]) < 1e-3 < max(ours["uncompensated_velocity_m_s"])


@pytest.mark.parametrize("name", sorted(SHORT))
def test_longwall_run_writes_metrics_parquet_and_recording(name, tmp_path, capsys):
    path, entities = shortened(name, tmp_path)
    out = tmp_path / "run"
    assert main(["run", str(path), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "paper" in printed and "ours" in printed
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics) == {"experiment", "ours", "paper"}
    assert metrics["experiment"]["experiment"] == name.removeprefix("seed000_")
    assert (out / "scenario.toml").is_file()
    errors = pq.read_table(out / "errors.parquet")
    assert {"group", "quantity", "variant", "t", "e", "n", "u"} <= set(errors.column_names)
    assert errors.num_rows > 0 and np.isfinite(errors.column("e").to_numpy()).all()
    chunks = RrdReader(out / "run.rrd").stream().to_chunks()
    found = {c.entity_path for c in chunks}
    assert set(entities) <= found, set(entities) - found
    # Run again: the same bytes, the recording included (its id from the scenario and seed).
    again = tmp_path / "again"
    assert main(["run", str(path), "--out", str(again), "--quiet"]) == 0
    for name in ("run.rrd", "metrics.json", "errors.parquet", "scenario.toml"):
        assert filecmp.cmp(out / name, again / name, shallow=False), name


def test_alignment_converges_from_the_paper_errors(tmp_path):
    """Table 1's setup on the navigation-grade IMU: 3, 3, 5 deg shrink, and so does each filter's sigma."""
    path, _ = shortened("seed000_alignment", tmp_path, alignment={"duration_s": 30.0, "grades": ["nav-004"]})
    res = run_experiment(load_experiment(path))
    for m in ("ekf", "ukf", "optimized_ukf"):
        r = res.ours["nav-004"][m]
        assert np.all(np.abs(r["error_deg"]) < 0.5), (m, r)
        assert np.all(np.array(r["sigma_deg"]) < [3.0, 3.0, 5.0])
    sigma = [s.values for s in res.series if s.quantity == "sigma"]
    assert all(np.all(s[-1] < s[0]) for s in sigma)
