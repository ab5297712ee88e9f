"""The shearer positioning methods by name, run on a sensor log (each an estimates/NAME stream):

* 001 (estimators.shearer.positioning): ``dr``, ``dr_compensated``, ``kf``, ``kf_rts``, ``kf_cpoem``,
  ``kf_cpoem_rts``,
  ``rts_offline``;
* 003 (estimators.shearer.adaptive_federated_mag): ``ckf_mag``, ``afkf`` (need the mag stream);
* 004 (estimators.shearer.rail_kinematics): ``fkf_rail`` (needs the push-ram stream and the support positions).
"""

from __future__ import annotations

import multiprocessing
import signal
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from estimators.io.log import Log
from estimators.shearer.adaptive_federated_mag import run_mag
from estimators.shearer.config import Config, PositioningError
from estimators.shearer.health import assess
from estimators.shearer.positioning import dead_reckoning, rts_offline, run_kf
from estimators.shearer.prepare import Prepared, prepare
from estimators.shearer.rail_kinematics import run_rail
from estimators.shearer.solution import Solution

METHODS = ("dr", "dr_compensated", "kf", "kf_rts", "kf_cpoem", "kf_cpoem_rts", "rts_offline", "ckf_mag", "afkf",
           "fkf_rail")


TASKS = (("kf_cpoem_rts", "rts_offline", "dr_compensated"), ("fkf_rail",), ("afkf",), ("ckf_mag",), ("kf_cpoem",),
         ("kf_rts",), ("kf",), ("dr",))
"""The methods in groups that run together (the smoother's forward run feeds rts_offline and dr_compensated), the
longest first, so that a pool of processes finishes together."""


Finish = Callable[[str, Solution], Any]
"""What a caller does with each method's solution where it is made (its process), e.g. write and score it; its
value is returned in place of the solution."""


def _run_group(log: Log, cfg: Config, prep: Prepared, finish: Finish | None, group: tuple[str, ...]) -> dict:
    """One task of TASKS, restricted to the requested methods of its group, each solution through `finish`."""
    out: dict[str, Solution] = {}
    if set(group) <= set(TASKS[0]):
        with tempfile.TemporaryDirectory(prefix="longwall-rts-") as tmp:
            keep = Path(tmp) if "rts_offline" in group else None
            _, smoothed, fwd = run_kf(log, cfg, prep, cpoem=True, smooth=True, keep_dir=keep)
            if "kf_cpoem_rts" in group:
                out["kf_cpoem_rts"] = smoothed
            if "rts_offline" in group:
                out["rts_offline"] = rts_offline(prep, cfg, fwd, smoothed.notes)
        if "dr_compensated" in group:
            out["dr_compensated"] = dead_reckoning(log, cfg, prep, smoothed.cal[-1])
    elif group[0] in ("kf", "kf_cpoem"):
        out[group[0]], _, _ = run_kf(log, cfg, prep, cpoem=group[0] == "kf_cpoem", smooth=False)
    elif group[0] == "kf_rts":
        _, out["kf_rts"], _ = run_kf(log, cfg, prep, cpoem=False, smooth=True)
    elif group[0] == "dr":
        out["dr"] = dead_reckoning(log, cfg, prep)
    elif group[0] in ("ckf_mag", "afkf"):
        out[group[0]] = run_mag(log, cfg, prep, federated=group[0] == "afkf")
    else:
        out["fkf_rail"] = run_rail(log, cfg, prep, cfg.isolate_by)
    for name, sol in out.items():
        assess(sol, cfg, name)
    return out if finish is None else {name: finish(name, out.pop(name)) for name in list(out)}


_SHARED: tuple[Log, Config, Prepared, Finish | None] | None = None
"""The log, configuration, prepared log and finish a forked worker inherits from its parent (never pickled)."""


def _worker_start() -> None:
    """A worker leaves Ctrl-C and SIGTERM to its parent, which stops the pool and says so once."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _worker_group(group: tuple[str, ...]) -> dict:
    return _run_group(*_SHARED, group)


def _run_forked(log: Log, cfg: Config, prep: Prepared, finish: Finish | None, groups: list[tuple[str, ...]],
                workers: int) -> list[dict]:
    """The groups on `workers` forked processes, which share the parent's log and prepared increments (copy on
    write) and its compiled kernels; results in the order of `groups`. An exception in a group is raised here."""
    global _SHARED
    _SHARED = (log, cfg, prep, finish)
    pool = multiprocessing.get_context("fork").Pool(min(workers, len(groups)), initializer=_worker_start)
    try:
        pending = [pool.apply_async(_worker_group, (g,)) for g in groups]
        results = [p.get() for p in pending]
        pool.close()
        return results
    finally:
        pool.terminate()
        pool.join()
        _SHARED = None


def estimate(log: Log, cfg: Config, methods: tuple[str, ...] = METHODS, workers: int = 1,
             finish: Finish | None = None) -> dict:
    """Run the requested methods on a log; returns method -> Solution, each through the health monitor
    (estimators.shearer.health), or what `finish` made of it in the process that made it. With `workers` > 1 the
    independent groups of methods (TASKS) run on that many forked processes (POSIX), a solution not sent back to
    the parent when `finish` writes it; every result is the one the sequential run gives, bit for bit."""
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise PositioningError(f"unknown method '{unknown[0]}' (methods: {', '.join(METHODS)})")
    if workers < 1:
        raise ValueError(f"workers: must be >= 1 (got {workers})")
    prep = prepare(log, cfg)
    groups = [g for g in (tuple(m for m in task if m in methods) for task in TASKS) if g]
    if workers > 1 and len(groups) > 1 and "fork" in multiprocessing.get_all_start_methods():
        results = _run_forked(log, cfg, prep, finish, groups, workers)
    else:
        results = [_run_group(log, cfg, prep, finish, g) for g in groups]
    out = {name: sol for res in results for name, sol in res.items()}
    return {m: out[m] for m in methods}
