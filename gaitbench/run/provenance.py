"""Where a result came from: gaitbench's version and commit, the solver packages' versions, the machine.

Computed once per process; each case records the provenance of the process that ran it, since Dask workers
may be other machines with other installs.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import platform
import socket
import subprocess
from collections.abc import Sequence
from functools import lru_cache
from importlib.metadata import PackageNotFoundError, entry_points, version
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
        "cpu": cpu_model(),
        "vector_extensions": vector_extensions(),
        "packages": package_versions(),
    }


VECTOR_EXTENSIONS = ("AVX512F", "AVX2", "FMA3", "AVX", "SSE42", "ASIMD", "SVE")
"""The CPU's vector instruction sets that select different compiled kernels in the solvers' libraries (PIQP ships an
AVX-512 and an AVX2 build; OpenBLAS picks kernels by CPU), and so can change a result's last bits and, over a long
walk, its path: the downward slope at N = 130 walked at the same code on two machines differed from its fourth step's
back-up window on (docs/results.md, "Reproducing a result")."""


def cpu_model() -> str:
    """The processor's model name (Linux's /proc/cpuinfo), else what ``platform.processor()`` says."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as cpuinfo:
            for line in cpuinfo:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def vector_extensions() -> list[str]:
    """The :data:`VECTOR_EXTENSIONS` this CPU has, as NumPy's runtime dispatch detects them."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # NumPy moved its private module
        return []
    return [name for name in VECTOR_EXTENSIONS if features.get(name)]


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
    """What a walk's steps were solved by, for its checkpoint (:mod:`gaitbench.checkpoint`): gaitbench's
    version, a hash of the source that solves walks (the Python files of the core and of the built-in plugins, as
    they are on disk, committed or not) and the versions of the packages that can change a result.

    The source, not the commit: a commit that changes only documentation, tests, benchmarks or results keeps the
    fingerprint, so a walk stopped in flight (a session's end, a crash) resumes across it, while any change to the
    code that solves walks starts it again from step 1. The front ends that only show results (the command line,
    the reports and the reporter plugins, :data:`FRONT_ENDS`) are left out: a walk's worker never runs them.
    """
    from gaitbench._version import __version__

    digest = hashlib.sha256()
    for root in _source_roots():
        for path in sorted(root.rglob("*.py")):
            if path.relative_to(root).parts[0] in FRONT_ENDS:
                continue
            digest.update(path.relative_to(root.parent).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    digest.update(repr(sorted(package_versions().items())).encode())
    return f"{__version__} {digest.hexdigest()[:16]}"


def plugins_fingerprint(plugin_dirs: Sequence[str | Path]) -> str | None:
    """The plugins from outside gaitbench that a walk may be solved by, for its checkpoint beside
    :func:`code_fingerprint`: a hash of the plugin files (names and contents) of ``plugin_dirs`` and
    ``$GAITBENCH_PLUGINS_DIR`` (:func:`gaitbench.plugins.plugin_files`, as they are on disk) and of the name and
    version of every distribution
    other than gaitbench with entry points in its group; None when there are none, so a walk without such plugins
    keeps the fingerprint it had before they were counted."""
    from gaitbench.plugins import ENTRY_POINT_GROUP, plugin_files

    digest, counted = hashlib.sha256(), False
    for path in plugin_files(plugin_dirs):  # by file name, not path: a store and its plugins may move together
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
        counted = True
    distributions = {(point.dist.name, point.dist.version) for point in entry_points(group=ENTRY_POINT_GROUP)
                     if point.dist is not None and point.dist.name != "gaitbench"}
    for name, release in sorted(distributions):
        digest.update(f"{name}=={release}\0".encode())
        counted = True
    return digest.hexdigest()[:16] if counted else None


FRONT_ENDS = frozenset({"cli", "reports", "reporters"})
"""Sub-packages of ``gaitbench`` and ``plugins`` outside :func:`code_fingerprint`: they show what the walks gave (a
change to a progress line or a report's table should not send hours of solved steps back to step 1)."""


def _source_roots() -> list[Path]:
    """The directories of the ``gaitbench`` package and of the built-in plugins (``gaitbench_plugins``, the folder
    ``plugins/``), found without importing the plugins (the core imports none)."""
    roots = [Path(__file__).resolve().parents[1]]  # gaitbench/: this file is gaitbench/run/provenance.py
    spec = importlib.util.find_spec("gaitbench_plugins")
    if spec is not None and spec.submodule_search_locations:
        roots += [Path(location).resolve() for location in spec.submodule_search_locations]
    return roots


def _git(*args: str) -> bytes | None:
    """The output of a git command in the gaitbench checkout, or None outside one (or without git)."""
    source = Path(__file__).resolve().parents[2]  # the checkout: gaitbench/run/provenance.py is three levels down
    if not (source / ".git").exists():
        return None
    try:
        return subprocess.run(["git", "-C", str(source), *args], capture_output=True, check=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        return None
