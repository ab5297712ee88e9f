"""Odometer, push-ram and fault-schedule models on small synthetic truth (no MuJoCo run)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimators.io.logformat import FAULTS, ODOMETER, PUSHRAM, check_table, make_table
from estimators.nav.rotations import euler_to_quat, quat_rotate
from tests.conftest import simulated
from tests.twin.sensors.test_survey_chunks import joined, random_starts, same
from twin.config.scenario import ScenarioError, parse_scenario
from twin.config.sensors import Fault
from twin.face.layout import support_stations
from twin.sensors.chunks import halo_rows, split_truth
from twin.sensors.faults import check_faults_in_run, faults_table, window_mask
from twin.sensors.odometer import Odometer, odometer_stream
from twin.sensors.pushram import pushram_stream, rail_deviation_m

MPP = 0.002


def scenario(odometer=None, pushram=None, faults=()):
    sensors = {"odometer": {"metres_per_pulse": MPP, "scale_error": 0.0, "mounting_deg": [0.0, 0.0, 0.0],
                            **(odometer or {})},
               "pushram": pushram or {}}
    return parse_scenario({"name": "t", "sensors": sensors, "faults": list(faults)})


def shearer_truth(speed, duration=300.0, rate=200.0, pitch=0.0, roll=0.0, yaw=0.0, s0=10.0):
    """A shearer moving along its own body y at speed(t) [m/s] with a fixed attitude."""
    t = np.arange(0, int(duration * rate) + 1) / rate
    v = np.broadcast_to(np.asarray(speed(t), dtype=float), t.shape)
    q = np.broadcast_to(euler_to_quat(pitch, roll, yaw), (t.size, 4))
    v_n = quat_rotate(q, np.stack([np.zeros_like(v), v, np.zeros_like(v)], axis=-1))
    s = s0 + np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))))
    truth = {"t": t, "s": s, **{f"v_n_{c}": v_n[:, i] for i, c in enumerate("enu")},
             **{f"q_nb_{c}": q[:, i].copy() for i, c in enumerate("wxyz")}}
    return truth, s - s0


def odo(scn, truth, seed=1):
    return odometer_stream(scn, truth, np.random.default_rng(seed), list(scn.faults))


# ----------------------------------------------------------------------------------------------- odometer


def test_odometer_scale_error_and_schema():
    se = 0.003
    scn = scenario({"scale_error": se})
    truth, travel = shearer_truth(lambda t: 0.15 + 0 * t, yaw=0.7, pitch=0.05)
    out = odo(scn, truth)
    check_table(ODOMETER, make_table(ODOMETER, out), "odometer")
    assert np.allclose(np.diff(out["t"]), 1 / scn.sensors.odometer.rate_hz)
    assert out["t"][0] == 0.0 and out["t"][-1] == 300.0
    d = out["distance"][-1]
    # true metres per nominal metre read = 1 + scale_error, to within one pulse over the distance
    assert abs(travel[-1] / d - (1 + se)) <= 1.01 * (1 + se) * MPP / d
    assert np.all(out["direction"] == 1)


def test_odometer_quantization_and_reproducibility():
    scn = scenario({"scale_error": -0.01})
    truth, _ = shearer_truth(lambda t: 0.05 + 0.1 * np.sin(t / 20) ** 2)
    out = odo(scn, truth, seed=3)
    k = out["distance"] / MPP
    assert np.allclose(k, np.round(k), atol=1e-9)
    assert np.array_equal(out["distance"], out["pulses"] * MPP)
    assert out["pulses"][0] == 0 and np.all(np.diff(out["pulses"]) >= 0)
    again = odo(scn, truth, seed=3)
    assert all(np.array_equal(out[c], again[c]) for c in out)


def test_odometer_direction_on_reversal():
    scn = scenario()

    def speed(t):
        return np.where(t < 100, 0.1, np.where(t < 110, 0.0, -0.1))

    truth, _ = shearer_truth(speed, duration=210.0)
    out = odo(scn, truth)
    t, p, d = out["t"], out["pulses"], out["direction"]
    assert np.all(d[(t > 1) & (t < 99)] == 1)
    assert np.all(d[(t > 101) & (t < 109)] == 0)
    assert np.all(d[(t > 111) & (t < 209)] == -1)
    assert np.all(np.diff(p[t <= 100]) >= 0) and np.all(np.diff(p[(t >= 100) & (t <= 110)]) == 0)
    assert np.all(np.diff(p[t >= 110]) <= 0)
    assert p[np.searchsorted(t, 100)] == pytest.approx(10.0 / MPP, abs=1)
    assert abs(out["distance"][-1]) <= MPP  # back where it started: within a pulse


@pytest.mark.parametrize("mounting, factor", [
    ([2.0, 0.0, 0.0], math.cos(math.radians(2.0))),
    ([0.0, 0.0, -3.0], math.cos(math.radians(3.0))),
    ([1.5, 0.0, 2.5], math.cos(math.radians(1.5)) * math.cos(math.radians(2.5))),
    ([0.0, 5.0, 0.0], 1.0),  # a rotation about the odometer's own forward axis changes nothing
])
def test_odometer_mounting_angle(mounting, factor):
    scn = scenario({"mounting_deg": mounting})
    truth, travel = shearer_truth(lambda t: 0.2 + 0 * t, duration=500.0, yaw=-1.2, pitch=0.08, roll=-0.03)
    out = odo(scn, truth)
    assert out["distance"][-1] == pytest.approx(travel[-1] * factor, abs=1.01 * MPP)
    if factor < 1:
        assert travel[-1] - out["distance"][-1] > 20 * MPP  # the reduction is well above quantization


def test_odometer_slip_only_inside_window():
    slip = {"kind": "odometer_slip", "t_start_s": 100.0, "t_end_s": 200.0, "value": 0.25}
    truth, _ = shearer_truth(lambda t: 0.12 + 0 * t)
    clean = odo(scenario(), truth)
    slipped = odo(scenario(faults=[slip]), truth)
    t = clean["t"]
    diff = clean["pulses"] - slipped["pulses"]
    assert np.all(diff[t <= 100.0] == 0)
    inside = (t >= 100.0) & (t < 200.0)
    rate = np.diff(slipped["pulses"][inside]).sum() / np.diff(clean["pulses"][inside]).sum()
    assert rate == pytest.approx(0.75, abs=2 / np.diff(clean["pulses"][inside]).sum())
    lost = 0.25 * 0.12 * 100.0 / MPP  # pulses missed in the window, not recovered afterwards
    assert set(np.unique(diff[t >= 200.0])) <= {math.floor(lost), math.ceil(lost)}
    assert np.array_equal(clean["direction"], slipped["direction"])


@pytest.mark.parametrize("rate", [50.0, 30.0])
@pytest.mark.parametrize("seed", range(3))
def test_odometer_over_random_partitions_is_the_whole_run(rate, seed):
    """The default run (both directions of travel) with two overlapping slip windows; at 30 Hz the readings fall
    between truth rows (interpolated from the halo)."""
    base, result = simulated("default")
    data = base.model_dump()
    data["sensors"]["odometer"]["rate_hz"] = rate
    scn = parse_scenario(data, "default")
    truth = result.tables["truth_shearer"]
    halo = halo_rows(scn)
    slips = [Fault(kind="odometer_slip", t_start_s=300.0013, t_end_s=700.0, value=0.3),
             Fault(kind="odometer_slip", t_start_s=650.0, t_end_s=1400.007, value=0.5)]
    whole = odometer_stream(scn, truth, np.random.default_rng(1), slips)
    edges = np.searchsorted(truth["t"], [t for f in slips for t in (f.t_start_s, f.t_end_s)])
    chunks = list(split_truth(truth, random_starts(np.random.default_rng(seed), truth["t"].size, halo, edges), halo))
    odometer = Odometer(scn, np.random.default_rng(1), slips)
    assert same(joined([odometer.step(c) for c in chunks]), whole)
    # The comparison catches a stepper that does not carry its travel on (an Odometer per chunk).
    assert not same(joined([Odometer(scn, np.random.default_rng(1), slips).step(c) for c in chunks]), whole)


# ----------------------------------------------------------------------------------------------- push rams


def supports_truth(n_sup, duration, seed=0):
    """Initial rows for every support at t = 0, then random ram changes (some rows share a time)."""
    rng = np.random.default_rng(seed)
    t = np.concatenate([np.zeros(n_sup), np.sort(rng.uniform(0, duration, 400))])
    t[n_sup + 10] = t[n_sup + 11]  # two rows at one time
    sup = np.concatenate([np.arange(n_sup), rng.integers(0, n_sup, 400)])
    sup[n_sup + 10] = sup[n_sup + 11]
    ram = 1.2 + rng.uniform(0.0, 0.8, t.size)
    return {"t": t, "support": sup.astype(np.int32), "ram": ram}


def reference_true_ram(supports, t_grid, n_sup):
    """Brute force: the last row (in stream order) of each support with t_row <= t."""
    out = np.empty((t_grid.size, n_sup))
    for j in range(n_sup):
        rows = np.flatnonzero(supports["support"] == j)
        for k, tk in enumerate(t_grid):
            before = rows[supports["t"][rows] <= tk]
            out[k, j] = supports["ram"][before[-1]]
    return out


def ram(scn, supports, t_end=1000.0, seed=5, shearer=None, faults=None):
    return pushram_stream(scn, supports, t_end, np.random.default_rng(seed),
                          list(scn.faults if faults is None else faults), shearer=shearer)


def as_grid(out, n_sup, col="extension"):
    return out[col].reshape(-1, n_sup)


def test_pushram_truth_noise_and_resolution():
    scn = scenario(pushram={"noise_m": 0.02, "resolution_m": 0.001, "rate_hz": 1.0})
    n_sup = support_stations(scn).size
    sup = supports_truth(n_sup, 2000.0)
    out = ram(scn, sup, t_end=2000.0)
    check_table(PUSHRAM, make_table(PUSHRAM, out), "pushram")
    t_grid = out["t"][::n_sup]
    assert np.allclose(t_grid, np.arange(2001.0)) and np.all(out["valid"] == 1)
    assert np.array_equal(out["support"][:n_sup], np.arange(n_sup))
    resid = as_grid(out, n_sup) - reference_true_ram(sup, t_grid, n_sup)
    assert abs(resid.mean()) < 1e-3
    assert resid.std() == pytest.approx(0.02, rel=0.1)
    k = out["extension"] / 0.001
    assert np.allclose(k, np.round(k), atol=1e-6)
    exact = ram(scenario(pushram={"noise_m": 0.0, "resolution_m": 0.0}), sup, t_end=2000.0)
    assert np.array_equal(as_grid(exact, n_sup), reference_true_ram(sup, t_grid, n_sup))


RAM_FAULTS = {
    "ram_stuck": 0.0, "ram_offset": 0.05, "ram_drift": 1e-3, "ram_scale": 0.1, "ram_dropout": 0.0,
    "ram_noise_burst": 0.05,
}


@pytest.mark.parametrize("kind", [*RAM_FAULTS, "push_shortfall"])
def test_ram_fault_only_inside_window(kind):
    value = RAM_FAULTS.get(kind, 0.3)
    fault = {"kind": kind, "t_start_s": 300.0, "t_end_s": 600.0, "target": 5, "value": value}
    cfg = {"noise_m": 0.002, "resolution_m": 1e-4}
    clean_scn, faulty_scn = scenario(pushram=cfg), scenario(pushram=cfg, faults=[fault])
    n_sup = support_stations(clean_scn).size
    sup = supports_truth(n_sup, 1000.0)
    a, b = ram(clean_scn, sup), ram(faulty_scn, sup)
    xa, xb = as_grid(a, n_sup), as_grid(b, n_sup)
    va, vb = as_grid(a, n_sup, "valid"), as_grid(b, n_sup, "valid")
    changed = ~((xa == xb) | (np.isnan(xa) & np.isnan(xb))) | (va != vb)
    t = a["t"][::n_sup]
    win = window_mask(t, faulty_scn.faults[0])
    expected = np.zeros_like(changed)
    expected[win, 5] = True
    if kind == "push_shortfall":
        assert not changed.any()  # the sensor reads the commanded stroke: nothing to see here
        return
    assert not changed[~expected].any()  # nothing outside the window or on another support
    if kind in ("ram_stuck", "ram_drift"):
        expected[np.flatnonzero(win)[0], 5] = False  # the frozen value / zero drift at t_start
    if kind in ("ram_stuck", "ram_noise_burst"):  # a noisy reading may hit the same quantum by chance
        assert changed[win, 5].mean() > 0.9
    else:
        assert np.array_equal(changed, expected)
    ra, rb = xa[win, 5], xb[win, 5]
    tol = 1.01e-4  # one quantization step
    if kind == "ram_stuck":
        assert np.all(rb == ra[0])
    elif kind == "ram_offset":
        assert np.allclose(rb - ra, value, atol=tol)
    elif kind == "ram_drift":
        assert np.allclose(rb - ra, value * (t[win] - 300.0), atol=tol)
    elif kind == "ram_scale":
        truth = reference_true_ram(sup, t[win], n_sup)[:, 5]
        assert np.allclose(rb - ra, value * truth, atol=tol)
    elif kind == "ram_dropout":
        assert np.all(np.isnan(rb)) and np.all(vb[win, 5] == 0)
        assert np.all(vb[~win, 5] == 1) and not np.isnan(xb[~win, 5]).any()
    elif kind == "ram_noise_burst":
        assert (rb - ra).std() == pytest.approx(value, rel=0.25)


def test_rail_deviation_formula():
    e = rail_deviation_m(np.arange(1, 7), 1.0, 1.8)
    seg = 1.8 * (1 + math.radians(1.0))
    angles = [1, 1, 2, 2, 3, 3]  # the angle grows by the value every two chutes
    assert np.allclose(e, np.cumsum([seg * math.sin(math.radians(a)) for a in angles]))


def test_rail_deviation_follows_the_shearer():
    value, length = 1.0, 1.75
    fault = {"kind": "rail_deviation", "t_start_s": 100.0, "t_end_s": 300.0, "value": value}
    scn_clean = scenario(pushram={"noise_m": 0.0, "resolution_m": 0.0})
    scn = scenario(pushram={"noise_m": 0.0, "resolution_m": 0.0}, faults=[fault])
    n_sup = support_stations(scn).size
    sup = supports_truth(n_sup, 400.0)
    shearer, _ = shearer_truth(lambda t: 0.1 + 0 * t, duration=400.0, s0=5.0)  # s = 5 + 0.1 t
    a = as_grid(ram(scn_clean, sup, t_end=400.0), n_sup)
    b = as_grid(ram(scn, sup, t_end=400.0, shearer=shearer), n_sup)
    t = np.arange(401.0)
    d = b - a
    assert not d[(t < 100) | (t >= 300)].any()
    start = math.floor(15.0 / length)  # the shearer's pan at t_start
    stations = support_stations(scn)
    for k in (100, 150, 299):
        here = math.floor((5.0 + 0.1 * k) / length) + 1  # the pan the shearer enters is deviated too
        hit = (stations >= start) & (stations <= here)
        assert np.allclose(d[k, hit], rail_deviation_m(stations[hit] - start + 1, value, length), atol=1e-12)
        assert not d[k, ~hit].any()
    assert d[299].max() > 0.5  # metres after ~12 chutes at 1 deg per two chutes
    # without the shearer the whole rail from the headgate is deviated inside the window
    whole = as_grid(ram(scn, sup, t_end=400.0), n_sup) - a
    assert np.allclose(whole[150], rail_deviation_m(stations - stations[0] + 1, value, length), atol=1e-12)
    assert not whole[(t < 100) | (t >= 300)].any()


# ----------------------------------------------------------------------------------------------- schedule


def test_faults_table_and_run_check():
    faults = [
        {"kind": "ram_offset", "t_start_s": 10.0, "t_end_s": 20.0, "target": 3, "value": 0.05},
        {"kind": "rail_deviation", "t_start_s": 2825.0, "t_end_s": 3131.0, "value": 1.0},
        {"kind": "odometer_slip", "t_start_s": 50.0, "t_end_s": 60.0, "value": 0.1},
    ]
    scn = scenario(faults=faults)
    table = faults_table(scn)
    check_table(FAULTS, make_table(FAULTS, table), "faults")
    assert list(table["kind"]) == ["ram_offset", "rail_deviation", "odometer_slip"]
    assert list(table["target"]) == [3, -1, -1]
    assert list(table["t_start"]) == [10.0, 2825.0, 50.0] and list(table["t_end"]) == [20.0, 3131.0, 60.0]
    assert list(table["value"]) == [0.05, 1.0, 0.1]
    assert faults_table(scenario())["kind"].size == 0
    check_faults_in_run(scn, 3000.0)  # partly inside is fine
    with pytest.raises(ScenarioError, match=r"^faults\[1\]: window 2825\.\.3131 s is outside the run "
                                            r"\(0\.\.2000 s\)$"):
        check_faults_in_run(scn, 2000.0)
    assert np.array_equal(window_mask(np.array([9.9, 10.0, 19.99, 20.0]), scn.faults[0]),
                          [False, True, True, False])


def test_speed_along_axis_is_the_axis_turned_into_n_dotted_with_the_velocity():
    """The per-sample kernel against C_b^n (quat_to_mat) applied to the axis, for random attitudes, velocities and
    a mounted (not body-y) axis."""
    from estimators.nav.rotations import quat_to_mat
    from twin.sensors.odometer import odometer_axis_b, speed_along_axis
    rng = np.random.default_rng(5)
    q = rng.normal(size=(1000, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    v_n = rng.normal(size=(1000, 3))
    axis_b = odometer_axis_b([2.0, -1.0, 3.0])
    cols = {**{f"q_nb_{c}": q[:, i] for i, c in enumerate("wxyz")}, **{f"v_n_{c}": v_n[:, i] for i, c in enumerate("enu")}}
    expected = np.einsum("kij,j,ki->k", quat_to_mat(q), axis_b, v_n)
    np.testing.assert_allclose(speed_along_axis(cols, axis_b), expected, rtol=0, atol=1e-14)
