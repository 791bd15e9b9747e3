"""The process pools a Dask worker runs its cases and fanned-out sections in (:mod:`gaitbench.run.executors`,
:mod:`gaitbench.run.dask_fan_out`): spawned processes that die with the worker, started from one long-lived thread.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

from gaitbench.solve.parallel import WorkerPool

DASK_ONLY_ENVIRONMENT = ("MALLOC_TRIM_THRESHOLD_",)
"""Variables a Dask nanny sets for its worker (``distributed.nanny.pre-spawn-environ``) that the process running
its cases does not inherit. glibc trimming its heap at 64 kB lets Dask report a worker's memory, but it made the
walks' many small allocations 5–30 % slower (docs/performance.md, "Executors")."""


_POOL_STARTER = ThreadPoolExecutor(1, thread_name_prefix="gaitbench-pool-starter")
"""The thread that starts the Dask worker's pools: it lives as long as the worker, and a pool's processes die with
the thread that started them (``die_with_parent``), while a Dask worker's own threads come and go (a task that
secedes is replaced by a new thread, and one of the two ends when it rejoins)."""


def spawned_pool(workers: int, state) -> WorkerPool:
    """A pool of spawned processes for a Dask worker's cases or sections, dying with it, without the environment
    only the Dask worker needs (:data:`DASK_ONLY_ENVIRONMENT`); started from :data:`_POOL_STARTER`."""
    for name in DASK_ONLY_ENVIRONMENT:  # read by glibc at start-up: the Dask worker keeps its setting
        os.environ.pop(name, None)

    def started() -> WorkerPool:
        pool = WorkerPool(workers, state=state, start="spawn", die_with_parent=True)
        pool.start()
        return pool

    return _POOL_STARTER.submit(started).result()
