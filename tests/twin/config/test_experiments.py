"""SINS experiment files (twin.config.experiments): the shipped ones load and round-trip, bad input is one line."""

from __future__ import annotations

import json
import tomllib

import pytest

from tests.conftest import EXPERIMENTS, SCENARIO_DIR
from twin.cli import main
from twin.config.experiments import EXPERIMENT_KIND, load_experiment, parse_experiment
from twin.config.scenario import ScenarioError, scenario_to_toml


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_shipped_experiments_load_and_round_trip(name):
    exp = load_experiment(SCENARIO_DIR / f"{name}.toml")
    assert exp.kind == EXPERIMENT_KIND and exp.site.lat_deg == 34.27
    assert parse_experiment(tomllib.loads(scenario_to_toml(exp))) == exp
    assert load_experiment(SCENARIO_DIR / f"{name}.toml", seed=7).seed == 7


@pytest.mark.parametrize("change, where", [
    (lambda d: d["coning"].update(half_cone_dg=1.0), "coning.half_cone_dg: unknown key"),
    (lambda d: d["coning"].pop("samples"), "coning.samples: Field required"),
    (lambda d: d["coning"].update(samples=9), "coning.samples:"),
    (lambda d: d.update(experiment="wobble"), "experiment: must be one of"),
    (lambda d: d.update(colour="red"), "colour: unknown key"),
])
def test_bad_experiment_file_is_one_line_exit_2(tmp_path, capsys, change, where):
    data = tomllib.loads((SCENARIO_DIR / "seed000_coning.toml").read_text())
    change(data)
    bad = tmp_path / "bad.toml"
    bad.write_text("\n".join(f"{k} = {json.dumps(v)}" for k, v in data.items() if not isinstance(v, dict))
                   + "\n" + "\n".join(f"[{k}]\n" + "\n".join(f"{kk} = {json.dumps(vv)}" for kk, vv in v.items())
                                      for k, v in data.items() if isinstance(v, dict)) + "\n")
    assert main(["run", str(bad), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(bad) in err and where in err, err
    assert not (tmp_path / "run").exists()
    with pytest.raises(ScenarioError):
        load_experiment(bad)


def test_bad_lever_arm_samples_and_grade():
    data = tomllib.loads((SCENARIO_DIR / "seed000_lever_arm.toml").read_text())
    data["lever_arm"]["samples"] = 3
    with pytest.raises(ScenarioError, match="lever_arm.samples: must be even"):
        parse_experiment(data, "x.toml")
    data = tomllib.loads((SCENARIO_DIR / "seed000_alignment.toml").read_text())
    data["alignment"]["grades"] = ["tactical-9000"]
    with pytest.raises(ScenarioError, match=r"x.toml: alignment.grades\[0\]: no IMU preset"):
        parse_experiment(data, "x.toml")
