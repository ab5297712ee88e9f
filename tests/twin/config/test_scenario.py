"""Scenario files: every shipped one loads, the resolved form round-trips, bad input is one clear line."""

from __future__ import annotations

import math
import tomllib

import pytest

from tests.conftest import EXPERIMENTS, SCENARIO_DIR, SCENARIOS, SEED004_VARIANTS
from twin.config.experiments import MODELS
from twin.config.scenario import (
    Scenario,
    ScenarioError,
    load_face_scenario,
    load_scenario,
    parse_any,
    parse_scenario,
    scenario_to_toml,
)
from twin.config.turntable import Turntable


@pytest.mark.parametrize("name", SCENARIOS + list(SEED004_VARIANTS))
def test_shipped_scenarios_load_and_round_trip(name):
    scn = load_scenario(SCENARIO_DIR / f"{name}.toml")
    again = parse_scenario(tomllib.loads(scenario_to_toml(scn)))
    assert again == scn


def test_paper_scenarios_match_their_experiments():
    s1 = load_scenario(SCENARIO_DIR / "seed001.toml")
    assert s1.cycles == 4 and s1.face.web_depth_m == 1.2
    assert math.isclose(s1.face.pan_count * s1.face.pan_length_m - s1.shearer.length_m, 44.6)
    s4 = load_scenario(SCENARIO_DIR / "seed004.toml")
    assert (s4.face.pan_count, s4.face.pan_length_m, s4.face.web_depth_m, s4.cycles) == (200, 1.8, 1.0, 5)
    from twin.face.haulage import Timeline
    assert 6.2 < Timeline(s4).duration / 3600 < 6.6


def test_seed002_face_instruments_supports_at_the_face_ends_and_mid_face():
    """seed002_face (002 section 5 in the twin, issue 8): 002's ICM-42605 units on supports at both face ends and
    mid-face, the shearer's field on, no shearer estimator (twin.pipeline.support_estimate runs 002's filters and ours)."""
    from twin.pipeline.support_estimate import support_class

    scn = load_scenario(SCENARIO_DIR / "seed002_face.toml")
    units = scn.sensors.support_imu
    assert units.grade == "icm-42605" and units.shearer_disturbance_t > 0 and scn.estimators.shearer.methods == []
    assert {support_class(scn, j) for j in units.supports} == {"face_end", "mid_face"}


def test_seed004_variants_change_only_what_they_say():
    """seed004_fault adds 004's rail deviation (2825-3131 s, 1 deg per two chutes); seed004_20cycles runs 20
    cycles on a longer panel; both run INS/odometer and the rail-model filter. panel_100 runs 100 cycles on a panel
    of 110 m with KF + CPOEM + RTS and the rail-model filter (both streamed). Nothing else differs."""
    base4 = load_scenario(SCENARIO_DIR / "seed004.toml").model_dump()
    for name in SEED004_VARIANTS:
        scn = load_scenario(SCENARIO_DIR / f"{name}.toml")
        data = scn.model_dump()
        assert data["estimators"]["shearer"]["methods"] == (["kf_cpoem_rts", "fkf_rail"] if name == "panel_100"
                                                            else ["kf", "fkf_rail"])
        changed = {k for k in data if data[k] != base4[k]}
        if name == "panel_100":
            assert changed == {"name", "cycles", "face", "estimators"} and scn.cycles == 100
            assert {k for k in data["face"] if data["face"][k] != base4["face"][k]} == {"panel_length_m"}
            continue
        if name == "seed004_fault":
            assert changed == {"name", "faults", "estimators"}
            (fault,) = scn.faults
            assert (fault.kind, fault.t_start_s, fault.t_end_s, fault.value) == ("rail_deviation", 2825.0, 3131.0, 1.0)
        else:
            assert changed == {"name", "cycles", "face", "estimators"} and scn.cycles == 20
            assert {k for k in data["face"] if data["face"][k] != base4["face"][k]} == {"panel_length_m"}


def base() -> dict:
    return load_scenario(SCENARIO_DIR / "default.toml").model_dump()


def with_value(path: str, value) -> dict:
    data = base()
    *sections, key = path.split(".")
    node = data
    for sec in sections:
        node = node[sec]
    node[key] = value
    return data


@pytest.mark.parametrize("path, value, words", [
    ("face.pan_lenght_m", 1.75, ["face.pan_lenght_m", "unknown key"]),
    ("face.pan_length_m", "long", ["face.pan_length_m"]),
    ("face.pan_length_m", float("nan"), ["face.pan_length_m"]),
    ("face.web_depth_m", -0.8, ["face.web_depth_m"]),
    ("shearer.length_m", 0.0, ["shearer.length_m"]),
    ("face.bend_limit_horizontal_deg", 12.0, ["face.bend_limit_horizontal_deg"]),
    ("face.bend_limit_vertical_deg", 0.0, ["face.bend_limit_vertical_deg"]),
    ("cycles", 40, ["cycles", "panel_length_m"]),
    ("face.pan_count", 20, ["face.pan_count", "too short"]),
    ("face.initial_bend_horizontal_deg", [0.1, 0.2], ["initial_bend_horizontal_deg", "pan_count - 1"]),
    ("pattern.snake_length_pans", 4, ["snake_length_pans"]),
    ("face.undulation_amplitude_m", 1.5, ["face.undulation_amplitude_m", "bend_limit_vertical_deg"]),
])
def test_bad_values_name_the_key(path, value, words):
    with pytest.raises(ScenarioError) as err:
        parse_scenario(with_value(path, value), "bad.toml")
    message = str(err.value)
    assert "\n" not in message and message.startswith("bad.toml: ")
    for word in words:
        assert word in message


def test_a_suspension_the_ride_cannot_sample_is_refused():
    """A suspension ringing at or above the ride's Nyquist frequency is one line saying what to change; a faster
    ride takes it."""
    data = with_value("shearer.suspension_damping_ratio", 0.1)
    data["shearer"]["suspension_frequency_hz"] = 60.0
    with pytest.raises(ScenarioError) as err:
        parse_scenario(data, "bad.toml")
    message = str(err.value)
    assert "\n" not in message and message.startswith("bad.toml: shearer.suspension_frequency_hz: ")
    assert "rings at 59.7 Hz" in message and "raise rates.ride_hz above 119.4 Hz" in message
    data["rates"]["ride_hz"] = 120.0
    assert parse_scenario(data).rates.ride_hz == 120.0


def test_missing_and_broken_files(tmp_path):
    with pytest.raises(ScenarioError, match="not found"):
        load_scenario(tmp_path / "nope.toml")
    broken = tmp_path / "broken.toml"
    broken.write_text("name = \n")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load_scenario(broken)


def test_load_scenario_dispatches_on_the_kind():
    """One loader for every kind: face scenarios (no `kind`), 000's experiments, 002's turntable; each resolved
    file reads back as the same object."""
    files = {name: Scenario for name in SCENARIOS} | {name: MODELS[name.removeprefix("seed000_")]
                                                       for name in EXPERIMENTS} | {"seed002_turntable": Turntable}
    for name, model in files.items():
        scn = load_scenario(SCENARIO_DIR / f"{name}.toml")
        assert type(scn) is model, name
        assert parse_any(tomllib.loads(scenario_to_toml(scn))) == scn
        assert load_scenario(SCENARIO_DIR / f"{name}.toml", seed=5).seed == 5


def test_unknown_kind_and_face_only_loading_are_one_line(tmp_path):
    odd = tmp_path / "odd.toml"
    odd.write_text('kind = "conveyor"\nname = "x"\n')
    with pytest.raises(ScenarioError, match=r"odd.toml: kind: must be one of sins_experiment, support_turntable"):
        load_scenario(odd)
    assert load_face_scenario(SCENARIO_DIR / "default.toml", seed=3).seed == 3
    for name in ("seed000_coning", "seed002_turntable"):
        with pytest.raises(ScenarioError, match=f"{name}.toml: kind: a face scenario is needed here") as err:
            load_face_scenario(SCENARIO_DIR / f"{name}.toml")
        assert "\n" not in str(err.value)
