"""Fault detectors (estimators.faults.detectors): the FSPRT (004 eqs. 20-24) against a direct evaluation of the
equations, its false alarms on fault-free innovations, soft and hard faults against the residual chi-square
(004 ref [23]) and the dual-state chi-square (004 ref [20]), clearing after the fault, and bad input."""

from __future__ import annotations

import numba as nb
import numpy as np
import pytest

from estimators.faults.detectors import (
    FSPRT_COUNT,
    FSPRT_LAMBDA,
    FSPRT_MEAN,
    FSPRT_N_SCALARS,
    DetectorConfig,
    chi2_dual_state,
    chi2_residual,
    chi2_threshold,
    fsprt_state,
    fsprt_update,
    hysteresis,
    run_detectors,
)

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

RATE = 10.0
"""Measurement epochs per second, as the shearer filter's aiding epochs."""


def random_spd(rng, m, scales):
    a = rng.normal(size=(m, m))
    c = a @ a.T + m * np.eye(m)
    d = np.asarray(scales) / np.sqrt(np.diag(c))
    return c * np.outer(d, d)


def reference_fsprt(v, s, b):
    """lambda_k and vbar_k straight from 004 eqs. 20-23, without the recursion of the module: vbar_k is the
    weighted mean sum_j b^(k-j) v_j / sum_j b^(k-j) (eqs. 21-22 unrolled), lambda_k = sum_j b^(k-j) dlambda_j
    (eq. 23 unrolled), dlambda_j from eq. 20 with S_j^-1 from numpy."""
    k = np.arange(v.shape[0])
    lag = k[:, None] - k[None, :]
    w = np.where(lag >= 0, b ** np.maximum(lag, 0).astype(float), 0.0)
    vbar = (w @ v) / w.sum(axis=1, keepdims=True)
    s_inv = np.linalg.inv(s)
    e = v - vbar
    dlam = 0.5 * (np.einsum("ki,kij,kj->k", v, s_inv, v) - np.einsum("ki,kij,kj->k", e, s_inv, e))
    return w @ dlam, vbar


# ------------------------------------------------------------------------------------------ FSPRT equations


@pytest.mark.parametrize("m", [1, 2])
def test_fsprt_matches_a_direct_evaluation_of_eqs_20_to_23(m):
    rng = np.random.default_rng(40 + m)
    n, b = 200, 0.9
    s = np.array([random_spd(rng, m, rng.uniform(0.5, 2.0, m)) for _ in range(n)])
    v = np.einsum("kij,kj->ki", np.linalg.cholesky(s), rng.normal(size=(n, m)))
    v[120:] += 2.0 * np.sqrt(np.diagonal(s[120:], axis1=1, axis2=2))  # a fault: lambda grows, too
    lam_ref, vbar_ref = reference_fsprt(v, s, b)
    state = fsprt_state(m)
    assert state.shape == (FSPRT_N_SCALARS + m,) and not state.any()
    lam = np.array([fsprt_update(state, v[k], s[k], b) for k in range(n)])
    np.testing.assert_allclose(lam, lam_ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(state[FSPRT_MEAN:], vbar_ref[-1], rtol=1e-12, atol=1e-12)
    assert state[FSPRT_COUNT] == n and state[FSPRT_LAMBDA] == lam[-1]
    # The first innovation has full weight (d_1 = 1): lambda_1 = v_1' S_1^-1 v_1 / 2.
    assert lam[0] == pytest.approx(0.5 * v[0] @ np.linalg.solve(s[0], v[0]), rel=1e-12)
    assert lam[150:].mean() > 5 * lam[:120].mean()  # ~0.74 m without, ~20 m with the fault


def test_non_finite_or_singular_input_leaves_the_fsprt_state_unchanged():
    rng = np.random.default_rng(3)
    s = random_spd(rng, 2, [1.0, 2.0])
    state = fsprt_state(2)
    for _ in range(30):
        lam = fsprt_update(state, rng.normal(size=2), s, 0.95)
    before = state.copy()
    bad = [
        (np.array([np.nan, 0.1]), s),
        (np.array([np.inf, 0.1]), s),
        (np.array([0.1, 0.2]), np.where(np.eye(2, dtype=bool), s, np.nan)),
        (np.array([0.1, 0.2]), s * np.array([[1.0, np.inf], [np.inf, 1.0]])),
        (np.array([0.1, 0.2]), np.ones((2, 2))),  # singular
        (np.array([0.1, 0.2]), np.diag([1.0, -1.0])),  # indefinite
    ]
    for v_bad, s_bad in bad:
        assert fsprt_update(state, v_bad, s_bad, 0.95) == lam
        np.testing.assert_array_equal(state, before)
        assert np.isnan(chi2_residual(v_bad, s_bad))
    # The next good innovation continues from where the sequence was (the bad epochs did not count).
    v = rng.normal(size=2)
    other = before.copy()
    assert fsprt_update(state, v, s, 0.95) == fsprt_update(other, v, s, 0.95)


def test_kernels_reject_mismatched_shapes_and_bad_fading():
    with pytest.raises(ValueError, match="do not match"):
        fsprt_update(fsprt_state(2), np.zeros(3), np.eye(3), 0.95)
    with pytest.raises(ValueError, match="fading"):
        fsprt_update(fsprt_state(1), np.zeros(1), np.eye(1), 1.0)
    with pytest.raises(ValueError, match="do not match"):
        chi2_residual(np.zeros(2), np.eye(3))
    with pytest.raises(ValueError, match="do not match"):
        chi2_dual_state(np.zeros(2), np.eye(2), np.zeros(3), np.eye(2))


def test_hysteresis_follows_eq_24():
    t_on, t_off = 20.0, 5.0
    stats = [1.0, 19.9, 20.0, 20.1, 10.0, 5.1, 5.0, 12.0, np.nan, 25.0, np.nan, 3.0]
    expected = [False, False, False, True, True, True, False, False, False, True, True, False]
    flag, flags = False, []
    for stat in stats:
        flag = hysteresis(flag, stat, t_on, t_off)
        flags.append(flag)
    assert flags == expected


# ------------------------------------------------------------------------------------------ fault-free innovations


@nb.njit(cache=False)
def _fault_free_run(v, s, fading, t_on, t_off, chi2_limit):
    """(FSPRT alarms raised, epochs flagged, largest lambda, chi-square exceedances) over v (K, m)."""
    state = fsprt_state(v.shape[1])
    flag = False
    raised, flagged, exceed, lam_max = 0, 0, 0, -np.inf
    for k in range(v.shape[0]):
        lam = fsprt_update(state, v[k], s, fading)
        new = hysteresis(flag, lam, t_on, t_off)
        raised += new and not flag
        flagged += new
        flag = new
        lam_max = max(lam_max, lam)
        exceed += chi2_residual(v[k], s) > chi2_limit
    return raised, flagged, lam_max, exceed


@pytest.mark.parametrize("m", [1, 2, 3])
def test_fsprt_raises_no_false_alarm_in_20_hours_of_fault_free_innovations(m):
    """20 runs of 1 h at 10 Hz of white Gaussian innovations with the S the detector is given (states of very
    different scales): no FSPRT alarm with the default thresholds. Measured (seed 70 + m): largest lambda over the
    20 h 6.2 (m = 1), 7.5 (m = 2), 8.6 (m = 3) against t_on = 20, so 0 false alarms in 720 000 epochs (an upper
    bound of ~4e-6 per epoch at 95 % confidence; 3300 h with m = 3 never passed 15.2). The residual chi-square on
    the same innovations exceeds its p = 1e-3 threshold 693, 791, 679 times of the 720 expected (5 binomial sigma
    allowed)."""
    cfg = DetectorConfig()
    rng = np.random.default_rng(70 + m)
    s = random_spd(rng, m, [0.02, 1e-3, 0.5][:m])
    chol = np.linalg.cholesky(s)
    p = 1e-3
    limit = chi2_threshold(m, p)
    hours, epochs = 20, int(3600 * RATE)
    raised = flagged = exceed = 0
    lam_max = -np.inf
    for _ in range(hours):
        v = rng.normal(size=(epochs, m)) @ chol.T
        r, f, lmax, e = _fault_free_run(v, s, cfg.fading, cfg.t_on, cfg.t_off, limit)
        raised, flagged, exceed, lam_max = raised + r, flagged + f, exceed + e, max(lam_max, lmax)
    print(f"fault-free m={m}: largest lambda {lam_max:.2f}, chi-square exceedances {exceed} of {p * hours * epochs:.0f}")
    assert raised == 0 and flagged == 0
    assert lam_max < 0.75 * cfg.t_on  # a margin, not just luck
    n = hours * epochs
    assert abs(exceed - p * n) < 5 * np.sqrt(p * n)


# ------------------------------------------------------------------------------------------ faults


def fault_innovations(rng, s, bias_sigma, kind):
    """t (s from the fault onset), innovations (K, 2) with covariance s: 60 s fault-free, a fault along a fixed
    direction of Mahalanobis size bias_sigma, ramped over 30 s (004's slowly growing rail deviation) or a step,
    held to 60 s, then gone for 90 s."""
    t = np.arange(int(210 * RATE)) / RATE - 60.0
    size = bias_sigma * (np.clip(t / 30.0, 0.0, 1.0) if kind == "ramp" else (t >= 0.0))
    size[t >= 60.0] = 0.0
    chol = np.linalg.cholesky(s)
    direction = chol @ np.array([1.0, 1.0]) / np.sqrt(2.0)  # Mahalanobis norm 1
    return t, rng.normal(size=(t.size, 2)) @ chol.T + size[:, None] * direction


def first(t, flag, after):
    hit = np.nonzero(flag & (t >= after))[0]
    return t[hit[0]] if hit.size else np.inf


def test_soft_fault_is_flagged_by_the_fsprt_before_the_residual_chi_square_and_cleared_after():
    """A bias ramp to 3 sigma over 30 s at 10 Hz, 20 seeds, default config (chi-square at p = 1e-6 per epoch, the
    FSPRT thresholds that gave no false alarm in 20 h above, a lower rate than the chi-square's). Measured: FSPRT
    median delay 13.0 s (11.4 to 14.5 s, at 1.1 to 1.5 sigma), residual chi-square median 31.1 s (it fires only once
    the bias is near its 3 sigma top); the FSPRT clears 8.3 to 12.8 s after the fault has gone."""
    cfg = DetectorConfig()
    rng = np.random.default_rng(80)
    s = random_spd(rng, 2, [0.02, 0.05])
    fsprt, chi2, clear = [], [], []
    for _ in range(20):
        t, v = fault_innovations(rng, s, 3.0, "ramp")
        run = run_detectors(v, s, cfg)
        assert not run.fsprt_flag[t < 0].any()
        fsprt.append(first(t, run.fsprt_flag, 0.0))
        chi2.append(first(t, run.chi2_flag, 0.0))
        cleared = first(t, ~run.fsprt_flag, 60.0)
        clear.append(cleared - 60.0)
        assert not run.fsprt_flag[t >= cleared].any()  # stays cleared
    fsprt, chi2, clear = np.array(fsprt), np.array(chi2), np.array(clear)
    print(f"soft fault: FSPRT {np.median(fsprt):.1f} s ({fsprt.min():.1f}-{fsprt.max():.1f}), chi-square "
          f"{np.median(chi2):.1f} s, clears in {clear.min():.1f}-{clear.max():.1f} s")
    assert np.all(fsprt < 30.0)  # before the ramp reaches 3 sigma
    assert np.sum(fsprt < chi2) >= 18
    assert np.median(chi2) - np.median(fsprt) > 10.0
    assert np.all(clear < 60.0)


def dual_state_filters(z, q, r, reset_every):
    """A random-walk position measured directly: filter A updates with every z, filter B only predicts and is reset
    to A every `reset_every` epochs; the dual-state chi-square of the two after each epoch."""
    x_a, p_a = 0.0, r
    x_b, p_b = x_a, p_a
    stat = np.empty(z.size)
    for k, zk in enumerate(z):
        p_a, p_b = p_a + q, p_b + q
        gain = p_a / (p_a + r)
        x_a, p_a = x_a + gain * (zk - x_a), (1.0 - gain) * p_a
        stat[k] = chi2_dual_state(np.array([x_a]), np.array([[p_a]]), np.array([x_b]), np.array([[p_b]]))
        if (k + 1) % reset_every == 0:
            x_b, p_b = x_a, p_a
    return stat


def test_hard_step_fault_is_flagged_by_every_detector_within_a_few_epochs():
    """An 8 sigma step (residual chi-square and FSPRT on 2-D innovations, the dual-state chi-square on a scalar
    random-walk filter pair; default config). Measured over 20 seeds, in epochs after the first faulty one: residual
    chi-square 0, FSPRT 4 to 6, dual-state chi-square 2 to 3. The FSPRT, whose lambda reaches ~1600 under this
    fault, clears 13.5 to 19.6 s after the step has gone."""
    cfg = DetectorConfig()
    rng = np.random.default_rng(90)
    s = random_spd(rng, 2, [0.02, 0.05])
    limit_1 = chi2_threshold(1, cfg.p_false_alarm)
    delays = {"chi2": [], "fsprt": [], "dual": []}
    clear = []
    for _ in range(20):
        t, v = fault_innovations(rng, s, 8.0, "step")
        run = run_detectors(v, s, cfg)
        delays["chi2"].append(first(t, run.chi2_flag, 0.0))
        delays["fsprt"].append(first(t, run.fsprt_flag, 0.0))
        clear.append(first(t, ~run.fsprt_flag, 60.0) - 60.0)
        z = rng.normal(size=t.size) + 8.0 * (t >= 0.0) * (t < 60.0)
        dual = dual_state_filters(z, q=0.01, r=1.0, reset_every=50)
        assert not (dual[t < 0] > limit_1).any()
        delays["dual"].append(first(t, dual > limit_1, 0.0))
    epochs = {name: np.round(np.array(d) * RATE).astype(int) for name, d in delays.items()}
    print("hard fault, epochs after the first faulty one:", {name: (int(e.min()), int(e.max())) for name, e in
                                                              epochs.items()}, f"FSPRT clears in {min(clear):.1f}-{max(clear):.1f} s")
    assert epochs["chi2"].max() <= 1
    assert epochs["fsprt"].max() <= 8
    assert epochs["dual"].max() <= 6
    assert max(clear) < 60.0


# ------------------------------------------------------------------------------------------ chi-square helpers


def test_chi2_dual_state_and_residual_against_hand_examples():
    # Diagonal: dx = (1, 2), P_a + P_b = diag(2, 4): 1/2 + 4/4.
    assert chi2_dual_state(np.array([1.0, 2.0]), np.diag([1.0, 2.0]), np.zeros(2), np.diag([1.0, 2.0])) == \
        pytest.approx(1.5, rel=1e-14)
    # Correlated: dx = (1, 1), P_a + P_b = [[2, 1], [1, 2]], inverse [[2, -1], [-1, 2]] / 3: 2/3.
    p_a = np.array([[1.5, 0.25], [0.25, 0.5]])
    p_b = np.array([[0.5, 0.75], [0.75, 1.5]])
    assert chi2_dual_state(np.array([3.0, -1.0]), p_a, np.array([2.0, -2.0]), p_b) == pytest.approx(2 / 3, rel=1e-14)
    # A subset of states of very different scales (m and rad/s): dx = (1 m, 1e-5 rad/s), sigmas (1 m, 1e-5 rad/s).
    x_a = np.array([101.0, 2e-5])
    x_b = np.array([100.0, 1e-5])
    half = np.diag([0.5, 0.5e-10])
    assert chi2_dual_state(x_a, half, x_b, half) == pytest.approx(2.0, rel=1e-12)
    assert np.isnan(chi2_dual_state(x_a, half, x_b, -half))
    assert chi2_residual(np.array([3.0]), np.array([[4.0]])) == pytest.approx(9 / 4, rel=1e-15)
    assert chi2_residual(np.array([1.0, 1.0]), p_a + p_b) == pytest.approx(2 / 3, rel=1e-14)


@pytest.mark.parametrize("dof, p, value", [(1, 0.05, 3.841), (2, 0.01, 9.210), (3, 0.001, 16.266), (4, 0.05, 9.488)])
def test_chi2_threshold_matches_the_table(dof, p, value):
    assert chi2_threshold(dof, p) == pytest.approx(value, abs=5e-4)


@pytest.mark.parametrize("dof, p, field", [(0, 0.01, "dof"), (1.5, 0.01, "dof"), (2, 0.0, "p_false_alarm"),
                                           (2, 1.0, "p_false_alarm"), (2, float("nan"), "p_false_alarm")])
def test_chi2_threshold_rejects_bad_arguments(dof, p, field):
    with pytest.raises(ValueError, match=f"^{field}:"):
        chi2_threshold(dof, p)


# ------------------------------------------------------------------------------------------ configuration


@pytest.mark.parametrize("kwargs, field", [
    ({"fading": 0.0}, "fading"),
    ({"fading": 1.0}, "fading"),
    ({"fading": 1.5}, "fading"),
    ({"fading": float("nan")}, "fading"),
    ({"fading": "high"}, "fading"),
    ({"t_off": 25.0}, "t_off"),
    ({"t_on": 4.0}, "t_off"),
    ({"t_on": float("inf")}, "t_on"),
    ({"p_false_alarm": 0.0}, "p_false_alarm"),
    ({"p_false_alarm": 1.0}, "p_false_alarm"),
    ({"p_false_alarm": -1e-3}, "p_false_alarm"),
])
def test_bad_config_values_raise_a_value_error_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=f"^{field}:") as err:
        DetectorConfig(**kwargs)
    assert "\n" not in str(err.value)


def test_config_defaults_are_valid_and_frozen():
    cfg = DetectorConfig()
    assert 0.0 < cfg.fading < 1.0 and cfg.t_off <= cfg.t_on
    with pytest.raises(AttributeError):
        cfg.fading = 0.5  # type: ignore[misc]


def test_run_detectors_shapes_and_an_unusable_epoch():
    rng = np.random.default_rng(5)
    v = rng.normal(size=50)
    v[20] = np.nan
    run = run_detectors(v, 1.0)
    assert run.chi2.shape == run.fsprt.shape == run.fsprt_flag.shape == (50,)
    assert not run.valid[20] and run.valid[np.arange(50) != 20].all()
    assert np.isnan(run.chi2[20]) and not run.chi2_flag[20]
    assert run.fsprt[20] == run.fsprt[19]
    assert run.chi2_threshold == pytest.approx(chi2_threshold(1, DetectorConfig().p_false_alarm))
    np.testing.assert_allclose(run.chi2[run.valid], v[run.valid] ** 2, rtol=1e-14)
    with pytest.raises(ValueError, match="^covariances:"):
        run_detectors(np.zeros((5, 2)), np.eye(3))
