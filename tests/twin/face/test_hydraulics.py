"""Push-ram hydraulics (twin.face.hydraulics) and the rams moving through time in the face events: cylinder figures
in closed form, ram readings that ramp at the cylinder's speed, pressures within the relief valve's, the end push's
time checked by the validator, and the floor's friction the pans' own."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from tests.conftest import capped, simulated
from twin.config.scenario import PAN_FLOOR_FRICTION, ScenarioError, parse_scenario
from twin.face.hydraulics import RamHydraulics, SupportHydraulics
from twin.face.layout import Floor, initial_pans
from twin.face.simulator import FaceSimulator
from twin.pipeline.simulate import simulate, window_sizes

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

SPEED_TOLERANCE = 0.1
"""A rod may run faster than its metered flow by catching up its lag: a drive frame (30 t) lags while it accelerates
in the time-scaled simulation (twin.face.simulator: inertia k^2 times the real one) and then catches up by the servo's
lead, 4 % faster (measured on the default face, support 43; 42 % before the relief valve capped the lead); the line
pans' rams stay within 0.5 %."""
SAME_TIME_JUMP_M = 2e-3
"""Change of a ram between two rows of one time (a trace's last sample and the event's settled end)."""


def test_cylinder_figures_in_closed_form():
    """160 mm bore, 110 mm rod, 31.5 MPa, 60 and 350 L/min: the annulus pushes, the full bore pulls."""
    hyd = RamHydraulics.from_scenario(capped("default").supports.hydraulics)
    bore, annulus = math.pi * 0.16**2 / 4, math.pi * (0.16**2 - 0.11**2) / 4
    assert hyd.force_push_n == pytest.approx(31.5e6 * annulus) and hyd.force_push_n == pytest.approx(333_990, abs=1)
    assert hyd.force_pull_n == pytest.approx(31.5e6 * bore) and hyd.force_pull_n == pytest.approx(633_345, abs=1)
    assert hyd.speed_push_m_s == pytest.approx(1e-3 / annulus) and hyd.speed_push_m_s == pytest.approx(0.0943, abs=1e-4)
    assert hyd.speed_pull_m_s == pytest.approx(350 / 6e4 / bore) and hyd.speed_pull_m_s == pytest.approx(0.2901, abs=1e-4)
    assert hyd.pressure_mpa(np.array([hyd.force_push_n, -hyd.force_pull_n, 0.0])) == pytest.approx([31.5, 31.5, 0.0])
    np.testing.assert_array_equal(hyd.speed(np.array([0.1, -0.1])), [hyd.speed_push_m_s, hyd.speed_pull_m_s])


def test_ram_readings_ramp_at_the_cylinders_speed():
    """Every support's ram length between truth rows changes no faster than its cylinder extends (pushing) or
    retracts (pulling its support up), and a support's advance is a ramp of many rows, not a jump."""
    scn, result = simulated("default")
    hyd = RamHydraulics.from_scenario(scn.supports.hydraulics)
    sup = result.tables["truth_supports"]
    order = np.lexsort((sup["t"], sup["support"]))
    t, ram, who = sup["t"][order], sup["ram"][order], sup["support"][order]
    same = who[1:] == who[:-1]
    dt, dram = np.diff(t)[same], np.diff(ram)[same]
    moving = dt > 0
    rate = dram[moving] / dt[moving]
    assert rate.max() <= hyd.speed_push_m_s * (1 + SPEED_TOLERANCE)
    assert rate.min() >= -hyd.speed_pull_m_s * (1 + SPEED_TOLERANCE)
    assert np.abs(dram[~moving]).max() <= SAME_TIME_JUMP_M
    # Both speeds are reached: the rams are limited by their flow, not slower by construction.
    assert rate.max() >= 0.9 * hyd.speed_push_m_s and rate.min() <= -0.95 * hyd.speed_pull_m_s
    # Support 20's advance: a web pulled in over web / pull speed, sampled all the way.
    mine = who == 20
    pulling = np.flatnonzero(mine[1:] & same & (np.diff(ram) < -1e-3))
    assert pulling.size >= scn.face.web_depth_m / hyd.speed_pull_m_s / 0.25 * 2 * 0.8  # two cycles of 0.25 s rows


def test_pressures_stay_within_the_relief_valves():
    scn, result = simulated("default")
    p = result.tables["truth_supports"]["ram_pressure"]
    assert np.all(p >= 0.0) and p.max() <= scn.supports.hydraulics.pump_pressure_mpa * (1 + 1e-9)
    # A push moves a pan against its feet's friction: a few MPa, far from the relief pressure, most of the time.
    assert np.median(p) < 0.1 * scn.supports.hydraulics.pump_pressure_mpa


def test_an_end_stop_too_short_for_the_hydraulics_is_refused():
    data = capped("default").model_dump()
    scn = capped("default")
    need = SupportHydraulics.from_scenario(scn.supports, scn.roof).end_push_s(scn.face.web_depth_m, scn.supports.lower_m)
    data["haulage"]["end_push_stop_s"] = math.floor(need)  # shorter than the push and advance alone
    with pytest.raises(ScenarioError, match="end_push_stop_s") as err:
        parse_scenario(data, "short.toml")
    assert "\n" not in str(err.value)
    data["supports"]["hydraulics"] |= {"push_flow_l_min": 180.0, "pull_flow_l_min": 700.0}  # faster rams: it fits
    parse_scenario(data, "short.toml")


def test_a_rod_as_thick_as_its_bore_is_refused():
    data = capped("default").model_dump()
    data["supports"]["hydraulics"]["ram_rod_mm"] = 160.0
    with pytest.raises(ScenarioError, match="ram_rod_mm"):
        parse_scenario(data, "rod.toml")


def test_the_pans_slide_on_the_floor_with_their_own_friction():
    """MuJoCo takes the larger of two geoms' frictions: every pan-floor contact of a window has the pans' feet's
    friction (the floor's default of 1 held the pans three times harder than the validator's friction angle says)."""
    scn = capped("default")
    rng = np.random.default_rng(scn.seed)
    floor = Floor.from_scenario(scn, rng)
    sim = FaceSimulator(scn, floor, window_sizes(scn))
    state = sim.initial_supports(initial_pans(scn, floor, rng))
    win = sim.windows[0]
    sim._load(win, state, 0)
    mujoco.mj_step(win.model, win.data, nstep=5)
    floor_geom = win.model.geom("floor").id
    contacts = win.data.contact[: win.data.ncon]
    on_floor = (contacts.geom[:, 0] == floor_geom) | (contacts.geom[:, 1] == floor_geom)
    assert on_floor.sum() >= 3 * win.count  # every pan on three feet or four
    np.testing.assert_array_equal(contacts.friction[on_floor, 0], PAN_FLOOR_FRICTION)


def test_an_obstruction_stalls_the_ram_at_its_relief_pressure():
    """An obstacle 0.1 m in front of support 20's pan from 250 s to 700 s: the pan stops at it (within the slide
    limit's give), its ram stands at its relief pressure; its support follows it short, and with the pushes by stroke
    from the support (twin.face.drift) the pan stays behind its neighbours once the obstacle is cleared (a dent in
    the face line that face alignment must take out: 0.47 m short after the next cycle)."""
    obstacle = {"kind": "obstruction", "t_start_s": 250.0, "t_end_s": 700.0, "target": 20, "value": 0.1}
    scn = capped("default", faults=[obstacle])
    result = simulate(scn)
    pans, sup = result.tables["truth_pans"], result.tables["truth_supports"]
    mine, t = pans["pan"] == 20, pans["t"]
    blocked = mine & (t > 250.0) & (t < 700.0)
    assert pans["advance"][blocked].max() == pytest.approx(0.1, abs=0.02)
    # The pans three away are pushed on past it as far as the connectors let them, short of the web.
    neighbours = np.isin(pans["pan"], [17, 23]) & (t > 500.0) & (t < 700.0)
    assert 0.2 < pans["advance"][neighbours].max() < scn.face.web_depth_m - 0.2
    s20 = (sup["support"] == 20) & (sup["t"] > 250.0) & (sup["t"] < 700.0)
    assert sup["ram_pressure"][s20].max() == pytest.approx(scn.supports.hydraulics.pump_pressure_mpa, rel=0.02)
    at_end = pans["advance"][mine & (t > 1000.0)]
    assert 0.3 < 2 * scn.face.web_depth_m - at_end[-1] < scn.face.web_depth_m - 0.1  # pushed a web, pulled along
