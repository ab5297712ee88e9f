"""estimators.io.self_assessment: what an estimate says of itself without truth, on closed-form paths."""

from __future__ import annotations

import json

import numpy as np
import pytest

from estimators.io.logformat import (
    FLAG_POSITION,
    FLAG_SKIPPED,
    FLAG_UNHEALTHY,
    FLAG_ZUPT,
)
from estimators.io.metrics import enu_offset_to_geodetic
from estimators.io.self_assessment import self_assessment, survey_residuals
from tests.estimators.io.test_metrics import (
    estimate_table,
    offset_estimate,
    straight_truth,
)


def test_distance_sigmas_and_flag_counts():
    truth = straight_truth()  # 0.1 m/s north, 0.02 m/s east, 0.001 m/s up for 100 s
    t = truth["t"][::5]
    flags = np.zeros(t.size, np.int32)
    flags[[3, 9]] = FLAG_POSITION
    flags[[9, 10, 11]] |= FLAG_ZUPT
    flags[-1] = FLAG_SKIPPED
    flags[[20, 21]] |= FLAG_UNHEALTHY
    own = self_assessment(offset_estimate(truth, t, [0.0, 0.0, 0.0], sd=0.04, flags=flags))
    assert own["samples"] == t.size and own["t_end"] == pytest.approx(100.0)
    assert own["distance_m"] == pytest.approx(100.0 * np.sqrt(0.1 ** 2 + 0.02 ** 2 + 0.001 ** 2), rel=1e-6)
    assert own["final_sd_pos_m"] == pytest.approx({"east": 0.04, "north": 0.04, "up": 0.04})
    assert own["final_sd_horizontal_m"] == pytest.approx(0.04 * np.sqrt(2))
    assert own["final_sd_att_deg"]["u"] == pytest.approx(np.degrees(0.04))
    assert own["flags"] == {"velocity_updates": 0, "position_fixes": 2, "zupts": 3, "skipped": 1,
                           "covariance_repaired": 0, "mag_updates": 0, "isolated": 0, "unhealthy": 2}
    assert "survey_residuals" not in own


def test_no_covariance_is_none_and_the_result_is_plain_json():
    truth = straight_truth(101)
    own = self_assessment(offset_estimate(truth, truth["t"], [0.0, 0.0, 0.0]))  # sd NaN: dead reckoning
    assert own["final_sd_horizontal_m"] is None and own["max_sd_horizontal_m"] is None
    assert json.loads(json.dumps(own, allow_nan=False)) == own
    assert self_assessment(estimate_table(*(np.empty(0),) * 4, np.empty((0, 4)))) == {"samples": 0}


def test_survey_residual_is_the_estimate_before_the_fix_minus_the_survey():
    truth = straight_truth()
    t = truth["t"][::10]  # 1 s epochs
    estimate = offset_estimate(truth, t, [0.3, -0.4, 0.1], sd=0.1)
    fix_t = np.array([0.0, 50.5, 99.95])  # the start pose (before the first epoch) and two fixes
    k = np.searchsorted(t, fix_t, side="left") - 1
    lat, lon, h = (truth[key][::10][np.maximum(k, 0)] for key in ("lat", "lon", "h"))  # the truth at those epochs
    survey = {"t": fix_t, "lat": lat, "lon": lon, "h": h, "sd_horizontal": np.full(3, 0.2),
              "sd_vertical": np.full(3, 0.2)}
    rows = survey_residuals(estimate, survey)
    assert [r["t_fix"] for r in rows] == [50.5, 99.95] and [r["t_estimate"] for r in rows] == [50.0, 99.0]
    for r in rows:
        assert (r["east"], r["north"], r["up"]) == pytest.approx((0.3, -0.4, 0.1), abs=1e-6)
        assert r["horizontal"] == pytest.approx(0.5, abs=1e-6)
        assert r["nis"] == pytest.approx((0.3 ** 2 + 0.4 ** 2 + 0.1 ** 2) / (0.1 ** 2 + 0.2 ** 2), rel=1e-5)
    assert self_assessment(estimate, survey)["survey_residuals"] == rows
    far = dict(survey, lat=enu_offset_to_geodetic(np.array([[0.0, 3.0, 0.0]] * 3), lat, lon, h)[0])
    assert survey_residuals(estimate, far)[0]["north"] == pytest.approx(-3.4, abs=1e-6)
