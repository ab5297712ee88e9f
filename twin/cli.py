"""`longwall` command line: run a scenario, view a recording.

Errors are one line on stderr ("longwall: error: ...") with exit code 2; no tracebacks for bad input.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from importlib import resources
from pathlib import Path

from tqdm import tqdm

from estimators.io.csvio import export_csv, import_csv
from estimators.io.logformat import STREAMS, LogError, make_table, write_stream
from estimators.shearer.positioning import PositioningError
from twin.config.scenario import ScenarioError, load_scenario, scenario_to_toml
from twin.pipeline.estimate import format_estimators, run_estimators, write_metrics
from twin.pipeline.montecarlo import MonteCarloError
from twin.pipeline.rundir import RunDirError, atomic_run_dir, check_target

EXIT_BAD_INPUT = 2


def default_scenario() -> Path:
    return Path(str(resources.files("twin.scenarios") / "default.toml"))


def run(scenario: Path, out: Path | None, seed: int | None, force: bool, quiet: bool = False,
        trials: int = 1, sensors: bool = True, workers: int = 1, ray_address: str | None = None) -> Path:
    """Simulate a scenario into a run directory (sensor trial 0 at the top, trials 1.. in trials/NNN/, each with
    its estimates; their metrics gathered in trials.parquet), the trials on `workers` local processes or on
    the Ray cluster at `ray_address` (twin.pipeline.montecarlo)."""
    from twin.papers.sins_experiments import is_experiment, run_experiment_file
    if is_experiment(scenario):  # a SINS experiment file (kind = "sins_experiment"): twin.papers.sins_experiments
        return run_experiment_file(scenario, out, seed, force, quiet)
    from twin.papers.turntable import is_turntable, run_turntable_file
    if is_turntable(scenario):  # 002's turntable (kind = "support_turntable"): twin.papers.turntable
        return run_turntable_file(scenario, out, seed, force, quiet)
    from twin.face.haulage import Timeline
    from twin.pipeline.montecarlo import (
        TrialResult,
        format_monte_carlo,
        trial_context,
        trial_runner,
        write_monte_carlo,
        write_sensors,
    )
    from twin.pipeline.simulate import simulate
    from twin.sensors.faults import check_faults_in_run
    from twin.view.recording import write_recording
    from twin.view.summary import format_summary, twin_summary

    scn = load_scenario(scenario, seed)
    try:
        check_faults_in_run(scn, Timeline(scn).duration)
    except ScenarioError as err:
        raise ScenarioError(f"{scenario}: {err}") from None
    out = Path(out) if out is not None else Path("runs") / f"{scn.name}-seed{scn.seed}"
    check_target(out, force)
    start = time.perf_counter()
    mc_trials = range(1, trials if sensors else 1)  # trial 0 is the run itself
    stages = {"face": 0.45, "shearer": 0.2, "sensors": 0.1, "write": 0.05, "recording": 0.05, "estimators": 0.15,
              "trials": 0.25 * len(mc_trials)}
    total = sum(stages.values())
    bar = tqdm(total=100, desc=f"longwall run {scn.name}", disable=quiet, leave=False,
               bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}")
    done = {k: 0.0 for k in stages}

    def progress(stage: str, frac: float) -> None:
        done[stage] = frac
        bar.n = round(100 * sum(stages[k] * v for k, v in done.items()) / total)
        bar.set_description(f"longwall run {scn.name} ({stage})")

    monte_carlo = None
    with atomic_run_dir(out, force) as staging, trial_runner(workers, ray_address) as runner:
        result = simulate(scn, progress)
        tables = {name: make_table(STREAMS[name], cols) for name, cols in result.tables.items()}
        for name, table in tables.items():
            write_stream(staging, STREAMS[name], table)
        if sensors:
            ctx = trial_context(scn, tables, staging)
            runner.submit(ctx, staging, mc_trials)  # runs beside trial 0 unless sequential
            tables.update(write_sensors(ctx, 0, staging))
            progress("sensors", 1.0)
        (staging / "scenario.toml").write_text(scenario_to_toml(scn))
        progress("write", 1.0)
        write_recording(staging / "run.rrd", scn, {k: v for k, v in tables.items() if k.startswith("truth_")},
                        result.floor_grid.mesh_t(result.frame),
                        sensors={k: v for k, v in tables.items() if not k.startswith("truth_")})
        progress("recording", 1.0)
        summary = twin_summary(scn, result.tables, time.perf_counter() - start)
        (staging / "metrics.json").write_text(json.dumps({"twin": summary, "estimators": {}}, indent=2) + "\n")
        estimated = run_estimators(staging, scn) if sensors else {}
        write_metrics(staging, estimated)
        progress("estimators", 1.0)
        if mc_trials:
            results = [TrialResult(0, estimated), *runner.gather(lambda n: progress("trials", n / len(mc_trials)))]
            monte_carlo = write_monte_carlo(staging, results, list(scn.estimators.shearer.methods),
                                            runner.description)
        bar.close()
    if not quiet:
        print(format_summary(summary))
        print(format_estimators(estimated, scn.name))
        if monte_carlo:
            print(format_monte_carlo(monte_carlo))
        print(f"\nrun directory: {out}")
    if monte_carlo and monte_carlo["failed"]:
        print(f"longwall: warning: {monte_carlo['failed']} of {monte_carlo['trials']} Monte Carlo trials failed "
              f"(trial {monte_carlo['failures'][0]['trial']}: {monte_carlo['failures'][0]['error']}); "
              f"see {out / 'trials.csv'}", file=sys.stderr)
    return out


def estimate(run_dir: Path, quiet: bool = False) -> dict:
    """Re-run the estimators the run's scenario.toml names on an existing (simulated or imported) run directory."""
    scenario = Path(run_dir) / "scenario.toml"
    if not scenario.is_file():
        raise ScenarioError(f"{scenario}: not found; the estimators take their configuration (IMU grade, lever arm, "
                            f"odometer pulse length, supports) from the run's scenario.toml")
    scn = load_scenario(scenario)
    estimated = run_estimators(Path(run_dir), scn)
    write_metrics(Path(run_dir), estimated)
    if not quiet:
        print(format_estimators(estimated, scn.name))
    return estimated


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="longwall", description="Longwall face digital twin")
    sub = parser.add_subparsers(dest="command", required=True)
    p_run = sub.add_parser("run", help="simulate a scenario and write a run directory")
    p_run.add_argument("scenario", nargs="?", type=Path, help="scenario TOML (default: the shipped default.toml)")
    p_run.add_argument("--out", type=Path, help="run directory (default: runs/NAME-seedN)")
    p_run.add_argument("--seed", type=int, help="override the scenario's random seed")
    p_run.add_argument("--force", action="store_true", help="replace an existing non-empty run directory")
    p_run.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    p_run.add_argument("--trials", type=int, default=1,
                       help="Monte Carlo: sensor-error trials drawn from the same truth (default 1)")
    p_run.add_argument("--twin-only", action="store_true", help="truth only, no sensor streams")
    p_run.add_argument("--workers", type=int, default=1,
                       help="Monte Carlo: local processes for trials 1.. (default 1: sequential)")
    p_run.add_argument("--ray", metavar="ADDRESS",
                       help="Monte Carlo: run trials 1.. on the Ray cluster at ADDRESS (auto, HOST:PORT)")
    p_est = sub.add_parser("estimate", help="re-run the estimators on a run directory (simulated or imported)")
    p_est.add_argument("run_dir", type=Path)
    p_est.add_argument("--quiet", action="store_true", help="no table")
    p_view = sub.add_parser("view", help="open a run's recording in the Rerun viewer")
    p_view.add_argument("run_dir", type=Path)
    p_imp = sub.add_parser("import", help="turn CSV files (one per stream, name[unit] headers) into a run directory")
    p_imp.add_argument("csv_dir", type=Path)
    p_imp.add_argument("--out", type=Path, required=True, help="run directory to create")
    p_exp = sub.add_parser("export", help="write a run directory's streams as CSV files")
    p_exp.add_argument("run_dir", type=Path)
    p_exp.add_argument("--csv", type=Path, required=True, help="folder for the CSV files")
    p_rep = sub.add_parser("report", help="plots of a run directory as one HTML page (DIR/report/report.html)")
    p_rep.add_argument("run_dir", type=Path)
    args = parser.parse_args(argv)
    try:
        if args.command == "run":
            if args.seed is not None and args.seed < 0:
                raise ScenarioError(f"--seed: must be >= 0 (got {args.seed})")
            if args.trials < 1:
                raise ScenarioError(f"--trials: must be >= 1 (got {args.trials})")
            if not 1 <= args.workers <= args.trials:
                raise ScenarioError(f"--workers: must be >= 1 and <= --trials (got {args.workers} for "
                                    f"{args.trials} trials)")
            if args.ray is not None and args.workers > 1:
                raise ScenarioError("--workers and --ray exclude each other: Ray runs the trials on the "
                                    "cluster's CPUs")
            run(args.scenario or default_scenario(), args.out, args.seed, args.force, args.quiet, args.trials,
                not args.twin_only, args.workers, args.ray)
        elif args.command == "estimate":
            estimate(args.run_dir, args.quiet)
        elif args.command == "view":
            from twin.view.recording import open_viewer
            open_viewer(args.run_dir)
        elif args.command == "import":
            report = import_csv(args.csv_dir, args.out)
            print(report.summary())
        elif args.command == "export":
            for path in export_csv(args.run_dir, args.csv):
                print(path)
        elif args.command == "report":
            from twin.view.report import build_report
            print(build_report(args.run_dir))
    except (ScenarioError, RunDirError, LogError, PositioningError, FileNotFoundError, MonteCarloError) as err:
        print(f"longwall: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("longwall: interrupted; nothing was written", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
