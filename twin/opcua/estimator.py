"""The shearer positioning estimator of a served face (`longwall serve --estimator METHOD`): the sensor rows the
server publishes go, as they come, to the method run online (estimators.shearer.online) in a worker thread, and
each pass, as it ends, comes back as the ESTIMATE stream's rows (twin.pipeline.estimate.solution_columns: the
tangent plane t and the face frame F, with one-sigma) and the alarms it raises. No asyncua here.

The worker is fed through a bounded queue (FEED_QUEUE items): `add` returns at once unless the estimator is that
far behind, when it waits (in an executor: the server keeps answering its clients) - the publisher is slowed rather
than a row lost. The streams reach the server one at a time, the push rams a cycle later than the shearer's, so the
worker feeds the method each stream's rows before the time every fed stream is complete to (their `made_until`):
all streams cut at one time, as a log cut into consecutive pieces, which gives the batch method's rows
(estimators.shearer.online). A pass is published once the publisher's clock reaches the time it became known.

Alarms (`Alarm`): a pass over which the health monitor found the filter lost track (LOST_TRACK); epochs of a pass
with the rail model isolated by its fault detector (RAIL_ISOLATED, fkf_rail: FLAG_ISOLATED in its rows); the
estimator stopped (FAILED: a log it cannot use, or any failure of its; the rows still coming are drained, so the
face goes on being served). The supports' hydraulic and push-ram checks raise their own
(twin.opcua.publishers.HydraulicAlarms).
"""

from __future__ import annotations

import asyncio
import queue
import threading
from dataclasses import dataclass

import numpy as np

from estimators.face.straightness import sd_in_face_frame
from estimators.io.logformat import FLAG_ISOLATED
from estimators.shearer.config import PositioningError
from estimators.shearer.online import ONLINE_METHODS, OnlinePositioning, PassEstimate
from twin.config.scenario import Scenario
from twin.opcua.access import ServeError
from twin.pipeline.estimate import positioning_config, solution_columns

DEFAULT_ESTIMATOR = "kf_cpoem_rts"
"""--estimator's default."""
NO_ESTIMATOR = "none"
"""--estimator's value that turns it off."""
FED_STREAMS = ("imu", "odometer", "survey", "pushram", "face_survey")
"""The sensor streams the online methods read (OnlinePositioning.feed)."""
FEED_QUEUE = 16
"""Sensor pieces the worker may be behind before `add` waits."""
LOST_TRACK, RAIL_ISOLATED, FAILED = "LostTrack", "RailIsolated", "EstimatorFailed"
"""The alarms' kinds."""
SEVERITY = {LOST_TRACK: 800, RAIL_ISOLATED: 600, FAILED: 900}
"""Their OPC UA severity (1..1000)."""
POSITION_AXES = ("x", "y", "z", "e", "n", "u")
"""ShearerPosition's and ShearerPositionSigma's components: the face frame F, then the tangent plane t [m]."""


def check_method(method: str) -> str | None:
    """--estimator's method (None: `none`); ServeError (one line) for one that does not run online."""
    if method == NO_ESTIMATOR:
        return None
    if method not in ONLINE_METHODS:
        raise ServeError(f"--estimator {method}: not a method that runs online; choose one of "
                         f"{', '.join(ONLINE_METHODS)} or {NO_ESTIMATOR}")
    return method


@dataclass(frozen=True)
class Alarm:
    """An alarm of the estimator: its kind (LOST_TRACK, ...), the simulated time it refers to and what happened."""

    kind: str
    t: float
    message: str


@dataclass(frozen=True)
class EstimatedPass:
    """One pass as published: its ESTIMATE columns, whether the filter kept track, its alarms and the simulated
    time it became known (inf: at the log's end)."""

    columns: dict[str, np.ndarray]
    healthy: bool
    alarms: list[Alarm]
    t_known: float


def pass_alarms(method: str, one: PassEstimate) -> list[Alarm]:
    """The alarms a pass raises (module docstring)."""
    t = one.solution.t
    out = []
    if not one.healthy:
        out.append(Alarm(LOST_TRACK, float(t[-1]), f"{method}: the filter lost track over the pass "
                                                   f"{t[0]:.1f}-{t[-1]:.1f} s (health monitor)"))
    isolated = (one.solution.flags & FLAG_ISOLATED) > 0
    if isolated.any():
        first, last = t[isolated][[0, -1]]
        out.append(Alarm(RAIL_ISOLATED, float(first), f"{method}: the rail model's fault detector isolated it over "
                                                      f"{first:.1f}-{last:.1f} s ({isolated.sum()} epochs)"))
    return out


def shearer_position(columns: dict[str, np.ndarray], azimuth_rad: float) -> tuple[float, np.ndarray, np.ndarray]:
    """The last row's time, position (POSITION_AXES) and its one-sigma: F's from the tangent plane's east, north and
    up one-sigma taken as independent."""
    sd_t = np.array([columns[f"sd_pos_{a}"][-1] for a in "enu"])
    sd_f = sd_in_face_frame(sd_t, azimuth_rad)
    p = [columns[f"p_f_{a}"][-1] for a in "xyz"] + [columns[f"p_t_{a}"][-1] for a in "enu"]
    return float(columns["t"][-1]), np.array(p), np.concatenate([sd_f, sd_t])


class EstimatorFeed:
    """`method` run online on the rows `add`ed (module docstring); `take` hands over the passes ended so far."""

    def __init__(self, scn: Scenario, method: str, streams: tuple[str, ...]):
        self.scn, self.method = scn, method
        self.streams = tuple(s for s in FED_STREAMS if s in streams)  # the fed streams the server publishes
        self.online = OnlinePositioning(positioning_config(scn), method)
        self.queue: queue.Queue = queue.Queue(maxsize=FEED_QUEUE)
        self.out: queue.SimpleQueue = queue.SimpleQueue()  # EstimatedPass or Alarm, in order
        self.pending = {s: [] for s in self.streams}  # rows not yet fed
        self.made_until = dict.fromkeys(self.streams, 0.0)
        self.t_fed = 0.0  # every stream is fed before this time
        self.thread = threading.Thread(target=self._run, name=f"estimator {method}", daemon=True)
        self.thread.start()

    async def add(self, name: str, columns: dict[str, np.ndarray], made_until: float) -> None:
        """A sensor stream's next rows and the time before which it has no more (BlockStream.add's)."""
        if name not in self.pending:
            return
        try:
            self.queue.put_nowait((name, columns, made_until))
        except queue.Full:
            await asyncio.get_running_loop().run_in_executor(None, self.queue.put, (name, columns, made_until))

    async def finish(self) -> None:
        """The log ends: the last passes are run; returns once they are handed over."""
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(None, self.queue.put, None)
        await loop.run_in_executor(None, self.thread.join)

    def take(self) -> list:
        """The passes (EstimatedPass) and failures (Alarm) since the last call."""
        out = []
        while not self.out.empty():
            out.append(self.out.get())
        return out

    def _run(self) -> None:
        try:
            while (item := self.queue.get()) is not None:
                name, columns, made_until = item
                if columns["t"].size:
                    self.pending[name].append(columns)
                self.made_until[name] = made_until
                self._feed(min(self.made_until.values()), final=False)
            self._feed(np.inf, final=True)
        except Exception as err:  # whatever stops the estimator, the face goes on being served: it says why
            said = err if isinstance(err, PositioningError) else f"{type(err).__name__}: {err}"
            self.out.put(Alarm(FAILED, min(self.made_until.values()), f"{self.method} stopped: {said}"))
            while self.queue.get() is not None:  # the rest is not read
                pass

    def _feed(self, t_cut: float, final: bool) -> None:
        """Feed every stream's rows before t_cut (all, with `final`); hand over the passes that ended."""
        if t_cut <= self.t_fed and not final:
            return
        self.t_fed = t_cut
        piece = {}
        for name, pieces in self.pending.items():
            rows = {k: np.concatenate([p[k] for p in pieces]) for k in pieces[0]} if pieces else None
            if rows is None:
                continue
            k = rows["t"].size if final else int(np.searchsorted(rows["t"], t_cut, side="left"))
            piece[name] = {c: v[:k] for c, v in rows.items()}
            self.pending[name] = [{c: v[k:] for c, v in rows.items()}] if k < rows["t"].size else []
        for one in self.online.feed(piece, final):
            self.out.put(EstimatedPass(solution_columns(one.solution, self.scn), one.healthy,
                                       pass_alarms(self.method, one), t_cut))

