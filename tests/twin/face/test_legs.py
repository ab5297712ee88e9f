"""The supports' legs (twin.face.hydraulics.LegHydraulics) against the roof: figures in closed form, a support that
lowers, advances and sets to its set pressure through MuJoCo, the roof converging until the yield valve opens, the
closed form between events agreeing with MuJoCo's legs, and the physical faults of the legs and the ram's valve."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.conftest import capped
from twin.config.scenario import ScenarioError, parse_scenario
from twin.face.hydraulics import LegHydraulics, RamHydraulics
from twin.face.layout import Floor, initial_pans
from twin.face.simulator import FaceSimulator
from twin.pipeline.simulate import simulate, window_sizes

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")


def _legs(scn) -> LegHydraulics:
    return LegHydraulics.from_scenario(scn.supports, scn.roof)


def _rows(sup: dict, support: int) -> dict:
    mine = sup["support"] == support
    return {k: v[mine] for k, v in sup.items()}


def test_leg_figures_in_closed_form():
    """Two 400 mm legs at 31.5 / 42 MPa, 1500 L/min, a 3 m oil column of 1.5 GPa."""
    legs = _legs(capped("default"))
    area = 2 * math.pi * 0.2 ** 2
    assert legs.area_m2 == pytest.approx(area)
    assert legs.force_set_n == pytest.approx(31.5e6 * area) and legs.force_set_n == pytest.approx(7.917e6, rel=1e-3)
    assert legs.force_yield_n == pytest.approx(42e6 * area)
    assert legs.speed_m_s == pytest.approx(1500 / 6e4 / area)
    assert legs.stiffness_n_m == pytest.approx(1.5e9 * area / 3.0)
    assert legs.pressure_mpa(np.array([legs.force_set_n, -1e5])) == pytest.approx([31.5, 0.0])


def test_the_closed_legs_squeeze_to_yield_and_leak_off_the_roof():
    legs = _legs(capped("default"))
    g_set, g_yield = legs.squeeze_set_m, legs.squeeze_yield_m
    r = 0.1 / 3600.0  # 100 mm/h
    t_yield = (g_yield - g_set) / r
    g = legs.hold(np.full(3, g_set), np.array([t_yield / 2, t_yield, 3 * t_yield]), r, np.zeros(3))
    assert g == pytest.approx([(g_set + g_yield) / 2, g_yield, g_yield])
    assert legs.force_n(g[1:]) == pytest.approx(legs.force_yield_n)
    leak = 2 * r  # the leak outruns the convergence: the legs unload, then the canopy hangs below the roof
    g = legs.hold(np.full(2, g_set), np.array([g_set / r, 2 * g_set / r]), r, np.full(2, leak))
    assert g == pytest.approx([0.0, -g_set], abs=1e-12)
    assert legs.force_n(g) == pytest.approx([0.0, 0.0], abs=1e-6)


def test_a_yield_valve_below_the_set_pressure_is_refused():
    data = capped("default").model_dump()
    data["supports"]["legs"]["yield_pressure_mpa"] = 30.0
    with pytest.raises(ScenarioError, match="yield_pressure_mpa"):
        parse_scenario(data, "legs.toml")


@pytest.fixture(scope="module")
def converging():
    """The default face under a roof converging at 100 mm/h: 21 mm take the legs from set to yield in 12.6 min."""
    scn = capped("default", roof={"convergence_mm_h": 100.0})
    return scn, simulate(scn).tables["truth_supports"]


def test_a_support_lowers_advances_and_sets_to_its_set_pressure(converging):
    """Support 10's advance: the pressure falls to nothing as the legs lower the canopy supports.lower_m, the ram pulls
    the support up, the legs set the canopy against the roof to the set pressure (within 1 %), on time."""
    scn, sup = converging
    legs, rows = _legs(scn), _rows(converging[1], 10)
    lowered = np.flatnonzero(rows["set"] == 0)
    first = lowered[: np.argmax(np.diff(lowered) > 1) + 1] if np.any(np.diff(lowered) > 1) else lowered
    during = slice(first[0], first[-1] + 2)
    p, canopy = rows["leg_pressure"][during], rows["canopy"][during]
    assert p[0] > 30.0 and p.min() == 0.0
    assert canopy.min() == pytest.approx(canopy[0] - scn.supports.lower_m, abs=0.01)
    assert rows["advance"][during][-1] - rows["advance"][during][0] == pytest.approx(scn.face.web_depth_m, abs=0.01)
    assert p[-1] == pytest.approx(scn.supports.legs.set_pressure_mpa, rel=0.01)
    took = rows["t"][during][-1] - rows["t"][during][0]
    need = legs.lower_s(scn.supports.lower_m) + legs.set_s(scn.supports.lower_m)
    assert need < took < need + scn.face.web_depth_m / 0.2 + 4.0  # the pull at its speed, the valves' ramps


def test_a_converging_roof_takes_the_legs_to_yield_and_no_further(converging):
    """Between advances the pressure of a set support rises at k_leg r / A (closed form) to the yield pressure and
    stays there while the canopy gives way with the roof."""
    scn, sup = converging
    legs = _legs(scn)
    r = scn.roof.convergence_mm_h * 1e-3 / 3600.0
    rate_mpa_s = legs.stiffness_n_m * r / legs.area_m2 * 1e-6
    assert sup["leg_pressure"].max() == pytest.approx(scn.supports.legs.yield_pressure_mpa, rel=1e-3)
    rows = _rows(sup, 30)
    rising = (rows["set"] == 1) & (rows["leg_pressure"] > 32.5) & (rows["leg_pressure"] < 41.5)
    t, p = rows["t"][rising], rows["leg_pressure"][rising]
    gaps = np.flatnonzero(np.diff(t) > 60.0)  # one stretch between two events
    stretch = slice(0, gaps[0] + 1) if gaps.size else slice(None)
    slope = np.polyfit(t[stretch], p[stretch], 1)[0]
    assert slope == pytest.approx(rate_mpa_s, rel=0.05)
    yielded = (rows["set"] == 1) & (rows["leg_pressure"] >= scn.supports.legs.yield_pressure_mpa - 1e-6)
    assert yielded.sum() >= 3
    k = np.flatnonzero(yielded)
    canopy_rate = np.diff(rows["canopy"][k[:2]]) / np.diff(rows["t"][k[:2]])
    assert canopy_rate == pytest.approx(-r, rel=0.05)


def test_the_closed_form_between_events_agrees_with_mujocos_legs():
    """Support 18 advancing 0.3 m (lowered, pulled, set: 6 s) beside support 20 nudging its pan a millimetre, under a
    roof converging at 500 mm/h, support 20's legs leaking 20 L/min: its legs' pressure through the event in MuJoCo
    against LegHydraulics.hold from the same start."""
    scn = capped("default", roof={"convergence_mm_h": 500.0})
    rng = np.random.default_rng(scn.seed)
    floor = Floor.from_scenario(scn, rng)
    sim = FaceSimulator(scn, floor, window_sizes(scn))
    state = sim.initial_supports(initial_pans(scn, floor, rng))
    sim.settle(state)
    sim.hold_legs(state, 60.0)
    p0 = _legs(scn).pressure_mpa(state.leg_force[20])
    moved = np.zeros(state.sup_x.size, bool)
    moved[[18, 20]] = True
    advancing = np.zeros_like(moved)
    advancing[18] = True
    target = state.ram.copy()
    target[18] -= 0.3
    target[20] += 0.001
    leak = 20.0 / 6e4 / _legs(scn).area_m2
    state.leg_leak_m_s[20] = leak
    _, _, trace = sim.step_event(state, moved, target, advancing, 60.0)
    legs = _legs(scn)
    r = scn.roof.convergence_mm_h * 1e-3 / 3600.0
    g = legs.hold(legs.hold(legs.squeeze_set_m, 60.0, r, 0.0), trace.t_s, r, leak)
    expected = legs.pressure_mpa(legs.force_n(g))
    measured = legs.pressure_mpa(trace.leg_force[:, list(trace.supports).index(20)])
    assert trace.t_s[-1] > 5.0 and p0 - expected[-1] > 2.0  # it moved measurably
    # Within a pressure transducer's step: the canopy follows the converging roof a fraction of a millimetre behind (the
    # roof limit's give, models/support.xml).
    np.testing.assert_allclose(measured, expected, atol=0.1)


@pytest.fixture(scope="module")
def faulty():
    """Support 12's legs leak 2 L/min from 300 s, support 25 sets at 12 MPa, support 33's ram valve passes 30 %."""
    faults = [{"kind": "leg_leak", "t_start_s": 300.0, "t_end_s": 2000.0, "target": 12, "value": 2.0},
              {"kind": "failed_set", "t_start_s": 0.0, "t_end_s": 2000.0, "target": 25, "value": 12.0},
              {"kind": "sticking_valve", "t_start_s": 0.0, "t_end_s": 2000.0, "target": 33, "value": 0.3}]
    scn = capped("default", faults=faults)
    return scn, simulate(scn).tables["truth_supports"]


def test_a_leaking_leg_loses_its_pressure_and_its_canopy_comes_off_the_roof(faulty):
    scn, sup = faulty
    legs = _legs(scn)
    rows = _rows(sup, 12)
    leak_m_s = 2.0 / 6e4 / legs.area_m2
    r = scn.roof.convergence_mm_h * 1e-3 / 3600.0
    # The longest run of falling pressure (each advance sets the legs to the set pressure again).
    t, p = rows["t"], rows["leg_pressure"]
    falling = np.r_[0, (np.diff(p) < 0) & (p[1:] > 1.0), 0]
    begin, end = np.flatnonzero(np.diff(falling) == 1), np.flatnonzero(np.diff(falling) == -1)
    k = np.argmax(end - begin)
    run = slice(begin[k], end[k] + 1)
    assert t[run][-1] - t[run][0] > 300.0
    slope = np.polyfit(t[run], p[run], 1)[0]
    assert slope == pytest.approx(-legs.stiffness_n_m * (leak_m_s - r) / legs.area_m2 * 1e-6, rel=0.02)
    unloaded = (rows["set"] == 1) & (rows["leg_pressure"] == 0.0)
    assert unloaded.any() and np.ptp(rows["canopy"][unloaded]) > 0.01  # hanging below the roof, sinking


def test_a_failed_set_stops_at_its_pressure(faulty):
    scn, sup = faulty
    rows = _rows(sup, 25)
    after_set = (rows["set"][1:] == 1) & (rows["set"][:-1] == 0)
    assert after_set.any()
    assert rows["leg_pressure"][1:][after_set] == pytest.approx(12.0, abs=0.2)


def test_a_sticking_valve_slows_its_ram(faulty):
    """Support 33's ram pulls it up at 30 % of its neighbours' speed, the metered pull speed (the stroke rate over
    the trace rows of its advances at full flow)."""
    scn, sup = faulty
    v = RamHydraulics.from_scenario(scn.supports.hydraulics).speed_pull_m_s

    def pull_speed(j):
        rows = _rows(sup, j)
        lowered = (rows["set"][1:] == 0) & (rows["set"][:-1] == 0)
        dt, d_ram = np.diff(rows["t"]), np.diff(rows["ram"])
        rate = -d_ram[lowered & (dt > 0.1)] / dt[lowered & (dt > 0.1)]
        return np.percentile(rate[rate > 0.01], 80)  # at full flow, the valves' ramps left out

    assert pull_speed(32) == pytest.approx(v, rel=0.05)
    assert pull_speed(33) == pytest.approx(0.3 * v, rel=0.05)


def test_a_failed_set_at_or_above_the_set_pressure_is_refused():
    """It would change nothing: the setting valve closes at the lower of the two."""
    data = capped("default").model_dump()
    data["faults"] = [{"kind": "failed_set", "t_start_s": 0.0, "t_end_s": 10.0, "target": 3, "value": 40.0}]
    with pytest.raises(ScenarioError, match="failed_set value 40 MPa is not below") as err:
        parse_scenario(data, "legs.toml")
    assert "\n" not in str(err.value)
