"""estimators.io.metrics: closed-form position and attitude errors, per-cycle statistics, NEES band."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from estimators.io import stream_median
from estimators.io.logformat import ESTIMATE, TRUTH_CYCLES, LogError, make_table
from estimators.io.metrics import (
    attitude_errors,
    cycle_metrics,
    enu_offset_to_geodetic,
    error_stats,
    nees,
    nees_band,
    position_errors,
    CycleScore,
    TruthTrack,
    column,
    slerp,
    truth_at,
)
from estimators.io.self_assessment import SelfAssessment, self_assessment
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


class CountedBlocks:
    """Blocks iterable again, counting the blocks read."""

    def __init__(self, blocks):
        self.blocks, self.read = blocks, 0

    def __iter__(self):
        for block in self.blocks:
            self.read += 1
            yield block


def test_truth_queried_in_pieces_reads_the_blocks_once_and_equals_the_whole():
    """Pieces of ascending times (a pass at a time; a piece may start on the previous piece's block) go on from
    the block the track is on: the blocks are read once, and each piece equals the whole table's answer bit for bit.
    A piece earlier than that block reads the blocks again from the first, and is right too."""
    truth = straight_truth(2001, 0.05)
    rng = np.random.default_rng(5)
    t = np.sort(np.concatenate([rng.uniform(0, truth["t"][-1], 900), truth["t"][[0, -1]]]))
    whole = truth_at(truth, t)
    edges = [0, 3, 400, 401, 1200, 1999, truth["t"].size]
    blocks = CountedBlocks([{k: v[a:b] for k, v in truth.items()} for a, b in zip(edges[:-1], edges[1:])])
    track = TruthTrack(blocks)
    cuts = [0, 1, 150, 151, 420, 899, t.size]
    for a, b in zip(cuts[:-1], cuts[1:]):
        part = track.at(t[a:b])
        for k in ("lat", "lon", "h", "q_nb"):
            np.testing.assert_array_equal(part[k], whole[k][a:b], err_msg=f"{k} over rows {a}..{b}")
    assert blocks.read == len(edges) - 1
    back = track.at(t[10:30])  # before the block the track is on: read again from the first
    np.testing.assert_array_equal(back["lat"], whole["lat"][10:30])
    assert blocks.read > len(edges) - 1


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


def assert_same_numbers(blocked, whole, where: str = "") -> None:
    """Equal structures; sums (rmse, distance) to 1e-12 relative, everything else exactly."""
    if isinstance(whole, dict):
        assert blocked.keys() == whole.keys(), where
        for k in whole:
            assert_same_numbers(blocked[k], whole[k], f"{where}/{k}")
    elif isinstance(whole, list):
        assert len(blocked) == len(whole), where
        for i, (b, w) in enumerate(zip(blocked, whole)):
            assert_same_numbers(b, w, f"{where}[{i}]")
    elif isinstance(whole, float) and ("rmse" in where or "distance" in where):
        assert blocked == pytest.approx(whole, rel=1e-12, nan_ok=True), where
    else:
        assert blocked == whole or (blocked != blocked and whole != whole), where


@pytest.mark.parametrize("spill", [False, True])
def test_scores_in_blocks_equal_the_whole(monkeypatch, spill):
    """CycleScore and SelfAssessment over an estimate pushed a few rows or a pass at a time (cuts inside cycles,
    on a cycle's end, on a straight cut's end, at a survey fix) give cycle_metrics and self_assessment of the
    whole: the sums to the last bits, counts, largest values and medians (held, or spilled to the scratch file)
    exactly; a cycle's errors are let go once the times pass its end; blocks out of time order are refused."""
    if spill:
        monkeypatch.setattr(stream_median, "IN_MEMORY", 40)
    truth = straight_truth()
    t = np.arange(0.05, 99.0, 0.25)
    rng = np.random.default_rng(11)
    estimate = offset_estimate(truth, t, [0.2, -0.1, 0.05], sd=0.03)
    lat = column(estimate, "lat") + rng.normal(0.0, 1e-7, t.size)
    sd = np.abs(rng.normal(0.1, 0.02, t.size))
    sd[5:40] = np.nan
    flags = rng.integers(0, 256, t.size).astype(np.int32)
    estimate = estimate.set_column(estimate.column_names.index("lat"), "lat", pa.array(lat))
    estimate = estimate.set_column(estimate.column_names.index("sd_pos_e"), "sd_pos_e", pa.array(sd))
    estimate = estimate.set_column(estimate.column_names.index("flags"), "flags", pa.array(flags))
    cycles = make_table(TRUTH_CYCLES, {
        "cycle": np.arange(3), "direction": np.array([1, -1, 1]), "t": np.array([0.0, 30.0, 60.0]),
        "t_cut_end": np.array([12.05, 40.0, 75.0]), "t_sump_end": np.array([15.0, 45.0, 80.0]),
        "t_push_end": np.array([16.0, 46.0, 81.0]), "t_end": np.array([30.0, 60.0, 99.0]),
        "s_sump": np.full(3, 5.0)})
    survey = {"t": np.array([0.0, 30.0, 30.01, 61.3, 120.0]), **{k: column(estimate, k)[[0, 50, 90, 200, -1]]
                                                                 for k in ("lat", "lon", "h")},
              "sd_horizontal": np.full(5, 0.2), "sd_vertical": np.full(5, 0.3)}
    t_err, err = position_errors(estimate, truth)
    whole_cycles, whole_self = cycle_metrics(t_err, err, cycles), self_assessment(estimate, survey)
    assert len(whole_self["survey_residuals"]) == 4 and whole_self["max_sd_horizontal_m"] is not None
    for edges in ([0, 1, 2, 48, 119, 120, 200, 321, t.size], [0, 120, 240, t.size], [0, t.size]):
        score, own = CycleScore(cycles), SelfAssessment(survey)
        for a, b in zip(edges[:-1], edges[1:]):
            score.push(t_err[a:b], err[a:b])
            own.push(estimate.slice(a, b - a))
            if t_err[b - 1] >= 60.0:
                assert all(isinstance(w, dict) for w in score.windows[:2])  # cycles 0 and 1 are final
        assert_same_numbers(score.rows(), whole_cycles, f"cycles cut at {edges}")
        assert_same_numbers(own.result(), whole_self, f"self cut at {edges}")
    with pytest.raises(ValueError, match="time order"):
        CycleScore(cycles).push(t_err[50:60], err[50:60]).push(t_err[:10], err[:10])


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
