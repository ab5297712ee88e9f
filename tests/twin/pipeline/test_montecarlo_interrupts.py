"""Ctrl-C with Monte Carlo workers: the workers leave it to the parent (no traceback each), which stops them."""

from __future__ import annotations

import os
import signal
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

from estimators.workers import leave_signals_to_parent
from twin.pipeline.montecarlo import ProcessTrials


def _interrupted_and_alive() -> str:
    os.kill(os.getpid(), signal.SIGINT)  # what a Ctrl-C in the terminal sends every process of the group
    time.sleep(0.2)
    return "alive"


def test_workers_ignore_ctrl_c_and_an_interrupted_parent_stops_them_at_once(capfd):
    trials = ProcessTrials(2)
    trials._pool = ProcessPoolExecutor(2, mp_context=get_context("spawn"), initializer=leave_signals_to_parent)
    assert trials._pool.submit(_interrupted_and_alive).result(timeout=120) == "alive"
    assert "Traceback" not in capfd.readouterr().err
    futures = [trials._pool.submit(time.sleep, 60) for _ in range(2)]
    while not all(f.running() for f in futures):
        time.sleep(0.05)
    workers = list(trials._pool._processes.values())
    start = time.monotonic()
    trials.__exit__(KeyboardInterrupt, KeyboardInterrupt(), None)  # leaving `with trial_runner(...)` on Ctrl-C
    assert time.monotonic() - start < 10 and trials._pool is None
    # Stopped, not left to sleep out their minute. The executor's own thread reaps them too, and a join racing it
    # can return before the exit status is on record, so their state is read until it is.
    while any(w.is_alive() for w in workers) and time.monotonic() - start < 10:
        time.sleep(0.05)
    assert not any(w.is_alive() for w in workers)
