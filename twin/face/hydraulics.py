"""Push-ram hydraulics: a double-acting cylinder between a support and its pan, fed from the face's pump.

The ram pushes the pan on its annulus (rod side) and pulls the support up to the pan on its full bore (the
relay-bar arrangement of a shield's advancing ram: the heavy support gets the larger force):

    A_bore = pi d_bore^2 / 4,        A_annulus = A_bore - pi d_rod^2 / 4
    F_push = p_pump A_annulus,       F_pull = p_pump A_bore                      (the relief valves' limits)
    v_push = Q_push / A_annulus,     v_pull = Q_pull / A_bore                    (the flow the valve meters)

A ram moves at its flow-limited speed until it reaches its stroke or its load reaches the force limit, where
the relief valve opens and the ram stands (stalls). The cylinder's pressure is its force over the pressurised
area. Figures of a 2-m shield's advancing ram (bore 160 mm, rod 110 mm, 31.5 MPa, 60 L/min push) give 334 kN
and 0.094 m/s pushing, 633 kN and 0.29 m/s pulling at 350 L/min.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.config.supports import Hydraulics


LOWER_S = 1.0
"""Time a support takes to lower its canopy off the roof before it advances [s]."""
SET_S = 2.5
"""Time a support takes to set its canopy against the roof again after it advances [s]."""
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

    def end_push_s(self, web_m: float) -> float:
        """Least time [s] the end of a face takes to push its pans a web and then advance its supports (the rams
        out and back at their speeds, each way with its valve's ramps, the supports lowered and set)."""
        return web_m / self.speed_push_m_s + web_m / self.speed_pull_m_s + LOWER_S + SET_S + 4 * VALVE_RAMP_S

    def pressure_mpa(self, force_n: np.ndarray) -> np.ndarray:
        """Pressure [MPa] in the side of the cylinder that carries `force_n` (positive: pushing, on the annulus)."""
        force = np.asarray(force_n, float)
        return np.where(force >= 0.0, force / self.area_annulus_m2, -force / self.area_bore_m2) * 1e-6
