"""Push-ram stroke sensors of the hydraulic supports (the PUSHRAM stream) and their faults.

Every support is sampled at scn.sensors.pushram.rate_hz at t = k / rate for 0 <= t <= t_end. The true ram
length at a sample is the latest truth_supports row of that support at or before the sample time (rows at
the same time: the later row wins; a sample before a support's first row takes that first row). The reading
is

    reading = quantize(true_with_faults + noise_m * N(0, 1) [+ burst noise]),   quantize = round to resolution_m,

valid = 1. Faults act on the samples inside their window only (twin.sensors.faults.window_mask), on their target
support, in this fixed order whatever their order in the schedule:

1. ram_scale        true * (1 + value)
2. ram_offset       + value [m]
3. ram_drift        + value * (t - t_start) [m/s]
4. rail_deviation   + the lateral rail error below (no target: acts on several supports)
5. noise            every sample: + noise_m * N(0, 1); ram_noise_burst adds value * N(0, 1) [m]
6. quantization     every sample
7. ram_stuck        the reading freezes at the (quantized) reading of the window's first sample
8. ram_dropout      extension NaN, valid 0

The base noise is drawn from the stream's generator in sample order and each fault's noise from a generator of its
own, so a fault changes nothing outside its window, and the stream drawn in chunks (a streaming run) is the stream
drawn at once.

push_shortfall is a fault of the face, not of the sensor: the pan falls short while the sensor reads the
full commanded stroke. The twin shortens the real push (the truth); this module leaves the reading unchanged,
so the sensor keeps reporting the commanded stroke the truth rows carry for that support.

rail_deviation (004 section V, eqs. 13-14)
------------------------------------------
004 injects "a measurement deviation with horizontal angle of 1 deg for every two chutes" into the rail
kinematics model that the support displacement sensors feed. We model it as a deviated stretch of rail that
the sensors report: counting chutes i = 1, 2, ... from the start chute, chute i makes the angle
Phi_i = value * ceil(i / 2) [deg] with the coal-wall line (the angle grows by `value` every two chutes), and
the lateral error accumulated up to chute n is eq. 13 in the advance direction (body x),

    e(n) = sum_{i=1..n} (l + b) sin(Phi_i),     b = pan_length_m (chute length),
    l = pi * b * |value| / 180                  (eq. 14: chord of the included angle, with a = b),

added to the ram reading (positive value: the pan appears further towards the coal wall). Which supports
and when:

* with the shearer truth (keyword `shearer`, the truth_shearer columns t and s): the start chute is the pan
  under the shearer's centre at t_start (pan = floor(s / pan_length_m)); at a sample time t in the window the
  deviated stretch is every pan the shearer's centre has covered since t_start (min..max of s over
  [t_start, t]) and the next pan in its direction of travel (the rail model predicts the path ahead); a support
  whose pan (twin.face.layout.support_stations) lies in it reads + e(|pan - start| + 1) until t_end. So the error builds up along the face as the shearer cuts through the window, as in 004.
* without it: the whole rail is deviated from the start of the window: the start chute is the pan of
  support `target` (support 0, the headgate, when the fault has no target) and every support from it towards
  the tailgate reads + e(pan - start + 1) inside the window.
"""

from __future__ import annotations

import numpy as np

from twin.config.scenario import Scenario
from twin.config.sensors import Fault
from twin.face.layout import support_stations
from twin.sensors.clock import sample_times, true_at
from twin.sensors.faults import ReadingFaults, apply_gain_faults, faults_of, window_mask


def rail_deviation_m(n_chutes: np.ndarray, value_deg: float, chute_length_m: float) -> np.ndarray:
    """Lateral error e(n) of 004 eq. 13 after n chutes (n >= 1) of a value_deg-per-two-chutes deviation."""
    n = np.asarray(n_chutes, dtype=np.int64)
    n_max = int(n.max(initial=0))
    i = np.arange(1, n_max + 1)
    phi = np.radians(value_deg * np.ceil(i / 2))
    seg = chute_length_m + np.pi * chute_length_m * abs(value_deg) / 180.0
    e = np.concatenate(([0.0], np.cumsum(seg * np.sin(phi))))
    return e[np.clip(n, 0, n_max)]


def _rail_deviation(x: np.ndarray, t_grid: np.ndarray, fault: Fault, scn: Scenario, stations: np.ndarray,
                    shearer: dict[str, np.ndarray] | None) -> None:
    rows = np.flatnonzero(window_mask(t_grid, fault))
    if rows.size == 0:
        return
    length, n_pans = scn.face.pan_length_m, scn.face.pan_count
    if shearer is None:
        start = stations[0 if fault.target is None else min(fault.target, stations.size - 1)]
        cols = np.flatnonzero(stations >= start)
        x[np.ix_(rows, cols)] += rail_deviation_m(stations[cols] - start + 1, fault.value, length)[None, :]
        return
    t_sh = np.asarray(shearer["t"], dtype=float)
    s_sh = np.asarray(shearer["s"], dtype=float)
    in_win = window_mask(t_sh, fault)
    s_win = s_sh[in_win]
    s0 = np.interp(fault.t_start_s, t_sh, s_sh)
    if s_win.size == 0:  # no shearer sample inside the window (window shorter than a truth step)
        s_win, t_win = np.array([s0]), np.array([fault.t_start_s])
    else:
        t_win = t_sh[in_win]
    lo, hi = np.minimum.accumulate(np.minimum(s_win, s0)), np.maximum.accumulate(np.maximum(s_win, s0))
    k = np.clip(np.searchsorted(t_win, t_grid[rows], side="right") - 1, 0, None)

    def pan(s):
        return np.clip(np.floor(s / length), 0, n_pans - 1).astype(np.int64)

    start = pan(s0)
    # The chute the shearer is entering belongs to the stretch too: the rail model predicts the path ahead.
    ahead = 1 if s_win[-1] >= s0 else -1
    first = np.clip(pan(lo[k]) - (ahead < 0), 0, n_pans - 1)
    last = np.clip(pan(hi[k]) + (ahead > 0), 0, n_pans - 1)
    covered = (first[:, None] <= stations[None, :]) & (stations[None, :] <= last[:, None])
    err = rail_deviation_m(np.abs(stations - start) + 1, fault.value, length)
    x[rows] += np.where(covered, err[None, :], 0.0)


class PushRams:
    """The PUSHRAM stream drawn chunk by chunk: `step` takes the next sample times (in order) and gives their rows. The
    base noise comes from `rng` in sample order and each fault's own draws from a generator of its own
    (twin.sensors.faults.ReadingFaults), so any partition of the samples gives the stream of one step."""

    def __init__(self, scn: Scenario, rng: np.random.Generator, faults: list[Fault]):
        self.scn, self.faults, self.rng = scn, faults, rng
        self.stations = support_stations(scn)
        self.reading = ReadingFaults(faults, "ram", rng, scn.sensors.pushram.resolution_m)

    def step(self, t_grid: np.ndarray, supports: dict[str, np.ndarray],
             shearer: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
        """Rows (t, support, extension, valid) of every support at the sample times t_grid. `supports` holds the
        truth_supports columns (t, support, ram are used) up to the last sample at least; `shearer` (truth_shearer
        columns t and s over the run) places rail_deviation where the shearer travels; see the module doc."""
        n_sup = self.stations.size
        x = true_at(supports, "ram", t_grid, n_sup)
        noise = self.rng.standard_normal(x.shape)  # drawn first, whatever the faults: see the module doc
        apply_gain_faults(x, t_grid, self.faults, "ram")
        for f in faults_of(self.faults, "rail_deviation"):
            _rail_deviation(x, t_grid, f, self.scn, self.stations, shearer)
        valid = self.reading.apply(x, t_grid, self.scn.sensors.pushram.noise_m * noise)
        return {"t": np.repeat(t_grid, n_sup), "support": np.tile(np.arange(n_sup, dtype=np.int32), t_grid.size),
                "extension": x.ravel(), "valid": valid.ravel()}


def pushram_stream(scn: Scenario, supports: dict[str, np.ndarray], t_end: float, rng: np.random.Generator,
                   faults: list[Fault], shearer: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """The PUSHRAM stream (t, support, extension, valid): every support at each sample of [0, t_end] (PushRams in one
    step).

    `supports` holds the truth_supports columns (t, support, ram are used); `faults` the scenario's fault
    schedule (ram_* on their target, rail_deviation; push_shortfall leaves the reading unchanged). `shearer`
    (truth_shearer columns t and s) places rail_deviation where the shearer travels; see the module doc.
    """
    return PushRams(scn, rng, faults).step(sample_times(0.0, t_end, scn.sensors.pushram.rate_hz), supports, shearer)
