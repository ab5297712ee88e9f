"""estimators.io.metrics: closed-form position and attitude errors, per-cycle statistics, NEES band."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.io.logformat import ESTIMATE, TRUTH_CYCLES, LogError, make_table
from estimators.io.metrics import (
    attitude_errors,
    cycle_metrics,
    enu_offset_to_geodetic,
    error_stats,
    nees,
    nees_band,
    position_errors,
    TruthTrack,
    slerp,
    truth_at,
)
from estimators.nav import earth
from estimators.nav.rotations import euler_to_quat, quat_mul, rotvec_to_quat

LAT0, LON0, H0 = np.radians(34.27), np.radians(117.18), 36.0


def straight_truth(n: int = 1001, dt: float = 0.1) -> dict[str, np.ndarray]:
    """A body moving north at 0.1 m/s and yawing slowly, given at dt."""
    t = np.arange(n) * dt
    lat, lon, h = earth.enu_to_lla(np.column_stack([0.02 * t, 0.1 * t, 0.001 * t]), LAT0, LON0, H0)
    q = euler_to_quat(0.01 * np.sin(t / 20), 0.02, 0.3 + 0.001 * t)
    return {"t": t, "lat": lat, "lon": lon, "h": h, **{f"q_nb_{a}": q[:, i] for i, a in enumerate("wxyz")}}


def estimate_table(t, lat, lon, h, q, sd=np.nan, flags=0):
    """An ESTIMATE table; sd: one-sigma of every position [m], velocity and attitude [rad] axis."""
    k = t.size
    return make_table(ESTIMATE, {
        "t": t, "lat": lat, "lon": lon, "h": h, **{f"p_t_{a}": np.full(k, np.nan) for a in "enu"},
        **{f"p_f_{a}": np.full(k, np.nan) for a in "xyz"},
        **{f"v_n_{a}": np.zeros(k) for a in "enu"},
        **{f"q_nb_{a}": q[:, i] for i, a in enumerate("wxyz")},
        **{f"sd_{p}_{a}": np.full(k, sd) for p in ("pos", "vel", "att") for a in "enu"},
        "flags": np.broadcast_to(flags, (k,)).astype(np.int32)})


def offset_estimate(truth, t, offset_enu, rotvec=(0.0, 0.0, 0.0), **kwargs):
    """The truth at times t displaced by offset_enu [m] East/North/Up, its attitude rotated by rotvec:
    C_b^n(est) = Exp([rotvec x]) C_b^n(true), so the psi-angle error is phi = -rotvec."""
    true = truth_at(truth, t)
    lat, lon, h = enu_offset_to_geodetic(np.broadcast_to(offset_enu, (t.size, 3)), true["lat"], true["lon"],
                                         true["h"])
    q = quat_mul(rotvec_to_quat(np.broadcast_to(rotvec, (t.size, 3))), true["q_nb"])
    return estimate_table(t, lat, lon, h, q, **kwargs)


def test_truth_in_blocks_is_the_whole_truth_bit_for_bit():
    """TruthTrack over blocks of rows cut anywhere gives the whole table's interpolation exactly: times between
    samples, on samples (a block's first and last included), at both ends; a longitude crossing +-pi unwrapped with
    its correction summed across the blocks; the cycle at or before each time."""
    truth = straight_truth(2001, 0.05)
    lon = truth["lon"] - LON0 + np.pi - 5e-9  # the track crosses the antimeridian
    truth["lon"] = np.angle(np.exp(1j * lon))
    truth["cycle"] = (truth["t"] // 37.0).astype(float)
    rng = np.random.default_rng(3)
    t = np.sort(np.concatenate([rng.uniform(0, truth["t"][-1], 700), truth["t"][::97], truth["t"][[0, -1]]]))
    whole = truth_at(truth, t)
    assert np.ptp(whole["lon"]) < 1.0  # unwrapped: no 2 pi jump
    whole_slerp = slerp(truth["t"], np.column_stack([truth[f"q_nb_{a}"] for a in "wxyz"]), t)
    np.testing.assert_array_equal(whole["q_nb"], whole_slerp)
    for cuts in ([1, 2, 500, 501, 1700], [97 * 5, 97 * 11 + 1], list(range(100, 2000, 131))):
        edges = [0, *cuts, truth["t"].size]
        blocks = [{k: v[a:b] for k, v in truth.items()} for a, b in zip(edges[:-1], edges[1:])]
        track = TruthTrack(blocks)
        part = track.at(t)
        for k in ("lat", "lon", "h", "q_nb", "cycle"):
            np.testing.assert_array_equal(part[k], whole[k], err_msg=f"{k} cut at {cuts}")
        assert track.at(t.copy()) is part  # the same epochs again: kept, not read again
    with pytest.raises(LogError, match="outside the truth span"):
        TruthTrack(blocks).at(np.array([truth["t"][-1] + 1.0]))


def test_constant_east_offset_gives_rmse_and_sep():
    truth = straight_truth()
    t = np.arange(0.05, 99.0, 0.37)  # between the truth samples
    _, err = position_errors(offset_estimate(truth, t, [0.3, 0.0, 0.0]), truth)
    np.testing.assert_allclose(err, np.broadcast_to([0.3, 0.0, 0.0], err.shape), atol=1e-7)
    stats = error_stats(err)
    assert stats["rmse_e"] == pytest.approx(0.3, abs=1e-7) and stats["sep"] == pytest.approx(0.3, abs=1e-7)
    assert stats["rmse_n"] < 1e-7 and stats["max_3d"] == pytest.approx(0.3, abs=1e-7)


def test_offset_in_exact_tangent_coordinates():
    """A 2 m north-east-up offset built through ECEF is read back to well below a millimetre."""
    truth = straight_truth()
    t = truth["t"][::10]
    p = earth.lla_to_enu(truth["lat"][::10], truth["lon"][::10], truth["h"][::10], LAT0, LON0, H0)
    lat, lon, h = earth.enu_to_lla(p + [1.2, -1.5, 0.4], LAT0, LON0, H0)
    q = np.column_stack([truth[f"q_nb_{a}"][::10] for a in "wxyz"])
    _, err = position_errors(estimate_table(t, lat, lon, h, q), truth)
    np.testing.assert_allclose(err, np.broadcast_to([1.2, -1.5, 0.4], err.shape), atol=1e-4)


def test_estimate_outside_truth_span_is_one_line():
    truth = straight_truth()
    est = offset_estimate(truth, np.array([1.0, 2.0]), [0.0, 0.0, 0.0])
    late = est.set_column(0, est.schema.field("t"), [np.array([1.0, 200.0])])
    with pytest.raises(LogError, match=r"outside the truth span 0 \.\. 100 s"):
        position_errors(late, truth)


def test_known_rotation_gives_known_phi():
    """C_b^n(true) = Exp([phi x]) C_b^n(est): an estimate rotated by -phi from the truth has error phi."""
    truth = straight_truth()
    t = np.arange(0.03, 99.0, 0.7)
    phi = np.array([2e-3, -1e-3, 0.02])
    _, got = attitude_errors(offset_estimate(truth, t, [0.0, 0.0, 0.0], -phi), truth)
    np.testing.assert_allclose(got, np.broadcast_to(phi, got.shape), atol=1e-12)


def test_yaw_too_large_is_negative_phi_u():
    truth = straight_truth()
    t = truth["t"][:5]
    true = truth_at(truth, t)
    q_est = quat_mul(rotvec_to_quat([0.0, 0.0, 0.01]), true["q_nb"])  # yaw estimate 0.01 rad too large
    _, phi = attitude_errors(estimate_table(t, true["lat"], true["lon"], true["h"], q_est), truth)
    np.testing.assert_allclose(phi, np.broadcast_to([0.0, 0.0, -0.01], phi.shape), atol=1e-12)


def test_slerp_constant_rate():
    """Rotation about a fixed axis at a constant rate is reproduced exactly between the samples."""
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    t_src = np.arange(11.0)
    q_src = rotvec_to_quat(0.2 * t_src[:, None] * axis)
    t = np.linspace(0, 10, 77)
    np.testing.assert_allclose(slerp(t_src, q_src, t), rotvec_to_quat(0.2 * t[:, None] * axis), atol=1e-13)


def test_cycle_metrics_windows():
    t = np.arange(0.0, 30.0, 0.5)
    err = np.zeros((t.size, 3))
    err[t < 10, 0] = 0.3           # cycle 0: 0.3 m east
    err[(t >= 10) & (t < 14), 1] = -0.4  # cycle 1 straight cut: 0.4 m south
    err[t >= 14, 2] = 1.0          # the rest of cycle 1: 1 m up
    cycles = make_table(TRUTH_CYCLES, {
        "cycle": np.array([0, 1]), "direction": np.array([1, -1]), "t": np.array([0.0, 10.0]),
        "t_cut_end": np.array([4.0, 13.9]), "t_sump_end": np.array([6.0, 16.0]),
        "t_push_end": np.array([7.0, 17.0]), "t_end": np.array([10.0, 29.5]), "s_sump": np.array([5.0, 5.0])})
    rows = cycle_metrics(t, err, cycles)
    assert [r["cycle"] for r in rows] == [0, 1, "all"]
    first, second, total = rows
    assert first["samples"] == 20 and first["rmse_e"] == pytest.approx(0.3) and first["sep"] == pytest.approx(0.3)
    assert first["straight_cut"]["samples"] == 9 and first["straight_cut"]["rmse_n"] == 0.0
    assert second["samples"] == 40 and second["max_3d"] == pytest.approx(1.0)
    assert second["sep"] == pytest.approx(1.0)  # 32 of 40 samples are 1 m up
    assert second["straight_cut"]["rmse_n"] == pytest.approx(0.4) and second["straight_cut"]["max_3d"] == 0.4
    assert second["max_horizontal"] == pytest.approx(0.4) and second["max_n"] == pytest.approx(0.4)
    assert first["max_e"] == pytest.approx(0.3) and first["max_n"] == 0.0
    assert total["samples"] == t.size and total["straight_cut"]["samples"] == 9 + 8
    assert total["rmse_u"] == pytest.approx(np.sqrt(32 / 60))


def test_nees_inside_band_when_consistent_outside_when_not():
    rng = np.random.default_rng(7)
    trials, steps, dof = 40, 500, 3
    sd = np.broadcast_to(np.array([0.1, 0.2, 0.05]), (trials, steps, dof))
    err = rng.normal(size=sd.shape) * sd
    lo, hi = nees_band(dof, trials)
    mean = nees(err, sd).mean(axis=0)
    inside = np.mean((mean >= lo) & (mean <= hi))
    assert 0.92 < inside < 0.98
    assert np.mean((nees(1.5 * err, sd).mean(axis=0) >= lo) & (nees(1.5 * err, sd).mean(axis=0) <= hi)) < 0.01
    assert np.mean(nees(0.7 * err, sd).mean(axis=0) < lo) > 0.99
    assert nees_band(3, 1) == pytest.approx((0.2158, 9.3484), abs=1e-4)


def test_nees_shape_mismatch():
    with pytest.raises(ValueError, match="differ in shape"):
        nees(np.zeros((4, 3)), np.ones((4, 2)))
