"""Values inside their types but absurd are refused in one line naming the key: physical ranges, real dates
within the geomagnetic model, faults on units that exist, combinations that cannot be."""

from __future__ import annotations

import tomllib

import pytest

from tests.conftest import SCENARIO_DIR
from twin.config.scenario import ScenarioError, load_scenario, parse_any
from twin.config.section import WMM_YEARS


def shipped(name: str) -> dict:
    return tomllib.loads((SCENARIO_DIR / f"{name}.toml").read_text())


def changed(name: str, path: str, value) -> dict:
    """A shipped file's data with the key at `path` (dots; a number indexes a list) set to `value`."""
    data = shipped(name)
    *parents, key = path.split(".")
    node = data
    for p in parents:
        node = node[int(p)] if p.isdigit() else node.setdefault(p, {})
    node[int(key) if key.isdigit() else key] = value
    return data


def refused(data: dict, *words: str) -> str:
    with pytest.raises(ScenarioError) as err:
        parse_any(data, "bad.toml")
    message = str(err.value)
    assert "\n" not in message and message.startswith("bad.toml: "), message
    for word in words:
        assert word in message, message
    return message


@pytest.mark.parametrize("name, path, value", [
    ("default", "sensors.pushram.noise_m", 1e12),  # was a singular matrix in the support filters
    ("default", "sensors.survey.sd_horizontal_m", 1e12),  # was a failure mid-run
    ("default", "sensors.survey.sd_yaw_deg", 1e12),
    ("default", "sensors.mag.noise_t", 1e12),
    ("default", "sensors.mag.hard_iron_t", [1.0, 0.0, 0.0]),
    ("default", "sensors.imu.lever_arm_m", [1e6, 0.0, 0.0]),
    ("default", "sensors.imu.misalignment_deg", [45.0, 0.0, 0.0]),
    ("default", "sensors.odometer.metres_per_pulse", 1e9),
    ("default", "haulage.reversal_stop_s", 1e12),
    ("default", "face.panel_length_m", 1e9),  # was a TiB floor
    ("default", "face.initial_straightness_deg", 1e6),
    ("seed004", "haulage.stops.0.duration_s", 1e12),  # was a TiB of truth
    ("seed003_interference", "faults.0.value", 1.0),  # a field of 1 T
    ("seed000_alignment", "alignment.duration_s", 1e12),
    ("seed000_alignment", "alignment.velocity_sigma_m_s", 1e12),
    ("seed000_coning", "coning.step_s", 1e6),
    ("seed002_turntable", "unit.mag_noise_t", 1e12),
    ("seed002_turntable", "motion.duration_s", 1e12),
])
def test_absurd_values_are_refused_naming_the_key(name, path, value):
    key = ".".join(p for p in path.split(".") if not p.isdigit())
    refused(changed(name, path, value), path.split(".")[-1], key.split(".")[0])


@pytest.mark.parametrize("date, words", [
    ("2026-13-45", "not a calendar date"), ("2026-02-30", "not a calendar date"),
    (f"{WMM_YEARS[0] - 1}-12-31", "outside the geomagnetic model's years"),
    (f"{WMM_YEARS[1] + 1}-01-01", "outside the geomagnetic model's years"),
])
def test_dates_are_real_dates_within_the_geomagnetic_model(date, words):
    refused(changed("default", "sensors.mag.date", date), "sensors.mag.date", words)
    refused(changed("seed002_turntable", "site.mag_date", date), "site.mag_date", words)


def test_the_model_years_are_pygeomags():
    """Both ends of WMM_YEARS evaluate; a day outside does not (estimators.nav.geomagnetic raises)."""
    from estimators.nav.geomagnetic import geomagnetic_reference

    for day in (f"{WMM_YEARS[0]}-01-01", f"{WMM_YEARS[1]}-12-31"):
        assert geomagnetic_reference(0.6, 2.0, 0.0, day).intensity > 2e-5
    for day in (f"{WMM_YEARS[0] - 1}-12-31", f"{WMM_YEARS[1] + 1}-01-01"):
        with pytest.raises(ValueError):
            geomagnetic_reference(0.6, 2.0, 0.0, day)


def fault(**kw) -> dict:
    return {"kind": "ram_offset", "t_start_s": 10.0, "t_end_s": 30.0, "target": 3, "value": 0.1} | kw


@pytest.mark.parametrize("faults, words", [
    ([fault(kind="mag_interference", target=999, value=1e-5)], ["faults[0]", "999", "no canopy unit"]),
    ([fault(target=44)], ["faults[0]", "target support 0..43"]),
    ([fault(target=None)], ["faults[0]", "needs a target"]),
    ([fault(kind="rail_deviation", target=3, value=1.0)], ["faults[0]", "takes no target"]),
    ([fault(kind="push_shortfall", value=1.2)], ["faults[0]", "web_depth_m"]),
    ([fault(kind="odometer_slip", target=None, value=2.0)], ["faults.0", "odometer_slip"]),
    ([fault(value=1e12)], ["faults.0", "value"]),
    ([fault(t_end_s=5.0)], ["faults.0", "t_end_s"]),
])
def test_faults_only_on_units_that_exist_with_sensible_values(faults, words):
    refused(changed("default", "faults", faults), *words)


def test_a_fault_on_a_support_with_a_canopy_unit_loads():
    data = changed("default", "sensors.support_imu.supports", [3])
    data["faults"] = [fault(kind="mag_interference", target=3, value=1e-5), fault(target=43)]
    assert len(parse_any(data, "ok.toml").faults) == 2


@pytest.mark.parametrize("name, path, value, words", [
    ("default", "sensors.vibration.rock_zones_m", [[10.0, 900.0]], ["rock_zones_m", "within the"]),
    ("default", "sensors.vibration.rock_zones_m", [[10.0, 5.0]], ["rock_zones_m"]),
    ("default", "sensors.mag.soft_iron", [[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 1.0]], ["singular"]),
    ("default", "estimators.shearer.mag_soft_iron_correction", [[0.0] * 3] * 3, ["singular"]),
    ("seed000_alignment", "alignment.update_hz", 400.0, ["alignment.update_hz", "rate_hz"]),
    ("seed002_turntable", "disturbance.pass_times_s", [150.0, 900.0], ["pass_times_s", "motion.duration_s"]),
])
def test_absurd_combinations_are_refused(name, path, value, words):
    refused(changed(name, path, value), *words)


def test_every_shipped_file_still_loads():
    for path in sorted(SCENARIO_DIR.glob("*.toml")):
        load_scenario(path)
