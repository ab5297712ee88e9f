"""The Python API under the `longwall` command: run a scenario, re-run the estimators, read a run directory.

    import twin
    run = twin.run("scenarios/seed001.toml", out="runs/s1", seed=3)   # or a twin.load_scenario(...) object
    run.metrics["estimators"]["kf_cpoem_rts"]["cycles"][-1]["sep"]
    run.stream("imu"), run.estimate("kf_cpoem_rts")                   # pyarrow Tables

The command line (twin.cli) parses its flags into these calls and prints what they return.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

import pyarrow as pa
from tqdm import tqdm

from estimators.heap import hold_mmap_threshold, release_free_memory
from estimators.io.logformat import (
    ESTIMATE,
    ESTIMATES_DIR,
    STREAMS,
    LogError,
    StreamBlocks,
    read_estimate,
    read_stream,
)
from twin.config.experiments import Experiment
from twin.config.resources import check_resources, estimate_resources, usable_cores
from twin.config.scenario import (
    Scenario,
    ScenarioError,
    load_face_scenario,
    load_scenario,
    parse_any,
    scenario_to_toml,
)
from twin.config.turntable import Turntable
from twin.face.export_target import DEFAULT_WIDTH_PX
from twin.pipeline.face_model import write_face_model
from twin.pipeline.rundir import (
    TIMING,
    RunDirError,
    atomic_run_dir,
    check_target,
    default_run_dir,
    run_lock,
    staged_update,
    write_timing,
)
from twin.view.record_rate import RECORD_RATE_HZ, check_record_rate, rate_label

if TYPE_CHECKING:
    from twin.face.drift import OffsetSource


@dataclass(frozen=True)
class Run:
    """A run directory (simulated, imported or recorded) and what it holds."""

    dir: Path

    @property
    def metrics(self) -> dict:
        """metrics.json: the twin's summary, each estimator's accuracy, the Monte Carlo section."""
        path = self.dir / "metrics.json"
        if not path.is_file():
            raise RunDirError(f"{path}: not found; is {self.dir} a run directory?")
        try:
            return json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as err:
            raise RunDirError(f"{path}: not valid JSON ({err}); run `longwall estimate {self.dir}` again") from None

    def stream(self, name: str) -> pa.Table:
        """One stream of the sensor log (estimators.io.logformat.STREAMS: imu, odometer, truth_shearer, ...)."""
        if name not in STREAMS:
            raise LogError(f"unknown stream '{name}' (streams: {', '.join(STREAMS)})")
        return read_stream(self.dir, STREAMS[name])

    def estimate(self, method: str) -> pa.Table:
        """Estimator `method`'s solution (estimates/METHOD.parquet): t, position, velocity, attitude, sigma, flags."""
        return read_estimate(self.dir, method, ESTIMATE)


def default_scenario() -> Path:
    """The shipped scenarios/default.toml, what `longwall run` runs with no argument."""
    return Path(str(resources.files("twin.scenarios") / "default.toml"))


def _seeded(scn, seed: int | None):
    """A loaded scenario of any kind with its seed replaced (validated again)."""
    if seed is None:
        return scn
    return parse_any({**scn.model_dump(), "seed": seed}, scn.name)


def run(scenario: str | Path | Scenario | Experiment | Turntable, out: str | Path | None = None,
        seed: int | None = None, trials: int = 1, *, force: bool = False, quiet: bool = True, sensors: bool = True,
        workers: int = 1, ray_address: str | None = None, cycles: int | None = None,
        record_rate_hz: float | None = RECORD_RATE_HZ, offsets: OffsetSource | None = None) -> Run:
    """Run a scenario (a TOML path, or what twin.load_scenario gave) into a run directory (default
    runs/NAME-seedN; runs/NAME-Ncycles-seedN with `cycles`, which replaces a face scenario's number of cutting
    cycles, validated as the file's would be).

    A face scenario is simulated: sensor trial 0 at the top of the directory; with `trials` > 1, trials 1..
    (sensor errors redrawn from the same truth) go to trials/NNN/ and their metrics to trials.parquet, run on
    `workers` local processes or on the Ray cluster at `ray_address`; `sensors=False` writes the truth only.
    000's SINS experiments and 002's turntable run their experiment. `quiet=False` shows the progress bar and
    prints the summary tables, as `longwall run` does. `record_rate_hz` is the rate of the face run's recordings
    run.rrd and estimates.rrd (twin.view.record_rate: Hz, or None for every sample), recorded in metrics.json.
    `offsets` is the roof support system's input per cycle (twin.face.drift.OffsetSource: the cycle and the pans'
    states in, per-support offsets out), added to the scenario's supports.push.offsets."""
    record_rate_hz = _record_rate(record_rate_hz)
    source, scenario, name = loaded_scenario(scenario, seed, cycles)
    out = Path(out) if out is not None else default_run_dir(name, scenario.seed)
    if not isinstance(scenario, Scenario):
        check_resources(source, estimate_resources(scenario))
        return _run_paper(scenario, out, force, quiet)
    check_trials(trials, workers, ray_address)
    check_resources(source, estimate_resources(scenario, trials, sensors, workers))
    return _run_face(scenario, source, out, force, quiet, trials, sensors, workers, ray_address, record_rate_hz,
                     offsets)


def loaded_scenario(scenario: str | Path | Scenario | Experiment | Turntable, seed: int | None, cycles: int | None
            ) -> tuple[str, Scenario | Experiment | Turntable, str]:
    """(where it came from, the scenario with `seed` and `cycles` applied, the run's name)."""
    if isinstance(scenario, str | Path):
        source, scenario = str(scenario), load_scenario(scenario, seed)
    else:
        source, scenario = scenario.name, _seeded(scenario, seed)
    name = scenario.name
    if cycles is not None:
        if not isinstance(scenario, Scenario):
            raise ScenarioError(f"{source}: --cycles: an experiment has no cutting cycles; run it without --cycles")
        scenario = parse_any({**scenario.model_dump(), "cycles": cycles}, f"{source} with --cycles {cycles}")
        name = f"{scenario.name}-{cycles}cycles"
    return source, scenario, name


def model(scenario: str | Path | Scenario, xml: str | Path | None = None, png: str | Path | None = None,
          width: int = DEFAULT_WIDTH_PX, seed: int | None = None) -> dict[Path, int]:
    """A face scenario's face as its run starts, written as one MJCF file `xml` and/or rendered to the PNG file `png`,
    `width` pixels wide (twin.pipeline.face_model). Returns each file written and its size [bytes]."""
    source, scenario, _ = loaded_scenario(scenario, seed, None)
    if not isinstance(scenario, Scenario):
        raise ScenarioError(f"{source}: an experiment has no face to export; give a face scenario")
    return write_face_model(scenario, xml, png, width)


def check_trials(trials: int, workers: int, ray_address: str | None,
                 names: tuple[str, str, str] = ("trials", "workers", "ray_address")) -> None:
    """ScenarioError (one line) for a Monte Carlo request that cannot run; `names` are the arguments as the caller
    spells them (the CLI: its flags)."""
    n_trials, n_workers, n_ray = names
    if trials < 1:
        raise ScenarioError(f"{n_trials}: must be >= 1 (got {trials})")
    if not 1 <= workers <= trials:
        raise ScenarioError(f"{n_workers}: must be >= 1 and <= {n_trials} (got {workers} for {trials} trials)")
    if ray_address is not None and workers > 1:
        raise ScenarioError(f"{n_workers} and {n_ray} exclude each other: Ray runs the trials on the cluster's CPUs")


def _run_paper(exp: Experiment | Turntable, out: Path, force: bool, quiet: bool) -> Run:
    """A paper's experiment (000's SINS experiments, 002's turntable): run, write the run directory, print ours
    beside the paper's."""
    check_target(out, force)
    start = time.perf_counter()
    if isinstance(exp, Turntable):
        from twin.papers import turntable as paper

        result, rows = paper.run_turntable(exp)
    else:
        from twin.papers import sins_experiments
        from twin.papers import sins_rundir as paper

        result = sins_experiments.run_experiment(exp)
        rows = result.table
    with atomic_run_dir(out, force) as staging:
        paper.write_run(staging, exp, result)
    if not quiet:
        print("\n".join(rows))
        print(f"\n{time.perf_counter() - start:.1f} s; run directory: {out}")
    return Run(out)


def _record_rate(rate_hz: float | None) -> float | None:
    """The record rate checked (twin.view.record_rate), a bad one as ScenarioError (one line)."""
    try:
        return check_record_rate(rate_hz)
    except ValueError as err:
        raise ScenarioError(str(err)) from None


def note_recordings(run_dir: Path, rates: dict[str, float | None]) -> None:
    """Record in metrics.json's "recordings" the rate each recording file of `rates` was written at (Hz, or "full"),
    for the recordings that exist."""
    path = Path(run_dir) / "metrics.json"
    data = json.loads(path.read_text()) if path.is_file() else {}
    noted = data.setdefault("recordings", {})
    noted.update({name: rate_label(rate) for name, rate in rates.items() if (Path(run_dir) / name).is_file()})
    path.write_text(json.dumps(data, indent=2) + "\n")


def _run_face(scn: Scenario, source: str, out: Path, force: bool, quiet: bool, trials: int, sensors: bool,
              workers: int, ray_address: str | None, record_rate_hz: float | None,
              offsets: OffsetSource | None = None) -> Run:
    from numba.core import event as numba_event

    from estimators.precompile import Precompiler
    from estimators.shearer.precompiled import method_kernels
    from twin.face.haulage import Timeline
    from twin.pipeline.estimate import format_estimators, run_estimators, write_metrics
    from twin.pipeline.montecarlo import TrialResult, trial_runner
    from twin.pipeline.montecarlo_table import format_monte_carlo, write_monte_carlo
    from twin.pipeline.twin_stream import stream_twin
    from twin.sensors.precompiled import SENSOR_KERNELS
    from twin.sensors.faults import check_faults_in_run
    from twin.view.recording import BLOCK_STREAMS, ESTIMATES_RRD, RUN_RRD, STREAM_COLUMNS, write_recording
    from twin.view.summary import format_summary, twin_summary

    hold_mmap_threshold()  # memory flat over a long run (estimators.heap)
    try:
        check_faults_in_run(scn, Timeline(scn).duration)
    except ScenarioError as err:
        raise ScenarioError(f"{source}: {err}") from None
    check_target(out, force)
    start = time.perf_counter()
    mc_trials = range(1, trials if sensors else 1)  # trial 0 is the run itself
    # The bar weighs each stage by its expected share of the run (twin.config.resources).
    # The estimators use every core unless Monte Carlo trials run beside trial 0 on local processes.
    est_workers = 1 if mc_trials and workers > 1 and ray_address is None else usable_cores()
    parts = estimate_resources(scn, trials, sensors, workers).parts_s
    twin_s, est_s = parts["twin"], parts["estimators"] / est_workers
    stages = {"face": 0.55 * twin_s, "shearer": 0.1 * twin_s, "sensors": 0.25 * twin_s, "write": 0.02 * twin_s,
              "recording": 0.08 * twin_s, "estimators": est_s, "trials": est_s * len(mc_trials) / workers}
    total = sum(stages.values())
    bar = tqdm(total=100, desc=f"longwall run {scn.name}", disable=quiet, leave=False,
               bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}<{remaining}")
    done = {k: 0.0 for k in stages}
    stage_s = {k: 0.0 for k in stages}  # wall time of each stage: the time up to each report goes to its stage
    last = [start]
    # The same on the clock (Unix seconds): [end, stage] of each run of reports of one stage, the time up to each
    # end going to its stage; timing.json's "stage_ends_unix_s", by which a memory sampler beside the run
    # (benchmarks/bench_scale.py) tells the stages apart. The face and shearer stages alternate chunk by chunk.
    stage_ends: list[list] = []

    running = ["face"]  # the stage under way, which the bar names
    compiling = [False]  # numba compiled a kernel in this stage: a first run after installing

    def show() -> None:
        notice = compiling[0] or precompiler.compiling
        bar.set_description(f"longwall run {scn.name} ({running[0]}"
                            + (": compiling numba kernels, first run only)" if notice else ")"))
        bar.refresh()

    def precompiled() -> None:
        """The estimators' kernels in the cache before their processes start (each would compile them)."""
        if precompiler.compiling:
            show()
        precompiler.wait()

    def progress(stage: str, frac: float) -> None:
        now = time.perf_counter()
        stage_s[stage] += now - last[0]
        last[0] = now
        if stage_ends and stage_ends[-1][1] == stage:
            stage_ends[-1][0] = round(time.time(), 3)
        else:
            stage_ends.append([round(time.time(), 3), stage])
        done[stage] = frac
        bar.n = round(100 * sum(stages[k] * v for k, v in done.items()) / total)
        after = [k for k in list(stages)[list(stages).index(stage) + 1:] if stages[k] and done[k] < 1.0]
        running[0] = stage if frac < 1.0 or not after else after[0]
        compiling[0] = False
        show()

    class CompileNotice(numba_event.Listener):
        """Names the compilation on the bar while a numba kernel compiles (nothing in a warm run)."""

        def on_start(self, event) -> None:
            if not compiling[0]:
                compiling[0] = True
                show()

        def on_end(self, event) -> None:
            pass

    monte_carlo = None
    # A first run compiles the sensors' kernels and the estimators' on the other cores while the face is simulated
    # (estimators.precompile).
    kernels = (*SENSOR_KERNELS, *method_kernels(scn.estimators.shearer.methods)) if sensors else ()
    with (Precompiler(kernels, usable_cores()) as precompiler, atomic_run_dir(out, force) as staging,
          trial_runner(workers, ray_address) as runner, numba_event.install_listener("numba:compile", CompileNotice())):
        # The truth and trial 0's sensors go to the run directory as the twin makes them (twin.pipeline.twin_stream).
        result, shearer_stats = stream_twin(scn, staging, sensors, progress, offsets=offsets)
        summary = twin_summary(scn, result.tables, shearer_stats, result.support_advance, result.offsets,
                               [a.sequence for a in result.alignment], result.path_errors)
        if mc_trials:
            precompiled()
            runner.submit(scn, staging, mc_trials)  # runs beside trial 0 unless sequential
        (staging / "scenario.toml").write_text(scenario_to_toml(scn))
        progress("write", 1.0)
        # The long streams are read a row group at a time (the recording holds a few of their columns whole).
        tables = {name: (StreamBlocks if name in BLOCK_STREAMS else read_stream)(
                      staging, STREAMS[name], STREAM_COLUMNS.get(name))
                  for name in STREAMS if (staging / STREAMS[name].filename).is_file()}
        write_recording(staging / RUN_RRD, scn, {k: v for k, v in tables.items() if k.startswith("truth_")},
                        result.floor_grid.mesh_t(result.frame), record_rate_hz,
                        sensors={k: v for k, v in tables.items() if not k.startswith("truth_")})
        progress("recording", 1.0)
        # The estimators read the log from the run directory: the run's tables go before they start, so that
        # their peak memory is not added to the twin's.
        del tables, result
        release_free_memory()  # and the free pages they leave (estimators.heap), before the workers fork
        wall_s = time.perf_counter() - start
        write_timing(staging, wall_s=wall_s, real_time_factor=summary["simulated_s"] / wall_s)
        (staging / "metrics.json").write_text(json.dumps({"twin": summary, "estimators": {}}, indent=2) + "\n")
        precompiled()
        estimated = run_estimators(staging, scn, record_rate_hz=record_rate_hz,
                                   workers=est_workers) if sensors else {}
        write_metrics(staging, estimated)
        note_recordings(staging, {RUN_RRD: record_rate_hz, ESTIMATES_RRD: record_rate_hz})
        progress("estimators", 1.0)
        if mc_trials:
            results = [TrialResult(0, estimated), *runner.gather(lambda n: progress("trials", n / len(mc_trials)))]
            monte_carlo = write_monte_carlo(staging, results, list(scn.estimators.shearer.methods),
                                            runner.description)
        bar.close()
        write_timing(staging, total_s=time.perf_counter() - start, stages_s={k: v for k, v in stage_s.items() if v},
                     stage_ends_unix_s=stage_ends)
    if not quiet:
        print(format_summary(summary, wall_s))
        print(format_estimators(estimated, scn.name))
        if monte_carlo:
            print(format_monte_carlo(monte_carlo))
        print(f"\nwall time {time.perf_counter() - start:.1f} s: "
              + ", ".join(f"{k} {v:.1f} s" for k, v in stage_s.items() if v) + f"\nrun directory: {out}")
    if monte_carlo and monte_carlo["failed"]:
        print(f"longwall: warning: {monte_carlo['failed']} of {monte_carlo['trials']} Monte Carlo trials failed "
              f"(trial {monte_carlo['failures'][0]['trial']}: {monte_carlo['failures'][0]['error']}); "
              f"see {out / 'trials.csv'}", file=sys.stderr)
    return Run(out)


def estimate(run_dir: str | Path, quiet: bool = True, record_rate_hz: float | None = RECORD_RATE_HZ) -> Run:
    """Re-run the estimators the run's scenario.toml names on an existing (simulated or imported) run directory;
    `quiet=False` prints their table; estimates.rrd is written at `record_rate_hz` (twin.view.record_rate: Hz, or
    None for every row), recorded in metrics.json. Without truth (a real face's log) every estimate is written and
    the metrics hold what each says of itself, marked "truth": false (twin.pipeline.estimate.run_estimators)."""
    from twin.pipeline.estimate import format_estimators, run_estimators, write_metrics
    from twin.pipeline.log_layout import check_run_dir
    from twin.view.recording import ESTIMATES_RRD

    record_rate_hz = _record_rate(record_rate_hz)
    hold_mmap_threshold()
    run_dir = Path(run_dir)
    scenario = run_dir / "scenario.toml"
    if not scenario.is_file():
        raise ScenarioError(f"{scenario}: not found; the estimators take their configuration (IMU grade, lever arm, "
                            f"odometer pulse length, supports) from the run's scenario.toml")
    scn = load_face_scenario(scenario)
    check_run_dir(run_dir, scn)
    with run_lock(run_dir), staged_update(run_dir, fresh=(ESTIMATES_DIR, ESTIMATES_RRD),
                                          copied=("metrics.json", TIMING)) as staging:
        # Written beside a copy: an interrupted one leaves run_dir as it was.
        estimated = run_estimators(staging, scn, record_rate_hz=record_rate_hz, workers=usable_cores())
        write_metrics(staging, estimated)
        note_recordings(staging, {ESTIMATES_RRD: record_rate_hz})
    if not quiet:
        print(format_estimators(estimated, scn.name))
    return Run(run_dir)
