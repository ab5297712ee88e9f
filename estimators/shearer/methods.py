"""The shearer positioning methods by name, run on a sensor log (each an estimates/NAME stream):

* 001 (estimators.shearer.positioning): ``dr``, ``dr_compensated``, ``kf``, ``kf_cpoem``, ``kf_cpoem_rts``,
  ``rts_offline``;
* 003 (estimators.shearer.adaptive_federated_mag): ``ckf_mag``, ``afkf`` (need the mag stream);
* 004 (estimators.shearer.rail_kinematics): ``fkf_rail`` (needs the push-ram stream and the support positions).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from estimators.io.log import Log
from estimators.shearer.adaptive_federated_mag import run_mag
from estimators.shearer.config import Config, PositioningError
from estimators.shearer.health import assess
from estimators.shearer.positioning import dead_reckoning, rts_offline, run_kf
from estimators.shearer.prepare import prepare
from estimators.shearer.rail_kinematics import run_rail
from estimators.shearer.solution import Solution

METHODS = ("dr", "dr_compensated", "kf", "kf_cpoem", "kf_cpoem_rts", "rts_offline", "ckf_mag", "afkf", "fkf_rail")


def estimate(log: Log, cfg: Config, methods: tuple[str, ...] = METHODS) -> dict[str, Solution]:
    """Run the requested methods on a log; returns method -> Solution, each through the health monitor
    (estimators.shearer.health)."""
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise PositioningError(f"unknown method '{unknown[0]}' (methods: {', '.join(METHODS)})")
    prep = prepare(log, cfg)
    out: dict[str, Solution] = {}
    if "kf" in methods:
        out["kf"], _, _ = run_kf(log, cfg, prep, cpoem=False, smooth=False)
    if "kf_cpoem" in methods:
        out["kf_cpoem"], _, _ = run_kf(log, cfg, prep, cpoem=True, smooth=False)
    needs_rts = {"kf_cpoem_rts", "rts_offline", "dr_compensated"} & set(methods)
    if needs_rts:
        with tempfile.TemporaryDirectory(prefix="longwall-rts-") as tmp:
            keep = Path(tmp) if "rts_offline" in methods else None
            _, smoothed, fwd = run_kf(log, cfg, prep, cpoem=True, smooth=True, keep_dir=keep)
            if "kf_cpoem_rts" in methods:
                out["kf_cpoem_rts"] = smoothed
            if "rts_offline" in methods:
                out["rts_offline"] = rts_offline(prep, cfg, fwd, smoothed.notes)
        if "dr_compensated" in methods:
            out["dr_compensated"] = dead_reckoning(log, cfg, prep, smoothed.cal[-1])
    if "dr" in methods:
        out["dr"] = dead_reckoning(log, cfg, prep)
    if "ckf_mag" in methods:
        out["ckf_mag"] = run_mag(log, cfg, prep, federated=False)
    if "afkf" in methods:
        out["afkf"] = run_mag(log, cfg, prep, federated=True)
    if "fkf_rail" in methods:
        out["fkf_rail"] = run_rail(log, cfg, prep, cfg.isolate_by)
    for name, sol in out.items():
        assess(sol, cfg, name)
    return {m: out[m] for m in methods}
