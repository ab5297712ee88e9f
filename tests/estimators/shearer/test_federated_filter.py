"""003's federated filter kernel (estimators.shearer.federated_filter): the fusion step against the centralized
update, and a blown-up sub-filter left out."""

import numpy as np
import pytest

from estimators.kalman import error_state as es
from estimators.kalman.update import joseph_update
from estimators.shearer import federated_filter as fk


@pytest.mark.parametrize("beta_od", [0.5, 0.1])
def test_one_fusion_equals_the_centralized_update(beta_od):
    """Sub-filters holding the shares P / beta_i of a dense prior, each updated with its own measurement, fuse
    to the centralized posterior (to rounding), and are reset to P_g / beta_i."""
    rng = np.random.default_rng(3)
    a = rng.normal(size=(es.N_STATES, es.N_STATES))
    p = a @ a.T + np.eye(es.N_STATES)
    h_od, r_od, z_od = rng.normal(size=(3, es.N_STATES)), 0.5 * np.eye(3), rng.normal(size=3)
    h_mag = np.zeros((1, es.N_STATES))
    h_mag[0, es.PHI] = rng.normal(size=3)
    r_mag, z_mag = np.array([[0.3]]), rng.normal(size=1)
    x_c, p_c = np.zeros(es.N_STATES), p.copy()
    joseph_update(x_c, p_c, z_od, h_od, r_od)
    joseph_update(x_c, p_c, z_mag, h_mag, r_mag)
    x_od, p_od = np.zeros(es.N_STATES), p / beta_od
    x_aiding, p_aiding = np.zeros(es.N_STATES), p / (1 - beta_od)
    joseph_update(x_od, p_od, z_od, h_od, r_od)
    joseph_update(x_aiding, p_aiding, z_mag, h_mag, r_mag)
    tr_od, tr_mag = np.trace(p_od), np.trace(p_aiding)
    x_g, p_g, beta, valid, ok = fk.fuse_epoch(x_od, p_od, x_aiding, p_aiding, False)
    assert ok and valid.all()
    assert np.allclose(x_g, x_c, atol=1e-12) and np.allclose(p_g, p_c, atol=1e-10 * np.abs(p_c).max())
    assert beta == pytest.approx([tr_od / (tr_od + tr_mag), tr_mag / (tr_od + tr_mag)])  # 003 section 4.3
    assert np.allclose(p_od, p_g / beta[0]) and np.allclose(p_aiding, p_g / beta[1]) and not x_od.any()


def test_a_blown_up_subfilter_is_left_out_and_restarted():
    p = np.diag(np.linspace(1.0, 2.0, es.N_STATES))
    x_od, p_od = np.full(es.N_STATES, 0.1), p.copy()
    x_aiding, p_aiding = np.zeros(es.N_STATES), p.copy()
    p_aiding[5, 5] = np.nan
    x_g, p_g, beta, valid, ok = fk.fuse_epoch(x_od, p_od, x_aiding, p_aiding, False)
    assert ok and list(valid) == [True, False] and list(beta) == [1.0, 0.0]
    assert np.allclose(x_g, 0.1) and np.allclose(p_g, p)
    assert np.allclose(p_aiding, p) and np.allclose(p_od, p)
