"""Where cases run: in this process, in a local pool of worker processes, or on a Dask cluster.

Every executor takes cases and yields their outcomes as they finish, so the runner records each at once.
The time limit per case is passed to the solver (so a slow solve ends with its own ``time_limit`` status) and,
outside the in-process executor, also enforced from outside: a case still running at 1.25 × its limit + 30 s
has its process stopped and is recorded as ``timeout``. A worker that dies takes only its case with it
(``crashed``, with the exit signal); the run goes on.
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import tempfile
from collections.abc import Iterable, Iterator
from concurrent.futures import TimeoutError as FutureTimeout
from concurrent.futures import as_completed
from pathlib import Path

from gaitbench.case import Case
from gaitbench.runner import CaseOutcome, failed_outcome, run_case

EXECUTORS = ("inprocess", "local", "dask")

DASK_ONLY_ENVIRONMENT = ("MALLOC_TRIM_THRESHOLD_",)
"""Variables a Dask nanny sets for its worker (``distributed.nanny.pre-spawn-environ``) that a case's child process
does not inherit. glibc trimming its heap at 64 kB lets Dask report a worker's memory, but it made the walks' many
small allocations 5–30 % slower (docs/performance.md, "Executors")."""


def hard_limit(case: Case) -> float | None:
    """Seconds after which a case's process is stopped: past the solver's own limit, with room for verification."""
    return None if case.time_limit_s is None else 1.25 * case.time_limit_s + 30.0


class InProcessExecutor:
    """Cases one after another in this process: for debugging and profiling. The time limit reaches the solver
    only; nothing can stop a case that hangs inside compiled code, and a crash ends the run (after every
    finished case has been recorded)."""

    name = "inprocess"
    jobs = 1

    def run(self, cases: Iterable[Case]) -> Iterator[CaseOutcome]:
        for case in cases:
            yield run_case(case)


class LocalPoolExecutor:
    """A pool of ``jobs`` long-lived worker processes (Pebble), which can stop a case and replace its worker."""

    name = "local"

    def __init__(self, jobs: int = 1) -> None:
        if jobs < 1:
            raise ValueError(f"jobs = {jobs}: need at least one worker")
        self.jobs = jobs

    def run(self, cases: Iterable[Case]) -> Iterator[CaseOutcome]:
        import multiprocessing

        from pebble import ProcessExpired, ProcessPool

        # spawn, not fork: the parent has threads (progress display, SQLite), which fork would copy mid-state
        pool = ProcessPool(max_workers=self.jobs, context=multiprocessing.get_context("spawn"))
        try:
            futures = {pool.schedule(run_case, (case,), timeout=hard_limit(case)): case for case in cases}
            for future in as_completed(futures):
                case = futures[future]
                try:
                    yield future.result()
                except FutureTimeout:
                    yield failed_outcome(case, "timeout", _timeout_message(case), hard_limit(case) or 0.0)
                except ProcessExpired as error:
                    yield failed_outcome(case, "crashed", _exit_message(error.exitcode))
                except Exception as error:  # the outcome could not be sent back (e.g. unpicklable)
                    yield failed_outcome(case, "error", f"{type(error).__name__}: {error}")
        finally:
            pool.stop()
            pool.join()


class DaskExecutor:
    """Cases as tasks on a Dask cluster: an existing one at ``scheduler``, or a local one of ``jobs`` workers.

    Each task runs its case in a child process of the Dask worker (:func:`run_case_isolated`), so a case that
    crashes or hangs costs that case and not the worker; the workers need gaitbench and the suite's plugins
    installed, and plugin directories at the same paths.
    """

    name = "dask"

    def __init__(self, scheduler: str | None = None, jobs: int = 1) -> None:
        self.scheduler = scheduler
        self.jobs = jobs

    def run(self, cases: Iterable[Case]) -> Iterator[CaseOutcome]:
        from distributed import Client, LocalCluster
        from distributed import as_completed as dask_completed

        cluster = None
        if self.scheduler is None:
            cluster = LocalCluster(n_workers=self.jobs, threads_per_worker=1, processes=True,
                                   dashboard_address=None)
        try:
            with Client(self.scheduler or cluster, timeout="30s") as client:
                futures = {client.submit(run_case_isolated, case, key=f"case-{case.key}", pure=False): case
                           for case in cases}
                for future in dask_completed(futures):
                    case = futures[future]
                    try:
                        yield future.result()
                    except Exception as error:  # the worker was lost (KilledWorker) or the task failed
                        yield failed_outcome(case, "crashed", f"Dask task failed: {type(error).__name__}: {error}")
        finally:
            if cluster is not None:
                cluster.close()


def run_case_isolated(case: Case) -> CaseOutcome:
    """Run a case in a fresh Python process, stopping it at :func:`hard_limit`; a crash becomes ``crashed``.

    A subprocess rather than multiprocessing because Dask's worker processes are daemonic and may not fork
    multiprocessing children.
    """
    with tempfile.TemporaryDirectory(prefix="gaitbench-case-") as directory:
        given, returned = Path(directory) / "case.pickle", Path(directory) / "outcome.pickle"
        given.write_bytes(pickle.dumps(case))
        limit = hard_limit(case)
        try:
            child = subprocess.run([sys.executable, "-m", "gaitbench.executors", str(given), str(returned)],
                                   capture_output=True, text=True, timeout=limit, env=_child_environment())
        except subprocess.TimeoutExpired:
            return failed_outcome(case, "timeout", _timeout_message(case), limit or 0.0)
        if child.returncode != 0 or not returned.exists():
            detail = child.stderr.strip().splitlines()[-1:] if child.stderr else []
            return failed_outcome(case, "crashed", _exit_message(child.returncode) + "".join(f": {line}"
                                                                                          for line in detail))
        return pickle.loads(returned.read_bytes())


def _child_environment() -> dict[str, str]:
    return {name: value for name, value in os.environ.items() if name not in DASK_ONLY_ENVIRONMENT}


def _timeout_message(case: Case) -> str:
    return (f"still running {hard_limit(case):.0f} s after it started (time limit {case.time_limit_s:g} s); "
            "its worker was stopped")


def _exit_message(code: int | None) -> str:
    if code is not None and code < 0:
        try:
            return f"worker process killed by {signal.Signals(-code).name}"
        except ValueError:
            pass
    return f"worker process exited with status {code}"


def _child_main(given: str, returned: str) -> None:
    case = pickle.loads(Path(given).read_bytes())
    Path(returned).write_bytes(pickle.dumps(run_case(case)))


if __name__ == "__main__":
    _child_main(*sys.argv[1:3])
