"""`longwall` command line: a thin layer over the Python API (twin.pipeline.api) and the readers and writers.

Errors are one line on stderr ("longwall: error: ...") with exit code 2; no tracebacks for bad input, and a usage
error is one line too. SIGTERM is handled as Ctrl-C: one line, exit 143 (130 for SIGINT); a run directory is
written only when complete (twin.pipeline.rundir), so an interrupted run leaves none. A worker process the system
killed (estimators.workers.WorkerLost: out of memory) is one line too, exit 1.
"""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path

from estimators.io.csv_import import import_csv
from estimators.io.csvio import export_csv
from estimators.io.logformat import LogError
from estimators.shearer.config import PositioningError
from estimators.workers import WorkerLost
from twin.config.scenario import ScenarioError
from twin.face.export_target import DEFAULT_WIDTH_PX, ExportError, check_width
from estimators.shearer.online import ONLINE_METHODS
from twin.opcua.access import DEFAULT_ENDPOINT, PASSWORD_ENV, ServeError
from twin.opcua.estimator import DEFAULT_ESTIMATOR, NO_ESTIMATOR
from twin.pipeline import api, serving
from twin.pipeline.api import default_scenario
from twin.pipeline.montecarlo import MonteCarloError
from twin.pipeline.rundir import RunDirError
from twin.view.record_rate import FULL_SPELLING, RECORD_RATE_HZ, parse_record_rate

EXIT_BAD_INPUT = 2
EXIT_SIGINT, EXIT_SIGTERM = 128 + signal.SIGINT, 128 + signal.SIGTERM


class Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line ("longwall: error: ..." and where to read the usage)."""

    def error(self, message: str):
        self.exit(EXIT_BAD_INPUT, f"longwall: error: {message}; see `{self.prog} --help`\n")


def record_rate(text: str) -> float | None:
    """--record-rate's value (twin.view.record_rate); a bad one is a usage error (one line)."""
    try:
        return parse_record_rate(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def speed_factor(text: str) -> float:
    """--speed's value: a factor of real time above 0, or 'max' (as fast as the twin runs)."""
    if text == "max":
        return float("inf")
    try:
        speed = float(text)
    except ValueError:
        speed = 0.0
    if not speed > 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a speed (a factor of real time above 0, or 'max')")
    return speed


def tcp_port(text: str) -> int:
    """--port's value: a TCP port, 1..65535; anything else is a usage error (one line)."""
    try:
        port = int(text)
    except ValueError:
        port = 0
    if not 1 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{text!r} is not a port (1..65535)")
    return port


def image_width(text: str) -> int:
    """--width's value: pixels within WIDTH_RANGE_PX; anything else is a usage error (one line)."""
    try:
        width = int(text)
        check_width(width)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a width in pixels") from None
    except ExportError as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    return width


RECORD_RATE_HELP = ("rate of the time series and the replay in the Rerun recording%s [Hz] "
                    f"(default {RECORD_RATE_HZ:g}; '{FULL_SPELLING}': every sample)")


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program is, so it unwinds (and cleans up) as Ctrl-C does."""


def _terminate(signum, frame) -> None:
    raise Terminated


@contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """While the block runs, SIGTERM raises Terminated (in the main thread only; elsewhere nothing changes)."""
    try:
        previous = signal.signal(signal.SIGTERM, _terminate)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _version() -> str:
    """The installed distribution's version (pyproject.toml's), or that it is not installed (run from a clone)."""
    try:
        return metadata.version("longwall-twin")
    except metadata.PackageNotFoundError:
        return "(not installed: pip install -e .)"


def _view(run_dir: Path, web: bool, port: int | None) -> None:
    """`longwall view`: the native viewer, detached; with `web`, the web viewer served until Ctrl-C."""
    from twin.view.layout import WEB_PORT, open_viewer, serve_web, stop_web
    if not web:
        open_viewer(run_dir)
        return
    server, url = serve_web(run_dir, WEB_PORT if port is None else port)
    print(f"Rerun web viewer of {run_dir}: {url}  (Ctrl-C stops it)", flush=True)
    try:
        server.wait()
    finally:
        stop_web(server)


def main(argv: list[str] | None = None) -> int:
    parser = Parser(prog="longwall", description="Longwall face digital twin")
    parser.add_argument("--version", action="version", version=f"longwall-twin {_version()}")
    sub = parser.add_subparsers(dest="command", required=True)
    p_run = sub.add_parser("run", help="simulate a scenario and write a run directory")
    p_run.add_argument("scenario", nargs="?", type=Path, help="scenario TOML (default: the shipped default.toml)")
    p_run.add_argument("--out", type=Path, help="run directory (default: runs/NAME-seedN)")
    p_run.add_argument("--seed", type=int, help="override the scenario's random seed")
    p_run.add_argument("--cycles", type=int, metavar="N", help="override a face scenario's number of cutting cycles")
    p_run.add_argument("--force", action="store_true", help="replace an existing non-empty run directory")
    p_run.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    p_run.add_argument("--trials", type=int, default=1,
                       help="Monte Carlo: sensor-error trials drawn from the same truth (default 1)")
    p_run.add_argument("--twin-only", action="store_true", help="truth only, no sensor streams")
    p_run.add_argument("--workers", type=int, default=1,
                       help="Monte Carlo: local processes for trials 1.. (default 1: sequential)")
    p_run.add_argument("--ray", metavar="ADDRESS",
                       help="Monte Carlo: run trials 1.. on the Ray cluster at ADDRESS (auto, HOST:PORT)")
    p_run.add_argument("--record-rate", type=record_rate, default=RECORD_RATE_HZ, metavar="HZ",
                       help=RECORD_RATE_HELP % "s run.rrd and estimates.rrd")
    p_est = sub.add_parser("estimate", help="re-run the estimators on a run directory (simulated or imported)")
    p_est.add_argument("run_dir", type=Path)
    p_est.add_argument("--quiet", action="store_true", help="no table")
    p_est.add_argument("--record-rate", type=record_rate, default=RECORD_RATE_HZ, metavar="HZ",
                       help=RECORD_RATE_HELP % " estimates.rrd")
    p_view = sub.add_parser("view", help="open a run's recording in the Rerun viewer")
    p_view.add_argument("run_dir", type=Path)
    p_view.add_argument("--web", action="store_true",
                        help="serve it to a browser on this machine instead (a machine without a display)")
    p_view.add_argument("--port", type=tcp_port, default=None, help="the web viewer's port (default 9090)")
    p_imp = sub.add_parser("import", help="turn CSV files (one per stream, name[unit] headers) into a run directory")
    p_imp.add_argument("csv_dir", type=Path)
    p_imp.add_argument("--out", type=Path, required=True, help="run directory to create")
    p_exp = sub.add_parser("export", help="write a run directory's streams as CSV files")
    p_exp.add_argument("run_dir", type=Path)
    p_exp.add_argument("--csv", type=Path, required=True, help="folder for the CSV files")
    p_rep = sub.add_parser("report", help="plots of a run directory as one HTML page (DIR/report/report.html)")
    p_rep.add_argument("run_dir", type=Path)
    p_srv = sub.add_parser("serve", help="run a face scenario and publish it on OPC UA (needs the opcua extra)")
    p_srv.add_argument("scenario", nargs="?", type=Path, help="scenario TOML (default: the shipped default.toml)")
    p_srv.add_argument("--endpoint", default=DEFAULT_ENDPOINT, help=f"opc.tcp://HOST:PORT (default {DEFAULT_ENDPOINT})")
    p_srv.add_argument("--speed", type=speed_factor, default=1.0,
                       help="times real time (default 1; 'max': as fast as the twin runs)")
    p_srv.add_argument("--publish-rate", type=float, default=None, metavar="HZ",
                       help="publications per simulated second (default 10)")
    p_srv.add_argument("--user", help="the one user a non-loopback endpoint admits (password in "
                                      f"{PASSWORD_ENV})")
    p_srv.add_argument("--out", type=Path, help="run directory written as it serves (default: runs/NAME-seedN-served)")
    p_srv.add_argument("--seed", type=int, help="override the scenario's random seed")
    p_srv.add_argument("--cycles", type=int, metavar="N", help="override the number of cutting cycles")
    p_srv.add_argument("--force", action="store_true", help="replace an existing non-empty run directory")
    p_srv.add_argument("--twin-only", action="store_true", help="truth only, no sensor streams")
    p_srv.add_argument("--history", type=float, default=None, metavar="S",
                       help="simulated time of sensor blocks held for a client that reconnects (default 60)")
    p_srv.add_argument("--estimator", default=DEFAULT_ESTIMATOR, metavar="METHOD",
                       help=f"shearer positioning method run online and published under Longwall/Estimator "
                            f"({', '.join(ONLINE_METHODS)}; {NO_ESTIMATOR}: off; default {DEFAULT_ESTIMATOR})")
    p_rec = sub.add_parser("record", help="record an OPC UA server (longwall serve) into a run directory, no truth")
    p_rec.add_argument("--opcua", required=True, metavar="ENDPOINT", help="opc.tcp://HOST:PORT of the server")
    p_rec.add_argument("--out", type=Path, required=True, help="run directory to create")
    p_rec.add_argument("--duration", type=float, metavar="S",
                       help="record the run's first S seconds of simulated time (default: until the run finishes)")
    p_rec.add_argument("--force", action="store_true", help="replace an existing non-empty run directory")
    p_mod = sub.add_parser("model", help="the assembled face (pans, supports, floor, shearer) as MJCF, or rendered")
    p_mod.add_argument("scenario", nargs="?", type=Path, help="scenario TOML (default: the shipped default.toml)")
    p_mod.add_argument("--xml", type=Path, metavar="FILE",
                       help="write the MuJoCo model (python -m mujoco.viewer --mjcf FILE opens it)")
    p_mod.add_argument("--png", type=Path, metavar="FILE", help="render it offscreen (no display needed: EGL)")
    p_mod.add_argument("--width", type=image_width, default=None,
                       help=f"the render's width in pixels, 16:9 (default {DEFAULT_WIDTH_PX})")
    p_mod.add_argument("--seed", type=int, help="override the scenario's random seed")
    try:
        args = parser.parse_args(argv)
        if args.command == "view" and args.port is not None and not args.web:
            parser.error("--port is the web viewer's: add --web")
        if args.command == "model" and args.xml is None and args.png is None:
            parser.error("model: give --xml FILE, --png FILE or both")
        if args.command == "model" and args.width is not None and args.png is None:
            parser.error("--width is the render's: add --png FILE")
    except SystemExit as done:  # --help, or a usage error (one line)
        return done.code
    try:
        with sigterm_as_interrupt():
            return _command(args)
    except (ScenarioError, RunDirError, LogError, PositioningError, FileNotFoundError, MonteCarloError,
            ServeError, ExportError) as err:
        print(f"longwall: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except WorkerLost as err:  # not the input's fault: the system's
        print(f"longwall: error: {err}; a run directory is only written when complete", file=sys.stderr)
        return 1
    except KeyboardInterrupt as err:
        term = isinstance(err, Terminated)
        print(f"longwall: stopped by {'SIGTERM' if term else 'Ctrl-C (SIGINT)'}; a run directory is only "
              f"written when complete", file=sys.stderr)
        return EXIT_SIGTERM if term else EXIT_SIGINT


def _command(args: argparse.Namespace) -> int:
    """Run the parsed command; 0 when done."""
    if args.command == "run":
        api.check_trials(args.trials, args.workers, args.ray, ("--trials", "--workers", "--ray"))
        api.run(args.scenario or default_scenario(), args.out, args.seed, args.trials, force=args.force,
                quiet=args.quiet, sensors=not args.twin_only, workers=args.workers, ray_address=args.ray,
                cycles=args.cycles, record_rate_hz=args.record_rate)
    elif args.command == "estimate":
        api.estimate(args.run_dir, args.quiet, record_rate_hz=args.record_rate)
    elif args.command == "view":
        _view(args.run_dir, args.web, args.port)
    elif args.command == "import":
        report = import_csv(args.csv_dir, args.out)
        print(report.summary())
    elif args.command == "export":
        for path in export_csv(args.run_dir, args.csv):
            print(path)
    elif args.command == "report":
        from twin.view.report import build_report
        print(build_report(args.run_dir))
    elif args.command == "serve":
        served = serving.serve(args.scenario or default_scenario(), args.out, args.seed, args.cycles,
                           endpoint=args.endpoint, speed=args.speed, publish_hz=args.publish_rate, user=args.user,
                           force=args.force, sensors=not args.twin_only, history_s=args.history,
                           estimator=args.estimator,
                           ready=lambda: print(f"serving on {args.endpoint} (Ctrl-C stops it)", flush=True))
        print(f"published {served['simulated_s']:.0f} s of the face in {served['wall_s']:.1f} s "
              f"({served['simulated_s'] / served['wall_s']:.0f}x real time, {served['ticks']} publications, "
              f"{served['passes']} estimated passes, {served['hydraulic_alarms']} hydraulic alarms)")
    elif args.command == "record":
        report = serving.record(args.opcua, args.out, args.duration, force=args.force)
        from twin.opcua.recorder import summary  # the opcua extra is there: serving.record said so otherwise
        print(summary(report, args.out))
    elif args.command == "model":
        written = api.model(args.scenario or default_scenario(), args.xml, args.png,
                            args.width or DEFAULT_WIDTH_PX, args.seed)
        for path, size in written.items():
            print(f"{path} ({size / 1e3:.0f} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
