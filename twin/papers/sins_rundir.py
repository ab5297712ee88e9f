"""The run directory of a SINS experiment: metrics.json, errors.parquet, run.rrd and the resolved scenario.toml."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from twin.config.experiments import EXPERIMENT_KIND, Experiment
from twin.config.scenario import scenario_to_toml
from twin.papers.sins_results import ExperimentResult, Series
from twin.pipeline.rundir import write_timing

UNITS = {"attitude": ("deg", np.degrees), "sigma": ("deg", np.degrees), "coning": ("rad", np.asarray),
         "velocity": ("m/s", np.asarray), "position": ("m", np.asarray)}
"""Units of the Rerun plots (SI in the Parquet file; degrees for angles at this edge)."""


def series_table(series: list[Series]) -> pa.Table:
    """The error time series as one long table: group, quantity, variant, t [s], e, n, u (SI)."""
    sizes = [s.t.size for s in series]
    cols = {"group": pa.array(np.repeat([s.group for s in series], sizes).astype(str)),
            "quantity": pa.array(np.repeat([s.quantity for s in series], sizes).astype(str)),
            "variant": pa.array(np.repeat([s.variant for s in series], sizes).astype(str)),
            "t": pa.array(np.concatenate([s.t for s in series]).astype(float))}
    values = np.concatenate([s.values for s in series]).astype(float)
    for k, axis in enumerate("enu"):
        cols[axis] = pa.array(values[:, k])
    meta = {"units": "attitude, coning, sigma [rad]; velocity [m/s]; position [m]",
            "axes": "e, n, u of the navigation frame (coning: body axes)"}
    return pa.table(cols, metadata=meta)


def entity_path(s: Series) -> str:
    return "/".join(x for x in ("errors", s.group, s.quantity, s.variant) if x)


def experiment_blueprint(experiment: str, groups_quantities: list[tuple[str, str]]):
    """The viewer's layout of an experiment's recording: one time-series view per group and quantity of its
    series (compensated beside uncompensated; for the alignment, the attitude errors and the filter's sigma of
    each filter), in the order given."""
    import rerun.blueprint as rrb

    views: dict[str, str] = {}
    for group, quantity in groups_quantities:
        origin = "/".join(x for x in ("errors", group, quantity if experiment != "alignment" else "") if x)
        views.setdefault(origin, f"{group + ' ' if group else ''}"
                                 f"{quantity if experiment != 'alignment' else 'attitude error and sigma'}")
    return rrb.Blueprint(rrb.Grid(*[rrb.TimeSeriesView(name=name, origin=origin) for origin, name in views.items()]),
                         collapse_panels=True)


def write_experiment_recording(path: Path, result: ExperimentResult, recording: str, rate_hz: float = 20.0) -> None:
    """The error time series as Rerun Scalars (one send_columns per entity `errors/[group/]quantity[/variant]`,
    decimated to about `rate_hz`; errors.parquet keeps every sample), written reproducibly as recording
    `recording` (twin.view.rrd_stream); its layout is experiment_blueprint's, which `longwall view` gives the
    viewer."""
    from twin.view.rerun_columns import series
    from twin.view.row_cuts import decimate
    from twin.view.rrd_stream import recording_stream

    with recording_stream(path, recording) as rec:
        rec.send_recording_name(result.name)
        for s in result.series:
            unit, convert = UNITS[s.quantity]
            label = f"{s.quantity}{' ' + s.variant if s.variant else ''}"
            keep = decimate(s.t, rate_hz)
            series(rec, entity_path(s), s.t[keep], convert(s.values[keep]), [f"{label} {a} [{unit}]" for a in "ENU"])


def _json_ready(obj):
    if isinstance(obj, dict):
        return {str(k): _json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_ready(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def write_run(staging: Path, exp: Experiment, result: ExperimentResult) -> None:
    """metrics.json {"experiment", "ours", "paper"}, errors.parquet, run.rrd, the resolved scenario.toml and the
    wall-clock figures in timing.json."""
    (staging / "scenario.toml").write_text(scenario_to_toml(exp))
    metrics = {"experiment": {"name": exp.name, "kind": EXPERIMENT_KIND, "experiment": exp.experiment,
                              "seed": exp.seed}, "ours": result.ours, "paper": result.paper}
    (staging / "metrics.json").write_text(json.dumps(_json_ready(metrics), indent=2) + "\n")
    if result.timing:
        write_timing(staging, **result.timing)
    pq.write_table(series_table(result.series), staging / "errors.parquet")
    from twin.view.rrd_stream import recording_id

    write_experiment_recording(staging / "run.rrd", result, recording_id(exp))
