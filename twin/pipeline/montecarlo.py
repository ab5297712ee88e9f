"""Monte Carlo trials: physics once, sensor errors redrawn per trial, estimators run on each trial.

Trial k's sensors are drawn from (scenario seed, k) (twin.sensors.streams), so its result does not depend on where it
runs: in this process (`SequentialTrials`), in local processes (`ProcessTrials`, each loading the truth from the
run's Parquet once) or on a Ray cluster (`RayTrials`, the truth put into the object store once). Trial k's
sensor streams and estimates go to trials/NNN/ of the run directory; trial 0 is the run itself (the top of the
run directory, with its recording) and is run by twin.cli. The gathered metrics: twin.pipeline.montecarlo_table.
"""

from __future__ import annotations

import logging
import os
import shutil
import socket
import tempfile
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, replace
from multiprocessing import get_context
from pathlib import Path
from typing import TYPE_CHECKING, Self

import numpy as np
import pyarrow as pa

from estimators.io.logformat import STREAMS, read_stream, write_stream
from estimators.workers import leave_signals_to_parent
from twin.config.scenario import Scenario
from twin.pipeline.estimate import run_estimators

if TYPE_CHECKING:
    from twin.sensors.streams import ImuTruth

SENSOR_TRUTH = ("truth_shearer", "truth_supports", "truth_cycles")
"""The truth streams the sensor models draw from."""
SCORING_TRUTH = ("truth_shearer.parquet", "truth_cycles.parquet", "truth_supports.parquet")
"""The truth files run_estimators scores against, linked into a trial's directory while it runs."""


class MonteCarloError(ValueError):
    """Trials cannot be run as asked (Ray missing or unreachable); one line saying why."""


@dataclass(frozen=True)
class TrialContext:
    """What every trial needs from the run: the scenario, the truth the sensors are drawn from (stream name →
    columns), the error-free IMU increments and the directory holding the SCORING_TRUTH files."""

    scn: Scenario
    truth: dict[str, dict[str, np.ndarray]]
    ideal: ImuTruth
    truth_dir: Path | None


@dataclass(frozen=True)
class TrialResult:
    """One trial: run_estimators' metrics, or the one-line reason it failed."""

    trial: int
    metrics: dict
    error: str | None = None


def one_line(err: BaseException) -> str:
    text = str(err).strip().splitlines()
    return f"{type(err).__name__}: {text[0]}" if text else type(err).__name__


def trial_dir(run_dir: Path, trial: int) -> Path:
    return Path(run_dir) / "trials" / f"{trial:03d}"


def trial_context(scn: Scenario, tables: dict[str, pa.Table], truth_dir: Path | None) -> TrialContext:
    """The context from the truth tables as logged (the same values whether in memory or read back)."""
    from twin.sensors.streams import imu_truth

    truth = {name: {c: tables[name].column(c).to_numpy() for c in tables[name].column_names}
             for name in SENSOR_TRUTH}
    return TrialContext(scn, truth, imu_truth(scn, truth["truth_shearer"]), truth_dir)


def load_trial_context(run_dir: Path, scn: Scenario) -> TrialContext:
    """The context from a run directory's truth Parquet."""
    return trial_context(scn, {name: read_stream(run_dir, STREAMS[name]) for name in SENSOR_TRUTH}, Path(run_dir))


def write_sensors(ctx: TrialContext, trial: int, target: Path) -> None:
    """Draw trial `trial`'s sensor streams and write them to `target`."""
    from twin.sensors.streams import sensor_streams

    target.mkdir(parents=True, exist_ok=True)
    for name, cols in sensor_streams(ctx.scn, ctx.truth, ctx.ideal, trial).items():
        write_stream(target, STREAMS[name], cols)


def _link(source: Path, target: Path) -> None:
    try:
        os.link(source, target)
    except OSError:
        shutil.copyfile(source, target)


def run_trial(ctx: TrialContext, trial: int, target: Path) -> TrialResult:
    """Draw a trial's sensors into `target`, run the scenario's estimators there (no recording) and return
    their metrics; an exception becomes a failed result with its one-line reason."""
    try:
        write_sensors(ctx, trial, target)
        links = [target / name for name in SCORING_TRUTH]
        try:
            for link in links:
                _link(ctx.truth_dir / link.name, link)
            return TrialResult(trial, run_estimators(target, ctx.scn, recording=False))
        finally:
            for link in links:
                link.unlink(missing_ok=True)
    except Exception as err:  # noqa: BLE001 -- any failure is recorded as a failed trial, never dropped
        return TrialResult(trial, {}, one_line(err))


Progress = Callable[[int], None]
"""Called with the number of trials done so far."""


class TrialRunner:
    """Runs trials 1.. of a run: `submit` starts them (the caller meanwhile runs trial 0), `gather` waits and
    returns their results in trial order, `close` (also on leaving a `with` block) cancels what is left."""

    description = ""

    def submit(self, scn: Scenario, run_dir: Path, trials: range) -> None:
        """Start trials `trials` of the run in `run_dir`, whose truth is on disk there."""
        raise NotImplementedError

    def gather(self, progress: Progress) -> list[TrialResult]:
        raise NotImplementedError

    def close(self, interrupted: bool = False) -> None:
        """Nothing to release; `interrupted`: leaving on an exception (Ctrl-C, SIGTERM), stop what runs now."""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type, *exc) -> None:
        self.close(interrupted=exc_type is not None)


class SequentialTrials(TrialRunner):
    """Trials one after the other in this process, when gathered."""

    description = "sequential"

    def __init__(self) -> None:
        self._jobs: tuple[Scenario, Path, range] | None = None

    def submit(self, scn: Scenario, run_dir: Path, trials: range) -> None:
        self._jobs = (scn, Path(run_dir), trials)

    def gather(self, progress: Progress) -> list[TrialResult]:
        if self._jobs is None:
            return []
        scn, run_dir, trials = self._jobs
        ctx = load_trial_context(run_dir, scn)  # loaded once trial 0 is done with its memory
        results = []
        for trial in trials:
            results.append(run_trial(ctx, trial, trial_dir(run_dir, trial)))
            progress(len(results))
        return results


_worker_context: TrialContext | None = None
"""A pool worker's context, loaded once by `_load_worker_context`."""


def _load_worker_context(run_dir: Path, scn: Scenario) -> None:
    global _worker_context
    leave_signals_to_parent()
    _worker_context = load_trial_context(run_dir, scn)


def _worker_trial(trial: int, target: Path) -> TrialResult:
    return run_trial(_worker_context, trial, target)


class ProcessTrials(TrialRunner):
    """Trials spread over local processes (spawned; each loads the truth from the run's Parquet once)."""

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self.description = f"{workers} processes"
        self._pool: ProcessPoolExecutor | None = None
        self._futures: dict = {}

    def submit(self, scn: Scenario, run_dir: Path, trials: range) -> None:
        if not trials:
            return
        self._pool = ProcessPoolExecutor(min(self.workers, len(trials)), mp_context=get_context("spawn"),
                                         initializer=_load_worker_context, initargs=(Path(run_dir), scn))
        self._futures = {self._pool.submit(_worker_trial, trial, trial_dir(run_dir, trial)): trial
                         for trial in trials}

    def gather(self, progress: Progress) -> list[TrialResult]:
        results = {}
        for future in as_completed(self._futures):
            trial = self._futures[future]
            try:
                results[trial] = future.result()
            except Exception as err:  # noqa: BLE001 -- a worker that died (BrokenProcessPool) fails its trials
                results[trial] = TrialResult(trial, {}, one_line(err))
            progress(len(results))
        return [results[trial] for trial in sorted(results)]

    def close(self, interrupted: bool = False) -> None:
        if self._pool is None:
            return
        if interrupted:  # the running trials are stopped, not waited for
            # Python 3.14 has terminate_workers(); before it, the executor's own table of its processes, taken before
            # shutdown(wait=False) drops it (terminating after it reached none: the workers ran their trials on,
            # and the interpreter's exit waited for them).
            processes = list((self._pool._processes or {}).values())
            self._pool.shutdown(wait=False, cancel_futures=True)
            for process in processes:
                process.terminate()
            for process in processes:
                process.join()
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._pool = None


def _ray_trial(ctx: TrialContext, scoring_truth: dict[str, bytes], trial: int) -> tuple[TrialResult, dict[str, bytes]]:
    """A Ray task: the trial in a scratch directory on whichever node runs it; returns its result and its files
    (path relative to trials/NNN → bytes), which the driver writes into the run directory."""
    with tempfile.TemporaryDirectory(prefix="longwall-trial-") as scratch:
        scratch = Path(scratch)
        for name, data in scoring_truth.items():
            (scratch / name).write_bytes(data)
        target = scratch / "trial"
        result = run_trial(replace(ctx, truth_dir=scratch), trial, target)
        files = {p.relative_to(target).as_posix(): p.read_bytes() for p in sorted(target.rglob("*")) if p.is_file()}
    return result, files


def check_reachable(address: str) -> None:
    """Fail fast on a host:port nothing listens on (ray.init would retry for minutes); "auto" is Ray's to
    resolve."""
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not port.isdigit():
        return
    try:
        socket.create_connection((host, int(port)), timeout=5).close()
    except OSError as err:
        raise MonteCarloError(f"--ray {address}: no Ray cluster answers there ({err.strerror or err}); start one "
                              f"with `ray start --head` or check the address") from None


class RayTrials(TrialRunner):
    """Trials as Ray tasks on the cluster at `address`: the truth goes into the object store once, one task
    per trial, the results gathered in trial order."""

    def __init__(self, address: str) -> None:
        try:
            import ray
        except ImportError:
            raise MonteCarloError('--ray: Ray is not installed; pip install -e ".[ray]"') from None
        check_reachable(address)
        try:
            ray.init(address=address, logging_level=logging.ERROR, log_to_driver=False)
        except Exception as err:  # noqa: BLE001 -- whatever Ray raises, one line
            raise MonteCarloError(f"--ray {address}: cannot connect to a Ray cluster ({one_line(err)})") from None
        self._ray = ray
        self.description = f"Ray cluster {address}"
        self._refs: dict = {}
        self._run_dir: Path | None = None

    def submit(self, scn: Scenario, run_dir: Path, trials: range) -> None:
        if not trials:
            return
        ray = self._ray
        self._run_dir = Path(run_dir)
        ctx_ref = ray.put(replace(load_trial_context(self._run_dir, scn), truth_dir=None))
        truth_ref = ray.put({name: (self._run_dir / name).read_bytes() for name in SCORING_TRUTH})
        task = ray.remote(_ray_trial)
        self._refs = {task.remote(ctx_ref, truth_ref, trial): trial for trial in trials}

    def gather(self, progress: Progress) -> list[TrialResult]:
        ray, results, pending = self._ray, {}, list(self._refs)
        while pending:
            [ref], pending = ray.wait(pending, num_returns=1)
            trial = self._refs[ref]
            try:
                results[trial], files = ray.get(ref)
            except Exception as err:  # noqa: BLE001 -- a task Ray could not run (worker died, node lost)
                results[trial], files = TrialResult(trial, {}, one_line(err)), {}
            for name, data in files.items():
                path = trial_dir(self._run_dir, trial) / name
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_bytes(data)
            progress(len(results))
        self._refs = {}
        return [results[trial] for trial in sorted(results)]

    def close(self, interrupted: bool = False) -> None:
        for ref in self._refs:
            self._ray.cancel(ref)
        self._refs = {}
        self._ray.shutdown()


def trial_runner(workers: int = 1, ray_address: str | None = None) -> TrialRunner:
    """The runner for `--workers` / `--ray` (connects to the Ray cluster now, so a bad address fails early)."""
    if ray_address is not None:
        return RayTrials(ray_address)
    return ProcessTrials(workers) if workers > 1 else SequentialTrials()
