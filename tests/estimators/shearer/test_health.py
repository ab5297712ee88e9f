"""The health monitor every shearer method goes through (estimators.shearer.health): a lost track is flagged and
said, a healthy one is left alone."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.io.logformat import FLAG_SKIPPED, FLAG_UNHEALTHY, FLAG_VELOCITY
from estimators.nav import earth
from estimators.shearer.config import Config, ImuNoise
from estimators.shearer.health import assess, innovations_inconsistent
from estimators.shearer.solution import N_SD, SD_POS, Solution

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

CFG = Config(imu=ImuNoise(gyro_arw=1e-4, accel_vrw=1e-3, gyro_bias=1e-5, accel_bias=1e-3))
LAT0 = np.radians(-30.0)


def _solution(east: np.ndarray, v_e: np.ndarray, sd_pos: float = 0.01) -> Solution:
    """A Solution at 10 Hz moving east by `east` [m] with velocity v_e [m/s] and a position one-sigma sd_pos."""
    t = np.arange(east.size) / 10.0
    _r_m, r_n = earth.radii(LAT0)
    llh = np.column_stack([np.full(t.size, LAT0), east / (r_n * np.cos(LAT0)), np.zeros(t.size)])
    v_n = np.column_stack([v_e, np.zeros(t.size), np.zeros(t.size)])
    sd = np.full((t.size, N_SD), 0.001)
    sd[:, SD_POS] = sd_pos
    return Solution(t, llh, v_n, np.tile([1.0, 0, 0, 0], (t.size, 1)), sd, np.full(t.size, FLAG_VELOCITY, np.int32))


def test_a_steady_pass_is_healthy():
    v = np.full(600, 0.3)
    sol = _solution(np.cumsum(v) / 10.0 - v[0] / 10.0, v)
    assert assess(sol, CFG, "kf") == 0
    assert not np.any(sol.flags & FLAG_UNHEALTHY) and sol.notes == []


def test_a_correction_far_beyond_the_covariance_is_a_lost_track():
    """A 0.8 m position change the velocity does not carry, at a one-sigma of 1 cm (the error-free fkf_rail's
    jump after a zero-sigma face-end fix): that epoch is flagged and the note names the method, when and how far."""
    v = np.full(600, 0.3)
    east = np.cumsum(v) / 10.0
    east[300:] += 0.8
    sol = _solution(east, v)
    assert assess(sol, CFG, "fkf_rail") == 1
    assert np.flatnonzero(sol.flags & FLAG_UNHEALTHY).tolist() == [300]
    assert sol.flags[300] & FLAG_VELOCITY  # the filter's own flags are kept
    (note,) = sol.notes
    assert note.startswith("health: fkf_rail lost track at 1 epoch (") and "t 30.0-30.0 s" in note and "sigma" in note


def test_the_same_correction_inside_a_wide_covariance_is_not():
    """The same 0.8 m at a one-sigma of 0.5 m is what a fix does to an uncertain filter: healthy."""
    v = np.full(600, 0.3)
    east = np.cumsum(v) / 10.0
    east[300:] += 0.8
    assert assess(_solution(east, v, sd_pos=0.5), CFG, "kf") == 0


@pytest.mark.parametrize("speed, bad", [(0.9, False), (2.8, True)])
def test_a_speed_no_shearer_hauls_at_is_a_lost_track(speed, bad):
    v = np.full(100, speed)
    sol = _solution(np.cumsum(v) / 10.0, v, sd_pos=np.nan)  # dead reckoning: no covariance
    assert (assess(sol, CFG, "dr") > 0) == bad
    assert any("faster than 1 m/s" in n for n in sol.notes) == bad


def test_a_state_that_is_not_finite_is_a_lost_track():
    v = np.full(100, 0.3)
    sol = _solution(np.cumsum(v) / 10.0, v)
    sol.llh[60:, 0] = np.nan
    assert assess(sol, CFG, "kf") >= 40
    assert np.all(sol.flags[60:] & FLAG_UNHEALTHY)
    assert any("not finite" in n for n in sol.notes)


RECOVERED = ("kf_cpoem", "kf_cpoem_rts", "rts_offline", "fkf_rail")
"""The methods that take the surveyed face ends (kf and the magnetometer filters take no position fix)."""


@pytest.fixture(scope="module")
def bad_face_end():
    """The independent ns_n55 trajectory's error-free log with its first face-end survey moved 5 m east at its
    stated 5 mm (a wrong survey): each method's Solution, the run's dead reckoning and the trajectory."""
    import dataclasses

    from estimators.shearer.methods import estimate
    from tests.estimators.shearer import test_independent_trajectories as ti

    traj, log = ti.trajectory("ns_n55"), ti.log_of("ns_n55", -1)
    llh = log.survey_llh.copy()
    llh[1] = earth.enu_to_lla(np.array([5.0, 0.0, 0.0]), *llh[1])
    sols = estimate(dataclasses.replace(log, survey_llh=llh), traj.config(ti.errors_of("ns_n55", -1)),
                    ("dr",) + RECOVERED)
    return sols, traj, ti


@pytest.mark.parametrize("method", RECOVERED)
def test_a_pass_that_loses_track_is_run_again_and_says_so(bad_face_end, method):
    """The 5 m wrong face end makes the pass jump 5 m beyond a centimetre sigma; the monitor catches it as the
    filter runs, the pass runs again from its start without its position fixes, and the estimate stays on the
    track (within 2 dr + 1 cm, as on the good log) with a note saying when and what was left out, and the
    survey's epoch flagged as skipped. Without the re-run the estimate ends the pass 5 m off."""
    sols, traj, ti = bad_face_end
    sol = sols[method]
    dr = ti.horizontal(ti.position_error(traj, sols["dr"]))
    final, largest = ti.horizontal(ti.position_error(traj, sol))
    assert largest <= 2 * dr[1] + 0.01, (largest, dr)
    notes = [n for n in sol.notes if n.startswith("health")]
    assert len(notes) == 1 and "t 164.0 s" in notes[0] and "without any position fix" in notes[0], notes
    assert not np.any(sol.flags & FLAG_UNHEALTHY)
    assert sol.flags[np.searchsorted(sol.t, 164.0)] & FLAG_SKIPPED


def test_consistent_innovations_pass_the_window_test():
    """500 fixes of chi-square(3) NIS (a consistent filter's): no window of NIS_WINDOW sums beyond the bound."""
    rng = np.random.default_rng(3)
    nis = rng.chisquare(3, 500)
    epoch = np.arange(500) * 20 + 5
    assert not innovations_inconsistent(nis, np.full(500, 40.0), epoch, 10_100).any()


def test_a_run_of_biased_fixes_inside_their_gate_is_inconsistent():
    """Ten fixes in a row at NIS 20 (2.6 sigma on each axis, each inside the gate of 40) sum beyond the window's
    bound (67.6 at 30 dof) once four of them are in the window: the track is lost from the fourth. Gated-out fixes and surveyed face ends (gate inf) do not
    count; fewer than NIS_WINDOW fixes are not tested."""
    nis = np.concatenate([np.full(30, 1.0), np.full(10, 20.0), np.full(5, 1.0)])
    gate = np.full(nis.size, 40.0)
    epoch = np.arange(nis.size) * 10 + 3
    lost = innovations_inconsistent(nis, gate, epoch, 500)
    assert np.flatnonzero(lost)[0] == epoch[33] and lost[-1]
    gate[30:40] = np.inf
    assert not innovations_inconsistent(nis, gate, epoch, 500).any()
    assert not innovations_inconsistent(nis[30:39], np.full(9, 40.0), epoch[30:39], 500).any()


def test_a_lost_run_is_let_go_before_the_pass_runs_again():
    """run_checked drops the lost run's result before the next run makes its own: a pass's stored matrices are
    0.5 GB on a 360 m face (panel_100 at 100 cycles lost track twice, each time holding two passes' at once)."""
    import weakref

    from estimators.shearer.health import run_checked

    class Result:
        def __init__(self, arg):
            self.arg = arg

    alive = []

    def run(arg):
        alive.append(sum(ref() is not None for ref in refs))
        result = Result(arg)
        refs.append(weakref.ref(result))
        return result

    refs: list = []
    notes: list[str] = []
    result, arg = run_checked(run, lambda r: np.array([r.arg != "third"]), lambda: None, "first",
                              [("second", "second"), ("third", "third")], np.array([0.0, 1.0]), notes)
    assert (result.arg, arg) == ("third", "third") and alive == [0, 0, 0]
    assert "run again from its start third" in notes[0]
