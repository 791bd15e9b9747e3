"""Where cases run: in this process, in a local pool of worker processes, or on a Dask cluster.

Every executor takes cases and yields their outcomes as they finish, so the runner records each at once. It asks
for the next case only when it can start it (a worker is free), because taking a case is what claims it for this
run in the store (:func:`gaitbench.run.runner.run_suite`): runs sharing a store then split the cases, largest first.
A quarter of the case's time limit is each solve's own limit (so a slow solve ends with its own ``time_limit``
status and the next rung of the retry ladder gets the rest), and the whole limit is the walk's deadline, after which
no solve starts. Outside the in-process executor the limit is also enforced from outside: a case still running at
1.25 × its limit + 30 s has its process stopped and is recorded as ``timeout``. A worker that dies takes only its
case with it (``crashed``, with the exit signal); the run goes on. On Dask, a case whose Dask worker dies is run
again on another worker first (:class:`DaskExecutor`).
"""

from __future__ import annotations

import multiprocessing
import signal
import threading
from collections.abc import Iterable, Iterator
from concurrent.futures import TimeoutError as FutureTimeout

from gaitbench.problem.build_cache import BuildCache
from gaitbench.run.case import Case
from gaitbench.run.dask_fan_out import DaskFanOut
from gaitbench.run.dask_pools import spawned_pool
from gaitbench.run.runner import CaseOutcome, failed_outcome, run_case
from gaitbench.solve.parallel import ProcessExpired, WorkerPool

EXECUTORS = ("inprocess", "local", "dask")

def hard_limit(case: Case) -> float | None:
    """Seconds after which a case's process is stopped (:attr:`Case.hard_limit_s`)."""
    return case.hard_limit_s


class InProcessExecutor:
    """Cases one after another in this process: for debugging and profiling. The time limit reaches the solver
    only; nothing can stop a case that hangs inside compiled code, and a crash ends the run (after every
    finished case has been recorded)."""

    name = "inprocess"
    jobs = 1
    local_files = True
    """Its workers write where the runner does: the walks keep step checkpoints in the store."""

    def run(self, cases: Iterable[Case]) -> Iterator[CaseOutcome]:
        builds = BuildCache()  # this process's, for the run
        for case in cases:
            yield run_case(case, builds)


class LocalPoolExecutor:
    """A pool of ``jobs`` long-lived worker processes (:class:`~gaitbench.solve.parallel.WorkerPool`), which can
    stop a case and replace its worker. Each worker keeps what its walks build for its next cases (a
    :class:`~gaitbench.problem.build_cache.BuildCache`)."""

    name = "local"
    local_files = True

    def __init__(self, jobs: int = 1) -> None:
        if jobs < 1:
            raise ValueError(f"jobs = {jobs}: need at least one worker")
        self.jobs = jobs

    def run(self, cases: Iterable[Case]) -> Iterator[CaseOutcome]:
        from concurrent.futures import FIRST_COMPLETED, wait

        # spawn, not fork: the parent has threads (progress display, SQLite), which fork would copy mid-state
        with WorkerPool(self.jobs, state=BuildCache, start="spawn", die_with_parent=True) as pool:
            upcoming = iter(cases)
            running = {}

            def fill() -> None:
                while len(running) < self.jobs and (case := next(upcoming, None)) is not None:
                    running[pool.schedule(run_case, case, timeout=hard_limit(case))] = case

            fill()
            while running:
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                finished = [(future, running.pop(future)) for future in done]
                try:
                    fill()  # the freed workers start their next cases while these are recorded
                finally:  # taking a case failed (the store): the finished outcomes go first
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

    Each Dask worker runs each case in a one-process :class:`~gaitbench.solve.parallel.WorkerPool` of its own, as
    the local executor does, so a case that crashes or hangs costs that case and not the Dask worker, and the pool's
    process keeps what its walks build for the next case; it dies with its Dask worker. That process is a child of
    the Dask worker, which Python allows only of processes that are not daemonic. A nanny makes its worker daemonic
    unless ``distributed.worker.daemon`` is false, and reads that setting each time it (re)starts the worker: the
    local cluster's nannies run in this process, which holds the setting false for the cluster's whole life; the
    workers of an existing cluster need it where they start (:data:`DAEMONIC_FIX`). A decrease-and-conquer case
    fans its sectional solves out over the whole cluster (:mod:`gaitbench.run.dask_fan_out`).

    A case whose worker dies is run again on another worker by the scheduler, up to its
    ``distributed.scheduler.allowed-failures`` (3 by default) deaths; after that it is recorded as ``crashed`` with
    the cause "worker died". The workers need gaitbench and the suite's plugins installed, and plugin directories
    at the same paths.
    """

    name = "dask"
    fans_out = True
    """A case's walk may spread its independent solves over every worker (:mod:`gaitbench.run.dask_fan_out`), so
    a local cluster keeps its ``jobs`` workers however few cases there are."""

    def __init__(self, scheduler: str | None = None, jobs: int = 1) -> None:
        self.scheduler = scheduler
        self.jobs = jobs

    @property
    def local_files(self) -> bool:
        """Only a local cluster's workers surely see the store's directory; a remote cluster's walks keep no step
        checkpoints."""
        return self.scheduler is None

    def run(self, cases: Iterable[Case]) -> Iterator[CaseOutcome]:
        import dask
        from distributed import Client, LocalCluster
        from distributed import as_completed as dask_completed

        with dask.config.set({DAEMON_SETTING: False}):  # read by the local nannies at every start of a worker
            cluster = None
            if self.scheduler is None:
                cluster = LocalCluster(n_workers=self.jobs, threads_per_worker=1, processes=True,
                                       dashboard_address=None)
            try:
                with Client(self.scheduler or cluster, timeout="30s") as client:
                    daemonic = [address for address, flag in client.run(_daemonic).items() if flag]
                    if daemonic:
                        raise ExecutorError(_daemonic_message(daemonic))
                    upcoming = iter(cases)
                    running = {}
                    completed = dask_completed()

                    def fill() -> None:  # as many cases as the cluster has threads now (workers come and go)
                        slots = max(self.jobs, sum(client.nthreads().values()))
                        while len(running) < slots and (case := next(upcoming, None)) is not None:
                            future = client.submit(run_case_pooled, case, key=f"case-{case.key}", pure=False)
                            running[future] = case
                            completed.add(future)

                    fill()
                    for future in completed:
                        case = running.pop(future)
                        try:
                            fill()
                        finally:  # taking a case failed (the store): the finished outcome goes first
                            yield _dask_outcome(future, case)
            except OSError as error:  # the scheduler unreachable or lost (distributed's CommClosedError, timeouts)
                where = f"the Dask scheduler at {self.scheduler}" if self.scheduler else "the local Dask cluster"
                raise ExecutorError(f"lost {where} ({type(error).__name__}: {error}); the cases finished before are "
                                    "stored: run again with --resume once it is reachable") from None
            finally:
                if cluster is not None:
                    cluster.close()


DAEMON_SETTING = "distributed.worker.daemon"
"""The Dask setting whose value a nanny gives its worker's daemon flag: false, the worker may start the process its
cases run in."""

DAEMONIC_FIX = ("start the workers with DASK_DISTRIBUTED__WORKER__DAEMON=False in the environment of `dask worker` "
                "(or distributed.worker.daemon: false in its Dask configuration), or with `dask worker --no-nanny`")
"""How to start the workers of an existing cluster so that they can run cases, restarts included."""


def _dask_outcome(future, case: Case) -> CaseOutcome:
    """The outcome a Dask task sent back; a task whose workers all died is ``crashed`` ("worker died")."""
    from distributed.scheduler import KilledWorker

    try:
        return future.result()
    except KilledWorker as error:
        return failed_outcome(case, "crashed", f"worker died: the {error.allowed_failures + 1} Dask workers that "
                              "ran this case each died while running it (distributed.scheduler.allowed-failures = "
                              f"{error.allowed_failures})")
    except Exception as error:  # the task could not be run or its result not sent back
        return failed_outcome(case, "error", f"Dask task failed: {type(error).__name__}: {error}")


class ExecutorError(Exception):
    """Cases cannot run where they were sent; the message says how to fix it."""


_IDLE_CASE_POOLS: list[WorkerPool] = []
"""This Dask worker's one-process case pools not running a case now; each keeps its process's builds for the next."""
_POOL_LOCK = threading.Lock()
def run_case_pooled(case: Case) -> CaseOutcome:
    """The Dask task: ``case`` run in a one-process pool of this Dask worker's, stopped past :func:`hard_limit`.

    On a Dask worker the walk may fan its sections out over the cluster (:mod:`gaitbench.run.dask_fan_out`), and
    this task secedes from the worker's threads while it waits: its thread is then free for sections, its own
    case's or another's, instead of idling while they queue behind it."""
    from distributed import get_worker, rejoin, secede

    try:
        worker = get_worker()
    except ValueError:  # called outside a Dask worker (tests): no cluster to fan out to
        worker = None
    if multiprocessing.current_process().daemon:  # a worker of an existing cluster that joined after the check
        return failed_outcome(case, "error", _daemonic_message([worker.address if worker else "?"]))
    with _POOL_LOCK:
        pool = _IDLE_CASE_POOLS.pop() if _IDLE_CASE_POOLS else None
    if pool is None:
        # dies with the Dask worker: a case whose worker was killed is run again elsewhere, not twice at once
        pool = spawned_pool(1, BuildCache)
    try:
        fan_out = None if worker is None else DaskFanOut(worker.scheduler.address, case)
        future = pool.schedule(_run_case_fanned_out, (case, fan_out), timeout=hard_limit(case))
        if worker is None:
            return _pool_outcome(future, case)
        secede()
        try:
            return _pool_outcome(future, case)
        finally:
            rejoin()
    finally:
        with _POOL_LOCK:
            _IDLE_CASE_POOLS.append(pool)


def _run_case_fanned_out(work: tuple[Case, DaskFanOut | None], builds: BuildCache) -> CaseOutcome:
    case, fan_out = work
    return run_case(case, builds, fan_out)


def _daemonic() -> bool:
    return multiprocessing.current_process().daemon


def _daemonic_message(workers: list[str]) -> str:
    return (f"Dask worker(s) {', '.join(workers)} are daemonic, and a daemonic process may not start the process "
            f"each case runs in; {DAEMONIC_FIX}")


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
