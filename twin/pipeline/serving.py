"""The Python API under `longwall serve` and `longwall record`: a face scenario served on OPC UA, an OPC UA server
recorded into a run directory (twin.opcua; the opcua extra, asked for in one line when it is missing)."""

from __future__ import annotations

from pathlib import Path

from twin.config.resources import check_resources, estimate_resources
from twin.config.scenario import Scenario, ScenarioError
from twin.opcua.estimator import DEFAULT_ESTIMATOR, check_method
from twin.pipeline.api import loaded_scenario
from twin.pipeline.rundir import default_run_dir


def serve(scenario: str | Path | Scenario, out: str | Path | None = None, seed: int | None = None,
          cycles: int | None = None, *, endpoint: str | None = None, speed: float = 1.0, publish_hz: float | None = None,
          user: str | None = None, force: bool = False, sensors: bool = True, ready=None,
          history_s: float | None = None, estimator: str = DEFAULT_ESTIMATOR) -> dict:
    """Serve a face scenario on OPC UA (twin.opcua.server; needs the opcua extra) until its run ends, the run
    directory (truth, sensor trial 0, the offsets applied) written to `out` (default runs/NAME-seedN-served) as it
    goes; each sensor stream's last `history_s` of simulated time (default twin.opcua.blocks.HISTORY_S) is held for
    a client that reconnects; the shearer positioning method `estimator` (an online one, or "none") runs on the
    published sensor rows and its estimate is published (twin.opcua.estimator). Returns the publication's
    figures."""
    import asyncio

    from twin.opcua.access import DEFAULT_ENDPOINT, ServeError, check_access, parse_endpoint

    check_access(parse_endpoint(endpoint or DEFAULT_ENDPOINT)[0], user)
    method = check_method(estimator)
    try:
        from twin.opcua.blocks import HISTORY_S
        from twin.opcua.server import PUBLISH_HZ
        from twin.opcua.server import serve as serve_face
    except ModuleNotFoundError as err:
        raise ServeError(f"longwall serve needs {err.name}: install the opcua extra (pip install -e \".[opcua]\")"
                         ) from None
    source, scenario, name = loaded_scenario(scenario, seed, cycles)
    if not isinstance(scenario, Scenario):
        raise ScenarioError(f"{source}: an experiment has no face to serve; serve a face scenario")
    if scenario.haulage.reversal_stop_s < 1.0:
        raise ServeError(f"{source}: haulage.reversal_stop_s = {scenario.haulage.reversal_stop_s:g} s: the served face "
                         f"hands each shear over in the reversal stop after it (for the offsets of the next); set it "
                         f"to at least 1 s")
    if scenario.alignment.mode != "none":
        raise ServeError(f"{source}: [alignment] mode = {scenario.alignment.mode}: the twin's own face alignment "
                         f"system would steer beside the external one OPC UA clients are; set mode = \"none\"")
    check_resources(source, estimate_resources(scenario, 1, sensors, 1))
    out = Path(out) if out is not None else default_run_dir(f"{name}-served", scenario.seed)
    return asyncio.run(serve_face(scenario, out, endpoint or DEFAULT_ENDPOINT, speed, publish_hz or PUBLISH_HZ, user,
                                  force, sensors, ready, HISTORY_S if history_s is None else history_s, method))


def record(endpoint: str, out: str | Path, duration_s: float | None = None, *, force: bool = False) -> dict:
    """Record the OPC UA server at `endpoint` (`longwall serve`'s model; needs the opcua extra) into the run directory
    `out`, without truth, until its run finishes or `duration_s` of simulated time (twin.opcua.recorder). Returns
    what was recorded (rows per stream, reconnects, gaps)."""
    import asyncio

    from twin.opcua.access import ServeError, parse_endpoint

    parse_endpoint(endpoint, "--opcua")
    try:
        from twin.opcua.recorder import Recorder
    except ModuleNotFoundError as err:
        raise ServeError(f"longwall record needs {err.name}: install the opcua extra (pip install -e \".[opcua]\")"
                         ) from None

    async def run() -> dict:
        return await Recorder(endpoint, Path(out), duration_s, force).run()

    return asyncio.run(run())
