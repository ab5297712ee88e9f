"""The Python API estimators.estimate: a log or a run directory, one method or several, the default config."""

import numpy as np
import pytest

import estimators
from estimators.io.log import log_from_columns
from estimators.io.logformat import STREAMS, write_stream
from estimators.shearer.config import Config, PositioningError
from estimators.shearer.methods import METHODS
from estimators.shearer.solution import Solution
from tests.conftest import simulated
from twin.pipeline.estimate import positioning_config
from twin.sensors.streams import imu_truth, sensor_streams

LOG_STREAMS = ("imu", "odometer", "survey", "pushram", "mag")


@pytest.fixture(scope="module")
def default_streams():
    scn, result = simulated("default")
    return scn, sensor_streams(scn, result.tables, imu_truth(scn, result.tables["truth_shearer"]), 0)


def test_one_method_gives_a_solution_and_several_a_dict_from_a_run_directory_or_a_log(default_streams, tmp_path):
    scn, streams = default_streams
    for name in LOG_STREAMS:
        write_stream(tmp_path, STREAMS[name], streams[name])
    cfg = positioning_config(scn)
    one = estimators.estimate(tmp_path, "dr", cfg)
    assert isinstance(one, Solution) and np.isfinite(one.llh).all()
    log = log_from_columns(*(streams[name] for name in LOG_STREAMS))
    both = estimators.estimate(log, ["kf", "dr"], cfg)
    assert list(both) == ["kf", "dr"] and all(isinstance(s, Solution) for s in both.values())
    assert np.array_equal(both["dr"].llh, one.llh) and np.array_equal(both["dr"].q_nb, one.q_nb)


def test_appendix_a_config_runs_and_an_unknown_method_names_the_methods(default_streams):
    _, streams = default_streams
    log = log_from_columns(*(streams[name] for name in LOG_STREAMS))
    assert np.isfinite(estimators.estimate(log, "dr", Config.appendix_a()).llh).all()
    with pytest.raises(PositioningError, match="unknown method 'cusum'") as err:
        estimators.estimate(log, ("dr", "cusum"), Config.appendix_a())
    assert all(name in str(err.value) for name in METHODS)
