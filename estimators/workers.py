"""Forked worker processes (the estimators' pools, the background compile, the Monte Carlo trials)."""

from __future__ import annotations

import signal


def leave_signals_to_parent() -> None:
    """A worker leaves Ctrl-C and SIGTERM to its parent, which stops the pool and says so once: no traceback per
    worker, and no copy of the parent's SIGTERM handler."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
