"""Strapdown mechanization: N-sample coning and sculling compensation against closed forms, bad input."""

from __future__ import annotations

from fractions import Fraction

import numba as nb
import numpy as np
import pytest

from estimators.nav.rotations import (
    quat_conj,
    quat_mul,
    quat_rotate,
    quat_to_rotvec,
    rotvec_to_quat,
)
from estimators.nav.earth import gravity_nb, nav_rates, radii_nb
from estimators.nav.rotation_kernels import cross3, qexp, qmul, qrot
from estimators.sins.coning import coefficients, coefficients_exact, coning_drift
from estimators.sins.strapdown import (
    Mechanization,
    NavState,
    body_attitude,
    compensate,
    mechanize,
    strapdown_step,
)
from twin.papers.motions import coning, sculling


def test_coefficients_are_the_published_ones():
    """2/3; 9/20, 27/20; 54/105, 92/105, 214/105 (000 eq. 70 prints 29/105 for the second velocity
    coefficient: a typo, duality needs 92/105); 250/504, 525/504, 650/504, 1375/504."""
    assert coefficients_exact(2) == (Fraction(2, 3),)
    assert coefficients_exact(3) == (Fraction(9, 20), Fraction(27, 20))
    assert coefficients_exact(4) == (Fraction(54, 105), Fraction(92, 105), Fraction(214, 105))
    assert coefficients_exact(5) == (Fraction(250, 504), Fraction(525, 504), Fraction(650, 504),
                                     Fraction(1375, 504))
    with pytest.raises(ValueError, match="sub-samples"):
        coefficients_exact(6)


def _cone_drift(n, alpha, psi, h, duration=40.0):
    t, dtheta, dv = coning(alpha, psi, dt=h, duration_s=duration, earth_rate=False, gravity=False)
    phi, _ = compensate(dtheta, dv, n)
    q = body_attitude(rotvec_to_quat(np.array([0.0, alpha, 0.0])), phi)
    tt = t[::n][: q.shape[0]]
    q_true = rotvec_to_quat(alpha * np.column_stack([0 * tt, np.cos(psi * tt), np.sin(psi * tt)]))
    err = quat_to_rotvec(quat_mul(q, quat_conj(q_true)))
    return -np.polyfit(tt, err[:, 0], 1)[0]  # about the cone axis


@pytest.mark.parametrize("n", [2, 3])
def test_coning_drift_matches_the_closed_form(n):
    """1 deg half-cone at 2 Hz, 0.01 s sub-samples: the measured drift is the algorithm's closed form within 5 %."""
    alpha, psi, h = np.radians(1.0), 2 * np.pi * 2, 0.01
    assert _cone_drift(n, alpha, psi, h) == pytest.approx(coning_drift(n, alpha, psi, h), rel=0.05)


def test_four_sample_coning_compensation_removes_the_drift_of_000_section_7_2():
    """alpha = 1 deg, omega = 2 pi rad/s, h = 10 ms, 40 s: >= 99 % less drift than no compensation (000: 64 %)."""
    alpha, psi, h = np.radians(1.0), 2 * np.pi, 0.01
    raw, four = _cone_drift(1, alpha, psi, h), _cone_drift(4, alpha, psi, h)
    assert abs(four) <= 0.01 * abs(raw) and raw == pytest.approx(coning_drift(1, alpha, psi, h), rel=1e-3)


def _velocity_drift(dtheta, dv, n, t, compensated):
    if compensated:
        phi, dv_b = compensate(dtheta, dv, n)
    else:
        phi, dv_b = compensate(dtheta, dv, 1)
        dv_b = dv[1:]  # a plain sum: no rotation, no sculling term
    q = body_attitude(np.array([1.0, 0.0, 0.0, 0.0]), phi)
    v = np.concatenate([[np.zeros(3)], np.cumsum(quat_rotate(q[:-1], dv_b), axis=0)])
    tt = t[::n if compensated else 1][: v.shape[0]]
    return np.array([np.polyfit(tt, v[:, i], 1)[0] for i in range(3)])


def test_sculling_compensation_removes_the_velocity_drift_of_eq_71():
    """f = 1 Hz, B = 0.1 deg, C = 0.01 g, 4 sub-samples of 6 ms: the true motion has no mean velocity; the
    compensated drift is >= 99 % smaller than the uncompensated one (000: 70 %). The preset is a physical
    oscillation, so the sensor's own z specific force carries the rectified term and the uncompensated error
    is the within-interval part, second order in Omega T (2e-8 m/s^2 here)."""
    t, dtheta, dv = sculling(1.0, np.radians(0.1), 0.01 * 9.80665, dt=0.006, duration_s=30.0)
    raw = np.linalg.norm(_velocity_drift(dtheta, dv, 4, t, compensated=False))
    comp = np.linalg.norm(_velocity_drift(dtheta, dv, 4, t, compensated=True))
    assert raw > 1e-9 and comp <= 0.01 * raw


def test_bad_input_is_refused():
    t = np.arange(101) * 0.01
    ok = np.zeros((101, 3))
    q0 = np.array([1.0, 0, 0, 0])
    bad = ok.copy()
    bad[40, 1] = np.nan
    with pytest.raises(ValueError, match="dtheta row 40"):
        mechanize(t, bad, ok, 0.5, 0.0, 0.0, np.zeros(3), q0)
    gap = t.copy()
    gap[60:] += 0.5
    with pytest.raises(ValueError, match="sample interval at row 60"):
        mechanize(gap, ok, ok, 0.5, 0.0, 0.0, np.zeros(3), q0)
    with pytest.raises(ValueError, match="outside \\[-89, 89\\]"):
        mechanize(t, ok, ok, np.radians(89.5), 0.0, 0.0, np.zeros(3), q0)


def test_mechanization_in_blocks_gives_the_rows_of_one_call_bit_for_bit():
    """Mechanization carries the last two updates from block to block (the mid-interval extrapolation reads them),
    so blocks of any whole number of updates give mechanize's rows exactly; a block's bad row is named in the
    whole log's numbering."""
    rng = np.random.default_rng(5)
    n = 4 * 600
    t = np.arange(n + 1) * 0.005
    dtheta = rng.normal(0.0, 1e-3, (n + 1, 3)) + np.array([0.0, 0.0, 2e-4])
    dv = rng.normal(0.0, 1e-3, (n + 1, 3)) + np.array([0.0, 0.0, 9.8 * 0.005])
    q0 = np.array([0.9, 0.1, -0.2, 0.3])
    args = (0.7, 0.2, 150.0, np.array([0.1, -0.2, 0.0]), q0)
    whole = mechanize(t, dtheta, dv, *args)
    blocks = Mechanization(*args)
    rows = []
    edges = [0, 4, 40, 1200, 2000, n]  # in increments; whole updates of 4
    for a, b in zip(edges[:-1], edges[1:]):
        part = blocks.run(t[a:b + 1], dtheta[a:b + 1], dv[a:b + 1])
        rows.append(part if a == 0 else NavState(*(x[1:] for x in vars(part).values())))
    for key, value in vars(whole).items():
        assert np.array_equal(np.concatenate([getattr(r, key) for r in rows]), value), key
    bad = dtheta.copy()
    bad[1500, 2] = np.nan
    with pytest.raises(ValueError, match="dtheta row 1500 is not finite"):
        Mechanization(*args).run(t[1200:2001], bad[1200:2001], dv[1200:2001], first_row=1200)


@nb.njit
def _vector_step(lat, lon, h, v, q, phi, dv_b, dt, lat_e, h_e, v_e, hold_height):
    """The strapdown step in its vector form (000 eqs. 3-5), as written before the scalar kernel: the reference."""
    w_ie, w_en = nav_rates(lat_e, h_e, v_e)
    zeta = (w_ie + w_en) * dt
    dv_n = qrot(q, dv_b)
    dv_n = dv_n - 0.5 * cross3(zeta, dv_n)
    g_n = np.array([0.0, 0.0, -gravity_nb(lat_e, h_e)])
    v_new = v + dv_n + (g_n - cross3(2.0 * w_ie + w_en, v_e)) * dt
    if hold_height:
        v_new[2] = 0.0
    v_bar = 0.5 * (v + v_new)
    h_new = h + v_bar[2] * dt
    h_bar = 0.5 * (h + h_new)
    lat_new = lat + v_bar[1] * dt / (radii_nb(lat)[0] + h_bar)
    lat_bar = 0.5 * (lat + lat_new)
    lon_new = lon + v_bar[0] * dt / ((radii_nb(lat_bar)[1] + h_bar) * np.cos(lat_bar))
    w_ie, w_en = nav_rates(lat_bar, h_bar, v_bar)
    q_new = qmul(qmul(qexp(-(w_ie + w_en) * dt), q), qexp(phi))
    return lat_new, lon_new, h_new, v_new, q_new / np.sqrt(np.sum(q_new * q_new)), dv_n, v_bar


def test_scalar_step_and_compensation_equal_their_vector_forms_bit_for_bit():
    """strapdown_step and compensate are written in scalars for speed; every number equals the vector form's."""
    rng = np.random.default_rng(8)
    for hold in (False, True):
        for _ in range(200):
            q = rng.normal(size=4)
            args = (rng.uniform(-1.4, 1.4), rng.uniform(-3, 3), rng.normal(0, 500), rng.normal(0, 3, 3),
                    q / np.linalg.norm(q), rng.normal(0, 1e-2, 3), rng.normal(0, 0.1, 3), rng.uniform(1e-3, 0.1),
                    rng.uniform(-1.4, 1.4), rng.normal(0, 500), rng.normal(0, 3, 3), hold)
            for ours, ref in zip(strapdown_step(*args), _vector_step(*args)):
                assert np.array_equal(ours, ref)
    for n in range(1, 6):
        dtheta, dv = rng.normal(0, 1e-3, (1 + 50 * n + 2, 3)), rng.normal(0, 1e-2, (1 + 50 * n + 2, 3))
        u = (dtheta.shape[0] - 1) // n  # the 2 rows over a whole update left out for n > 2
        th, v = dtheta[1:1 + u * n].reshape(u, n, 3), dv[1:1 + u * n].reshape(u, n, 3)
        k = coefficients(n)
        c, d = np.einsum("i,uij->uj", k, th[:, :-1]), np.einsum("i,uij->uj", k, v[:, :-1])
        phi_ref = th.sum(axis=1) + np.cross(c, th[:, -1])
        dv_ref = (v.sum(axis=1) + 0.5 * np.cross(th.sum(axis=1), v.sum(axis=1)) + np.cross(c, v[:, -1])
                  + np.cross(d, th[:, -1]))
        phi, dv_b = compensate(dtheta, dv, n)
        assert np.array_equal(phi, phi_ref) and np.array_equal(dv_b, dv_ref)
