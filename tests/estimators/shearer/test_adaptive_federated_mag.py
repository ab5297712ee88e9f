"""003's SINS/odometer/magnetometer filters (estimators.shearer.adaptive_federated_mag): the adaptive federated
filter and the centralized one on the seed003 face with and without magnetic interference."""

import dataclasses

import numpy as np
import pytest

from estimators.io import metrics
from estimators.io.log import log_from_columns
from estimators.io.logformat import FLAG_MAG
from estimators.shearer import federated_filter as fk
from estimators.shearer.adaptive_federated_mag import run_mag
from estimators.shearer.config import PositioningError
from estimators.shearer.positioning import run_kf
from estimators.shearer.prepare import prepare
from estimators.shearer.solution import estimate_columns
from tests.conftest import simulated
from twin.pipeline.estimate import positioning_config
from twin.sensors.streams import imu_truth, sensor_streams

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")


@pytest.fixture(scope="module", params=["seed003", "seed003_interference"])
def face(request):
    scn, result = simulated(request.param)
    streams = sensor_streams(scn, result.tables, imu_truth(scn, result.tables["truth_shearer"]), 0)
    log = log_from_columns(streams["imu"], streams["odometer"], streams["survey"], mag=streams["mag"])
    cfg = positioning_config(scn)
    return scn, result.tables["truth_shearer"], log, cfg, prepare(log, cfg)


def _max_horizontal(sol, truth) -> float:
    _, err = metrics.position_errors(estimate_columns(sol), truth)
    return float(np.hypot(err[:, 0], err[:, 1]).max())


def test_without_readings_both_filters_are_the_odometer_filter(face):
    """No magnetometer reading: the magnetometer sub-filter only holds its share of the information, and the
    fusion gives back the SINS/odometer filter exactly."""
    _scn, _truth, log, cfg, prep = face
    blind = dataclasses.replace(log, mag_b=np.full_like(log.mag_b, np.nan))
    ref = run_kf(blind, cfg, prep, cpoem=False, smooth=False)[0]
    for federated in (False, True):
        sol = run_mag(blind, cfg, prep, federated)
        assert np.allclose(sol.llh, ref.llh, rtol=0, atol=1e-12) and np.allclose(sol.sd, ref.sd, rtol=1e-6)
        assert not (sol.flags & FLAG_MAG).any() and "not finite" in " ".join(sol.notes)


def test_the_magnetometer_bounds_the_heading_and_the_federated_filter_survives_interference(face):
    scn, truth, log, cfg, prep = face
    odometer_only = _max_horizontal(run_kf(log, cfg, prep, cpoem=False, smooth=False)[0], truth)
    ckf = run_mag(log, cfg, prep, federated=False)
    fed = run_mag(log, cfg, prep, federated=True)
    e_ckf, e_fed = _max_horizontal(ckf, truth), _max_horizontal(fed, truth)
    disturbed = (fed.fusion["mag_flags"] & fk.MAG_DISTURBED) > 0
    if scn.faults:
        window = (fed.t >= 10.0) & (fed.t <= 30.1)
        assert disturbed[window].mean() > 0.9 and not disturbed[~window].any()
        assert e_fed < e_ckf / 3 and e_fed < 0.5
    else:
        assert not disturbed.any()
        assert e_fed == pytest.approx(e_ckf, rel=1e-6)  # nothing disturbed: the fusion is the centralized filter
        assert e_fed < 0.4 * odometer_only
    beta = fed.fusion["beta_aiding"][1:]
    assert np.all((beta > 0) & (beta < 1)) and np.isfinite(fed.sd).all()


def test_bad_magnetometer_readings_are_left_out_and_noted(face):
    scn, _truth, log, cfg, prep = face
    if scn.faults:
        pytest.skip("one face is enough")
    mag_b = log.mag_b.copy()
    mag_b[100:200] = np.nan
    mag_b[300:400, 0] = cfg.mag.saturation_t
    sol = run_mag(dataclasses.replace(log, mag_b=mag_b), cfg, prep, federated=True)
    assert np.isfinite(sol.llh).all()
    assert any("200 readings saturated or not finite" in n for n in sol.notes)
    with pytest.raises(PositioningError, match="mag: no magnetometer readings"):
        run_mag(dataclasses.replace(log, mag_t=np.zeros(0), mag_b=np.zeros((0, 3))), cfg, prep, federated=True)


def test_a_calibration_undoes_the_iron_it_was_fitted_for(face):
    """Readings distorted by hard and soft iron, with that calibration in the settings, give the undistorted
    readings' solution."""
    scn, _truth, log, cfg, prep = face
    if scn.faults:
        pytest.skip("one face is enough")
    soft = np.array([[1.05, 0.02, 0.0], [0.02, 0.96, 0.01], [0.0, 0.01, 1.01]])
    hard = np.array([3e-6, -2e-6, 1e-6])
    distorted = dataclasses.replace(log, mag_b=log.mag_b @ soft.T + hard)
    calibrated = dataclasses.replace(cfg, mag=dataclasses.replace(
        cfg.mag, hard_iron_t=tuple(hard), soft_iron_correction=tuple(map(tuple, np.linalg.inv(soft)))))
    ref = run_mag(log, cfg, prep, federated=True)
    sol = run_mag(distorted, calibrated, prep, federated=True)
    raw = run_mag(distorted, cfg, prep, federated=True)
    assert np.allclose(sol.llh, ref.llh, rtol=0, atol=1e-12)
    assert np.abs(raw.llh - ref.llh).max() > 1e-8  # ~6 cm: the uncalibrated iron matters
