"""The physical lower bound of each thesis experiment's ACOT (:mod:`gaitbench.solve.bound`), for the thesis comparison.

The thesis's figures are net-power costs, so the bounds are too: once with push-off charged as the kinetic energy
its impulse adds (the real cost), once as the thesis's ½ m_stance |v_foot|² (3.77). Each is the lesser of the bounds
from the two start poses a walk of the thesis's may have started from (on the ground, gaitbench's; the thesis's
printed pose), so that a published figure flagged below it is below whichever the thesis used.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from gaitbench.plugins import PluginConflictError, PluginRegistry, UnknownPluginError, load_registry
from gaitbench.problem.gait_problem import START_POSES
from gaitbench.solve.bound import WalkBound, walk_bound


@dataclass(frozen=True)
class ExperimentBounds:
    """An experiment's ACOT bounds under net-power; NaN where the walk needs no energy it has not got (no useful
    bound: flat ground, downhill)."""

    impulse: float
    thesis_push_off: float

    @property
    def useful(self) -> bool:
        return not math.isnan(self.impulse)


def experiment_bounds(experiments: Iterable[str],
                      registry: PluginRegistry | None = None) -> dict[str, ExperimentBounds]:
    """The bounds of each named experiment that the registry can build; the others are left out."""
    registry = registry or load_registry()
    found = {}
    for name in experiments:
        try:
            experiment = registry.create("experiment", name)
            impulse, thesis = (_least(walk_bound(experiment, push_off_cost=cost, start_pose=pose)
                                      for pose in START_POSES) for cost in ("impulse", "thesis"))
        except (UnknownPluginError, PluginConflictError, ValueError):
            continue  # an experiment the registry lacks, or a terrain the legs cannot walk: no bound to show
        found[name] = ExperimentBounds(impulse, thesis)
    return found


def _least(bounds: Iterable[WalkBound]) -> float:
    """The least of the useful bounds' ACOTs; NaN when one of them is of no use (then neither is the least)."""
    values = [bound.acot if bound.useful else math.nan for bound in bounds]
    return math.nan if any(math.isnan(value) for value in values) else min(values)
