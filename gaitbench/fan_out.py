"""Fan-out: a walk's independent solves mapped over the run's workers, wherever the run's executor has them.

Decrease and conquer solves N−3 sectional problems per step that do not depend on each other. On one machine it
spreads them over forked processes that inherit its built problems (:class:`gaitbench.solve.parallel.WorkerPool`,
with the idle cores of :mod:`gaitbench.cores`). On a cluster the walk is one task among the run's, and a case's
sections can run on every worker of the cluster, so that the longest case gets shorter and not only the sweep.
A run context that can do that gives the walk a :class:`~gaitbench.contracts.FanOut` (``WalkProblem.fan_out``);
without one the strategy keeps its local processes.

What crosses to a worker is small: the task (a module-level function), the item, and a *state factory*. A worker
cannot receive built problems (CasADi functions do not pickle), so it rebuilds the walk's problem from the run's
own description of the case and asks the factory for the state the task needs (the sectional NLPs), once per worker
process and walk; later items of the same walk, on any step, find it there (:class:`WorkerStates`). The results
come back in the items' order and are those the walk's own process would compute: the same NLPs, solved from the
same items.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from gaitbench.contracts import WalkProblem

StateFactory = Callable[["WalkProblem"], Any]
"""``factory(problem)``: what a worker holds for the walk's tasks, made from the walk's problem rebuilt there. A
module-level function or class (it is pickled)."""


class FanOutError(RuntimeError):
    """A fanned-out task could not be run (its workers died, the cluster went away); the message says which."""


class WorkerStates:
    """A worker process's states, one per walk and factory, the ``keep`` most recently used: what a fanned-out
    task finds already built when an earlier item of its walk ran here.

    Keeping a few walks covers the cases a worker serves at once (one per Dask worker thread of the cluster, sharing
    this process) without keeping every walk the run ever had.
    """

    def __init__(self, keep: int = 4) -> None:
        self._keep = keep
        self._states: OrderedDict[tuple[Hashable, StateFactory], Any] = OrderedDict()

    def get(self, walk: Hashable, factory: StateFactory, problem: Callable[[], WalkProblem]) -> Any:
        """The state ``factory`` made for ``walk`` (a key naming the walk), made now from ``problem()`` (the walk's
        problem rebuilt here) if this process holds none."""
        key = (walk, factory)
        if key in self._states:
            self._states.move_to_end(key)
        else:
            self._states[key] = factory(problem())
            while len(self._states) > self._keep:
                self._states.popitem(last=False)
        return self._states[key]
