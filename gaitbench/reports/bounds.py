"""The physical lower bound of each thesis experiment's ACOT (:mod:`gaitbench.solve.bound`), for the thesis comparison.

The thesis's figures are net-power costs, so the bounds are too, from the default start pose: once with push-off
charged as the kinetic energy its impulse adds (the real cost), once as the thesis's ½ m_stance |v_foot|² (3.77).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from gaitbench.plugins import PluginConflictError, PluginRegistry, UnknownPluginError, load_registry
from gaitbench.solve.bound import walk_bound


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
            values = [walk_bound(experiment, push_off_cost=cost) for cost in ("impulse", "thesis")]
        except (UnknownPluginError, PluginConflictError, ValueError):
            continue  # an experiment the registry lacks, or a terrain the legs cannot walk: no bound to show
        impulse, thesis = (bound.acot if bound.useful else math.nan for bound in values)
        found[name] = ExperimentBounds(impulse, thesis)
    return found
