"""The legs' phases of an event in a window (twin.face.simulator): lowering a support's canopy off the roof and
setting it again to its set load, their valves (setting, yield) and leaks, in MuJoCo at a quasi-static time scale."""

from __future__ import annotations

import mujoco
import numpy as np

from twin.face.hydraulics import LegHydraulics
from twin.face.window import (
    ARRIVED_M,
    RAM_SAMPLE_S,
    ROOF_CONTACT_M,
    STALL_S,
    VALVE_TIMEOUT_FACTOR,
    FaceState,
    RoofLimits,
    TraceBuilder,
    Window,
)

QS_LEG_SPEED_M_S = 0.6
"""Speed at which MuJoCo moves the legs' oil columns while supports lower and set (a free canopy follows 14 mm behind)."""
ROOF_APPROACH_M = 0.05
"""A setting canopy this close under the roof slows down, to ROOF_APPROACH_FLOOR of its flow at the roof."""
ROOF_APPROACH_FLOOR = 0.1
"""Share of its flow a setting canopy meets the roof at: 6 cm/s in MuJoCo, so that the roof limit gives under a
millimetre and the set pressure holds within 1 % once the canopy has come to rest."""
LEG_SETTLE_STEPS = 10
"""Steps for a canopy to come to its legs' oil column after they lowered (the servo's time constant is 4 steps)."""


def leak(win: Window, state: FaceState, sups: np.ndarray, dt_s: float) -> None:
    """The oil the leaking legs of the window's supports `sups` lose over `dt_s` of real time."""
    adr = win.model.actuator_actadr[win.index.leg_act]
    win.data.act[adr] -= state.leg_leak_m_s[sups] * dt_s


def leg_valves(win: Window, legs: LegHydraulics, cap_n: np.ndarray) -> None:
    """After a step: the legs' oil no more than the load `cap_n` needs (the yield valve, or a setting valve closing at
    the set load), so the column never winds up past its relief."""
    m, d, ix = win.model, win.data, win.index
    adr = m.actuator_actadr[ix.leg_act]
    d.act[adr] = np.minimum(d.act[adr], d.qpos[ix.sup_qpos[:, 1]] + cap_n / legs.stiffness_n_m)


def drive_legs(win: Window, legs: LegHydraulics, state: FaceState, sups: np.ndarray, which: np.ndarray,
               roof: RoofLimits, lower_m: float, setting: bool, t0: float, trace: TraceBuilder) -> float:
    """Lower the legs of supports `which` (window order) `lower_m` below the roof (their load released first), or,
    `setting`, set them against the roof to their set load (state.set_force_n; the caller closes the setting valves
    once the window has come to rest); returns the real time when all are done. The oil columns move at the valve's flow, MuJoCo at the quasi-static QS_LEG_SPEED_M_S."""
    m, d, ix = win.model, win.data, win.index
    adr = m.actuator_actadr[ix.leg_act]
    k = QS_LEG_SPEED_M_S / legs.speed_m_s
    nstep = max(1, round(RAM_SAMPLE_S / (k * m.opt.timestep)))
    seg_sim = nstep * m.opt.timestep
    set_force = state.set_force_n[sups]
    yield_cap = np.full(sups.size, legs.force_yield_n)
    deadline = t0 + VALVE_TIMEOUT_FACTOR * legs.lower_s(lower_m) + STALL_S
    t, moving = t0, which.copy()
    while moving.any() and t < deadline:
        roof.place(t + seg_sim * k)  # the roof where it is at the end of the step
        reach = legs.speed_m_s * k * seg_sim
        if setting:
            goal = d.qpos[ix.sup_qpos[:, 1]] + set_force / legs.stiffness_n_m
            # The canopy meets the roof at the valve's least flow: in the quasi-static time scale its inertia is
            # k^2 times the real one, and it would bounce off the roof.
            gap = roof.clearance - d.qpos[ix.sup_qpos[:, 1]]
            reach = reach * np.where(gap > ROOF_CONTACT_M, np.clip(gap / ROOF_APPROACH_M, ROOF_APPROACH_FLOOR, 1.0), 1.0)
        else:
            goal = roof.clearance - lower_m
        d.ctrl[ix.leg_act] = np.where(moving, np.clip(goal - d.act[adr], -reach, reach) / seg_sim, 0.0)
        mujoco.mj_step(m, d, nstep=nstep)
        t += seg_sim * k
        leak(win, state, sups, seg_sim * k)
        leg_valves(win, legs, np.where(which & setting, set_force, yield_cap))
        if setting:
            moving &= win.leg_load() < (1.0 - 1e-3) * set_force
        else:
            moving &= d.act[adr] > goal + ARRIVED_M
        trace.sample(t)
    d.ctrl[ix.leg_act] = 0.0
    mujoco.mj_step(m, d, nstep=LEG_SETTLE_STEPS)  # the canopies come to rest on their oil columns
    return t
