"""Pressure transducers of the supports' legs and push rams (the PRESSURE stream) and their faults.

Every support is sampled at scn.sensors.pressure.rate_hz at t = k / rate for 0 <= t <= t_end, each transducer reading
the latest truth_supports row of its support at or before the sample (twin.sensors.clock.true_at): the legs'
pressure `leg_pressure` and the ram's loaded side `ram_pressure` (MPa). Each reading is

    reading = quantize(true_with_faults + noise_mpa N(0, 1) [+ burst noise]),   quantize = round to resolution_mpa,

with the sensor faults of twin.sensors.faults (apply_gain_faults, ReadingFaults) on the samples inside their
window, on their target: `leg_pressure_*` on the leg transducer, `ram_pressure_*` on the ram's. The faults of the
face (leg_leak, failed_set, sticking_valve, obstruction) are in the truth: the transducers read them.
"""

from __future__ import annotations

import numpy as np

from twin.config.scenario import Scenario
from twin.config.sensors import Fault
from twin.face.layout import support_stations
from twin.sensors.clock import sample_times, true_at
from twin.sensors.faults import ReadingFaults, apply_gain_faults

CHANNELS = (("leg", "leg_pressure"), ("ram", "ram_pressure"))
"""The stream's columns and the truth_supports column (and fault prefix) each reads."""


class Pressures:
    """The PRESSURE stream drawn chunk by chunk: `step` takes the next sample times (in order) and gives their rows.
    Each transducer channel has its own generator (spawned from `rng`) for its base noise, drawn in sample order, and
    each fault its own (twin.sensors.faults.ReadingFaults), so any partition of the samples gives the stream of one
    step."""

    def __init__(self, scn: Scenario, rng: np.random.Generator, faults: list[Fault]):
        cfg = scn.sensors.pressure
        self.noise_mpa, self.faults = cfg.noise_mpa, faults
        self.n_sup = support_stations(scn).size
        self.noise = rng.spawn(len(CHANNELS))
        self.reading = [ReadingFaults(faults, sensor, gen, cfg.resolution_mpa)
                        for (_, sensor), gen in zip(CHANNELS, rng.spawn(len(CHANNELS)))]

    def step(self, t_grid: np.ndarray, supports: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Rows (t, support, leg, ram, valid_leg, valid_ram) of every support at the sample times t_grid; `supports`
        holds the truth_supports columns (t, support, leg_pressure, ram_pressure are used) up to the last sample at
        least."""
        n_sup = self.n_sup
        out = {"t": np.repeat(t_grid, n_sup), "support": np.tile(np.arange(n_sup, dtype=np.int32), t_grid.size)}
        for (column, sensor), noise, reading in zip(CHANNELS, self.noise, self.reading):
            x = true_at(supports, sensor, t_grid, n_sup)
            apply_gain_faults(x, t_grid, self.faults, sensor)
            valid = reading.apply(x, t_grid, self.noise_mpa * noise.standard_normal(x.shape))
            out[column] = x.ravel()
            out[f"valid_{column}"] = valid.ravel()
        return {key: out[key] for key in ("t", "support", "leg", "ram", "valid_leg", "valid_ram")}


def pressure_stream(scn: Scenario, supports: dict[str, np.ndarray], t_end: float, rng: np.random.Generator,
                    faults: list[Fault]) -> dict[str, np.ndarray]:
    """The PRESSURE stream (t, support, leg, ram, valid_leg, valid_ram): every support at each sample of [0, t_end]
    (Pressures in one step).

    `supports` holds the truth_supports columns (t, support, leg_pressure, ram_pressure are used)."""
    return Pressures(scn, rng, faults).step(sample_times(0.0, t_end, scn.sensors.pressure.rate_hz), supports)
