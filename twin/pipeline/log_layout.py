"""What a scenario says its run directory's log holds (estimators.io.run_check.LogLayout), checked before the
estimators start: an edited or foreign scenario.toml is refused in one line instead of changing results silently."""

from __future__ import annotations

from pathlib import Path

from estimators.io.run_check import Expected, LogLayout, check_layout, read_metrics
from twin.config.scenario import Scenario
from twin.face.layout import support_stations


def log_layout(scn: Scenario, source: str = "scenario.toml") -> LogLayout:
    """The sample rates, supports and odometer pulse length of the scenario's sensors (`source` names the file)."""
    sensors = scn.sensors
    rates = {name: Expected(getattr(sensors, name).rate_hz, f"[sensors.{name}] rate_hz")
             for name in ("imu", "odometer", "pushram", "pressure", "mag", "support_imu")}
    n = int(support_stations(scn).size)
    return LogLayout(
        rates_hz=rates,
        ram_supports=Expected(n, f"[face] pan_count = {scn.face.pan_count} / [supports] pans_per_support = "
                                 f"{scn.supports.pans_per_support}"),
        imu_supports=Expected(tuple(sensors.support_imu.supports), "[sensors.support_imu] supports"),
        metres_per_pulse=Expected(sensors.odometer.metres_per_pulse, "[sensors.odometer] metres_per_pulse"),
        source=source)


def check_run_dir(run_dir: Path, scn: Scenario) -> None:
    """LogError before any work when run_dir's metrics.json is damaged or its log disagrees with `scn`."""
    read_metrics(run_dir)
    check_layout(run_dir, log_layout(scn, str(Path(run_dir) / "scenario.toml")))
