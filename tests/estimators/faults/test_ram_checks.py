"""Per-support push-ram checks (estimators.faults.ram_checks) on twin runs: every sensor fault the twin injects is found
in its window, on its support, and a healthy face gives no finding.

The physics is the default scenario capped at two cycles (conftest, simulated once per session); the sensors are
redrawn per case from it with the fault added to the schedule (ram faults do not change the physics). Support 20
of the default face pushes from 315 s to 492 s of cycle 1 (its ram ramping at the push speed in each snake step), is
lowered at 497 s and pulled up from 498 s to 502 s (one reading a second).
Delays are the confirmation time (Finding.t_detect) after the fault starts:

* dropout      0 s (the invalid readings themselves)
* noise_burst  BURST_WINDOW // 2 = 15 s (half the centred scatter window) to 3 BURST_WINDOW // 4 = 23 s (the
               median-of-three confirmation, which tells a noise burst from a staircase of ramping pushes)
* stuck        flat run - 1 = 29 s for the default sensor (noise = resolution = 0.1 mm); a sensor without noise
               is found by its neighbours once they push and it does not follow (here 96 s: 48 s after the
               neighbours' push begins)
* offset       NEIGHBOUR_WINDOW // 2 = 7 s (half the running median of the neighbour residual)
* drift        tau / rate + 7 s (tau = 28 mm inside the face: 63 s at 0.5 mm/s)
* scale        7 s: the error (0.1 x 1.2 m at rest) shows against the neighbours at once; the commanded
               stroke check confirms it at the advance
* rail_deviation  the run is named once three supports have been inconsistent in turn (36 s after the
               window opens at 0.5 deg per two chutes)
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pyarrow as pa
import pytest

from estimators.faults import ram_checks as rc
from estimators.faults.ram_grid import _grid
from estimators.faults.ram_levels import CHANGE_SIGMAS
from estimators.faults.ram_neighbours import NEIGHBOUR_WINDOW
from estimators.faults.ram_self_checks import BURST_WINDOW, _flat_run, _self_checks
from estimators.faults.ram_strokes import _advances, _stroke_checks, _stroke_threshold
from estimators.io.logformat import PUSHRAM, make_table
from tests.conftest import simulated
from twin.config.scenario import parse_scenario
from twin.pipeline.estimate import ram_layout
from twin.sensors.streams import imu_truth, sensor_streams

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

SUPPORT = 20


@cache
def _ideal(name: str):
    scn, result = simulated(name)
    return imu_truth(scn, result.tables["truth_shearer"])


def pushram(name: str = "default", faults=(), trial: int = 0, sensor: dict | None = None):
    """(scenario, PUSHRAM stream) of a trial of the simulated run with `faults` scheduled and the push-ram
    sensor section changed by `sensor`."""
    scn, result = simulated(name)
    data = scn.model_dump()
    data["faults"] = list(faults)
    if sensor:
        data["sensors"]["pushram"].update(sensor)
    scn = parse_scenario(data, scn.name)
    return scn, sensor_streams(scn, result.tables, _ideal(name), trial)["pushram"]


def findings(name: str = "default", faults=(), trial: int = 0, sensor: dict | None = None):
    scn, ram = pushram(name, faults, trial, sensor)
    return scn, rc.check_log(ram, ram_layout(scn))


def fault(kind, t0, t1, value=0.0, target=SUPPORT):
    return {"kind": kind, "t_start_s": t0, "t_end_s": t1, "value": value, "target": target}


def only(found, kind, support=SUPPORT) -> rc.Finding:
    """The single finding, of `kind`, on `support` (the message lists them all otherwise)."""
    assert len(found) == 1 and found[0].kind == kind and found[0].support == found[0].last_support == support, \
        rc.format_findings(found)
    return found[0]


# ------------------------------------------------------------------------------------------ no false alarms


@pytest.mark.parametrize("name, trial, sensor", [
    ("default", 0, None), ("default", 1, None), ("default", 2, None),
    ("default", 0, {"noise_m": 0.02}), ("default", 1, {"noise_m": 0.02}), ("default", 2, {"noise_m": 0.02}),
    ("default", 0, {"noise_m": 0.0}),
    ("default-before-push", 0, None), ("default-before-push", 1, {"noise_m": 0.02}),
])
def test_no_findings_on_a_healthy_face(name, trial, sensor):
    """Redrawn sensor noise (0.1 mm as the default sensor, 20 mm as 004's, none), both advance sequences."""
    _, found = findings(name, trial=trial, sensor=sensor)
    assert found == [], rc.format_findings(found)


# ------------------------------------------------------------------------------------ each fault, named


def test_dropout_is_its_invalid_readings():
    f = only(findings(faults=[fault("ram_dropout", 300.0, 400.0)])[1], "dropout")
    assert (f.t_start, f.t_end, f.t_detect) == (300.0, 399.0, 300.0)
    assert f.value == 100.0


def test_noise_burst_within_half_a_window():
    f = only(findings(faults=[fault("ram_noise_burst", 600.0, 700.0, 0.01)])[1], "noise_burst")
    assert abs(f.t_start - 600.0) <= 3 and abs(f.t_end - 699.0) <= 3
    assert BURST_WINDOW // 2 <= f.t_detect - 600.0 <= 3 * BURST_WINDOW // 4 + 3
    assert f.value == pytest.approx(0.01, rel=0.3)


def test_stuck_ram_is_flat_through_its_push():
    """Frozen at rest before its push, through the push and the advance: the flat run names it after 30
    readings (noise = resolution: a reading stays in its quantum with p = 0.38). The run ends at the fault's last
    reading, or later by exactly the healthy readings after it that happen to fall in the frozen quantum."""
    faults = [fault("ram_stuck", 250.0, 700.0)]
    scn, ram = pushram(faults=faults)
    found = rc.check_log(ram, ram_layout(scn))
    run = _flat_run(ram_layout(scn))
    assert run == 30
    f = only(found, "stuck")
    mine = ram["support"] == SUPPORT
    t, reading = ram["t"][mine], ram["extension"][mine]
    after = reading[t >= 700.0]
    coincident = int(np.argmax(after != reading[t == 250.0][0]))
    assert (f.t_start, f.t_end) == (250.0, 699.0 + coincident)
    assert f.t_detect - 250.0 == run - 1


def test_stuck_fine_sensor_stops_following_its_neighbours():
    """A sensor without noise reads constant at rest anyway: the neighbour check names it once the neighbours
    push and it does not follow."""
    scn, found = findings(faults=[fault("ram_stuck", 250.0, 700.0)], sensor={"noise_m": 0.0})
    assert _flat_run(ram_layout(scn)) is None
    f = only(found, "stuck")
    assert 250.0 <= f.t_detect <= 360.0
    assert f.t_start <= 250.0 and f.t_end >= 699.0  # the whole frozen stretch


def test_offset_mid_push():
    f = only(findings(faults=[fault("ram_offset", 300.0, 700.0, 0.05)])[1], "offset")
    assert abs(f.t_start - 300.0) <= 2 and abs(f.t_end - 699.0) <= 2
    assert f.t_detect - 300.0 <= NEIGHBOUR_WINDOW // 2 + 1
    assert f.value == pytest.approx(0.05, abs=0.005)


def test_drift_found_when_it_passes_the_threshold():
    _, found = findings(faults=[fault("ram_drift", 600.0, 1100.0, 5e-4)])
    f = only(found, "drift")
    tau = f.threshold
    assert tau < 0.03
    assert f.t_detect - 600.0 <= tau / 5e-4 + NEIGHBOUR_WINDOW
    assert abs(f.t_start - 600.0) <= 10 and abs(f.t_end - 1099.0) <= 2  # the start from the fitted line
    assert f.value == pytest.approx(5e-4, rel=0.1)


def test_scale_over_a_push_and_advance():
    f = only(findings(faults=[fault("ram_scale", 250.0, 700.0, 0.1)])[1], "scale")
    assert abs(f.t_start - 250.0) <= 2 and abs(f.t_end - 699.0) <= 2
    assert f.t_detect - 250.0 <= NEIGHBOUR_WINDOW // 2 + 1
    assert f.value == pytest.approx(0.1, abs=0.01)


def test_commanded_stroke_check_alone_sees_a_scale_error():
    """Check (a) on its own: the stroke of the push and the retraction of the advance are 10 % long."""
    scn, ram = pushram(faults=[fault("ram_scale", 250.0, 700.0, 0.1)])
    layout = ram_layout(scn)
    tg, x = _grid(ram["t"], ram["support"], ram["extension"], ram["valid"], layout.n_supports)
    usable = ~_self_checks(tg, x, layout)[1]
    idxs, candidates, _ = _advances(x, usable, layout)
    strokes = _stroke_checks(x, idxs, candidates, layout)
    assert {s.support for s in strokes} == {SUPPORT}
    # The advance: the ram retracts a web at the pull speed (0.8 m at 0.29 m/s and the valve's ramps), a ramp of a
    # few readings from 498 s to 503 s, confirmed at its last reading.
    drop = [s for s in strokes if 3 <= s.last - s.first <= 8]
    assert len(drop) == 1 and drop[0].relative == pytest.approx(0.1, abs=0.01)
    assert (tg[drop[0].first], tg[drop[0].last], tg[drop[0].confirmed]) == (498.0, 503.0, 503.0)


def test_rail_deviation_names_the_run_of_supports():
    """004's deviated rail over the stretch the shearer cuts from 150 s to 300 s, 0.5 deg per two chutes: the
    deviated supports are those whose readings the fault changes."""
    faults = [{"kind": "rail_deviation", "t_start_s": 150.0, "t_end_s": 300.0, "value": 0.5}]
    scn, ram = pushram(faults=faults)
    _, clean = pushram()
    changed = np.unique(ram["support"][np.abs(ram["extension"] - clean["extension"]) > 1e-9])
    assert changed.size >= 10 and np.all(np.diff(changed) == 1)
    found = rc.check_log(ram, ram_layout(scn))
    assert len(found) == 1 and found[0].kind == "rail_deviation", rc.format_findings(found)
    f = found[0]
    assert changed[0] <= f.support and f.last_support <= changed[-1]
    assert f.last_support - f.support + 1 >= changed.size - 3  # the run's last support is seen as the window ends
    assert 150.0 <= f.t_start and f.t_end <= 300.0
    assert f.t_detect - 150.0 <= 40.0


@pytest.mark.parametrize("target", [0, 1, 42, 43])
def test_offset_at_the_face_ends(target):
    """The end supports are predicted by extrapolation (looser thresholds, and the last two supports' fault
    patterns nearly alike): a 0.15 m offset is still named on its own support."""
    _, found = findings(faults=[fault("ram_offset", 300.0, 700.0, 0.15, target)])
    f = only(found, "offset", target)
    assert f.value == pytest.approx(0.15, abs=0.01)


# ------------------------------------------------------------------------------------- thresholds, input


def test_thresholds_follow_the_ram_noise():
    quiet = rc.RamLayout(44, 1.75, 0.8, 1e-4, 1e-4, bend_limit_deg=1.0)
    noisy = rc.RamLayout(44, 1.75, 0.8, 0.02, 1e-4, bend_limit_deg=1.0)
    assert quiet.sigma_m == pytest.approx(math.sqrt(1e-8 + 1e-8 / 12))
    assert _flat_run(quiet) == 30 and _flat_run(noisy) == 6
    assert _flat_run(rc.RamLayout(44, 1.75, 0.8, 0.0, 1e-4)) is None
    assert quiet.bend_m == pytest.approx(1.75 * math.tan(math.radians(1.0)))
    # stroke check: 3 % of the stroke + the step a change test can miss + 5 sigma of two plateau medians
    tau = _stroke_threshold(noisy, np.array([15]), np.array([15]))[0]
    hidden = CHANGE_SIGMAS * 0.02 * math.sqrt(1 + 1 / 14)
    assert tau == pytest.approx(0.024 + hidden + 5 * noisy.sigma_m * 1.2533 * math.sqrt(2 / 15))


def test_formatter_one_line_each():
    f = rc.Finding(3, 3, "offset", 300.0, 699.0, 307.0, 0.05, 0.052, 0.028, "m")
    g = rc.Finding(14, 24, "rail_deviation", 152.0, 296.0, 186.0, 0.41, 0.41, 0.028, "m")
    text = rc.format_findings([f, g])
    assert text.count("\n") == 1
    assert text.splitlines()[0].startswith("support 3 ") and "offset" in text and "+0.05 m" in text
    assert text.splitlines()[1].startswith("supports 14-24")
    assert rc.format_findings([]) == "no push-ram faults found"


def test_a_pyarrow_table_works_too():
    scn, ram = pushram(faults=[fault("ram_dropout", 300.0, 400.0)])
    table = make_table(PUSHRAM, ram)
    assert isinstance(table, pa.Table)
    assert [f.kind for f in rc.check_log(table, ram_layout(scn))] == ["dropout"]


def test_bad_input_is_one_clear_line():
    layout = rc.RamLayout(44, 1.75, 0.8, 1e-4)
    empty = {c: np.zeros(0) for c in ("t", "support", "extension", "valid")}
    with pytest.raises(ValueError, match=r"^pushram: the log has no rows; pass the PUSHRAM stream"):
        rc.check_log(empty, layout)
    log = {"t": np.array([0.0, 0.0, 1.0]), "support": np.array([0, 57, 0]), "extension": np.ones(3),
           "valid": np.ones(3)}
    with pytest.raises(ValueError, match=r"^pushram: support id 57 is not one of the layout's supports 0\.\.43"):
        rc.check_log(log, layout)
    with pytest.raises(ValueError, match=r"^pushram: the table needs the columns t, support, extension, valid"):
        rc.check_log({"t": np.zeros(3)}, layout)
    with pytest.raises(ValueError, match=r"^RamLayout.stroke_m = -0.8: must be positive"):
        rc.RamLayout(44, 1.75, -0.8, 1e-4)
    with pytest.raises(ValueError, match=r"^RamLayout.n_supports = 3: must be an integer >= 5"):
        rc.RamLayout(3, 1.75, 0.8, 1e-4)
    dup = {"t": np.array([0.0, 0.0, 1.0]), "support": np.array([2, 2, 2]), "extension": np.ones(3),
           "valid": np.ones(3)}
    with pytest.raises(ValueError, match=r"^pushram: support 2 has two rows at t = 0 s"):
        rc.check_log(dup, layout)


def test_the_median_of_three_scatter_constant():
    """MED3_MAD: median |x[k] - median(x[k-1], x[k], x[k+1])| of unit white Gaussian noise; a third of the residuals
    are exactly zero (the middle reading is the median), and a monotone ramp leaves none."""
    from estimators.faults.ram_self_checks import MED3_MAD

    x = np.random.default_rng(5).standard_normal(2_000_000)
    r = x[1:-1] - np.median(np.stack([x[:-2], x[1:-1], x[2:]]), axis=0)
    assert np.median(np.abs(r)) == pytest.approx(MED3_MAD, rel=1e-2)
    assert np.mean(r == 0) == pytest.approx(1 / 3, abs=2e-3)
    ramp = np.cumsum(np.random.default_rng(6).uniform(0.0, 0.1, 100))
    assert np.all(ramp[1:-1] == np.median(np.stack([ramp[:-2], ramp[1:-1], ramp[2:]]), axis=0))
