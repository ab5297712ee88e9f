"""The SINS/odometer/magnetometer filters of 003 (estimators.shearer.federated_filter, estimators.afkf): the fusion step against
the centralized update, and both filters on the seed003 face with and without magnetic interference."""

import dataclasses

import numpy as np
import pytest

from estimators.io import metrics
from estimators.io.logformat import FLAG_MAG
from estimators.shearer import federated as fp
from estimators.shearer import federated_filter as fk
from estimators.shearer import odometer_filter as kf
from estimators.shearer import positioning as sp
from tests.conftest import simulated
from twin.pipeline.estimate import positioning_config
from twin.sensors.streams import imu_truth, sensor_streams


@pytest.mark.parametrize("beta_od", [0.5, 0.1])
def test_one_fusion_equals_the_centralized_update(beta_od):
    """Sub-filters holding the shares P / beta_i of a dense prior, each updated with its own measurement, fuse
    to the centralized posterior (to rounding), and are reset to P_g / beta_i."""
    rng = np.random.default_rng(3)
    a = rng.normal(size=(kf.N_STATES, kf.N_STATES))
    p = a @ a.T + np.eye(kf.N_STATES)
    h_od, r_od, z_od = rng.normal(size=(3, kf.N_STATES)), 0.5 * np.eye(3), rng.normal(size=3)
    h_mag = np.zeros((1, kf.N_STATES))
    h_mag[0, kf.PHI] = rng.normal(size=3)
    r_mag, z_mag = np.array([[0.3]]), rng.normal(size=1)
    x_c, p_c = np.zeros(kf.N_STATES), p.copy()
    kf.joseph_update(x_c, p_c, z_od, h_od, r_od)
    kf.joseph_update(x_c, p_c, z_mag, h_mag, r_mag)
    x_od, p_od = np.zeros(kf.N_STATES), p / beta_od
    x_aiding, p_aiding = np.zeros(kf.N_STATES), p / (1 - beta_od)
    kf.joseph_update(x_od, p_od, z_od, h_od, r_od)
    kf.joseph_update(x_aiding, p_aiding, z_mag, h_mag, r_mag)
    tr_od, tr_mag = np.trace(p_od), np.trace(p_aiding)
    x_g, p_g, beta, valid, ok = fk.fuse_epoch(x_od, p_od, x_aiding, p_aiding, False)
    assert ok and valid.all()
    assert np.allclose(x_g, x_c, atol=1e-12) and np.allclose(p_g, p_c, atol=1e-10 * np.abs(p_c).max())
    assert beta == pytest.approx([tr_od / (tr_od + tr_mag), tr_mag / (tr_od + tr_mag)])  # 003 section 4.3
    assert np.allclose(p_od, p_g / beta[0]) and np.allclose(p_aiding, p_g / beta[1]) and not x_od.any()


def test_a_blown_up_subfilter_is_left_out_and_restarted():
    p = np.diag(np.linspace(1.0, 2.0, kf.N_STATES))
    x_od, p_od = np.full(kf.N_STATES, 0.1), p.copy()
    x_aiding, p_aiding = np.zeros(kf.N_STATES), p.copy()
    p_aiding[5, 5] = np.nan
    x_g, p_g, beta, valid, ok = fk.fuse_epoch(x_od, p_od, x_aiding, p_aiding, False)
    assert ok and list(valid) == [True, False] and list(beta) == [1.0, 0.0]
    assert np.allclose(x_g, 0.1) and np.allclose(p_g, p)
    assert np.allclose(p_aiding, p) and np.allclose(p_od, p)


@pytest.fixture(scope="module", params=["seed003", "seed003_interference"])
def face(request):
    scn, result = simulated(request.param)
    streams = sensor_streams(scn, result.tables, imu_truth(scn, result.tables["truth_shearer"]), 0)
    log = sp.log_from_columns(streams["imu"], streams["odometer"], streams["survey"], mag=streams["mag"])
    cfg = positioning_config(scn)
    return scn, result.tables["truth_shearer"], log, cfg, sp.prepare(log, cfg)


def _max_horizontal(sol, truth) -> float:
    _, err = metrics.position_errors(sp.estimate_columns(sol), truth)
    return float(np.hypot(err[:, 0], err[:, 1]).max())


def test_without_readings_both_filters_are_the_odometer_filter(face):
    """No magnetometer reading: the magnetometer sub-filter only holds its share of the information, and the
    fusion gives back the SINS/odometer filter exactly."""
    _scn, _truth, log, cfg, prep = face
    blind = dataclasses.replace(log, mag_b=np.full_like(log.mag_b, np.nan))
    ref = sp.run_kf(blind, cfg, prep, cpoem=False, smooth=False)[0]
    for federated in (False, True):
        sol = fp.run_mag(blind, cfg, prep, federated)
        assert np.allclose(sol.llh, ref.llh, rtol=0, atol=1e-12) and np.allclose(sol.sd, ref.sd, rtol=1e-6)
        assert not (sol.flags & FLAG_MAG).any() and "not finite" in " ".join(sol.notes)


def test_the_magnetometer_bounds_the_heading_and_the_federated_filter_survives_interference(face):
    scn, truth, log, cfg, prep = face
    odometer_only = _max_horizontal(sp.run_kf(log, cfg, prep, cpoem=False, smooth=False)[0], truth)
    ckf = fp.run_mag(log, cfg, prep, federated=False)
    fed = fp.run_mag(log, cfg, prep, federated=True)
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
    sol = fp.run_mag(dataclasses.replace(log, mag_b=mag_b), cfg, prep, federated=True)
    assert np.isfinite(sol.llh).all()
    assert any("200 readings saturated or not finite" in n for n in sol.notes)
    with pytest.raises(sp.PositioningError, match="mag: no magnetometer readings"):
        fp.run_mag(dataclasses.replace(log, mag_t=np.zeros(0), mag_b=np.zeros((0, 3))), cfg, prep, federated=True)


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
    ref = fp.run_mag(log, cfg, prep, federated=True)
    sol = fp.run_mag(distorted, calibrated, prep, federated=True)
    raw = fp.run_mag(distorted, cfg, prep, federated=True)
    assert np.allclose(sol.llh, ref.llh, rtol=0, atol=1e-12)
    assert np.abs(raw.llh - ref.llh).max() > 1e-8  # ~6 cm: the uncalibrated iron matters
