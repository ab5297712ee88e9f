"""The supports' pressure transducers (twin.sensors.pressure): readings of the truth, and every sensor fault of both
transducers acting on its target inside its window only."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import capped
from twin.config.sensors import READING_FAULTS, Fault
from twin.face.layout import support_stations
from twin.sensors.pressure import pressure_stream

T_END = 100.0


def _truth(scn):
    """Every support's legs rising 0.1 MPa/s from 30 MPa and its ram at 5 MPa, rows every 2 s."""
    n = support_stations(scn).size
    t = np.repeat(np.arange(0.0, T_END + 1, 2.0), n)
    sup = np.tile(np.arange(n), t.size // n)
    return {"t": t, "support": sup, "leg_pressure": 30.0 + 0.1 * t, "ram_pressure": np.full(t.size, 5.0) + 0.01 * sup}


def _scn(noise=0.0, resolution=0.0):
    return capped("default", sensors={**capped("default").sensors.model_dump(),
                                      "pressure": {"rate_hz": 1.0, "noise_mpa": noise, "resolution_mpa": resolution}})


def test_the_readings_are_the_latest_truth_quantized():
    scn = _scn(resolution=0.1)
    out = pressure_stream(scn, _truth(scn), T_END, np.random.default_rng(0), [])
    t, sup = out["t"], out["support"]
    expected_leg = np.round((30.0 + 0.1 * 2.0 * np.floor(t / 2.0)) / 0.1) * 0.1
    np.testing.assert_allclose(out["leg"], expected_leg, atol=1e-9)
    np.testing.assert_allclose(out["ram"], np.round((5.0 + 0.01 * sup) / 0.1) * 0.1, atol=1e-9)
    assert out["valid_leg"].all() and out["valid_ram"].all()


def test_the_noise_has_its_standard_deviation():
    scn = _scn(noise=0.05)
    out = pressure_stream(scn, _truth(scn), T_END, np.random.default_rng(1), [])
    clean = pressure_stream(_scn(), _truth(scn), T_END, np.random.default_rng(1), [])
    assert np.std(out["leg"] - clean["leg"]) == pytest.approx(0.05, rel=0.1)


@pytest.mark.parametrize("sensor", ["leg_pressure", "ram_pressure"])
@pytest.mark.parametrize("fault", READING_FAULTS)
def test_a_transducer_fault_acts_on_its_target_inside_its_window(sensor, fault):
    scn = _scn(noise=0.05, resolution=0.1)
    value = {"stuck": 0.0, "offset": 3.0, "drift": 0.05, "scale": 0.2, "dropout": 0.0, "noise_burst": 2.0}[fault]
    f = Fault(kind=f"{sensor}_{fault}", t_start_s=40.0, t_end_s=60.0, target=7, value=value)
    clean = pressure_stream(scn, _truth(scn), T_END, np.random.default_rng(2), [])
    faulty = pressure_stream(scn, _truth(scn), T_END, np.random.default_rng(2), [f])
    column = "leg" if sensor == "leg_pressure" else "ram"
    other = "ram" if column == "leg" else "leg"
    changed = ~np.isclose(clean[column], faulty[column], atol=1e-9, equal_nan=False)
    inside = (faulty["t"] >= 40.0) & (faulty["t"] < 60.0) & (faulty["support"] == 7)
    assert not changed[~inside].any()
    if fault == "stuck":  # frozen at the window's first reading, which the clean readings leave now and then
        assert np.all(faulty[column][inside] == faulty[column][inside][0]) and changed[inside].sum() >= 3
    else:
        assert changed[inside].sum() >= 10
    np.testing.assert_array_equal(clean[other], faulty[other])
    if fault == "dropout":
        assert np.isnan(faulty[column][inside]).all() and not faulty[f"valid_{column}"][inside].any()
