"""Faults of the face against faults of the sensors (estimators.faults.hydraulic_checks) on the default face's logs:
a fault-free run gives nothing, an obstruction and a failed set are the face's, a leg transducer's offset the
sensor's, and the ram checks' findings around an obstruction are explained by it."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.faults.hydraulic_checks import HydraulicLayout, check_hydraulics
from estimators.faults.ram_checks import check_log
from tests.conftest import capped
from twin.pipeline.estimate import hydraulic_layout, ram_layout
from twin.pipeline.simulate import simulate
from twin.sensors.streams import imu_truth, sensor_streams

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")


def _attributions(faults: list[dict]):
    scn = capped("default", cycles=1, faults=faults)
    result = simulate(scn)
    streams = sensor_streams(scn, result.tables, imu_truth(scn, result.tables["truth_shearer"]), 0)
    ram = streams["pushram"]
    return check_hydraulics(ram, streams["pressure"], hydraulic_layout(scn), check_log(ram, ram_layout(scn)))


def test_a_fault_free_face_gives_nothing():
    assert _attributions([]) == []


def test_an_obstruction_is_the_faces_and_explains_the_ram_checks():
    """0.3 m of free advance for support 20's pan: its ram stalls at the relief pressure; what the ram checks see on
    it (the short stroke) is attributed to the face too."""
    found = _attributions([{"kind": "obstruction", "t_start_s": 250.0, "t_end_s": 700.0, "target": 20,
                            "value": 0.3}])
    mine = [a for a in found if a.support == 20]
    assert any(a.kind == "ram_stall" and a.cause == "face" and 250.0 <= a.t_detect < 700.0 for a in mine)
    assert all(a.cause == "face" for a in mine)


@pytest.mark.parametrize(("fault", "kind", "cause"), [
    ({"kind": "failed_set", "t_start_s": 0.0, "t_end_s": 1200.0, "target": 25, "value": 12.0}, "failed_set", "face"),
    ({"kind": "leg_pressure_offset", "t_start_s": 300.0, "t_end_s": 1200.0, "target": 25, "value": -19.5},
     "leg_pressure", "sensor"),
])
def test_a_low_set_pressure_is_told_from_a_transducer_reading_low(fault, kind, cause):
    """A failed set and a leg transducer reading 19.5 MPa low both show the legs at 12 MPa after their set; the
    transducer at the lowered legs tells them apart (nothing, or minus 19.5 MPa)."""
    found = [a for a in _attributions([fault]) if a.support == 25]
    assert found and {(a.kind, a.cause) for a in found} == {(kind, cause)}


def test_a_layout_without_pressures_is_refused():
    with pytest.raises(ValueError, match="relief_mpa"):
        HydraulicLayout(n_supports=44, relief_mpa=0.0, set_mpa=31.5, noise_mpa=0.05, ram_noise_m=1e-4)


def test_a_pressure_log_without_its_columns_is_refused():
    ram = {"t": np.arange(3.0), "support": np.zeros(3, int), "extension": np.ones(3), "valid": np.ones(3, int)}
    with pytest.raises(ValueError, match="^pressure: the table needs the columns"):
        check_hydraulics(ram, {"t": np.arange(3.0)}, HydraulicLayout(44, 31.5, 31.5, 0.05, 1e-4))
