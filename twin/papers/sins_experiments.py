"""SINS experiments: the simulations of 000 as scenario files, run beside the paper's figures.

A second kind of scenario file, marked by the top-level key `kind = "sins_experiment"`; `experiment` names one
of the four simulations of 000_78d1df35b229913e.txt and a section of the same name holds all its parameters
(no hidden defaults: every parameter is a required key, in the units the paper writes):

* ``alignment`` (000 section 5.3, Table 1): a standing IMU at 34.27 deg, 36 m, 000's heading angle 270 deg,
  initial attitude errors 3, 3, 5 deg, 200 Hz; `estimators.sins.fine_alignment.fine_align` with each filter
  (EKF, UKF, optimized UKF) on each IMU grade named (twin.config.imu_grades, errors drawn by twin.sensors.imu_errors).
* ``lever_arm`` (000 section 6.4, Tables 2-3): the sway of 000 eq. 54 (pitch, roll, yaw 10 deg, periods 6, 8,
  10 s) of a body whose reference point rests at the site, the sensor at lever arms r_p = [1, 1, 1] and
  [1.5, 1.5, 1] m. Part 1 mechanizes an error-free sensor (twin.sensors.imu's exact increments) for 400 s with and
  without the two-sample compensation (estimators.sins.installation.compensate_lever_arm, eqs. 48-53); part 2
  (``[closed_loop]``) runs the paper's own setting as far as it is specified: a 15-state closed-loop fine
  alignment with zero-velocity observations and the paper's sensor errors (estimators.sins.lever_arm_filter).
* ``coning`` (000 section 7.2): the cone of eq. 55 (alpha = 1 deg, omega = 2 pi rad/s, h = 10 ms, 3 samples,
  40 s; twin.papers.motions.coning): the N-sample rotation vector (estimators.sins.strapdown.compensate) against the
  exact one, and the body attitude integrated from either against the true cone.
* ``sculling`` (000 section 7.4): eq. 71 (f = 1 Hz, B = 0.1 deg, C = 0.01 g, 4 samples of 6 ms, 30 s;
  twin.papers.motions.sculling): the velocity integrated from plain sums and from the N-sample sculling
  compensation against the true vibration.

Each run gives our figures, the paper's, a table of both, and error time series against the truth: quantity
"attitude" [rad] (error angles phi with C_true = Exp(phi) C_est, E/N/U), "velocity" [m/s], "position" [m]
(E/N/U), and where the experiment has them "coning" (the per-update coning error [rad], body axes) and
"sigma" (a filter's one-sigma attitude uncertainty [rad]). In coning and sculling the body rests level with
b = n (twin.papers.motions), so their axes are E, N, U too.

The files are twin.config.experiments'; errors in a file are a `ScenarioError` of one line naming the file and
the key, as for face scenarios. The runs are twin.papers.coning_sculling, lever_arm and alignment; the run
directory twin.papers.sins_rundir's.
"""

from __future__ import annotations

import time
from pathlib import Path

from twin.config.experiments import Experiment, is_experiment, load_experiment
from twin.papers.alignment import run_alignment
from twin.papers.coning_sculling import run_coning, run_sculling
from twin.papers.lever_arm import run_lever_arm
from twin.papers.sins_results import ExperimentResult

__all__ = ["RUNNERS", "benchmark", "is_experiment", "run_experiment", "run_shipped"]

RUNNERS = {"alignment": run_alignment, "lever_arm": run_lever_arm, "coning": run_coning, "sculling": run_sculling}


def run_experiment(exp: Experiment) -> ExperimentResult:
    return RUNNERS[exp.experiment](exp)


def run_shipped(name: str, seed: int | None = None) -> ExperimentResult:
    """Run the shipped experiment file scenarios/NAME.toml (its seed, or `seed`): ours and the paper's figures."""
    from importlib import resources

    return run_experiment(load_experiment(Path(str(resources.files("twin.scenarios") / f"{name}.toml")), seed))


def benchmark(names: list[str]) -> None:
    """Run shipped experiment files (scenarios/NAME.toml) and print ours beside the paper's with run times: the
    benchmarks' entry point (benchmarks/bench_coning_sculling.py, bench_lever_arm.py)."""
    for name in names:
        start = time.perf_counter()
        result = run_shipped(name)
        print("\n".join(result.table))
        print(f"({name}: {time.perf_counter() - start:.1f} s)\n")
