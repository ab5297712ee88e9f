"""The IMU error model (twin.sensors.imu_errors) and the grade presets (twin.config.imu_grades): statistics, not just shapes."""

from __future__ import annotations

import inspect
import math
import re

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from twin.config import imu_grades
from twin.config import sensors as sensor_config
from twin.config.imu_grades import (
    GM_ADEV_PEAK,
    GM_ADEV_PEAK_TAU,
    GRADES,
    ImuGrade,
    gm_adev,
    grade,
)
from twin.sensors import imu_errors
from twin.sensors.imu_errors import ImuErrorModel, apply_imu_errors

FS = 200.0
DT = 1.0 / FS


def _apply(g: ImuGrade, dtheta, dv=None, seed=0, **kw):
    dv = np.zeros_like(dtheta) if dv is None else dv
    return apply_imu_errors(dtheta, dv, DT, g, np.random.default_rng(seed), **kw)


# ---------------------------------------------------------------------------------------------------------
# (a) Allan deviation of a stationary sensor


def test_gm_adev_constant_derivation():
    """The Gauss-Markov ADEV maximum used to read the bias-instability floor, derived three ways.

    1. Closed form: for autocovariance sigma^2 exp(-|t|/T), AVAR(tau) = Var(mean over tau) - Cov(adjacent
       means) = sigma^2 [2/u - (3 - 4 e^-u + e^-2u)/u^2], u = tau/T; its numerical maximum is 0.6174 sigma at
       u = 1.8926 (the commonly quoted "0.62 sigma near 1.89 T").
    2. The exact discrete covariance sums of the simulated process (phi = exp(-dt/T), held over each sample)
       agree with the closed form within 1 % for dt = T/200.
    3. The Monte Carlo record in test_allan_deviation_recovers_configuration sees the same peak.
    """
    def neg_avar(u):
        return -(2.0 / u - (3.0 - 4.0 * math.exp(-u) + math.exp(-2.0 * u)) / u ** 2)

    best = minimize_scalar(neg_avar, bounds=(0.1, 20.0), method="bounded", options={"xatol": 1e-10})
    assert best.x == pytest.approx(GM_ADEV_PEAK_TAU, rel=1e-6)
    assert math.sqrt(-best.fun) == pytest.approx(GM_ADEV_PEAK, rel=1e-8)
    assert float(gm_adev(GM_ADEV_PEAK_TAU * 7.0, 2.0, 7.0)) == pytest.approx(2.0 * GM_ADEV_PEAK, rel=1e-9)

    tc, steps = 1.0, 200
    phi = math.exp(-1.0 / steps)
    for m in (20, 100, 379, 1000, 3000):
        lags = np.arange(1, m)
        var_mean = (m + 2.0 * np.sum((m - lags) * phi ** lags)) / m ** 2
        geo = (1.0 - phi ** m) / (1.0 - phi)
        cov_adjacent = phi * geo * geo / m ** 2  # sum_{i,j} phi^(m + j - i) over i, j in [0, m)
        discrete = math.sqrt(var_mean - cov_adjacent)
        assert discrete == pytest.approx(float(gm_adev(m / steps, 1.0, tc)), rel=0.01)
    # Small-u branch (series) joins the full expression.
    assert float(gm_adev(0.999e-3, 1.0, 1.0)) == pytest.approx(float(gm_adev(1.001e-3, 1.0, 1.0)), rel=2e-3)


def overlapping_adev(rate: np.ndarray, fs: float, taus: np.ndarray) -> np.ndarray:
    """Overlapping Allan deviation of a rate record (IEEE Std 952, written here independently of the generator): with
    x the integrated record and m = tau fs samples per cluster,
    AVAR(tau) = sum_i (x_{i+2m} - 2 x_{i+m} + x_i)^2 / (2 tau^2 (N - 2m))."""
    x = np.concatenate([[0.0], np.cumsum(rate)]) / fs
    out = []
    for tau in taus:
        m = int(round(tau * fs))
        d = x[2 * m:] - 2.0 * x[m:-m] + x[:-2 * m]
        out.append(np.sqrt(np.mean(d * d) / (2.0 * (m / fs) ** 2)))
    return np.array(out)


def test_allan_deviation_recovers_configuration():
    """Stationary gyro and accelerometer, 200 Hz, 2 h; overlapping ADEV (overlapping_adev).

    Random walk: white noise of density N has ADEV(tau) = N / sqrt(tau), so ADEV(1 s) = N (within 10 %; the
    Gauss-Markov part adds sqrt(2/3 * tau/T) sigma = 0.18 sigma in quadrature there, < 2 %), and the slope is
    -1/2 (ADEV(0.1 s) / ADEV(1 s) = sqrt(10) within 10 %).
    Bias instability: after removing the white part (N^2/tau, N from tau = 1 s) the ADEV peaks at
    GM_ADEV_PEAK * sigma = 0.6174 sigma near 1.89 T (see test_gm_adev_constant_derivation); sigma read back
    from that peak is within 25 %. Averaged over the three axes.
    """
    tc, hours = 20.0, 2.0
    n_g, s_g = 0.6 * imu_grades.DEG_PER_SQRT_H, 36.0 * imu_grades.DEG_PER_H
    n_a, s_a = 0.08 * imu_grades.MG_PER_SQRT_HZ, 0.08 * imu_grades.MG
    g = ImuGrade(gyro_bias=720 * imu_grades.DEG_PER_H, gyro_arw=n_g, gyro_bias_instability=s_g, gyro_bias_tau=tc,
                 accel_bias=3 * imu_grades.MG, accel_vrw=n_a, accel_bias_instability=s_a, accel_bias_tau=tc)
    zero = np.zeros((int(hours * 3600 * FS), 3))
    dtheta, dv, _ = _apply(g, zero, zero, seed=11)
    taus = np.r_[0.1, 1.0, tc * np.geomspace(0.5, 6.0, 13)]
    for rate, dens, sigma in ((dtheta / DT, n_g, s_g), (dv / DT, n_a, s_a)):
        avar = np.mean([overlapping_adev(rate[:, i], FS, taus) ** 2 for i in range(3)], axis=0)
        n_est = math.sqrt(avar[1])
        assert n_est == pytest.approx(dens, rel=0.10)
        assert math.sqrt(avar[0] / avar[1]) == pytest.approx(math.sqrt(10.0), rel=0.10)
        gm_part = np.sqrt(np.clip(avar[2:] - n_est ** 2 / taus[2:], 0.0, None))
        k = int(np.argmax(gm_part))
        assert gm_part[k] / GM_ADEV_PEAK == pytest.approx(sigma, rel=0.25)
        assert 0.9 <= taus[2 + k] / tc <= 4.0
        # The whole curve follows the model.
        model = np.sqrt(dens ** 2 / taus + gm_adev(taus, sigma, tc) ** 2)
        np.testing.assert_allclose(np.sqrt(avar), model, rtol=0.2)


def test_drift_record_is_the_configured_markov_process():
    tc, sigma = 5.0, 2e-3
    g = ImuGrade(gyro_bias_instability=sigma, gyro_bias_tau=tc, accel_bias_instability=3 * sigma, accel_bias_tau=tc)
    zero = np.zeros((400_000, 3))
    dtheta, dv, info = _apply(g, zero, zero, seed=3, keep_drift=True)
    beta = info.gyro_drift
    assert beta.shape == zero.shape and info.accel_drift.shape == zero.shape
    np.testing.assert_allclose(dtheta, beta * DT, rtol=1e-12, atol=0)
    np.testing.assert_allclose(dv, info.accel_drift * DT, rtol=1e-12, atol=0)
    # Stationary from the first sample (beta_0 ~ N(0, sigma^2)): std over many independent starts.
    starts = np.array([_apply(g, np.zeros((1, 3)), seed=s, keep_drift=True)[2].gyro_drift[0] for s in range(300)])
    assert starts.std() == pytest.approx(sigma, rel=0.1)
    # Lag-1 autocorrelation exp(-dt/T) and a stationary variance sigma^2 (record of 400 T, 3 axes).
    x = beta - beta.mean(axis=0)
    rho = np.sum(x[1:] * x[:-1]) / np.sum(x * x)
    assert rho == pytest.approx(math.exp(-DT / tc), abs=2e-4)
    assert beta.std() == pytest.approx(sigma, rel=0.15)
    assert _apply(g, zero[:10], seed=3)[2].gyro_drift is None


# ---------------------------------------------------------------------------------------------------------
# (b) turn-on bias and sensor matrix in the mean of constant-rate records


def test_bias_and_matrix_show_in_constant_rate_means():
    """Four constant segments (at rest, then about x, y, z) of one run: the segment means give b and M."""
    g = ImuGrade(gyro_bias=720 * imu_grades.DEG_PER_H, gyro_bias_instability=10 * imu_grades.DEG_PER_H,
                 gyro_bias_tau=50.0, gyro_arw=0.6 * imu_grades.DEG_PER_SQRT_H, gyro_scale=2e-3, gyro_nonorth=1e-3,
                 accel_bias=3 * imu_grades.MG, accel_bias_instability=15 * imu_grades.UG, accel_bias_tau=50.0,
                 accel_vrw=0.08 * imu_grades.MG_PER_SQRT_HZ, accel_scale=2e-3, accel_nonorth=1e-3)
    seg = int(1000 * FS)  # 1000 s each
    r_w, r_f = 0.5, 9.8
    w_true = np.array([[0, 0, 0], [r_w, 0, 0], [0, r_w, 0], [0, 0, r_w]], float)
    f_true = np.array([[0, 0, 0], [r_f, 0, 0], [0, r_f, 0], [0, 0, r_f]], float)
    dtheta, dv, info = _apply(g, np.repeat(w_true * DT, seg, axis=0), np.repeat(f_true * DT, seg, axis=0), seed=5)
    for out, true, r, m_drawn, b_drawn, dens, sig, tau in (
            (dtheta, w_true, r_w, info.gyro_matrix, info.gyro_bias, g.gyro_arw, g.gyro_bias_instability, 50.0),
            (dv, f_true, r_f, info.accel_matrix, info.accel_bias, g.accel_vrw, g.accel_bias_instability, 50.0)):
        means = out.reshape(4, seg, 3).mean(axis=1) / DT
        np.testing.assert_allclose(means, true @ m_drawn.T + b_drawn, rtol=0, atol=5 * math.hypot(
            dens / math.sqrt(seg * DT), sig * math.sqrt(2 * tau / (seg * DT))))
        b_est = means[0]
        m_est = (means[1:] - b_est).T / r
        tol_m = 10 * math.hypot(dens / math.sqrt(seg * DT), sig * math.sqrt(2 * tau / (seg * DT))) / r
        np.testing.assert_allclose(m_est, m_drawn, rtol=0, atol=tol_m)
        # The errors are far larger than the tolerance, so this is a real check of b and M.
        assert np.abs(b_drawn).max() > 5 * tol_m * r and np.abs(m_drawn - np.eye(3)).max() > 3 * tol_m


def test_drawn_constants_have_the_configured_statistics():
    g = ImuGrade(gyro_bias=1e-3, gyro_scale=2e-3, gyro_nonorth=3e-3, accel_bias=0.03, accel_scale=4e-3,
                 accel_nonorth=5e-3)
    infos = [_apply(g, np.zeros((1, 3)), seed=s)[2] for s in range(400)]
    gm = np.array([i.gyro_matrix for i in infos])
    am = np.array([i.accel_matrix for i in infos])
    for mats, scale, nonorth in ((gm, g.gyro_scale, g.gyro_nonorth), (am, g.accel_scale, g.accel_nonorth)):
        np.testing.assert_array_equal(mats, np.transpose(mats, (0, 2, 1)))  # skew-free: no rotation part
        diag = np.diagonal(mats, axis1=1, axis2=2) - 1.0
        off = mats[:, [0, 0, 1], [1, 2, 2]]
        assert diag.std() == pytest.approx(scale, rel=0.1)
        assert off.std() == pytest.approx(nonorth, rel=0.1)
        assert abs(diag.mean()) < 4 * scale / math.sqrt(diag.size)
    assert np.std([i.gyro_bias for i in infos]) == pytest.approx(g.gyro_bias, rel=0.1)
    assert np.std([i.accel_bias for i in infos]) == pytest.approx(g.accel_bias, rel=0.1)
    # Zero sigma draws nothing visible.
    info = _apply(ImuGrade(), np.zeros((1, 3)))[2]
    np.testing.assert_array_equal(info.gyro_matrix, np.eye(3))
    np.testing.assert_array_equal(info.accel_bias, np.zeros(3))


# ---------------------------------------------------------------------------------------------------------
# (c) saturation


def test_saturation_clips_rate_and_specific_force():
    r_g, r_a = math.radians(125.0), 16 * imu_grades.G0
    g = ImuGrade(gyro_range=r_g, accel_range=r_a)
    ramp = np.linspace(-2.0, 2.0, 4001)
    w = np.column_stack([ramp * r_g, -ramp * r_g, 0.5 * ramp * r_g])
    f = np.column_stack([ramp * r_a, 0.1 * ramp * r_a, -ramp * r_a])
    dtheta, dv, info = _apply(g, w * DT, f * DT)
    np.testing.assert_array_equal(dtheta, np.clip(w * DT, -r_g * DT, r_g * DT))
    np.testing.assert_array_equal(dv, np.clip(f * DT, -r_a * DT, r_a * DT))
    assert np.abs(dtheta).max() == r_g * DT and np.abs(dv).max() == r_a * DT
    np.testing.assert_array_equal(info.gyro_clipped, np.count_nonzero(np.abs(w) > r_g, axis=0))
    np.testing.assert_array_equal(info.accel_clipped, np.count_nonzero(np.abs(f) > r_a, axis=0))
    assert info.gyro_clipped[2] == 0 and info.accel_clipped[1] == 0
    # Errors are applied before the clip: a biased sensor saturates at the same limit.
    biased = ImuGrade(gyro_range=r_g, gyro_bias=0.1, gyro_arw=1e-3, accel_range=r_a)
    dtheta_b, _, _ = _apply(biased, w * DT, f * DT, seed=2)
    assert np.abs(dtheta_b).max() <= r_g * DT
    # With quantization the carried residual may take a reported increment past the limit, by under one step,
    # while the running sum stays within half a step of the clipped running sum.
    q = 1e-4
    dtheta_q, _, _ = _apply(ImuGrade(gyro_range=r_g, gyro_quant=q), w * DT)
    assert np.abs(dtheta_q).max() < r_g * DT + q
    clipped_sum = np.cumsum(np.clip(w * DT, -r_g * DT, r_g * DT), axis=0)
    assert np.abs(np.cumsum(dtheta_q, axis=0) - clipped_sum).max() <= q / 2 * (1 + 1e-6)


# ---------------------------------------------------------------------------------------------------------
# (d) quantization with residual carry


@pytest.mark.parametrize("q_th, q_v", [(1e-6, 1e-5), (3.3e-5, 7e-4)])
def test_quantization_carries_the_residual(q_th, q_v):
    rng = np.random.default_rng(8)
    n = 200_000
    w = 0.3 * np.sin(np.linspace(0, 40, n))[:, None] + rng.normal(0, 0.05, (n, 3))
    f = np.array([0.2, -0.1, 9.81]) + rng.normal(0, 0.3, (n, 3))
    ideal_th, ideal_v = w * DT, f * DT
    dtheta, dv, _ = _apply(ImuGrade(gyro_quant=q_th, accel_quant=q_v), ideal_th, ideal_v)
    for out, ideal, q in ((dtheta, ideal_th, q_th), (dv, ideal_v, q_v)):
        steps = out / q
        np.testing.assert_allclose(steps, np.rint(steps), rtol=0, atol=1e-9)
        gap = np.abs(np.cumsum(out, axis=0) - np.cumsum(ideal, axis=0))
        assert gap.max() <= q / 2 * (1 + 1e-6) + 1e-12 * np.abs(np.cumsum(ideal, axis=0)).max()
        # Rounding each sample on its own would drift.
        naive = np.abs(np.cumsum(np.rint(ideal / q) * q, axis=0) - np.cumsum(ideal, axis=0)).max()
        assert naive > 5 * q


def test_quantization_after_noise_stays_on_the_grid():
    q = 1e-5
    g = {"gyro_arw": 1e-3, "gyro_bias": 1e-2, "gyro_quant": q}
    dtheta, _, _ = _apply(ImuGrade(**g), np.full((10_000, 3), 1e-3))
    unq, _, _ = _apply(ImuGrade(**{**g, "gyro_quant": 0.0}), np.full((10_000, 3), 1e-3))
    np.testing.assert_allclose(dtheta / q, np.rint(dtheta / q), rtol=0, atol=1e-9)
    assert np.abs(np.cumsum(dtheta, axis=0) - np.cumsum(unq, axis=0)).max() <= q / 2 * (1 + 1e-6)


# ---------------------------------------------------------------------------------------------------------
# (e) reproducibility


def test_same_seed_same_output_different_seed_different(monkeypatch):
    g = grade("icm-42605")
    rng = np.random.default_rng(1)
    w = rng.normal(0, 0.5, (60_000, 3)) * DT
    f = (np.array([0, 0, 9.8]) + rng.normal(0, 1, (60_000, 3))) * DT
    a = _apply(g, w, f, seed=42, keep_drift=True)
    b = _apply(g, w, f, seed=42, keep_drift=True)
    c = _apply(g, w, f, seed=43)
    for x, y in zip(a[:2], b[:2]):
        np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(a[2].gyro_matrix, b[2].gyro_matrix)
    np.testing.assert_array_equal(a[2].accel_drift, b[2].accel_drift)
    assert not np.array_equal(a[0], c[0]) and not np.array_equal(a[1], c[1])
    assert not np.array_equal(a[2].gyro_bias, c[2].gyro_bias)
    # The two-thread path (long records) and the serial path give the same numbers.
    monkeypatch.setattr(imu_errors, "_THREAD_MIN_SAMPLES", 10 ** 12)
    s = _apply(g, w, f, seed=42)
    np.testing.assert_array_equal(s[0], a[0])
    np.testing.assert_array_equal(s[1], a[1])


def test_stepping_in_blocks_equals_one_step():
    """ImuErrorModel fed a run in blocks (empty ones, single samples, long ones on two threads) gives, bit for bit,
    apply_imu_errors over the run: Gauss-Markov bias, quantizer residual, clip counts and generators carry on, and
    beta_0 is drawn at the run's first sample only."""
    g = ImuGrade(gyro_bias=1e-3, gyro_bias_instability=2e-4, gyro_bias_tau=3.0, gyro_arw=1e-4, gyro_scale=1e-3,
                 gyro_nonorth=1e-3, gyro_quant=1e-6, gyro_range=0.5, accel_bias=1e-2, accel_bias_instability=1e-3,
                 accel_bias_tau=5.0, accel_vrw=1e-3, accel_scale=1e-3, accel_nonorth=1e-3, accel_quant=1e-5,
                 accel_range=12.0)
    rng = np.random.default_rng(24)
    n = 2 * imu_errors._THREAD_MIN_SAMPLES + 5000
    w, f = rng.normal(0, 0.4, (n, 3)) * DT, rng.normal(0, 8, (n, 3)) * DT
    dtheta, dv, info = _apply(g, w, f, seed=6, keep_drift=True)
    assert info.gyro_clipped.min() > 0 and info.accel_clipped.min() > 0  # saturation active
    for cuts in ([0, 0, 1, 2, 3, 10, imu_errors._THREAD_MIN_SAMPLES + 10, n - 1],
                 np.sort(rng.integers(0, n, 12)), np.sort(rng.integers(0, 20, 12))):
        model = ImuErrorModel(DT, g, np.random.default_rng(6), keep_drift=True)
        out = [model.step(a, b) for a, b in zip(np.split(w, cuts), np.split(f, cuts))]
        np.testing.assert_array_equal(np.concatenate([o[0] for o in out]), dtheta)
        np.testing.assert_array_equal(np.concatenate([o[1] for o in out]), dv)
        for field in ("gyro_bias", "accel_matrix", "gyro_clipped", "accel_clipped", "gyro_drift", "accel_drift"):
            np.testing.assert_array_equal(getattr(model.info, field), getattr(info, field))
        assert model.samples == n


def test_common_random_numbers_across_grades():
    """Par 4 and Par 5 of 001 differ only in the gyro random walk (1 and 2 deg/sqrt(h)): same seed, same draws."""
    zero = np.zeros((5000, 3))
    d4, v4, _ = _apply(grade("par4"), zero, zero, seed=9)
    d5, _, _ = _apply(grade("par5"), zero, zero, seed=9)
    np.testing.assert_allclose(d5, 2.0 * d4, rtol=1e-12)
    np.testing.assert_array_equal(v4, zero)
    assert d4.std() / math.sqrt(DT) == pytest.approx(1.0 * imu_grades.DEG_PER_SQRT_H, rel=0.05)


def test_ideal_grade_is_identity_and_inputs_untouched():
    rng = np.random.default_rng(4)
    w, f = rng.normal(size=(1000, 3)), rng.normal(size=(1000, 3))
    w0, f0 = w.copy(), f.copy()
    dtheta, dv, info = _apply(grade("ideal"), w, f)
    np.testing.assert_array_equal(dtheta, w0)
    np.testing.assert_array_equal(dv, f0)
    np.testing.assert_array_equal(w, w0)
    assert dtheta is not w
    assert info.gyro_drift is None and np.all(info.gyro_clipped == 0)
    empty = _apply(grade("mti-g-700"), np.zeros((0, 3)))
    assert empty[0].shape == (0, 3) and empty[1].shape == (0, 3)


def test_invalid_inputs_are_rejected():
    z = np.zeros((10, 3))
    g = grade("mti-g-700")
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="shape"):
        apply_imu_errors(np.zeros((10, 2)), z, DT, g, rng)
    with pytest.raises(ValueError, match="same shape"):
        apply_imu_errors(z, np.zeros((9, 3)), DT, g, rng)
    bad = z.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        apply_imu_errors(z, bad, DT, g, rng)
    for dt in (0.0, -1.0, math.inf):
        with pytest.raises(ValueError, match="dt"):
            apply_imu_errors(z, z, dt, g, rng)
    with pytest.raises(TypeError):
        apply_imu_errors(z, z, DT, "mti-g-700", rng)
    with pytest.raises(TypeError):
        apply_imu_errors(z, z, DT, g, 1)
    with pytest.raises(ValueError, match="same shape"):
        ImuErrorModel(DT, g, rng).step(z, np.zeros((9, 3)))
    with pytest.raises(ValueError):
        ImuGrade(gyro_arw=-1.0)
    with pytest.raises(ValueError):
        ImuGrade(gyro_bias_instability=1e-5)  # no correlation time
    with pytest.raises(ValueError):
        ImuGrade(accel_bias=math.inf)
    with pytest.raises(ValueError):
        ImuGrade(gyro_range=0.0)


# ---------------------------------------------------------------------------------------------------------
# (f) presets


def _names_in(text: str) -> set[str]:
    """Grade names in a docstring's list, with 'par1 .. par12' expanded."""
    names = set(re.findall(r"\b(mti-g-700|nav-004|mti-30|icm-42605|ideal)\b", text))
    for lo, hi in re.findall(r"par(\d+)\s*\.\.\s*par(\d+)", text):
        names |= {f"par{i}" for i in range(int(lo), int(hi) + 1)}
    return names


def test_every_documented_preset_exists():
    expected = {"mti-g-700", "nav-004", "mti-30", "icm-42605", "ideal"} | {f"par{i}" for i in range(1, 13)}
    assert set(GRADES) == expected
    assert _names_in(imu_grades.__doc__) == expected
    source = inspect.getsource(sensor_config)
    listed = re.search(r"A preset of twin\.config\.imu_grades \(([^)]*)\)", source)
    assert listed is not None
    assert _names_in(listed.group(1)) <= set(GRADES)
    assert sensor_config.Imu().grade in GRADES and sensor_config.SupportImu().grade in GRADES
    for name, g in GRADES.items():
        assert grade(name) is g and isinstance(g, ImuGrade)


def test_unknown_grade_lists_the_valid_names():
    with pytest.raises(KeyError) as err:
        grade("nope")
    msg = str(err.value)
    assert "nope" in msg and "\n" not in msg
    for name in GRADES:
        assert name in msg


def test_preset_values_in_si():
    """Spot checks of the unit conversions against the papers' tables."""
    mti = grade("mti-g-700")  # 001 Table 1
    assert mti.gyro_bias == pytest.approx(math.radians(720.0) / 3600.0)
    assert mti.gyro_arw == pytest.approx(math.radians(0.6) / 60.0)
    assert mti.gyro_arw == pytest.approx(math.radians(0.01))  # = 0.01 deg/s/sqrt(Hz), the Xsens figure
    assert mti.accel_bias == pytest.approx(3e-3 * 9.80665)
    assert mti.accel_vrw == pytest.approx(0.08e-3 * 9.80665)
    assert GM_ADEV_PEAK * mti.gyro_bias_instability == pytest.approx(math.radians(10.0) / 3600.0)
    assert GM_ADEV_PEAK * mti.accel_bias_instability == pytest.approx(15e-6 * 9.80665)
    for i, (gb, grw, ab, arw) in enumerate([(100, 0, 0, 0), (200, 0, 0, 0), (300, 0, 0, 0), (0, 1, 0, 0),
                                            (0, 2, 0, 0), (0, 3, 0, 0), (0, 0, 1, 0), (0, 0, 2, 0),
                                            (0, 0, 3, 0), (0, 0, 0, 1), (0, 0, 0, 2), (0, 0, 0, 3)], start=1):
        expect = ImuGrade(gyro_bias=math.radians(gb) / 3600, gyro_arw=math.radians(grw) / 60,
                          accel_bias=ab * 9.80665e-3, accel_vrw=arw * 9.80665e-3)
        got = grade(f"par{i}")  # 001 Table 2
        for field in ("gyro_bias", "gyro_arw", "accel_bias", "accel_vrw"):
            assert getattr(got, field) == pytest.approx(getattr(expect, field), abs=1e-15)
        assert got.gyro_bias_instability == got.accel_bias_instability == 0 == got.gyro_scale
        assert math.isinf(got.gyro_range) and math.isinf(got.accel_range)
    nav = grade("nav-004")  # 004 Table 1
    assert nav.gyro_bias == pytest.approx(math.radians(0.001) / 3600)
    assert nav.gyro_arw == pytest.approx(math.radians(0.0001) / 60)
    assert nav.accel_bias == pytest.approx(30e-6 * 9.80665)
    icm = grade("icm-42605")  # 002 section 2.2 ranges
    assert icm.gyro_range == pytest.approx(math.radians(125.0))
    assert icm.accel_range == pytest.approx(16 * 9.80665)
    ideal = grade("ideal")
    assert all(getattr(ideal, f) == 0 for f in ("gyro_bias", "gyro_arw", "accel_bias", "accel_vrw", "gyro_quant"))
    assert math.isinf(ideal.gyro_range) and math.isinf(ideal.accel_range)


def test_bias_psd_is_the_random_walk_matching_the_gauss_markov_bias():
    """A filter's random-walk bias state grows like the Gauss-Markov bias over its correlation time:
    q tau = 2 sigma^2 (the bias's variance doubled), and no in-run bias gives none."""
    g = grade("mti-g-700")
    assert g.gyro_bias_instability > 0 and g.accel_bias_instability > 0
    assert g.gyro_bias_psd * g.gyro_bias_tau == pytest.approx(2 * g.gyro_bias_instability ** 2, rel=1e-15)
    assert g.accel_bias_psd * g.accel_bias_tau == pytest.approx(2 * g.accel_bias_instability ** 2, rel=1e-15)
    assert grade("ideal").gyro_bias_psd == 0.0 == grade("ideal").accel_bias_psd
