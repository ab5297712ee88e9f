"""Navigation estimators for a longwall face, run on a sensor log (estimators.io.logformat): the shearer
positioning of 001, 003 and 004 (estimators.shearer), the SINS and its alignment (estimators.sins), the supports'
attitude (estimators.support) and the push-ram fault checks (estimators.faults).

    import estimators
    sol = estimators.estimate("runs/default", "kf_cpoem_rts", config) # one method -> Solution
    sols = estimators.estimate(log, ("kf", "afkf"), config)          # several -> {name: Solution}

The subpackages are imported when first used: ``import estimators`` stays fast.
"""

from __future__ import annotations

from collections.abc import Sequence
from os import PathLike
from pathlib import Path

from estimators import kernel_cache

kernel_cache.install()  # before any kernel is defined: one cache stamp over all the project's kernels


def estimate(log, method: str | Sequence[str], config):
    """Run shearer positioning method(s) (estimators.shearer.methods.METHODS) on a log.

    log: an estimators.io.log.Log, or a run directory (str or path) read with estimators.io.log.load_log;
    method: one name (returns its estimators.shearer.solution.Solution) or a sequence of names (returns a dict
    name -> Solution, in the given order); config: an estimators.shearer.config.Config, the IMU's error budget,
    lever arm, odometer pulse length and support positions of the machine that made the log (no default: a guess
    would give a silently wrong answer; Config.appendix_a(...) is 001's tuning). An unknown method raises
    PositioningError naming the methods."""
    from estimators.io.log import Log, load_log
    from estimators.shearer.methods import estimate as run_methods

    if isinstance(log, (str, PathLike)):
        log = load_log(Path(log))
    elif not isinstance(log, Log):
        raise TypeError(f"log: an estimators.io.log.Log or a run directory, not {type(log).__name__}")
    names = (method,) if isinstance(method, str) else tuple(method)
    sols = run_methods(log, config, names)
    return sols[method] if isinstance(method, str) else sols
