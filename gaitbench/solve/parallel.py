"""Worker processes: the one place gaitbench starts a pool of them (Pebble).

Two users, one mechanism. The local executor runs a suite's cases in spawned workers, each case with a time limit
past which its worker is stopped and replaced (:mod:`gaitbench.run.executors`). Decrease-and-conquer solves a step's
sectional problems in forked workers, which inherit the built NLPs and solvers instead of receiving them (CasADi
functions do not pickle). Each worker holds one state object for its lifetime — a case worker's
:class:`~gaitbench.problem.build_cache.BuildCache`, the walk's sectional problems — and every task is called with
it, after its item.
Pebble's workers are not daemonic, so a case worker may start a pool of its own.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, Future, wait
from typing import Generic, TypeVar

from pebble import ProcessExpired, ProcessPool

__all__ = ["ProcessExpired", "WorkerPool"]

State = TypeVar("State")
Item = TypeVar("Item")
Result = TypeVar("Result")

_PR_SET_PDEATHSIG = 1
"""prctl(2) option: the signal this process gets when the thread that started it ends."""


class WorkerPool(Generic[State]):
    """``workers`` long-lived processes, started by ``start`` ("spawn" or "fork"), each holding ``state()``.

    ``state`` is called once in each worker as it starts (spawned workers receive it pickled, so a class or a
    module-level function; forked ones inherit it, so any callable). With ``die_with_parent`` (the default for
    forked workers) the workers die with the process that started them (on Linux): a case stopped at its time limit
    leaves no sectional workers solving on, and a run killed from outside leaves no case workers solving on, which
    nothing would record (and whose walks would write the same step checkpoints as the run that resumes them).
    """

    def __init__(self, workers: int, state: Callable[[], State], start: str = "spawn",
                 die_with_parent: bool | None = None) -> None:
        if workers < 1:
            raise ValueError(f"workers = {workers}: need at least one")
        if start not in multiprocessing.get_all_start_methods():
            raise ValueError(f"the {start!r} start method is not available on this platform")
        self.workers = workers
        self._pool = ProcessPool(max_workers=workers, context=multiprocessing.get_context(start),
                                 initializer=_worker_started,
                                 initargs=(state, start == "fork" if die_with_parent is None else die_with_parent,
                                           os.getpid()))

    def start(self) -> None:
        """Start the workers now, from this thread (else the first :meth:`schedule` starts them, from its thread):
        with ``die_with_parent`` they die with the thread that started them."""
        self._pool.schedule(_call, (_nothing, None))

    def schedule(self, task: Callable[[Item, State], Result], item: Item,
                 timeout: float | None = None) -> Future[Result]:
        """``task(item, state)`` in a free worker. Past ``timeout`` seconds the worker is stopped (and replaced)
        and the future raises ``TimeoutError``; a worker that dies makes it raise :class:`ProcessExpired`."""
        return self._pool.schedule(_call, (task, item), timeout=timeout)

    def map(self, task: Callable[[Item, State], Result], items: Iterable[Item],
            width: Callable[[int], int] | None = None) -> list[Result]:
        """``task(item, state)`` for every item, spread over the workers; the results in the items' order.

        ``width(unfinished)``, asked again each time a task ends, says how many tasks may run at once (at least one)
        while ``unfinished`` items are not done yet; without it, all the workers run.
        """
        if width is None:
            futures = [self.schedule(task, item) for item in items]
            return [future.result() for future in futures]
        items = list(items)
        results: list[Result] = [None] * len(items)  # type: ignore[list-item]
        running: dict[Future[Result], int] = {}
        started = 0
        while started < len(items) or running:
            allowed = max(1, width(len(items) - started + len(running)))
            while started < len(items) and len(running) < allowed:
                running[self.schedule(task, items[started])] = started
                started += 1
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in done:
                results[running.pop(future)] = future.result()
        return results

    def close(self) -> None:
        """Stop every worker, busy or not."""
        self._pool.stop()
        self._pool.join()

    def __enter__(self) -> WorkerPool[State]:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


_STATE: object = None
"""The state of this process when it is a pool's worker: set once as it starts, for :func:`_call`."""


def _nothing(item: object, state: object) -> None:
    return None


def _call(task: Callable[[Item, object], Result], item: Item) -> Result:
    return task(item, _STATE)


def _worker_started(state: Callable[[], object], die_with_parent: bool, parent: int) -> None:
    """Pool worker initializer: die with the parent (if asked), ignore a SIGTERM while exiting, build the state.

    Pebble stops a pool by closing its channels (idle workers then exit on their own) and sending each worker
    SIGTERM, whose handler ends the process at once (``os._exit``). Landing in the middle of a worker's own exit,
    it cut the multiprocessing finalizers short between unlinking a semaphore that a plugin had created (pyomo
    makes one on import) and telling the resource tracker, which then warned of "leaked semaphore objects" after
    clean runs. A worker already exiting finishes by itself (Pebble kills it if it takes more than 3 s); any
    other SIGTERM (a case past its time limit) still ends it at once.
    """
    global _STATE
    if die_with_parent and sys.platform.startswith("linux"):
        # An idle worker exits when its parent's end of the channel closes, a busy one only after its task: without
        # this, a case stopped at its time limit would leave its sectional workers solving on.
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
        if os.getppid() != parent:  # the parent died before the signal was asked for
            os._exit(1)
    from multiprocessing import util

    stop_now = signal.getsignal(signal.SIGTERM)

    def on_sigterm(signum: int, frame) -> None:
        if util.is_exiting():
            return
        if callable(stop_now):
            stop_now(signum, frame)
        else:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            os.kill(os.getpid(), signal.SIGTERM)

    signal.signal(signal.SIGTERM, on_sigterm)
    _STATE = state()
