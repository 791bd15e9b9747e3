"""A case's fanned-out solves as tasks on the Dask cluster that runs the case (:mod:`gaitbench.fan_out`).

The case runs in a child process of its Dask worker (:func:`gaitbench.run.executors.run_case_pooled`). That process
connects a client of its own to the cluster's scheduler and submits the walk's items as tasks, which the scheduler
places on any worker with a free thread, its own included: the case's Dask task *secedes* from its worker's threads
while its process walks, so a cluster whose every thread holds a case still runs their sections (a task that waits
for tasks while holding its thread would deadlock a full cluster).

On a worker an item runs in a spawned process of that Dask worker's *section pool* (as many processes as the worker
has threads): away from the nanny's ``MALLOC_TRIM_THRESHOLD_`` as the cases are, and a crash costs a section
process, not the worker. Each such process keeps what the walks' items need (:class:`~gaitbench.fan_out.WorkerStates`,
made from the case's problem rebuilt there, and a :class:`~gaitbench.problem.build_cache.BuildCache` shared by the
walks it serves), so a walk's NLPs are built once per process, not shipped, and not built once per item.

A section whose Dask worker dies is run again on another worker, as a case is (``allowed-failures``); a section
whose process dies, or that the cluster cannot run, fails its walk's step with :class:`~gaitbench.fan_out.FanOutError`,
which the runner records as the case's error.
"""

from __future__ import annotations

import itertools
import os
import threading
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from gaitbench.fan_out import FanOutError, WorkerStates
from gaitbench.problem.build_cache import BuildCache
from gaitbench.run.case import Case
from gaitbench.run.dask_pools import spawned_pool

if TYPE_CHECKING:
    from gaitbench.contracts import WalkProblem
    from gaitbench.solve.parallel import WorkerPool

_CLIENTS: dict[str, Any] = {}
"""This process's client of each scheduler it fanned out to: a case process serves many cases, connected once."""

_MAPS = itertools.count()


class DaskFanOut:
    """The :class:`~gaitbench.fan_out.FanOut` of ``case``, run on the Dask cluster at ``scheduler``."""

    def __init__(self, scheduler: str, case: Case) -> None:
        self.scheduler = scheduler
        self.case = case

    def map(self, task: Callable[[Any, Any], Any], items: Sequence[Any],
            state: Callable[[WalkProblem], Any]) -> list[Any]:
        from distributed.scheduler import KilledWorker

        client = _client(self.scheduler)
        batch = f"fan-out-{self.case.key}-{os.getpid()}-{next(_MAPS)}"
        futures = client.map(run_item, items, key=[f"{batch}-{index}" for index in range(len(items))], pure=False,
                             case=self.case, task=task, state=state)
        try:
            return client.gather(futures)
        except BaseException as error:
            client.cancel(futures)  # a failed map leaves nothing running for it
            if isinstance(error, KilledWorker):
                raise FanOutError(f"a fanned-out task's Dask workers all died while running it ({error})") from None
            raise


def _client(scheduler: str):
    from distributed import Client

    if scheduler not in _CLIENTS:
        _CLIENTS[scheduler] = Client(scheduler, timeout="30s", set_as_default=False)
    return _CLIENTS[scheduler]


def run_item(item: Any, case: Case, task: Callable[[Any, Any], Any], state: Callable[[WalkProblem], Any]) -> Any:
    """The Dask task of one fanned-out item: ``task(item, state)`` in this Dask worker's section pool, its process
    stopped (and replaced) past the case's hard limit, as the case's own would be."""
    from concurrent.futures import TimeoutError as FutureTimeout

    from gaitbench.solve.parallel import ProcessExpired

    future = _section_pool().schedule(_run_in_worker, (item, case, task, state), timeout=case.hard_limit_s)
    try:
        return future.result()
    except ProcessExpired as error:
        raise FanOutError(f"the section process of case {case.key} died (exit status {error.exitcode})") from None
    except FutureTimeout:
        raise FanOutError(f"a section of case {case.key} still ran {case.hard_limit_s:.0f} s after it started; "
                          "its process was stopped") from None


_POOL_LOCK = threading.Lock()
_POOL: list[WorkerPool] = []


def _section_pool() -> WorkerPool:
    """This Dask worker's section pool, started by its first fanned-out task: a process per worker thread."""
    with _POOL_LOCK:
        if not _POOL:
            from distributed import get_worker


            _POOL.append(spawned_pool(get_worker().state.nthreads, SectionProcess))
        return _POOL[0]


class SectionProcess:
    """What a section-pool process keeps: the walks' states and the builds they share."""

    def __init__(self) -> None:
        self.builds = BuildCache()
        self.states = WorkerStates()


def _run_in_worker(work: tuple[Any, Case, Callable[[Any, Any], Any], Callable[[WalkProblem], Any]],
                   process: SectionProcess) -> Any:
    from gaitbench.run.runner import case_walk

    item, case, task, state = work
    held = process.states.get(case.key, state, lambda: case_walk(case, builds=process.builds)[1])
    return task(item, held)
