"""The independent trajectory generator (tests/estimators/shearer/trajectories.py) checked on its own: its exact
increments mechanized from the true start reproduce its closed-form truth, and its log says what the path is."""

import numpy as np
import pytest

from estimators.nav import earth
from estimators.nav.rotations import quat_to_euler
from estimators.sins.strapdown import mechanize
from tests.estimators.shearer.trajectories import Errors, Face, Trajectory

DEG = np.pi / 180


@pytest.mark.parametrize("azimuth, lat, minutes", [(0.0, 55.0, 10), (250.0, -30.0, 10), (90.0, 70.0, 4),
                                                    (45.0, -60.0, 4)])
def test_mechanized_increments_reproduce_the_path_to_a_millimetre(azimuth, lat, minutes):
    """Minutes of a 100 m face (bent, undulating, rolling, with stops and the web advance) at 200 Hz integrated by
    estimators.sins.strapdown.mechanize from the true state at t = 0. (At 100 Hz the mechanization's own
    discretization leaves 2 mm vertically over 10 minutes, 0.5 mm at 200 Hz: the generator is not the limit.)"""
    traj = Trajectory(Face(azimuth_deg=azimuth, lat_deg=lat, length_m=100.0, speeds_mps=(0.3, 0.4, 0.25)))
    t, dtheta, dv = traj.increments(60.0 * minutes)
    start = traj.truth(t[:1])
    nav = mechanize(t, dtheta, dv, *start["llh"][0], start["v_n"][0], start["q_nb"][0], 4)
    true = traj.truth(nav.t)["llh"]
    err = earth.lla_to_enu(nav.lat, nav.lon, nav.h, true[:, 0], true[:, 1], true[:, 2])
    assert np.abs(err).max() < 1e-3, np.abs(err).max(axis=0)
    assert np.ptp(traj.states(nav.t)["s"]) > 50.0 * (minutes > 5) + 25.0  # the path covered (much of) the face


def test_the_path_follows_the_face_azimuth_and_stands_at_the_stops():
    face = Face(azimuth_deg=250.0, lat_deg=-30.0, s_curve_m=0.0, bend_m=0.0, floor_m=0.0, dip_deg=0.0,
                roll_deg=0.0)
    traj = Trajectory(face)
    t = np.array([1.0, face.stand_s + 20.0])
    truth = traj.truth(t)
    d = earth.lla_to_enu(*truth["llh"][1], *truth["llh"][0])
    assert np.degrees(np.arctan2(d[0], d[1])) % 360 == pytest.approx(250.0, abs=1e-6)
    assert np.degrees(quat_to_euler(truth["q_nb"][0])[2]) % 360 == pytest.approx(110.0, abs=1e-6)  # ccw yaw
    st = traj.states(np.array(traj.arrivals) + 1.0)
    assert np.all(np.abs(st["v_n"]) < 1e-12)


def test_the_log_carries_the_exact_odometer_and_the_surveyed_face_ends():
    traj = Trajectory(Face(length_m=40.0, speeds_mps=(0.5, 0.5)))
    log = traj.log(Errors(odo_scale=0.01))
    u, _ = traj.face_points(0.01)
    first_pass = np.interp(traj.arrivals[0], log.odo_t, log.odo_distance)
    assert first_pass == pytest.approx(1.01 * u[-1], abs=0.011)  # the arc length, 1 % long
    assert log.odo_distance[-1] == pytest.approx(0.0, abs=0.05)  # back at the start
    assert log.survey_t.size == 1 + len(traj.arrivals) and np.isnan(log.survey_yaw[1:]).all()
    assert np.isfinite(log.mag_b).all() and log.face_u.size > 20 and log.ram_t.size > 0
