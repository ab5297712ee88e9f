"""What a run directory holds for the report (`longwall report`): truth, estimates, detectors, metrics, and notes
on what is missing."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import pyarrow as pa

from estimators.io.logformat import (
    ALIGNMENT,
    ESTIMATE,
    ESTIMATE_DETECTORS,
    ESTIMATES_DIR,
    PRESSURE,
    PUSHRAM,
    STREAMS,
    Stream,
    estimate_path,
    read_estimate,
    read_schema,
    read_stream,
)
from estimators.io.run_check import read_metrics
from twin.config.scenario import Scenario, load_face_scenario
from twin.pipeline.rundir import RunDirError

TRUTH_NAMES = ("truth_shearer", "truth_cycles", "truth_pans")


@dataclass
class RunData:
    """What a run directory holds for the report; an absent stream is missing from its dict."""

    run_dir: Path
    scenario: Scenario | None
    metrics: dict
    truth: dict[str, pa.Table]
    estimates: dict[str, pa.Table]
    detectors: dict[str, pa.Table]
    pressure: pa.Table | None = None
    """The supports' pressure readings (PRESSURE), when the log has them."""
    alignment: pa.Table | None = None
    """The offsets the supports' pushes applied (ALIGNMENT), when the log has them."""
    pushram: pa.Table | None = None
    """The supports' push-ram stroke readings (PUSHRAM), when the log has them."""
    notes: list[str] = field(default_factory=list)
    """What the report leaves out and why."""


def _methods(run_dir: Path, stream: Stream) -> list[str]:
    """Methods with a file of `stream` in run_dir/estimates (file names as estimate_path gives them)."""
    suffix = estimate_path(Path(), "m", stream).stem.removeprefix("m")
    methods = []
    for path in sorted((run_dir / ESTIMATES_DIR).glob(f"*{suffix}.parquet")):
        if (read_schema(path).metadata or {}).get(b"stream") == stream.name.encode():
            methods.append(path.stem.removesuffix(suffix))
    return methods


def load_run(run_dir: Path) -> RunData:
    """Read what the report plots; RunDirError when run_dir is missing or holds neither truth nor estimates."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunDirError(f"{run_dir}: no such run directory")
    truth = {name: read_stream(run_dir, STREAMS[name]) for name in TRUTH_NAMES
             if (run_dir / STREAMS[name].filename).is_file()}
    estimates = {m: read_estimate(run_dir, m) for m in _methods(run_dir, ESTIMATE)}
    if not truth and not estimates:
        raise RunDirError(f"{run_dir}: nothing to report (no truth_*.parquet, no {ESTIMATES_DIR}/*.parquet); "
                          f"give a directory written by `longwall run`, `longwall import` or `longwall estimate`")
    scenario = run_dir / "scenario.toml"
    data = RunData(run_dir, load_face_scenario(scenario) if scenario.is_file() else None,
                   read_metrics(run_dir), truth, estimates,
                   {m: read_estimate(run_dir, m, ESTIMATE_DETECTORS) for m in _methods(run_dir, ESTIMATE_DETECTORS)},
                   *(read_stream(run_dir, s) if (run_dir / s.filename).is_file() else None
                     for s in (PRESSURE, ALIGNMENT, PUSHRAM)))
    missing = [STREAMS[name].filename for name in TRUTH_NAMES if name not in truth]
    if missing:
        data.notes.append(f"no {', '.join(missing)} (a run without truth, e.g. imported): left out "
                          + "; ".join(what for name, what in (
                              ("truth_shearer", "the true path in the top view and the errors against time"),
                              ("truth_cycles", "the cutting-cycle boundaries"),
                              ("truth_pans", "the pan line's straightness")) if name not in truth))
    if not estimates:
        data.notes.append(f"no estimates in {ESTIMATES_DIR}/: left out every estimator plot "
                          f"(`longwall estimate {run_dir}` writes them)")
    if data.scenario is None:
        data.notes.append("no scenario.toml: the top view's origin is the first position in the run; the "
                          "detector thresholds and the figures in the face frame (no face azimuth) are left out")
    return data
