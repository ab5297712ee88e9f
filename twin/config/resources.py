"""What a validated scenario will cost before it runs: samples per stream, memory, disk, simulated and wall time.

A face run's cost follows from its simulated span (the haulage timeline in closed form, `simulated_s`) times each
stream's rate, and the per-row byte counts and speeds below, measured on scenarios/default.toml (`longwall run`,
2 cycles, 2262 s simulated; /usr/bin/time for the peak memory) and seed004 (benchmarks/bench_speed.py). The
paper experiments (000's SINS experiments, 002's turntable) cost their sample count at their measured speed.
`check_resources` refuses a run over MAX_MEMORY_BYTES, MAX_DISK_BYTES or MAX_WALL_S with one line naming the
figure, the limit and the keys to reduce.
The figures are estimates (a factor of two either way); the limits are far enough above the shipped scenarios
(seed004_20cycles, the largest, is estimated at 12 GB, 2 GB and 40 minutes; README: about 14 GB of memory) that
only absurd scenarios meet them.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from estimators.shearer.config import STREAMED
from twin.config.experiments import (
    AlignmentExperiment,
    ConingExperiment,
    Experiment,
    LeverArmExperiment,
    ScullingExperiment,
)
from twin.config.scenario import (
    Scenario,
    ScenarioError,
    sump_length_m,
    support_count,
    travel_length_m,
)
from twin.config.turntable import Turntable
from twin.face.layout import MESH_MAX_CELLS

GIB = 1 << 30


def _machine_memory() -> int:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return 20 * GIB


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity, as a container or `taskset` limits it)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


MAX_MEMORY_BYTES = int(0.8 * _machine_memory())
"""80 % of the machine's RAM (os.sysconf; of 20 GiB where it cannot be read): a run that swaps or is killed by the
kernel's OOM killer hours in is worse than a refusal."""
MAX_DISK_BYTES = 50 * GIB
"""A run directory of more than 50 GiB is a mistake, not a run (the largest shipped run writes 3 GB)."""
MAX_WALL_S = 6 * 3600.0
"""Six hours of computing (on this project's 2-core reference machine) is a batch job, not a twin run."""

BASE_MEMORY = 0.45e9
"""Peak memory of any stage of a face run before its data [bytes]: the imports (210 MB measured at the start),
MuJoCo's window models, numba's compiled kernels, the workers' own."""
CYCLE_BYTES_PER_TRUTH_ROW = 800.0
"""The twin stage's peak memory per truth_shearer row of a cycle [bytes]: it holds about two cycles of the shearer's
ride and truth (208 bytes a row) with their sensor draws in chunks (seed004: 1.21 GB with 937 000 rows a cycle)."""
RECORDING_BYTES = 0.3e9
"""The run recording's own: its blocks of the long streams, the pans' and supports' frames a chunk at a time
(seed004's write_recording: 250 MB above its start)."""
HELD_BYTES = {"recording_s": 1200.0, "epochs_batch": 2700.0}
"""What a run's stages hold for its whole length [bytes per item]: the run recording's (per simulated second: its
series are cut and sent a block at a time, what grows is its paths and the writer's allocations; panel_100: 5 MB a
cycle of 4,600 s between 5 and 20 cycles), and each batch method's solution and filter arrays (per filter epoch, the
methods of a group and of the other workers at once; the streamed methods hold none and are scored a row group at a
time: estimators.shearer.config.STREAMED, twin.pipeline.estimate.EstimateWriter; seed004 with five batch methods and
234 000 epochs: 3.16 GB, streamed: 2.11 GB)."""
PASS_BYTES_PER_EPOCH = 20e3
"""A streamed filter's peak memory per filter epoch of its pass [bytes]: the pass's rows (states, sigmas, navigation),
its IMU rows and increments, the forward pass's and the smoother's outputs; the smoother's per-epoch matrices are on
disk (estimators.kalman.rts.StoredInterval). panel_100 over 5 cycles: 1.35 GB with two methods on two workers,
23 000 epochs a pass (2.57 GB with the matrices in memory)."""
BATCH_LOG_STREAMS = ("odometer", "mag", "pushram")
"""The streams a batch method's log holds whole (estimators.io.log.load_log; the IMU stays on disk)."""
FLOOR_BYTES_PER_CELL = 120.0
"""Memory per cell of the recording's floor mesh (its heights, vertices and triangles)."""
FLOOR_CELL_M = 0.25
"""Cell size of the floor's height field (twin.face.model.HFIELD_RESOLUTION_M) [m]."""
FLOOR_MARGIN_M = 12.0
"""Floor beyond the panel and the face along each axis (twin.face.model: margins and the supports' base) [m]."""


@dataclass(frozen=True)
class RowCost:
    """A stream's bytes per row in memory (the pyarrow table) and on disk (Parquet and its share of the .rrd)."""

    memory: float
    disk: float


ROW_COSTS = {
    "truth_shearer": RowCost(208.0, 114.0), "imu": RowCost(57.0, 41.0), "mag": RowCost(33.0, 18.0),
    "odometer": RowCost(25.0, 2.0), "pushram": RowCost(21.0, 5.0), "pressure": RowCost(38.0, 8.0), "support_imu": RowCost(85.0, 59.0),
    "estimates": RowCost(386.0, 694.0),
}
"""Measured on default.toml's run (support_imu on seed002_face's); `estimates` per method and filter epoch: the
solution, the filter's states and their share of estimates.rrd."""
SENSOR_STREAMS = ("imu", "mag", "odometer", "pushram", "pressure", "support_imu", "estimates")
"""What each Monte Carlo trial draws and writes again (the truth is shared)."""
TWIN_S_PER_STEP = 1.1e-5
"""Wall time per step of the twin (face steps, ride steps and truth samples; default.toml: 9.8 s for 904 900;
seed004 4.3e-6)."""
ESTIMATOR_S_PER_SAMPLE = 9e-6
"""Wall time per IMU sample per shearer estimator (default.toml: `longwall estimate` 25 s for 6 methods x 452 450
samples on the loaded 2-core machine; seed004's benchmark 4.3e-6 for the KF with the smoother)."""
PAPER_START_S = 12.0
"""Wall time of a paper experiment before its first sample (imports, numba's compilation)."""
PAPER_S_PER_SAMPLE = {"alignment": 2.4e-5, "lever_arm": 1.6e-4, "coning": 1e-3, "sculling": 6e-4, "turntable": 2.2e-3}
"""Wall time per sample (per grade and filter for the alignment, per lever arm for the lever arm) of each paper
experiment beyond PAPER_START_S, measured on its shipped file (seed000_alignment 20 s for 360 000 samples,
seed002_turntable 124 s for 50 000)."""
PAPER_BYTES_PER_SAMPLE = 1000.0
"""Peak memory per sample of a paper experiment beyond the imports (seed000_lever_arm: 170 MB for 240 000 samples;
rounded up)."""
PAPER_BASE_MEMORY = 320e6
"""The imports' resident memory (measured: 318 MB)."""


@dataclass(frozen=True)
class Resources:
    """What a run will take: rows per stream, peak memory and disk [bytes], simulated and wall time [s]."""

    rows: dict[str, float]
    memory_bytes: float
    disk_bytes: float
    simulated_s: float
    wall_s: float
    reduce: str
    """The keys that make it big, for the refusal."""
    parts_s: dict[str, float] | None = None
    """A face run's wall time [s] of the twin (simulation, sensors, writing) and of one trial's estimators on one
    core: what the progress bar weighs its stages by."""


def simulated_s(scn: Scenario) -> float:
    """The run's simulated span: twin.face.haulage.Timeline's duration in closed form (each leg at its speed,
    each rest-to-rest run v / a longer for its ramps, every stand); within 1 % of the timeline (tested)."""
    h, a = scn.haulage, scn.haulage.acceleration_m_s2
    cut, ret, sump = (v / 60.0 for v in (h.cutting_speed_m_min, h.return_speed_m_min, h.sump_speed_m_min))
    travel, sump_m = travel_length_m(scn), sump_length_m(scn)
    first = travel / cut + cut / a
    later = sump_m / ret + (travel - sump_m) / cut + max(cut, ret) / a
    each = 2 * h.reversal_stop_s + h.end_push_stop_s + sump_m / sump + sump / a + sump_m / cut + cut / a
    stops = sum(st.duration_s + (cut / a if st.at_m > 0 else 0.0) for st in h.stops)
    return first + (scn.cycles - 1) * later + scn.cycles * each + stops


def face_resources(scn: Scenario, trials: int = 1, sensors: bool = True, workers: int = 1) -> Resources:
    """The cost of `longwall run` on a face scenario with `trials` sensor trials on `workers` processes."""
    t = simulated_s(scn)
    s = scn.sensors
    rows = {"truth_shearer": t * scn.rates.truth_hz}
    if sensors:
        rows |= {"imu": t * s.imu.rate_hz, "mag": t * s.mag.rate_hz, "odometer": t * s.odometer.rate_hz,
                 "pushram": t * s.pushram.rate_hz * support_count(scn),
                 "pressure": t * s.pressure.rate_hz * support_count(scn),
                 "support_imu": t * s.support_imu.rate_hz * len(s.support_imu.supports),
                 "estimates": t * scn.estimators.shearer.filter_rate_hz * len(scn.estimators.shearer.methods)}
    f = scn.face
    # The window models' floor is a band under the window (twin.face.model.FloorBand); the recording's floor mesh
    # covers the run's face, at most MESH_MAX_CELLS cells.
    cells = min(MESH_MAX_CELLS, ((min(f.panel_length_m, scn.cycles * f.web_depth_m) + FLOOR_MARGIN_M) / FLOOR_CELL_M)
                * ((f.pan_count * f.pan_length_m + FLOOR_MARGIN_M) / FLOOR_CELL_M))
    stages = stage_memory(scn, t, rows, sensors, workers)
    memory = max(stages.values()) + FLOOR_BYTES_PER_CELL * cells
    disk_once = {k: n * ROW_COSTS[k].disk for k, n in rows.items()}
    disk = sum(v * (trials if k in SENSOR_STREAMS else 1) for k, v in disk_once.items())
    steps = t / scn.rates.face_timestep_s + t * scn.rates.ride_hz + rows["truth_shearer"]
    estimating = ESTIMATOR_S_PER_SAMPLE * rows.get("imu", 0.0) * len(scn.estimators.shearer.methods)
    wall = TWIN_S_PER_STEP * steps + estimating * trials / workers
    return Resources(rows, memory, disk, t, wall, "cycles, the haulage stops and speeds, the rates (rates.*, "
                     "sensors.*.rate_hz), face.pan_count, face.panel_length_m, the estimators, --trials",
                     {"twin": TWIN_S_PER_STEP * steps, "estimators": estimating})


def stage_memory(scn: Scenario, t: float, rows: dict[str, float], sensors: bool = True, workers: int = 1
                 ) -> dict[str, float]:
    """Peak memory [bytes] of each stage of a face run of simulated span t (`rows` per stream): the twin (two cycles
    of the shearer's truth; support IMUs keep the supports' truth and the shearer's (t, s) whole), the run
    recording (its plotted series), the estimators (the scored estimates; batch methods their logs and solutions,
    each Monte Carlo worker its own)."""
    twin = BASE_MEMORY + CYCLE_BYTES_PER_TRUTH_ROW * rows["truth_shearer"] / scn.cycles
    if scn.sensors.support_imu.supports:
        twin += rows["truth_shearer"] * 16.0 + ROW_COSTS["support_imu"].memory * rows.get("support_imu", 0.0)
    out = {"twin": twin,
           "recording": BASE_MEMORY + RECORDING_BYTES + HELD_BYTES["recording_s"] * t}
    methods = scn.estimators.shearer.methods
    if sensors and methods:
        epochs = t * scn.estimators.shearer.filter_rate_hz
        at_once = min(len(methods), usable_cores())
        batch = [m for m in methods if m not in STREAMED]
        streamed = PASS_BYTES_PER_EPOCH * epochs / (2 * scn.cycles) * min(len(methods) - len(batch), at_once)
        if batch:  # the log and the whole-run arrays of the batch methods, which run first (TASKS)
            batch_bytes = (sum(rows.get(k, 0.0) * ROW_COSTS[k].memory for k in BATCH_LOG_STREAMS)
                           + HELD_BYTES["epochs_batch"] * epochs * min(len(batch), 2 * at_once))
            streamed = max(streamed, batch_bytes)
        out["estimators"] = BASE_MEMORY + streamed * workers
    return out



def paper_resources(exp: Experiment | Turntable) -> Resources:
    """The cost of a paper experiment: its samples at its measured speed."""
    if isinstance(exp, AlignmentExperiment):
        p = exp.alignment
        name, span, n, keys = "alignment", p.duration_s, p.rate_hz * p.duration_s * len(p.grades) * len(
            p.methods), "alignment.rate_hz, duration_s, grades, methods"
    elif isinstance(exp, LeverArmExperiment):
        p = exp.lever_arm
        name, span, n, keys = "lever_arm", p.duration_s, p.rate_hz * p.duration_s * (
            len(p.lever_arms_m) + 1), "lever_arm.rate_hz, duration_s, lever_arms_m"
    elif isinstance(exp, ConingExperiment | ScullingExperiment):
        name = exp.experiment
        p = getattr(exp, name)
        span, n, keys = p.duration_s, p.duration_s / p.step_s, f"{name}.duration_s or raise {name}.step_s"
    else:
        runs = (exp.paper_filters.gd_iterations + 1) / 26  # the shipped file's 25 iterations and the test run
        name, span, n, keys = "turntable", exp.motion.duration_s, exp.motion.duration_s * exp.unit.rate_hz * runs, \
            "motion.duration_s, unit.rate_hz, paper_filters.gd_iterations"
    return Resources({name: n}, PAPER_BASE_MEMORY + PAPER_BYTES_PER_SAMPLE * n, 0.0, span,
                     PAPER_START_S + PAPER_S_PER_SAMPLE[name] * n, keys)


def estimate_resources(scn: Scenario | Experiment | Turntable, trials: int = 1, sensors: bool = True,
              workers: int = 1) -> Resources:
    """The cost of running any kind of scenario file (the Monte Carlo arguments apply to face scenarios)."""
    if isinstance(scn, Scenario):
        return face_resources(scn, trials, sensors, workers)
    return paper_resources(scn)


def check_resources(source: str, res: Resources) -> None:
    """ScenarioError (one line) when the run would exceed a limit: the figure, the limit, the keys to reduce."""
    for what, value, limit, unit in (("peak memory", res.memory_bytes, MAX_MEMORY_BYTES, GIB),
                                     ("disk", res.disk_bytes, MAX_DISK_BYTES, GIB),
                                     ("wall time", res.wall_s, MAX_WALL_S, 3600.0)):
        if not value <= limit:  # also refuses NaN
            u = "GiB" if unit == GIB else "h"
            raise ScenarioError(f"{source}: the run would need about {_fmt(value / unit)} {u} of {what} "
                                f"({_fmt(res.simulated_s)} s simulated), over the limit of {_fmt(limit / unit)} {u} "
                                f"(twin.config.resources); reduce {res.reduce}")


def _fmt(x: float) -> str:
    return f"{x:.3g}" if math.isfinite(x) and abs(x) < 1e6 else f"{x:.2e}"
