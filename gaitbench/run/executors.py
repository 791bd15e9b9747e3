"""Where cases run: in this process, in a local pool of worker processes, or on a Dask cluster.

Every executor takes cases and yields their outcomes as they finish, so the runner records each at once. It asks
for the next case only when it can start it (a worker is free), because taking a case is what claims it for this
run in the store (:func:`gaitbench.run.runner.run_suite`): runs sharing a store then split the cases, largest first.
The time limit per case is passed to the solver (so a slow solve ends with its own ``time_limit`` status) and,
outside the in-process executor, also enforced from outside: a case still running at 1.25 × its limit + 30 s
has its process stopped and is recorded as ``timeout``. A worker that dies takes only its case with it
(``crashed``, with the exit signal); the run goes on.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import select
import signal
import subprocess
import sys
import tempfile
import threading
from collections.abc import Iterable, Iterator
from concurrent.futures import TimeoutError as FutureTimeout
from pathlib import Path

from gaitbench.problem.build_cache import BuildCache
from gaitbench.run.case import Case
from gaitbench.run.runner import CaseOutcome, failed_outcome, run_case
from gaitbench.solve.parallel import ProcessExpired, WorkerPool

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
        builds = BuildCache()  # this process's, for the run
        for case in cases:
            yield run_case(case, builds)


class LocalPoolExecutor:
    """A pool of ``jobs`` long-lived worker processes (:class:`~gaitbench.solve.parallel.WorkerPool`), which can
    stop a case and replace its worker. Each worker keeps what its walks build for its next cases (a
    :class:`~gaitbench.problem.build_cache.BuildCache`)."""

    name = "local"

    def __init__(self, jobs: int = 1) -> None:
        if jobs < 1:
            raise ValueError(f"jobs = {jobs}: need at least one worker")
        self.jobs = jobs

    def run(self, cases: Iterable[Case]) -> Iterator[CaseOutcome]:
        from concurrent.futures import FIRST_COMPLETED, wait

        # spawn, not fork: the parent has threads (progress display, SQLite), which fork would copy mid-state
        with WorkerPool(self.jobs, state=BuildCache, start="spawn") as pool:
            upcoming = iter(cases)
            running = {}

            def fill() -> None:
                while len(running) < self.jobs and (case := next(upcoming, None)) is not None:
                    running[pool.schedule(run_case, case, timeout=hard_limit(case))] = case

            fill()
            while running:
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                finished = [(future, running.pop(future)) for future in done]
                fill()  # the freed workers start their next cases while these are recorded
                for future, case in finished:
                    yield _pool_outcome(future, case)


def _pool_outcome(future, case: Case) -> CaseOutcome:
    try:
        return future.result()
    except FutureTimeout:
        return failed_outcome(case, "timeout", _timeout_message(case), hard_limit(case) or 0.0)
    except ProcessExpired as error:
        return failed_outcome(case, "crashed", _exit_message(error.exitcode))
    except Exception as error:  # the outcome could not be sent back (e.g. unpicklable)
        return failed_outcome(case, "error", f"{type(error).__name__}: {error}")


class DaskExecutor:
    """Cases as tasks on a Dask cluster: an existing one at ``scheduler``, or a local one of ``jobs`` workers.

    Each task runs its case in a long-lived child process of the Dask worker (:class:`CaseServer`), so a case that
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
                upcoming = iter(cases)
                running = {}
                completed = dask_completed()

                def fill() -> None:  # as many cases as the cluster has threads now (workers may come and go)
                    slots = max(self.jobs, sum(client.nthreads().values()))
                    while len(running) < slots and (case := next(upcoming, None)) is not None:
                        future = client.submit(run_case_served, case, key=f"case-{case.key}", pure=False)
                        running[future] = case
                        completed.add(future)

                fill()
                for future in completed:
                    case = running.pop(future)
                    fill()
                    try:
                        yield future.result()
                    except Exception as error:  # the worker was lost (KilledWorker) or the task failed
                        yield failed_outcome(case, "crashed", f"Dask task failed: {type(error).__name__}: {error}")
        finally:
            if cluster is not None:
                cluster.close()


class CaseServer:
    """A long-lived child process that runs one Dask worker's cases one at a time, as a local-pool worker does.

    A subprocess rather than a :class:`~gaitbench.solve.parallel.WorkerPool` because Dask's worker processes are
    daemonic (unless the cluster is configured otherwise) and may not have multiprocessing children, and because the
    child must not inherit :data:`DASK_ONLY_ENVIRONMENT`. The child keeps what a walk builds (sectional NLPs in its
    :class:`~gaitbench.problem.build_cache.BuildCache`, derived interval functions) for the worker's next
    cases, and Python starts once per worker, not once per case (docs/performance.md, "Executors").
    A case that crashes or outlives :func:`hard_limit` costs only the child, which the next case replaces.
    """

    def __init__(self) -> None:
        self._child: subprocess.Popen | None = None
        self._replies = -1  # read end of the pipe on which the child reports each finished case
        self._errors = tempfile.TemporaryFile()  # the child's stderr during the current case, for a crash's last words

    @property
    def pid(self) -> int | None:
        return None if self._child is None else self._child.pid

    def run(self, case: Case) -> CaseOutcome:
        with tempfile.TemporaryDirectory(prefix="gaitbench-case-") as directory:
            given, returned = Path(directory) / "case.pickle", Path(directory) / "outcome.pickle"
            given.write_bytes(pickle.dumps(case))
            child = self._running()
            os.ftruncate(self._errors.fileno(), 0)  # the child writes at the shared offset, now 0 again
            os.lseek(self._errors.fileno(), 0, os.SEEK_SET)
            try:
                child.stdin.write(f"{given}\t{returned}\n")
                child.stdin.flush()
            except BrokenPipeError:  # it died after its last case: the read below sees the end of its pipe
                pass
            limit = hard_limit(case)
            if not select.select([self._replies], [], [], limit)[0]:
                self.stop()
                return failed_outcome(case, "timeout", _timeout_message(case), limit or 0.0)
            if not os.read(self._replies, 1) or not returned.exists():  # the child died with the case
                code = child.wait()
                errors = os.pread(self._errors.fileno(), os.fstat(self._errors.fileno()).st_size, 0)
                detail = errors.decode(errors="replace").strip().splitlines()[-1:]
                self.stop()
                return failed_outcome(case, "crashed", _exit_message(code) + "".join(f": {line}" for line in detail))
            return pickle.loads(returned.read_bytes())

    def stop(self) -> None:
        """End the child (killing it if it is still busy); the next case starts a new one."""
        if self._child is not None:
            self._child.kill()
            self._child.wait()
            with contextlib.suppress(BrokenPipeError):
                self._child.stdin.close()
            os.close(self._replies)
            self._child = None

    def _running(self) -> subprocess.Popen:
        if self._child is not None and self._child.poll() is not None:
            self.stop()
        if self._child is None:
            self._replies, reply_end = os.pipe()
            self._child = subprocess.Popen([sys.executable, "-m", "gaitbench.run.executors", str(reply_end)],
                                           stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=self._errors,
                                           text=True, env=_child_environment(), pass_fds=(reply_end,))
            os.close(reply_end)
        return self._child


_SERVERS = threading.local()


def run_case_served(case: Case) -> CaseOutcome:
    """The Dask task: ``case`` run by this worker thread's :class:`CaseServer`."""
    if not hasattr(_SERVERS, "server"):
        _SERVERS.server = CaseServer()
    return _SERVERS.server.run(case)


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


def _serve(reply_fd: int) -> None:
    """The child's loop: for each line "case path<TAB>outcome path" on stdin, run the case, write its outcome, and
    report on ``reply_fd``. It ends when its server closes stdin or kills it."""
    builds = BuildCache()
    for line in sys.stdin:
        given, returned = line.rstrip("\n").split("\t")
        case = pickle.loads(Path(given).read_bytes())
        Path(returned).write_bytes(pickle.dumps(run_case(case, builds)))
        os.write(reply_fd, b"\n")


if __name__ == "__main__":
    _serve(int(sys.argv[1]))
