"""Where a result came from: gaitbench's version and commit, the solver packages' versions, the machine.

Computed once per process; each case records the provenance of the process that ran it, since Dask workers
may be other machines with other installs.
"""

from __future__ import annotations

import hashlib
import os
import platform
import socket
import subprocess
from functools import lru_cache
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

PACKAGES = ("casadi", "numpy", "scipy", "pluggy", "qpsolvers", "osqp", "proxsuite", "clarabel", "daqp", "piqp",
            "highspy", "quadprog", "cyipopt-wheels", "unopy", "pyomo", "pyomo-ripopt", "pandas", "dask", "distributed")
"""The packages whose versions can change a result: the solvers and what they are built on."""


@lru_cache(maxsize=1)
def provenance() -> dict[str, Any]:
    from gaitbench._version import __version__

    return {
        "gaitbench": __version__,
        "git_commit": git_commit(),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "hostname": socket.gethostname(),
        "cpus": os.cpu_count(),
        "packages": package_versions(),
    }


def package_versions() -> dict[str, str | None]:
    versions: dict[str, str | None] = {}
    for package in PACKAGES:
        try:
            versions[package] = version(package)
        except PackageNotFoundError:
            versions[package] = None
    return versions


def git_commit() -> str | None:
    """The commit of the gaitbench source tree (``+dirty`` with uncommitted changes), or None outside a checkout."""
    commit = _git("rev-parse", "HEAD")
    dirty = _git("status", "--porcelain", "--untracked-files=no")
    if commit is None or dirty is None:
        return None
    return commit.decode().strip() + ("+dirty" if dirty.strip() else "")


@lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """What a walk's steps were solved by, for its checkpoint (:mod:`gaitbench.solve.checkpoint`): gaitbench's
    version, its commit, and a hash of any uncommitted change to tracked files; outside a checkout, the version."""
    from gaitbench._version import __version__

    commit, diff = _git("rev-parse", "HEAD"), _git("diff", "HEAD")
    if commit is None or diff is None:
        return __version__
    return f"{__version__} {commit.decode().strip()}" + (f"+{hashlib.sha256(diff).hexdigest()[:16]}" if diff else "")


def _git(*args: str) -> bytes | None:
    """The output of a git command in the gaitbench checkout, or None outside one (or without git)."""
    source = Path(__file__).resolve().parents[2]  # the checkout: gaitbench/run/provenance.py is three levels down
    if not (source / ".git").exists():
        return None
    try:
        return subprocess.run(["git", "-C", str(source), *args], capture_output=True, check=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        return None
