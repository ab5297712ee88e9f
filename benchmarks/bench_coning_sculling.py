"""Reproduction of 000 sections 7.2 (coning) and 7.4 (sculling) beside the paper's figures.

The experiments are the scenario files scenarios/seed000_coning.toml and seed000_sculling.toml (every
parameter there); twin.papers.sins_experiments runs them (`longwall run scenarios/seed000_coning.toml` also writes the error
time series and a Rerun recording).
Coning: alpha = 1 deg, omega = 2 pi rad/s, h = 10 ms, 40 s, 3 sub-samples (the paper's n = 3). The coning error of
an update is the algorithm's rotation vector minus the exact equivalent rotation vector over the interval; the
table gives its largest component per axis (eq. 55's axes: x is the cone axis), uncompensated (sum of the
increments) and compensated.
Sculling: eq. 71 with f = 1 Hz, B = 0.1 deg, C = 0.01 g, 30 s, 4 sub-samples of 6 ms (T = 0.024 s): the largest
velocity error against the true motion, uncompensated and compensated.
Run: python benchmarks/bench_coning_sculling.py
"""

from twin.papers.sins_experiments import benchmark

if __name__ == "__main__":
    benchmark(["seed000_coning", "seed000_sculling"])
