"""The shearer's suspension in the ride model: a MuJoCo weld whose sampled response is the suspension's.

At impedance 1 a weld drives its residual r with a_ref = -b v - k r, b = 2 / timeconst and
k = 1 / (timeconst dampratio)^2 (solref = [timeconst, dampratio]), once per step of dt and explicitly
(v' = v + dt a_ref, r' = r + dt v'). With b and k of the continuous suspension that map rings and decays
ever less like it as f dt grows (at 100 Hz a 7 Hz critically damped suspension measured 11 Hz, damping
ratio 1.5), and MuJoCo raises a timeconst under two steps to two steps. Here b and k put the map's poles
at exp(s dt), s the poles of the continuous suspension, so the ride's samples decay and ring as the
scenario's suspension for any frequency the samples can carry: a ringing below the ride's Nyquist
frequency (timeconst = 2 dt / (1 - exp(-2 zeta w dt)) is then always over two steps).
"""

from __future__ import annotations

import math


def ringing_hz(frequency_hz: float, damping_ratio: float) -> float:
    """Damped natural frequency of the suspension (0 when damped critically or more)."""
    return frequency_hz * math.sqrt(max(0.0, 1.0 - damping_ratio ** 2))


def weld_solref(frequency_hz: float, damping_ratio: float, timestep: float) -> list[float]:
    """Solref [timeconst, dampratio] of a weld at impedance 1 whose steps of `timestep` sample the suspension."""
    w, zeta = 2 * math.pi * frequency_hz, damping_ratio
    spread = w * math.sqrt(abs(1.0 - zeta ** 2)) * timestep
    decay = math.exp(-zeta * w * timestep)
    trace = 2 * decay * (math.cos(spread) if zeta < 1 else math.cosh(spread))  # z1 + z2
    det = decay ** 2  # z1 z2
    damping, stiffness = (1 - det) / timestep, (1 + det - trace) / timestep ** 2
    timeconst = 2 / damping
    return [timeconst, 1 / (timeconst * math.sqrt(stiffness))]
