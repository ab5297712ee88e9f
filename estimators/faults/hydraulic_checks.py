"""Checks of the supports' hydraulics from their logs, and whose fault each finding is: the face's or a sensor's.

Input is the push-ram stroke log (PUSHRAM), the pressure transducers' log (PRESSURE: legs and push ram per
support) and what a user knows of the hydraulics (`HydraulicLayout`: the relief, set and yield pressures and the
transducers' noise); optionally the ram checks' findings (estimators.faults.ram_checks) to attribute. Output is a
list of `Attribution`s: support, kind, cause ("face" or "sensor"), window, when it was confirmed, a value, and the
evidence in words. The readings go on the logs' common sample grid (estimators.faults.ram_grid).

What each fault of the face does to the readings, and what tells it from a sensor's:

* ram_stall (the pan meets an obstacle, or the chain of pans holds it): the ram's pressure stands at its relief
  valve's while its stroke stands, for STALL_S or more. A stroke sensor fault does not load the ram.
* sticking_valve (a slow ram): the support's advances (its ram pulling it up at full flow) run at under SLOW_SHARE
  of the face's typical rate while they still complete. A ram stroke sensor's scale error changes the rate and the stroke together (the ram
  checks name it a scale: it stays the sensor's).
* failed_set: after a set, the legs' pressure settles below FAILED_SET_SHARE of the set pressure, the transducer
  having read the lowered legs' nothing before (a transducer with an offset does not).
* leg_leak: a set support's legs lose pressure steadily (faster than LEAK_MPA_S) down to nothing, and stay at
  nothing (their canopy comes off the roof). A drifting transducer reads on through zero into negative pressure.

A sensor's, beside the ram checks' findings:

* leg_pressure: the legs read more than LOWERED_MPA, or less than -ZERO_MPA, while the support advances (its ram
  pulls it up, the legs lowered: nothing is under them), or below -NEGATIVE_MPA at any time: an offset, a stuck or a
  drifting transducer.
* the ram checks' findings (estimators.faults.ram_checks) are the ram stroke sensor's, unless a fault of the face
  above explains them on that support in that window (a ram that stalls behind an obstacle falls short of its
  stroke and its neighbours: the ram checks see the shortfall, the pressure says it is real).

Measured (benchmarks/bench_hydraulic_faults.py: the default face, 2 cycles, 1 Hz transducers of 0.05 MPa and 0.1 MPa
steps, each fault alone): 9 of 9 faults found on their support and attributed right (obstruction 0.3 m, sticking
valve 30 %, failed set 12 MPa, leaking leg 2 L/min; ram stroke offset 0.15 m and stuck; leg transducer offset 8 MPa,
stuck and drifting -0.05 MPa/s), each confirmed at the first push, advance or set that shows it; nothing on the
fault-free run.

Limits: a leg transducer's fault shows only when its support advances (or reads below zero); a leak slower than
LEAK_MPA_S, or one that the next advance sets again before the legs are empty, is not called a leak.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from estimators.faults.ram_findings import Finding
from estimators.faults.ram_grid import _grid, _runs, table_columns

RELIEF_SHARE = 0.95
"""A ram reading at least this share of the relief pressure stands at its relief valve."""
STALL_S = 2.0
"""A ram at its relief with its stroke standing this long has stalled against something (the twin's valve closes a
stalled ram after 1 s at the relief; at the default 1 Hz that shows as two samples or more)."""
STANDING_M = 0.005
"""A stroke that changes less than this per sample stands."""
SLOW_SHARE = 0.6
"""A support whose strokes run under this share of the face's median stroke rate has a slow (sticking) valve."""
MOVING_M_S = 0.01
"""A stroke changing faster than this is moving (a push or an advance)."""
FAILED_SET_SHARE = 0.9
"""Legs that settle below this share of the set pressure after a set have failed to set."""
SET_SETTLE_S = 5.0
"""Time after the legs' pressure rises through half the set pressure at which the set is judged."""
LOWERED_MPA = 3.0
"""Most a leg transducer reads while its support advances (the legs lowered off the roof), beside its noise."""
ZERO_MPA = 0.2
"""Least a leg transducer reads at nothing, beside its noise (a step below zero): lower, it is offset."""
NEGATIVE_MPA = 1.0
"""A leg transducer reading below minus this (beside its noise) is wrong: the legs carry no tension."""
LEAK_MPA_S = 0.005
"""Legs losing pressure faster than this while their support stands set leak (a roof converging raises it)."""
LEAK_MIN_S = 60.0
"""Shortest steady loss of pressure taken for a leak."""
ADVANCE_M = 0.3
"""A stroke that shortens by this much within ADVANCE_S is an advance (the support pulled up to its pan)."""
ADVANCE_S = 30.0
ADVANCE_PAD_S = 10.0
"""The legs lower before the stroke shortens and set after it stops: an advance's samples extend this far each side."""

FACE_KINDS = ("ram_stall", "sticking_valve", "failed_set", "leg_leak")
SENSOR_KINDS = ("leg_pressure",)


@dataclass(frozen=True)
class HydraulicLayout:
    """What a user knows of the supports' hydraulics and transducers."""

    n_supports: int
    relief_mpa: float
    """The push ram's relief (the pump's) pressure."""
    set_mpa: float
    """The legs' set pressure."""
    noise_mpa: float
    """One sigma of a pressure reading."""
    ram_noise_m: float
    """One sigma of a stroke reading."""

    def __post_init__(self):
        for name in ("relief_mpa", "set_mpa"):
            if not getattr(self, name) > 0:
                raise ValueError(f"HydraulicLayout.{name}: {getattr(self, name)} must be positive (MPa)")
        if int(self.n_supports) != self.n_supports or self.n_supports < 1:
            raise ValueError(f"HydraulicLayout.n_supports: {self.n_supports} must be a positive integer")


@dataclass(frozen=True)
class Attribution:
    """A fault found in the supports' logs, and whose it is. cause "face" (the hydraulics or the face did it, the
    sensors read it right) or "sensor" (a reading is wrong); value in the kind's unit (ram_stall: the stroke
    reading at the stall [m]; sticking_valve: the support's rate over the face's; failed_set: the settled pressure
    [MPa]; leg_leak: the rate of loss [MPa/s]; leg_pressure: the wrong reading [MPa]; a ram check's kind: its
    Finding.value)."""

    support: int
    kind: str
    cause: str
    t_start: float
    t_end: float
    t_detect: float
    value: float
    evidence: str


def _advancing(tg: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(T, S) mask of the samples within an advance: the stroke shortening by ADVANCE_M within ADVANCE_S, from
    ADVANCE_PAD_S before it starts to shorten to ADVANCE_PAD_S after it stops (the legs lowering and setting)."""
    dt = float(np.median(np.diff(tg)))
    w = max(1, round(ADVANCE_S / dt))
    pad = max(1, round(ADVANCE_PAD_S / dt))
    shortening = np.zeros(x.shape, bool)
    shortening[1:] = np.diff(x, axis=0) < -STANDING_M
    out = np.zeros(x.shape, bool)
    for col, a, b in zip(*_runs(shortening)):
        first, last = max(a - pad, 0), min(b + pad, x.shape[0] - 1)
        drop = x[max(a - 1, 0), col] - np.nanmin(x[a:b + 1, col])
        if drop >= ADVANCE_M and (b - a + 1) <= w:
            out[first:last + 1, col] = True
    return out


def _stalls(tg, x, ram, layout) -> list[Attribution]:
    dt = float(np.median(np.diff(tg)))
    standing = np.zeros(x.shape, bool)
    standing[1:] = np.abs(np.diff(x, axis=0)) < STANDING_M
    relief = (ram >= RELIEF_SHARE * layout.relief_mpa) & standing
    out = []
    for col, a, b in zip(*_runs(relief)):
        if (b - a + 1) * dt >= STALL_S:
            out.append(Attribution(int(col), "ram_stall", "face", float(tg[a]), float(tg[b]),
                                   float(tg[a + max(1, round(STALL_S / dt)) - 1]), float(x[b, col]),
                                   f"ram at {np.nanmax(ram[a:b + 1, col]):.1f} MPa (relief {layout.relief_mpa:g}) "
                                   f"with its stroke standing for {(b - a + 1) * dt:.0f} s"))
    return out


def _slow_valves(tg, x, advancing) -> list[Attribution]:
    dt = np.diff(tg)
    rate = -np.diff(x, axis=0) / dt[:, None]  # shortening: the ram pulling its support up
    moving = (rate > MOVING_M_S) & advancing[1:]
    typical = np.full(x.shape[1], np.nan)
    for j in range(x.shape[1]):
        r = rate[moving[:, j], j]
        if r.size >= 3:
            typical[j] = np.percentile(r, 80)  # at full flow, the valves' ramps left out
    face = np.nanmedian(typical)
    out = []
    for j in np.flatnonzero(typical < SLOW_SHARE * face):
        k = np.flatnonzero(moving[:, j])
        out.append(Attribution(int(j), "sticking_valve", "face", float(tg[k[0]]), float(tg[k[-1] + 1]),
                               float(tg[k[2] + 1]), float(typical[j] / face),
                               f"advances at {typical[j]:.3f} m/s against the face's {face:.3f} m/s"))
    return out


def _sets(tg, leg, advancing, layout) -> tuple[list[Attribution], list[Attribution]]:
    """Failed sets (face) and transducers reading a load under lowered legs (sensor)."""
    dt = float(np.median(np.diff(tg)))
    settle = max(1, round(SET_SETTLE_S / dt))
    lowered_max = LOWERED_MPA + 4 * layout.noise_mpa
    face, sensor = [], []
    for col, a, b in zip(*_runs(advancing)):
        during = leg[a:b + 1, col]
        if not np.isfinite(during).any():
            continue
        low = float(during[np.nanargmin(np.abs(during))])  # the reading nearest nothing
        if low > lowered_max or low < -(ZERO_MPA + 4 * layout.noise_mpa):
            sensor.append(Attribution(int(col), "leg_pressure", "sensor", float(tg[a]), float(tg[b]), float(tg[b]),
                                      low, f"legs read {low:.1f} MPa at best while the support advanced "
                                           f"(lowered legs carry nothing)"))
            continue
        k = min(b + settle, leg.shape[0] - 1)
        after = leg[k:min(k + settle, leg.shape[0]), col]
        if not np.isfinite(after).any():
            continue
        settled = float(np.nanmedian(after))
        if settled < FAILED_SET_SHARE * layout.set_mpa:
            face.append(Attribution(int(col), "failed_set", "face", float(tg[b]), float(tg[k]), float(tg[k]),
                                    settled, f"legs set to {settled:.1f} MPa (set pressure {layout.set_mpa:g}), "
                                             f"having read {low:.1f} MPa lowered"))
    return face, sensor


def _leaks_and_drifts(tg, leg, advancing, layout) -> tuple[list[Attribution], list[Attribution]]:
    """Steady losses of the set legs' pressure: a leak (down to nothing) or a transducer below zero."""
    dt = float(np.median(np.diff(tg)))
    w = max(2, round(LEAK_MIN_S / dt))
    face, sensor = [], []
    negative = leg < -(NEGATIVE_MPA + 4 * layout.noise_mpa)
    for col, a, b in zip(*_runs(negative)):
        sensor.append(Attribution(int(col), "leg_pressure", "sensor", float(tg[a]), float(tg[b]), float(tg[a]),
                                  float(np.nanmin(leg[a:b + 1, col])), "legs read a negative pressure"))
    # Rate of change over a window of w samples, while the support stands set.
    slope = np.full(leg.shape, np.nan)
    slope[w:] = (leg[w:] - leg[:-w]) / (tg[w:] - tg[:-w])[:, None]
    advances = np.cumsum(advancing, axis=0)
    standing = np.zeros(leg.shape, bool)
    standing[w:] = advances[w:] - advances[:-w] == 0  # no advance within the window
    losing = standing & (slope < -LEAK_MPA_S)
    for col, a, b in zip(*_runs(losing)):
        if b - a + 1 < w or any(s.support == col and s.t_start <= tg[b] and tg[a - w] <= s.t_end for s in sensor):
            continue
        # Down to nothing while the support stands, within a window of the loss.
        empty = np.flatnonzero((leg[a:b + w + 1, col] <= LOWERED_MPA) & ~advancing[a:b + w + 1, col])
        if not empty.size:
            continue
        rate = float(np.nanmedian(slope[a:b + 1, col]))
        face.append(Attribution(int(col), "leg_leak", "face", float(tg[a - w]), float(tg[a + empty[0]]),
                                float(tg[a]), rate, f"set legs losing {-rate * 60:.2f} MPa/min down to nothing"))
    return face, sensor


def check_hydraulics(pushram, pressure, layout: HydraulicLayout,
                     ram_findings: Sequence[Finding] = ()) -> list[Attribution]:
    """The faults of the supports' hydraulics in the logs (PUSHRAM and PRESSURE tables: mappings of column arrays or
    pyarrow tables), and the ram checks' `ram_findings` attributed: sorted by time then support."""
    t, sup, ext, valid = table_columns(pushram, ("t", "support", "extension", "valid"), "pushram")
    tp, sp, leg, ram, v_leg, v_ram = table_columns(pressure, ("t", "support", "leg", "ram", "valid_leg", "valid_ram"),
                                          "pressure")
    tg, x = _grid(t, sup, ext, valid, layout.n_supports)
    tpg, leg_g = _grid(tp, sp, leg, v_leg, layout.n_supports, "pressure")
    _, ram_g = _grid(tp, sp, ram, v_ram, layout.n_supports, "pressure")
    if tpg.size != tg.size or not np.allclose(tpg, tg):
        # The transducers on the stroke sensors' grid: the latest reading at or before each stroke sample.
        k = np.clip(np.searchsorted(tpg, tg, side="right") - 1, 0, tpg.size - 1)
        leg_g, ram_g = leg_g[k], ram_g[k]
    advancing = _advancing(tg, x)
    face = _stalls(tg, x, ram_g, layout) + _slow_valves(tg, x, advancing)
    set_face, set_sensor = _sets(tg, leg_g, advancing, layout)
    leak_face, leak_sensor = _leaks_and_drifts(tg, leg_g, advancing, layout)
    face += set_face + leak_face
    out = face + set_sensor + leak_sensor
    for f in ram_findings:
        explained = [a for a in face if f.support <= a.support <= f.last_support and a.t_start <= f.t_end
                     and f.t_start <= a.t_end + ADVANCE_S]
        cause = "face" if explained else "sensor"
        why = (f"the ram checks' {f.kind}, explained by the face's {explained[0].kind}" if explained
               else f"the ram checks' {f.kind} with the ram's hydraulics normal")
        out.append(Attribution(f.support, f"ram_{f.kind}", cause, f.t_start, f.t_end, f.t_detect, f.value, why))
    out.sort(key=lambda a: (a.t_start, a.support, a.kind))
    return out


def format_attribution(a: Attribution) -> str:
    return (f"support {a.support:<4} {a.kind:<18} {a.cause:<6} {a.t_start:9.1f} .. {a.t_end:9.1f} s  confirmed "
            f"{a.t_detect:9.1f} s  value {a.value:+.4g}  ({a.evidence})")
