"""The one worker pool: each task runs with its worker's state, a task past its time limit costs only its worker,
and busy workers die with their parent."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from concurrent.futures import TimeoutError as FutureTimeout

import psutil
import pytest

from gaitbench.solve.parallel import WorkerPool


def _remember(item: int, seen: list) -> tuple[int, int, int]:
    seen.append(item)
    return item, os.getpid(), len(seen)


def _sleep(seconds: float, state: object) -> float:
    time.sleep(seconds)
    return seconds


def test_tasks_keep_their_order_and_their_worker_s_state() -> None:
    with WorkerPool(2, state=list) as pool:
        results = pool.map(_remember, range(6))
    assert [item for item, _, _ in results] == list(range(6))
    for pid in {pid for _, pid, _ in results}:  # each worker's list grew with every task it ran
        counts = [count for _, worker, count in results if worker == pid]
        assert counts == list(range(1, len(counts) + 1))


def test_a_task_past_its_time_limit_loses_its_worker_and_the_pool_goes_on() -> None:
    with WorkerPool(1, state=list) as pool:
        with pytest.raises(FutureTimeout):
            pool.schedule(_sleep, 60.0, timeout=1.0).result()
        assert pool.schedule(_sleep, 0.0).result() == 0.0


def _report_and_hang(item: int, state: object) -> None:
    os.write(1, f"{os.getpid()}\n".encode())  # one write: two workers' lines must not interleave
    time.sleep(3600)


PARENT = """
import time
from test_parallel import _report_and_hang
from gaitbench.solve.parallel import WorkerPool

pool = WorkerPool(2, state=list, {options})
futures = [pool.schedule(_report_and_hang, item) for item in range(2)]
time.sleep(3600)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="parent-death signal: Linux only")
@pytest.mark.parametrize("options", ['start="fork"', 'start="spawn", die_with_parent=True'],
                         ids=["forked sections", "spawned case workers"])
def test_busy_workers_die_with_their_parent(options: str) -> None:
    """Forked (D&C's sections): a case stopped at its time limit must not leave its sectional workers behind, still
    solving (an idle worker would see its channel close and exit anyway). Spawned with ``die_with_parent`` (the
    local executor's case workers): a run killed from outside must not leave its cases solving on, unrecorded."""
    parent = subprocess.Popen([sys.executable, "-c", PARENT.format(options=options)], stdout=subprocess.PIPE,
                              text=True, env=os.environ | {"PYTHONPATH": os.pathsep.join(sys.path)})
    try:
        workers = [psutil.Process(int(parent.stdout.readline())) for _ in range(2)]
    finally:
        parent.kill()
        parent.wait()
    _, alive = psutil.wait_procs(workers, timeout=10)
    for worker in alive:
        worker.kill()
    assert not alive


def _timed(seconds: float, state: object) -> tuple[float, float]:
    started = time.monotonic()
    time.sleep(seconds)
    return started, time.monotonic()


@pytest.mark.parametrize("allowed", [1, 2])
def test_a_map_runs_no_more_tasks_at_once_than_its_width_allows(allowed: int) -> None:
    asked = []

    def width(unfinished: int) -> int:
        asked.append(unfinished)
        return allowed

    with WorkerPool(2, state=list) as pool:
        spans = pool.map(_timed, [0.3] * 4, width)
    running_at_each_start = [sum(start <= moment < stop for start, stop in spans) for moment, _ in spans]
    assert max(running_at_each_start) == allowed
    assert asked[0] == 4 and asked == sorted(asked, reverse=True)  # asked again as tasks end, fewer left each time
