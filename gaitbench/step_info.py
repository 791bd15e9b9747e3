"""What the closed loop tells every controller, observer and disturbance call about the current step.

Their contracts are in :mod:`gaitbench.contracts`; the loop (:mod:`gaitbench.control.closed_loop`) calls them.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class StepInfo:
    """What every plugin call knows about the current step (1-based ``index``; times in seconds)."""

    index: int
    stance: int
    slope: float
    chord: float
    time_step: float  # h of the reference grid: the friction of the linear joints scales with it (thesis §5.1)
    duration: float
    start_time: float  # global time at the step's start (after the previous heel strike)
