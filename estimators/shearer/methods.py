"""The shearer positioning methods by name, run on a sensor log (each an estimates/NAME stream):

* 001 (estimators.shearer.positioning): ``dr``, ``dr_compensated``, ``kf``, ``kf_rts``, ``kf_cpoem``,
  ``kf_cpoem_rts``,
  ``rts_offline``;
* 003 (estimators.shearer.adaptive_federated_mag): ``ckf_mag``, ``afkf`` (need the mag stream);
* 004 (estimators.shearer.rail_kinematics): ``fkf_rail`` (needs the push-ram stream and the support positions).
"""

from __future__ import annotations

import multiprocessing
import tempfile
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, Protocol

from estimators.heap import release_free_memory
from estimators.io.log import Log
from estimators.shearer.adaptive_federated_mag import run_mag
from estimators.shearer.config import DEAD_RECKONING, STREAMED, Config, PositioningError
from estimators.shearer.health import Assessment, assess
from estimators.shearer.online import OnlinePositioning
from estimators.shearer.dead_reckoning import dead_reckoning
from estimators.shearer.positioning import PassStore, rts_offline, run_kf
from estimators.shearer.prepare import Prepared, prepare
from estimators.shearer.rail_kinematics import run_rail
from estimators.shearer.solution import Solution, join_rows
from estimators.workers import ForkedTasks

METHODS = ("dr", "dr_compensated", "kf", "kf_rts", "kf_cpoem", "kf_cpoem_rts", "rts_offline", "ckf_mag", "afkf",
           "fkf_rail")


TASKS = (("kf_cpoem_rts", "rts_offline", "dr_compensated"), ("fkf_rail",), ("afkf",), ("ckf_mag",), ("kf_cpoem",),
         ("kf_rts",), ("kf",), ("dr",))
"""The methods in groups that run together (the smoother's forward run feeds rts_offline and dr_compensated), the
longest first, so that a pool of processes finishes together."""


Pieces = Callable[[], Iterator[tuple[Mapping[str, Mapping[str, Any]], bool]]]
"""The log in consecutive pieces of time, (stream name -> columns, last piece), read afresh at each call
(estimators.io.log.log_pieces)."""


class Sink(Protocol):
    """What a caller does with each method's rows where they are made (the process that runs the method): `rows`
    takes them in time order (a batch method's whole solution, an online one's passes), their flags final; `done`
    the method's notes, and returns what `estimate` gives for the method."""

    def rows(self, name: str, sol: Solution) -> None: ...

    def done(self, name: str, notes: list[str]) -> Any: ...


def _run_group(log: Log, cfg: Config, prep: Prepared, sink: Sink | None, group: tuple[str, ...], scratch: Path
               ) -> dict:
    """One task of TASKS, restricted to the requested methods of its group, each solution given to `sink`; what it
    keeps on disk in a folder of its own under `scratch`."""
    out: dict[str, Solution] = {}
    if set(group) <= set(TASKS[0]):
        with tempfile.TemporaryDirectory(dir=scratch) as tmp:
            store = PassStore(Path(tmp)) if "rts_offline" in group else None
            _, smoothed = run_kf(log, cfg, prep, cpoem=True, smooth=True, store=store)
            if "kf_cpoem_rts" in group:
                out["kf_cpoem_rts"] = smoothed
            if "rts_offline" in group:
                out["rts_offline"] = rts_offline(cfg, store, smoothed.notes)
        if "dr_compensated" in group:
            out["dr_compensated"] = dead_reckoning(log, cfg, prep, smoothed.cal[-1])
    elif group[0] in ("kf", "kf_cpoem"):
        out[group[0]], _ = run_kf(log, cfg, prep, cpoem=group[0] == "kf_cpoem", smooth=False)
    elif group[0] == "kf_rts":
        _, out["kf_rts"] = run_kf(log, cfg, prep, cpoem=False, smooth=True)
    elif group[0] == "dr":
        out["dr"] = dead_reckoning(log, cfg, prep)
    elif group[0] in ("ckf_mag", "afkf"):
        out[group[0]] = run_mag(log, cfg, prep, federated=group[0] == "afkf")
    else:
        out["fkf_rail"] = run_rail(log, cfg, prep, cfg.isolate_by)
    for name, sol in out.items():
        assess(sol, cfg, name)
    if sink is None:
        return out
    for name in list(out):
        sol = out.pop(name)
        sink.rows(name, sol)
        out[name] = sink.done(name, sol.notes)
    return out


def _online(cfg: Config, pieces: Pieces, sink: Sink | None, name: str, **kwargs
            ) -> tuple[OnlinePositioning, Assessment, Solution]:
    """Method `name` run online over the log's pieces (OnlinePositioning with `kwargs`), each pass (after epoch 0's
    row) through the health monitor to `sink` as it ends (None: not written), a pass held at a time: the run, its
    health monitor and its last pass."""
    online = OnlinePositioning(cfg, name, **kwargs)
    health = Assessment(cfg, name, covariance=name not in DEAD_RECKONING)
    last = None
    for piece, final in pieces():
        for one in online.feed(piece, final):
            # Epoch 0 goes with the first pass: its rows computed alone would differ in the last bit (BLAS).
            sol = join_rows([online.initial, one.solution]) if last is None else one.solution
            health.check(sol)
            if sink is not None:
                sink.rows(name, sol)
            last = sol
            release_free_memory()  # what the pass freed, back to the system (a long run's memory stays flat)
    if last is None:
        raise PositioningError(f"{name}: the log holds no pass to filter (no odometer travel after the start)")
    return online, health, last


def _run_online(cfg: Config, pieces: Pieces, sink: Sink, group: tuple[str, ...], scratch: Path) -> dict:
    """A group of TASKS run online over the log's pieces: each method's rows and notes those of the batch group's,
    to `sink` a pass at a time. The smoother's group reads the log twice: kf_cpoem_rts keeps its passes on disk (in
    a folder of its own under `scratch`) for rts_offline (run backward over them, then written forward), and its
    final calibration drives dr_compensated."""
    if not set(group) <= set(TASKS[0]):
        online, health, _ = _online(cfg, pieces, sink, group[0])
        return {group[0]: sink.done(group[0], online.finish() + health.notes())}
    out, lead = {}, "kf_cpoem_rts"
    with tempfile.TemporaryDirectory(dir=scratch) as tmp:
        store = PassStore(Path(tmp)) if "rts_offline" in group else None
        online, health, last = _online(cfg, pieces, sink if lead in group else None, lead, store=store)
        notes = online.finish()
        if lead in group:
            out[lead] = sink.done(lead, notes + health.notes())
        if store is not None:
            health = Assessment(cfg, "rts_offline", covariance=True)
            for sol in store.smoothed(cfg):
                health.check(sol)
                sink.rows("rts_offline", sol)
            out["rts_offline"] = sink.done("rts_offline", notes + health.notes())
    if "dr_compensated" in group:
        online, health, _ = _online(cfg, pieces, sink, "dr_compensated", cal=last.cal[-1])
        out["dr_compensated"] = sink.done("dr_compensated", online.finish() + health.notes())
    return {name: out[name] for name in group}


Task = tuple[str, tuple[str, ...]]
"""("batch", a group of TASKS) or ("online", (a method of STREAMED,))."""

_SHARED: tuple[Log | None, Config, Prepared | None, Sink | None, Pieces | None, Path] | None = None
"""What a forked worker inherits from its parent (never pickled): the log, configuration, prepared log (batch
groups), sink, the log's pieces (online methods) and the parent's scratch folder."""


def _run_task(task: Task) -> dict:
    log, cfg, prep, sink, pieces, scratch = _SHARED
    kind, group = task
    if kind == "batch":
        return _run_group(log, cfg, prep, sink, group, scratch)
    return _run_online(cfg, pieces, sink, group, scratch)


def _run_tasks(tasks: list[Task], workers: int) -> list[dict]:
    """The tasks on forked processes, a process each and `workers` at once (estimators.workers.ForkedTasks), which
    share the parent's log and prepared increments (copy on write) and its compiled kernels; results in the order of
    `tasks`. An exception in a task is raised here."""
    with ForkedTasks(_run_task, tasks, workers) as running:
        return running.results()


def estimate(log: Log | None, cfg: Config, methods: tuple[str, ...] = METHODS, workers: int = 1,
             sink: Sink | None = None, pieces: Pieces | None = None) -> dict:
    """Run the requested methods on a log; returns method -> Solution, each through the health monitor
    (estimators.shearer.health), or what `sink` made of it in the process that made it. Given the log's `pieces`
    too, the methods of STREAMED run online over them, their rows to the sink pass by pass (the log need not be
    loaded if all run so: None). With `workers` > 1 the independent groups of methods (TASKS) run on that many
    forked processes (POSIX), a solution not sent back to the parent when a sink writes it; every result is the
    one the sequential run gives, bit for bit."""
    global _SHARED
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise PositioningError(f"unknown method '{unknown[0]}' (methods: {', '.join(METHODS)})")
    if workers < 1:
        raise ValueError(f"workers: must be >= 1 (got {workers})")
    tasks: list[Task] = []
    for task in TASKS:
        group = tuple(m for m in task if m in methods)
        if group:
            online = sink is not None and pieces is not None and set(group) <= set(STREAMED)
            tasks.append(("online" if online else "batch", group))
    prep = prepare(log, cfg) if any(kind == "batch" for kind, _ in tasks) else None
    # The tasks' files go under a folder of this process's: a worker stopped by a signal leaves its own, and this
    # process removes them when it ends (stopped too: the CLI raises SIGTERM as an exception), after the workers.
    with tempfile.TemporaryDirectory(prefix="longwall-rts-") as scratch:
        _SHARED = (log, cfg, prep, sink, pieces, Path(scratch))
        try:
            if workers > 1 and len(tasks) > 1 and "fork" in multiprocessing.get_all_start_methods():
                results = _run_tasks(tasks, workers)
            else:
                results = [_run_task(task) for task in tasks]
        finally:
            _SHARED = None
    out = {name: sol for res in results for name, sol in res.items()}
    return {m: out[m] for m in methods}
