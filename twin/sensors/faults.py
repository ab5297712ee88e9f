"""The injected fault schedule: the FAULTS stream, the run-window check and the shared window mask.

Every sensor model applies a fault only to the samples `window_mask` selects, t_start_s <= t < t_end_s, so
each injected fault appears in its stream exactly inside its window (and the FAULTS stream, the ground truth
of the detectors, states that window). Ram faults and push_shortfall have a target support; the others have
none (target -1 in the table).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from twin.config.scenario import Scenario, ScenarioError
from twin.config.sensors import Fault, FaultKind


def window_mask(t: np.ndarray, fault: Fault) -> np.ndarray:
    """Boolean mask of the sample times inside the fault's window, t_start_s <= t < t_end_s."""
    t = np.asarray(t, dtype=float)
    return (t >= fault.t_start_s) & (t < fault.t_end_s)


def window_overlap(t0: np.ndarray, t1: np.ndarray, fault: Fault) -> np.ndarray:
    """Fraction of each interval (t0, t1] that lies inside the fault's window (0 for empty intervals).

    For sensors that integrate over an interval (the odometer's travel increments): an interval entirely
    inside the window gets 1, one entirely outside 0, one straddling a window edge its share.
    """
    t0, t1 = np.asarray(t0, dtype=float), np.asarray(t1, dtype=float)
    width = t1 - t0
    inside = np.clip(np.minimum(t1, fault.t_end_s) - np.maximum(t0, fault.t_start_s), 0.0, None)
    return np.divide(inside, width, out=np.zeros_like(width), where=width > 0)


SHORTFALL_SPREAD = 3
"""A push shortfall takes the pans of this many supports on each side back with the target, tapering off:
an AFC is a chain, so one pan cannot stand alone behind neighbours that its joints tie it to."""


def shortfall_profile(fault: Fault, n_supports: int) -> np.ndarray:
    """Metres each support's pan falls short under a push_shortfall fault (`value` at the target support,
    tapering linearly to zero SHORTFALL_SPREAD + 1 supports away)."""
    distance = np.abs(np.arange(n_supports) - fault.target)
    return fault.value * np.clip(1.0 - distance / (SHORTFALL_SPREAD + 1), 0.0, None)


def faults_of(faults: Iterable[Fault], *kinds: FaultKind) -> list[Fault]:
    """The faults of the given kinds, in schedule order."""
    return [f for f in faults if f.kind in kinds]


def apply_gain_faults(x: np.ndarray, t: np.ndarray, faults: Iterable[Fault], sensor: str) -> None:
    """The scale, offset and drift faults of `sensor` (`<sensor>_scale` ...: twin.config.sensors.SUPPORT_SENSORS) on
    their target's column of the true readings x (samples t x supports), in place, in that order:

        x (1 + value),   + value,   + value (t - t_start)
    """
    for f in faults_of(faults, f"{sensor}_scale"):
        x[window_mask(t, f), f.target] *= 1.0 + f.value
    for f in faults_of(faults, f"{sensor}_offset"):
        x[window_mask(t, f), f.target] += f.value
    for f in faults_of(faults, f"{sensor}_drift"):
        m = window_mask(t, f)
        x[m, f.target] += f.value * (t[m] - f.t_start_s)


class ReadingFaults:
    """The rest of a support transducer's reading, applied chunk by chunk (samples t x supports, in time order): the
    base noise, `<sensor>_noise_burst` (+ value N(0, 1), from a generator of its own per fault, spawned from `rng`),
    quantization to `resolution`, `<sensor>_stuck` (frozen at the window's first quantized reading, carried to the
    chunks after it) and `<sensor>_dropout` (NaN). Each fault's draws come in its window's sample order, so any
    partition of the samples into chunks gives the readings of one chunk, and a fault changes nothing outside its
    window."""

    def __init__(self, faults: Iterable[Fault], sensor: str, rng: np.random.Generator, resolution: float):
        self.resolution = resolution
        bursts = faults_of(faults, f"{sensor}_noise_burst")
        self.bursts = list(zip(bursts, rng.spawn(len(bursts))))
        self.stuck: list[tuple[Fault, list[float]]] = [(f, []) for f in faults_of(faults, f"{sensor}_stuck")]
        self.dropouts = faults_of(faults, f"{sensor}_dropout")

    def apply(self, x: np.ndarray, t: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """The reading of the true values x (samples t x supports) with the base `noise`, in place; returns the valid
        flags (int8, 0 on dropout)."""
        x += noise
        for f, gen in self.bursts:
            m = window_mask(t, f)
            x[m, f.target] += f.value * gen.standard_normal(int(m.sum()))
        if self.resolution > 0:
            x[:] = np.round(x / self.resolution) * self.resolution
        for f, frozen in self.stuck:
            rows = np.flatnonzero(window_mask(t, f))
            if rows.size:
                if not frozen:
                    frozen.append(float(x[rows[0], f.target]))
                x[rows, f.target] = frozen[0]
        valid = np.ones(x.shape, dtype=np.int8)
        for f in self.dropouts:
            m = window_mask(t, f)
            x[m, f.target] = np.nan
            valid[m, f.target] = 0
        return valid


def faults_table(scn: Scenario) -> dict[str, np.ndarray]:
    """The FAULTS stream (estimators.io.logformat.FAULTS) of the scenario's schedule, one row per fault."""
    faults = scn.faults
    return {
        "kind": np.array([f.kind for f in faults], dtype=object),
        "target": np.array([-1 if f.target is None else f.target for f in faults], dtype=np.int32),
        "t_start": np.array([f.t_start_s for f in faults], dtype=float),
        "t_end": np.array([f.t_end_s for f in faults], dtype=float),
        "value": np.array([f.value for f in faults], dtype=float),
    }


def check_faults_in_run(scn: Scenario, duration_s: float) -> None:
    """Raise ScenarioError (one line) for the first fault whose window does not intersect the run [0, duration].

    A window [t_start, t_end) intersects the run when t_start < duration (t_end > t_start >= 0 is already
    checked by the scenario). A window that only partly overlaps the run is accepted: the fault acts on the
    part inside.
    """
    for k, f in enumerate(scn.faults):
        if not (f.t_start_s < duration_s and f.t_end_s > 0.0):
            raise ScenarioError(f"faults[{k}]: window {f.t_start_s:g}..{f.t_end_s:g} s is outside the run "
                                f"(0..{duration_s:g} s)")
