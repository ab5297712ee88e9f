"""The resource estimate (twin.config.resources): close to what a run takes, and a one-line refusal over its
limits before anything is written."""

from __future__ import annotations

import pytest

from tests.conftest import SCENARIO_DIR
from tests.twin.config.test_ranges import changed
from twin.config.resources import (
    MAX_MEMORY_BYTES,
    check_resources,
    estimate_resources,
    face_resources,
    simulated_s,
)
from twin.config.scenario import ScenarioError, load_scenario, parse_any


@pytest.mark.parametrize("name", ["default", "seed001", "seed004"])
def test_simulated_span_is_the_timelines(name):
    from twin.face.haulage import Timeline

    scn = load_scenario(SCENARIO_DIR / f"{name}.toml")
    assert simulated_s(scn) == pytest.approx(Timeline(scn).duration, rel=0.005)


def test_the_default_runs_figures():
    """default.toml as measured: 452 450 IMU samples, 0.70 GB peak (the process tree's PSS, benchmarks/bench_scale.py),
    165 MB written; 10 trials write more."""
    res = face_resources(load_scenario(SCENARIO_DIR / "default.toml"))
    assert res.rows["imu"] == pytest.approx(452_450, rel=0.01)
    assert res.memory_bytes == pytest.approx(0.70e9, rel=0.5) and res.disk_bytes == pytest.approx(1.65e8, rel=0.1)
    assert res.wall_s < 120
    more = face_resources(load_scenario(SCENARIO_DIR / "default.toml"), trials=10)
    assert more.disk_bytes > 5 * res.disk_bytes and more.wall_s > res.wall_s


def test_every_shipped_file_fits():
    for path in sorted(SCENARIO_DIR.glob("*.toml")):
        check_resources(str(path), estimate_resources(load_scenario(path)))


def every_key_at_its_maximum() -> dict:
    data = changed("default", "cycles", 4000)  # the panel's maximum: 6000 m of 1.5 m webs
    data["face"] |= {"pan_count": 400, "pan_length_m": 2.05, "web_depth_m": 1.5, "panel_length_m": 6000.0,
                     "bend_limit_horizontal_deg": 10.0}
    data["pattern"] = {"snake_length_pans": 40}
    data["rates"] = {"truth_hz": 2000.0, "ride_hz": 2000.0, "face_timestep_s": 0.001}
    data["haulage"] = {"cutting_speed_m_min": 1.0, "return_speed_m_min": 1.0, "sump_speed_m_min": 1.0,
                       "end_push_stop_s": 3600.0, "reversal_stop_s": 3600.0}
    data["sensors"] = {k: {"rate_hz": 2000.0} for k in ("imu", "mag", "odometer", "pushram")}
    return data


@pytest.mark.parametrize("data, figure", [
    (every_key_at_its_maximum(), "peak memory"),
    (changed("default", "haulage.stops", [{"cycle": 0, "at_m": 1.0, "duration_s": 86400.0}] * 3), "peak memory"),
    (changed("seed000_alignment", "alignment.duration_s", 86400.0), "peak memory"),
    (changed("seed000_coning", "coning.step_s", 1e-6), "peak memory"),
    (changed("seed002_turntable", "motion.duration_s", 86400.0) | {"unit": changed(
        "seed002_turntable", "unit.rate_hz", 200.0)["unit"]}, "wall time"),
])
def test_over_a_limit_is_one_line_naming_the_figure_the_limit_and_the_keys(data, figure):
    with pytest.raises(ScenarioError) as err:
        check_resources("big.toml", estimate_resources(parse_any(data, "big.toml")))
    message = str(err.value)
    assert "\n" not in message and message.startswith("big.toml: the run would need about ")
    # memory is checked first: on a machine with less RAM than this one's 23 GB it may be the figure named
    assert figure in message or "peak memory" in message, message
    assert "over the limit of" in message and "reduce " in message, message


def test_cycles_are_bounded_by_the_panel_and_the_resource_estimate_not_a_cap():
    """More cycles than the old cap of 200 load when the panel holds them, and the resource estimate decides whether
    the run fits this machine: 003's magnetometer filters (afkf, ckf_mag) hold the whole log, so 1000 cycles of
    seed003's face do not; 50 do, and so do panel_100's streamed methods over 200 cycles of its face."""
    data = changed("seed003", "cycles", 1000)
    data["face"]["panel_length_m"] = 1200.0
    scn = parse_any(data, "long.toml")
    assert scn.cycles == 1000
    with pytest.raises(ScenarioError, match="peak memory"):
        check_resources("long.toml", estimate_resources(scn))
    check_resources("fewer.toml", estimate_resources(parse_any(data | {"cycles": 50}, "fewer.toml")))
    panel = changed("panel_100", "cycles", 200)
    panel["face"]["panel_length_m"] = 210.0
    check_resources("panel.toml", estimate_resources(parse_any(panel, "panel.toml")))


def test_memory_limit_is_the_machines():
    import os

    assert 0 < MAX_MEMORY_BYTES <= os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def test_a_run_over_a_limit_writes_nothing(tmp_path):
    """twin.run refuses before the run directory exists (the estimate is checked first)."""
    import twin

    scn = parse_any(every_key_at_its_maximum(), "big")
    with pytest.raises(ScenarioError, match="peak memory"):
        twin.run(scn, out=tmp_path / "out")
    assert not (tmp_path / "out").exists()
