"""`longwall view`: the Rerun viewer opened on a run directory's recordings, with their layout (the blueprint)
built from what the directory holds.

It is built from what the directory holds, not stored in it: rerun-sdk 0.41 gives a blueprint a random store id
(and chunk and row ids from the clock), so a blueprint in the .rrd would make two runs of the same scenario and
seed differ (twin.view.rrd_stream). A face run gets twin.view.blueprint's layout for what it holds: truth or not, the
face alignment loop or not, the estimators found in estimates/ (their errors, or sigmas without truth, sensor states,
fusion, detectors, the supports' canopy attitude), the 3-D eye and the plan's bounds from its face (the pans, or
without truth the first estimate shown); a SINS experiment one time-series view per group and quantity of its
errors.parquet (twin.papers.sins_rundir).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
import urllib.request
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import rerun.blueprint as rrb

from estimators.io.logformat import ESTIMATES_DIR
from estimators.shearer.methods import METHODS
from twin.config.experiments import EXPERIMENT_KIND
from twin.config.scenario import load_face_scenario
from twin.view import plan
from twin.view.blueprint import HIDDEN_METHODS, RunContents, face_blueprint, face_eye, hidden_methods
from twin.view.recording import ESTIMATES_RRD, RUN_RRD
from twin.view.rerun_columns import APPLICATION_ID

SUFFIXES = ("states", "fusion", "detectors")
"""The estimates/METHOD_SUFFIX.parquet tables a method's Estimates views come from, besides METHOD.parquet."""


def _experiment(run_dir: Path) -> str | None:
    """The SINS experiment a run directory holds (metrics.json), None for a face run."""
    try:
        meta = json.loads((run_dir / "metrics.json").read_text()).get("experiment", {})
    except (OSError, ValueError, AttributeError):
        return None
    return meta.get("experiment") if isinstance(meta, dict) and meta.get("kind") == EXPERIMENT_KIND else None


def run_blueprint(run_dir: Path) -> rrb.Blueprint:
    """The layout of `run_dir`'s recordings (module docstring)."""
    run_dir = Path(run_dir)
    experiment = _experiment(run_dir)
    if experiment is not None:
        from twin.papers.sins_rundir import experiment_blueprint

        table = pq.read_table(run_dir / "errors.parquet", columns=["group", "quantity"])
        pairs = list(dict.fromkeys(zip(table.column("group").to_pylist(), table.column("quantity").to_pylist())))
        return experiment_blueprint(experiment, pairs)
    folder = run_dir / ESTIMATES_DIR
    names = {p.stem for p in folder.glob("*.parquet")} if folder.is_dir() else set()
    methods = [m for m in METHODS if m in names]
    by_suffix = {suffix: [m for m in methods if f"{m}_{suffix}" in names] for suffix in SUFFIXES}
    scenario = run_dir / "scenario.toml"
    scn = load_face_scenario(scenario) if scenario.is_file() else None
    truth = (run_dir / "truth_shearer.parquet").is_file()
    framed = _face_points(run_dir, methods) if scn is not None else None
    eye, plan_bounds = None, None
    if framed is not None:
        eye = face_eye(framed, np.radians(scn.face.azimuth_deg))
        plan_bounds = (plan.plan_bounds(scn) if truth
                       else plan.bounds_of(plan.plotted(plan.face_coordinates(scn, framed, 0))))
    return face_blueprint(RunContents(
        truth=truth, alignment=scn is not None and scn.alignment.mode != "none", methods=methods,
        state_methods=by_suffix["states"], fusion_methods=by_suffix["fusion"], detector_methods=by_suffix["detectors"],
        support_attitude=any(name.endswith("_support_attitude") for name in names), eye=eye, plan_bounds=plan_bounds,
        streams=frozenset(p.stem for p in run_dir.glob("*.parquet") if _rows(p)),
        hidden=hidden_methods(methods, _run_sep(run_dir))))


def _run_sep(run_dir: Path) -> dict[str, float]:
    """Each method's SEP over the whole run from metrics.json (none without truth, or without the file)."""
    try:
        estimators = json.loads((run_dir / "metrics.json").read_text()).get("estimators", {})
        return {m: float(e["cycles"][-1]["sep"]) for m, e in estimators.items()
                if isinstance(e, dict) and e.get("cycles")}
    except (OSError, ValueError, AttributeError, KeyError, TypeError):
        return {}


def _rows(path: Path) -> int:
    """Rows of a Parquet file (0 if it cannot be read: the viewer shows what can)."""
    try:
        return pq.read_metadata(path).num_rows
    except (OSError, ValueError):  # pyarrow's ArrowInvalid is a ValueError
        return 0


def _face_points(run_dir: Path, methods: list[str]) -> np.ndarray | None:
    """Points in t that frame the face: the pans' positions (truth_pans), or without truth the path of the first
    method not hidden by default (twin.view.blueprint.HIDDEN_METHODS); None without either."""
    pans = run_dir / "truth_pans.parquet"
    shown = [m for m in methods if m not in HIDDEN_METHODS]
    path = pans if pans.is_file() else (run_dir / ESTIMATES_DIR / f"{shown[0]}.parquet" if shown else None)
    if path is None:
        return None
    table = pq.read_table(path, columns=["p_t_e", "p_t_n", "p_t_u"])
    return np.column_stack([table.column(c).to_numpy() for c in ("p_t_e", "p_t_n", "p_t_u")])


def blueprint_file(run_dir: Path) -> Path:
    """run_blueprint saved as an .rbl the viewer opens beside the recordings (in the temporary directory, one per
    run directory, replaced each time)."""
    key = hashlib.sha256(str(Path(run_dir).resolve()).encode()).hexdigest()[:16]
    path = Path(tempfile.gettempdir()) / f"longwall-view-{key}.rbl"
    run_blueprint(run_dir).save(APPLICATION_ID, path)
    return path


def _viewer_command(run_dir: Path) -> list[str]:
    """`rerun` with `run_dir`'s recordings (run.rrd, estimates.rrd: whichever it holds; a run without truth, e.g.
    imported, has estimates.rrd only) and their layout (run_blueprint, as an .rbl)."""
    files = [str(p) for p in (Path(run_dir) / RUN_RRD, Path(run_dir) / ESTIMATES_RRD) if p.is_file()]
    if not files:
        raise FileNotFoundError(f"{run_dir}: no {RUN_RRD} or {ESTIMATES_RRD}; `longwall run` writes both, and "
                                f"`longwall estimate {run_dir}` writes {ESTIMATES_RRD} for an imported log")
    beside = Path(sys.executable).parent / "rerun"
    exe = str(beside) if beside.is_file() else shutil.which("rerun")
    if exe is None:
        raise FileNotFoundError(f"rerun viewer executable not found next to {sys.executable} or on PATH "
                                "(pip install rerun-sdk)")
    return [exe, *files, str(blueprint_file(run_dir))]


def has_display() -> bool:
    """Whether a native viewer window can open: on Linux and the BSDs an X11 or Wayland display must be set."""
    return not sys.platform.startswith(("linux", "freebsd", "openbsd")) or bool(
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def open_viewer(run_dir: Path) -> None:
    """Open `run_dir`'s recordings in the native Rerun viewer (a detached `rerun` process) with the run's layout.
    Without a display, FileNotFoundError says to use the web viewer (serve_web)."""
    command = _viewer_command(run_dir)
    if not has_display():
        raise FileNotFoundError(f"no display to open the viewer on (DISPLAY and WAYLAND_DISPLAY are unset); "
                                f"`longwall view {run_dir} --web` serves it to a browser instead")
    subprocess.Popen(command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


WEB_PORT = 9090
"""Default port of the web viewer (Rerun's own default)."""
WEB_START_S = 30.0
"""How long the web viewer may take to answer before it is taken as failed."""


def free_port() -> int:
    """A TCP port free on the loopback address now (the system's choice)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def serve_web(run_dir: Path, port: int = WEB_PORT) -> tuple[subprocess.Popen, str]:
    """Serve `run_dir`'s recordings and layout to a browser: Rerun's web viewer on http://127.0.0.1:`port` (loopback
    only) and its data on a free gRPC port. Returns the server process (in a session of its own: stop it with
    stop_web), once it answers, and the URL that opens the recordings; FileNotFoundError (one line) when it cannot
    start (the port taken, say)."""
    grpc = free_port()
    command = _viewer_command(run_dir)
    server = subprocess.Popen([command[0], "--serve-web", "--bind", "127.0.0.1", "--web-viewer-port", str(port),
                               "--port", str(grpc), *command[1:]],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    url = f"http://127.0.0.1:{port}/?url={urllib.parse.quote(f'rerun+http://127.0.0.1:{grpc}/proxy', safe='')}"
    deadline = time.monotonic() + WEB_START_S
    while server.poll() is None and time.monotonic() < deadline:
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=1.0):
                return server, url
        except OSError:
            time.sleep(0.2)
    stop_web(server)
    raise FileNotFoundError(f"the Rerun web viewer did not start on 127.0.0.1:{port} (is the port in use? "
                            f"choose another with --port)")


def stop_web(server: subprocess.Popen) -> None:
    """Stop a serve_web server: its whole process group (the `rerun` launcher runs the viewer as a child)."""
    try:
        os.killpg(server.pid, signal.SIGTERM)
    except ProcessLookupError:
        pass
    server.wait()
