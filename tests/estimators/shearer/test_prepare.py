"""The filter epochs' odometer channel (estimators.shearer.prepare): a coasting stop waits before its zero-velocity
update."""

from __future__ import annotations

import dataclasses

import numpy as np

from estimators.io.log import log_from_columns
from estimators.shearer.odometer_filter import MODE_MOVING, MODE_SETTLING, MODE_STANDING
from estimators.nav.rotations import euler_to_mat
from estimators.shearer.prepare import prepare
from estimators.sins.strapdown import compensated_increments
from tests.conftest import simulated
from twin.pipeline.estimate import positioning_config
from twin.sensors.streams import imu_truth, sensor_streams


def test_a_coasting_stop_settles_before_the_zero_velocity_update():
    """The twin's haulage coasts after its direction signal drops (0.2 s at the end of a pass, moving by less
    than a pulse) and creeps before it comes on. No epoch within stand_settle_s of the odometer's counts or
    direction is a stand; the machine stands still (within the update's noise) in every stand epoch; a longer settle time makes more epochs
    settle. Without the settle window the epochs next to a stop or start are stands while the machine moves."""
    scn, result = simulated("default")
    streams = sensor_streams(scn, result.tables, imu_truth(scn, result.tables["truth_shearer"]), 0)
    log = log_from_columns(streams["imu"], streams["odometer"], streams["survey"])
    cfg = positioning_config(scn)
    prep = prepare(log, cfg)
    active = (log.odo_direction != 0) | (np.diff(log.odo_distance, prepend=log.odo_distance[0]) != 0)
    t_last = log.odo_t[active]
    lo = prep.t_kf[:-1]
    last = np.searchsorted(t_last, lo, side="right") - 1
    since = np.where(last >= 0, lo - t_last[np.maximum(last, 0)], np.inf)  # before the first motion: settled
    nxt = np.searchsorted(t_last, prep.t_kf[1:], side="left")
    until = np.where(nxt < t_last.size, t_last[np.minimum(nxt, t_last.size - 1)] - prep.t_kf[1:], np.inf)
    since = np.minimum(since, until)
    mode = prep.mode[1:]
    assert np.all(since[mode == MODE_STANDING] >= cfg.stand_settle_s)
    settling = mode == MODE_SETTLING
    assert settling.any() and np.all(since[settling] < cfg.stand_settle_s)
    stops = np.flatnonzero((mode[:-1] == MODE_MOVING) & (mode[1:] != MODE_MOVING)) + 1
    starts = np.flatnonzero((mode[:-1] != MODE_MOVING) & (mode[1:] == MODE_MOVING))
    assert stops.size >= 2 and np.all(mode[stops] == MODE_SETTLING) and np.all(mode[starts] == MODE_SETTLING)
    # The truth still moves in some settling epochs: they are the ones a stand would have got wrong.
    truth = result.tables["truth_shearer"]
    speed = np.interp(prep.t_kf[1:], truth["t"], np.linalg.norm(np.column_stack(
        [truth[f"v_n_{a}"] for a in "enu"]), axis=1))
    assert speed[settling].max() > cfg.r_zupt
    # Within the zero-velocity update's noise: a standing shearer still rides its pans, which move by the connectors'
    # axial play (mm) while neighbours are pushed.
    assert speed[mode == MODE_STANDING].max() < cfg.r_zupt
    longer = prepare(log, dataclasses.replace(cfg, stand_settle_s=2 * cfg.stand_settle_s))
    assert (longer.mode == MODE_SETTLING).sum() > (prep.mode == MODE_SETTLING).sum()


def test_a_log_in_which_the_machine_never_moves_is_all_stand():
    """The default run up to 2 s before the haulage first moves (the alignment stand): every epoch is a stand,
    none settling or moving (there was an IndexError: no odometer sample showed motion)."""
    scn, result = simulated("default")
    streams = sensor_streams(scn, result.tables, imu_truth(scn, result.tables["truth_shearer"]), 0)
    odo = streams["odometer"]
    t_end = odo["t"][np.argmax(odo["direction"] != 0)] - 2.0
    cut = {name: {k: v[streams[name]["t"] <= t_end] for k, v in streams[name].items()}
           for name in ("imu", "odometer")}
    log = log_from_columns(cut["imu"], cut["odometer"], streams["survey"])
    assert not np.any(log.odo_direction) and np.ptp(log.odo_distance) == 0
    prep = prepare(log, positioning_config(scn))
    assert np.all(prep.mode == MODE_STANDING) and prep.cuts == []


def test_each_pass_reads_the_increments_the_whole_log_gives():
    """The filters read a pass's increments when they run it (Prepared.mech): every segment's, and any window of
    epochs, are the whole log's compensated increments sliced at its epochs, bit for bit, and the epochs' times are
    the whole log's update times."""
    scn, result = simulated("default")
    streams = sensor_streams(scn, result.tables, imu_truth(scn, result.tables["truth_shearer"]), 0)
    log = log_from_columns(streams["imu"], streams["odometer"], streams["survey"])
    cfg = positioning_config(scn)
    prep = prepare(log, cfg)
    dt = np.median(np.diff(log.imu_t))
    mat_bs = euler_to_mat(*cfg.imu_mounting_rad)
    t = np.concatenate([[log.imu_t[0] - 1.0 / (1.0 / dt)], log.imu_t])
    zero = np.zeros((1, 3))
    t_mech, phi_b, dv_b = compensated_increments(t, np.concatenate([zero, log.dtheta @ mat_bs.T]),
                                                 np.concatenate([zero, log.dv @ mat_bs.T]), cfg.n_samples)
    assert np.array_equal(prep.t_kf, t_mech[::prep.steps][:prep.t_kf.size])
    assert len(prep.segments) >= 3
    for a, b in [*prep.segments, (0, 7), (prep.segments[1][0] + 3, prep.segments[2][0] + 5)]:
        mech = prep.mech(a, b)
        rows = slice(a * prep.steps, b * prep.steps)
        assert np.array_equal(mech.t, t_mech[a * prep.steps:b * prep.steps + 1])
        assert np.array_equal(mech.phi_b, phi_b[rows]) and np.array_equal(mech.dv_b, dv_b[rows])
