"""Whether a run is still working: what lets runs share a store (a live run's claims hold, a dead run's are taken
over) without a server. A run on this host is alive while its process is; any run, while its heartbeat is younger
than a lease.
"""

from __future__ import annotations

import os
import socket
import time
from collections.abc import Mapping
from datetime import datetime
from typing import Any

from gaitbench.run.store_files import process_alive

LEASE_S = 120.0
"""A run whose heartbeat is older than this is dead, and its claims free: the only test for a run on another host
(on the same host a run is also dead as soon as its process is)."""

OPEN_RUNS: set[str] = set()
"""Runs this process is running: a claim whose pid is this process's is alive only if its run is one of them."""


def run_alive(run: Mapping[str, Any]) -> bool:
    """Whether a ``runs`` row is a run still working: not finished, its process alive when it is on this host, and
    its heartbeat younger than :data:`LEASE_S` (which also ends a run whose pid was reused or that hangs)."""
    if run["finished_at"]:
        return False
    keys = run.keys()
    host = run["host"] if "host" in keys else None
    pid = run["pid"] if "pid" in keys else None
    if host == socket.gethostname() and pid:
        if pid == os.getpid():
            return run["run_id"] in OPEN_RUNS
        if not process_alive(pid):
            return False
    beat = (run["heartbeat_at"] if "heartbeat_at" in keys else None) or run["started_at"]
    try:
        age = time.time() - datetime.fromisoformat(beat).timestamp()
    except (TypeError, ValueError):
        return False
    return age < LEASE_S
