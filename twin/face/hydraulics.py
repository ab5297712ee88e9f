"""Support hydraulics: the push ram between a support and its pan, and the legs between its base and canopy.

Push ram. A double-acting cylinder fed from the face's pump.

The ram pushes the pan on its annulus (rod side) and pulls the support up to the pan on its full bore (the
relay-bar arrangement of a shield's advancing ram: the heavy support gets the larger force):

    A_bore = pi d_bore^2 / 4,        A_annulus = A_bore - pi d_rod^2 / 4
    F_push = p_pump A_annulus,       F_pull = p_pump A_bore                      (the relief valves' limits)
    v_push = Q_push / A_annulus,     v_pull = Q_pull / A_bore                    (the flow the valve meters)

A ram moves at its flow-limited speed until it reaches its stroke or its load reaches the force limit, where
the relief valve opens and the ram stands (stalls). The cylinder's pressure is its force over the pressurised
area. Figures of a 2-m shield's advancing ram (bore 160 mm, rod 110 mm, 31.5 MPa, 60 L/min push) give 334 kN
and 0.094 m/s pushing, 633 kN and 0.29 m/s pulling at 350 L/min.

Legs. n cylinders of bore d_leg that hold the canopy against the roof. Their oil column, closed between the setting
and the yield valve, is a spring of stiffness

    k_leg = beta A_leg / L,     A_leg = n pi d_leg^2 / 4,   L the leg's length (the mining height)

on the squeeze g = l_oil - h (the length l_oil the trapped oil would make unloaded less the canopy's height h, held
at the roof): F_leg = k_leg g, the legs' pressure F_leg / A_leg. Setting, the valve feeds the legs at the pump's flow
until F_leg reaches the set load p_set A_leg; as the roof converges at r and oil leaks out at lambda, g changes at
r - lambda; the yield valve releases oil above p_yield A_leg. With the defaults (two 400 mm legs, 31.5 / 42 MPa,
beta 1.5 GPa, 3 m) the set load is 7.9 MN, yield 10.6 MN, k_leg 126 MN/m: the roof converges 21 mm from set to
yield.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.config.supports import Hydraulics, Roof, Supports

OIL_BULK_MODULUS_PA = 1.5e9
"""Effective bulk modulus of a leg's oil column: the HFA emulsion's 2.2 GPa softened by the hoses and seals."""
CANOPY_TOP_M = 0.1
"""The canopy's top above its leg joint (models/support.xml): the roof is this far above a set leg's height."""
CANOPY_CENTRE_X_M = -1.0
"""Where the canopy meets the roof, in x from the support's ram connection (models/support.xml)."""
VALVE_RAMP_S = 0.75
"""Time over which a proportional valve opens to its metered flow, and closes again before the goal [s]."""


@dataclass(frozen=True)
class RamHydraulics:
    """The push ram's force limits [N], speeds [m/s] and areas [m^2] from a scenario's hydraulics."""

    area_bore_m2: float
    area_annulus_m2: float
    force_push_n: float
    force_pull_n: float
    speed_push_m_s: float
    speed_pull_m_s: float

    @classmethod
    def from_scenario(cls, hyd: Hydraulics) -> RamHydraulics:
        bore = math.pi * (hyd.ram_bore_mm * 1e-3) ** 2 / 4
        annulus = bore - math.pi * (hyd.ram_rod_mm * 1e-3) ** 2 / 4
        p = hyd.pump_pressure_mpa * 1e6
        return cls(bore, annulus, p * annulus, p * bore, hyd.push_flow_l_min / 6e4 / annulus,
                   hyd.pull_flow_l_min / 6e4 / bore)

    def speed(self, stroke_m: np.ndarray) -> np.ndarray:
        """Flow-limited speed [m/s] of rams commanded `stroke_m` (positive: extending, the push)."""
        return np.where(np.asarray(stroke_m) >= 0.0, self.speed_push_m_s, self.speed_pull_m_s)

    def pressure_mpa(self, force_n: np.ndarray) -> np.ndarray:
        """Pressure [MPa] in the side of the cylinder that carries `force_n` (positive: pushing, on the annulus)."""
        force = np.asarray(force_n, float)
        return np.where(force >= 0.0, force / self.area_annulus_m2, -force / self.area_bore_m2) * 1e-6


@dataclass(frozen=True)
class LegHydraulics:
    """A support's legs together: area [m^2], set and yield loads [N], speed [m/s] at the valve's flow, the oil
    column's stiffness [N/m] and the squeeze [m] at set and yield."""

    area_m2: float
    force_set_n: float
    force_yield_n: float
    speed_m_s: float
    stiffness_n_m: float

    @classmethod
    def from_scenario(cls, sup: Supports, roof: Roof) -> LegHydraulics:
        legs = sup.legs
        area = legs.count * math.pi * (legs.bore_mm * 1e-3) ** 2 / 4
        return cls(area, legs.set_pressure_mpa * 1e6 * area, legs.yield_pressure_mpa * 1e6 * area,
                   legs.flow_l_min / 6e4 / area, OIL_BULK_MODULUS_PA * area / (roof.mining_height_m - CANOPY_TOP_M))

    @property
    def squeeze_set_m(self) -> float:
        return self.force_set_n / self.stiffness_n_m

    @property
    def squeeze_yield_m(self) -> float:
        return self.force_yield_n / self.stiffness_n_m

    def pressure_mpa(self, force_n: np.ndarray) -> np.ndarray:
        """Pressure [MPa] under the legs' pistons carrying `force_n` (none while they pull the canopy down, on their
        annuli)."""
        return np.maximum(np.asarray(force_n, float), 0.0) / self.area_m2 * 1e-6

    def force_n(self, squeeze_m: np.ndarray) -> np.ndarray:
        """Load [N] of legs squeezed by `squeeze_m` (none when the canopy hangs below the roof)."""
        return self.stiffness_n_m * np.clip(squeeze_m, 0.0, self.squeeze_yield_m)

    def lower_s(self, lower_m: float) -> float:
        """Time [s] set legs take to release their load and lower the canopy `lower_m` off the roof."""
        return (self.squeeze_set_m + lower_m) / self.speed_m_s

    def set_s(self, lower_m: float) -> float:
        """Time [s] legs `lower_m` under the roof take to reach it and build up the set load."""
        return self.lower_s(lower_m)

    def hold(self, squeeze_m: np.ndarray, dt_s: np.ndarray, convergence_m_s: float,
             leak_m_s: np.ndarray) -> np.ndarray:
        """Squeeze after `dt_s` of the legs' valves closed (quasi-static): the roof converging at `convergence_m_s`
        squeezes the oil, a leak of `leak_m_s` (oil column per second) relieves it, the yield valve caps it at the
        yield squeeze. Negative: the canopy hangs that far below the roof (the legs unloaded).

            g(t) = min(g0 + (r - lambda) t, max(g0, g_yield))

        (g changes monotonically, so the cap applies once: a leg above its yield squeeze only stays there.)"""
        g0 = np.asarray(squeeze_m, float)
        return np.minimum(g0 + (convergence_m_s - np.asarray(leak_m_s, float)) * np.asarray(dt_s, float),
                          np.maximum(g0, self.squeeze_yield_m))


@dataclass(frozen=True)
class SupportHydraulics:
    """A support's push ram and legs."""

    ram: RamHydraulics
    legs: LegHydraulics

    @classmethod
    def from_scenario(cls, sup: Supports, roof: Roof) -> SupportHydraulics:
        return cls(RamHydraulics.from_scenario(sup.hydraulics), LegHydraulics.from_scenario(sup, roof))

    def advance_s(self, web_m: float, lower_m: float) -> float:
        """Least time [s] a support takes to advance a web: lowered, pulled up by its ram (with the valve's ramps),
        set again."""
        return self.legs.lower_s(lower_m) + web_m / self.ram.speed_pull_m_s + 2 * VALVE_RAMP_S + self.legs.set_s(lower_m)

    def end_push_s(self, web_m: float, lower_m: float) -> float:
        """Least time [s] the end of a face takes to push its pans a web and then advance its supports."""
        return web_m / self.ram.speed_push_m_s + 2 * VALVE_RAMP_S + self.advance_s(web_m, lower_m)
