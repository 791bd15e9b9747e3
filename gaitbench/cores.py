"""Idle cores: a machine-wide ledger of the cores gaitbench's walks are using, so that a walk can borrow the rest.

A suite on 2 workers keeps 2 cores busy until its last case, which then runs alone beside an idle core for as long
as it takes (at N = 200, hours of decrease and conquer). A walk solved on its own (`gaitbench solve`) leaves every
core but one idle. Decrease and conquer's sectional solves are independent, so a walk can spread them over the
cores nobody else is using, and give them back when another walk needs them; what it computes does not change.

The ledger is one lock file per core in a directory shared by every gaitbench process of a user on the machine
(:meth:`IdleCores.machine`). A process running a walk holds one (:meth:`IdleCores.occupy`); a walk that wants more
takes what is free (:meth:`Lease.hold`). Locks are ``flock`` locks on separately opened files, so they are per
holder (a thread, a process) and the kernel drops them when their holder dies: a killed worker leaves no core
taken. Only gaitbench's walks are counted; a machine busy with other work looks idle to the ledger. Without
``fcntl`` (Windows), or where the directory cannot be written, no core is ever free, and walks solve serially.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

try:
    import fcntl
except ImportError:  # Windows
    fcntl = None

CORES_DIR_ENV = "GAITBENCH_CORES_DIR"
"""Environment variable naming the ledger's directory (default: ``gaitbench-cores-<uid>`` in the temp directory)."""


class IdleCores:
    """The ledger of ``cores`` cores kept in ``directory``."""

    def __init__(self, directory: str | Path, cores: int) -> None:
        if cores < 1:
            raise ValueError(f"cores = {cores}: need at least one")
        self.directory = Path(directory)
        self.cores = cores

    @classmethod
    def machine(cls) -> IdleCores:
        """This machine's ledger: its cores (those this process may run on), in the user's shared directory."""
        default = Path(tempfile.gettempdir()) / f"gaitbench-cores-{os.getuid() if hasattr(os, 'getuid') else 0}"
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
        return cls(os.environ.get(CORES_DIR_ENV, default), cores)

    def lease(self) -> Lease:
        """An empty lease, to :meth:`Lease.hold` cores with."""
        return Lease(self)

    def occupy(self) -> Lease:
        """A lease on one core for this walk's own work, if one is free (a run with more jobs than cores finds
        none, and its walks then borrow none either)."""
        lease = Lease(self)
        lease.hold(1)
        return lease


class Lease:
    """The cores one holder has taken from an :class:`IdleCores` ledger; a context manager that gives them back."""

    def __init__(self, ledger: IdleCores) -> None:
        self.ledger = ledger
        self._held: dict[int, int] = {}  # core index -> open file descriptor holding its lock

    @property
    def count(self) -> int:
        return len(self._held)

    def hold(self, wanted: int) -> int:
        """Hold ``wanted`` cores if that many are free, else as many as are; give back any beyond ``wanted``.
        Returns how many are held."""
        wanted = max(0, min(wanted, self.ledger.cores))
        while self.count > wanted:
            self._give_back(max(self._held))
        if self.count < wanted and fcntl is not None:
            for core in range(self.ledger.cores):
                if self.count == wanted:
                    break
                if core not in self._held:
                    self._take(core)
        return self.count

    def release(self) -> None:
        """Give back every core held."""
        for core in list(self._held):
            self._give_back(core)

    def _take(self, core: int) -> None:
        try:
            if not self.ledger.directory.is_dir():  # made once; a stat, not a mkdir, as each section ends
                self.ledger.directory.mkdir(mode=0o700, parents=True, exist_ok=True)
            descriptor = os.open(self.ledger.directory / f"core-{core}.lock", os.O_RDWR | os.O_CREAT, 0o600)
        except OSError:  # a ledger that cannot be written lends no core: the walk solves serially
            return
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # held by another walk
            os.close(descriptor)
        else:
            self._held[core] = descriptor

    def _give_back(self, core: int) -> None:
        descriptor = self._held.pop(core)
        fcntl.flock(descriptor, fcntl.LOCK_UN)  # also for the forked children that share the descriptor
        os.close(descriptor)

    def __enter__(self) -> Lease:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.release()
