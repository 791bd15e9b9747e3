"""An objective plugin: the actuators' positive work, with absorbed (negative) work charged at a chosen rate.

A motor that cannot give energy back pays for the work it does and not for the work it absorbs, which a brake or
the gearbox's friction takes. The hip motor acts between the legs (rate q̇_sw − q̇_st), the ankle between the stance
foot and the stance leg (rate q̇_st); their generalised torques on the absolute angles are τ_st = τ_a − τ_h and
τ_sw = τ_h. The push-off actuator's work is charged the same way.

An objective is a frozen dataclass (gaitbench caches built NLPs under it) that overrides only what it charges: here
the powers of its channels and the weights of their positive and negative parts. The same methods serve the NLP,
verification and decrease and conquer's point costs, so what is optimised is what is reported.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from gaitbench import Registration, hookimpl
from gaitbench.problem.objective import Objective


@dataclass(frozen=True)
class PositiveWork(Objective):
    """Σ_j ∫ max(P_j, 0) + absorbed · max(−P_j, 0) dt over the hip and the ankle, plus the push-off's work charged
    alike. ``absorbed``: the cost of a joule of negative work, 0 (free) to 1 (the actuators' absolute work)."""

    name: ClassVar[str] = "example-positive-work"
    channels: ClassVar[tuple[str, ...]] = ("hip", "ankle")
    absorbed: float = 0.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.absorbed <= 1.0:
            raise ValueError(f"absorbed = {self.absorbed}: expected a cost per joule from 0 to 1")

    @property
    def negative_weight(self) -> float:
        return self.absorbed

    def powers(self, dq_st: Any, dq_sw: Any, tau_st: Any, tau_sw: Any) -> list[Any]:
        hip = tau_sw * (dq_sw - dq_st)
        ankle = (tau_st + tau_sw) * dq_st
        return [hip, ankle]


@hookimpl
def register_objectives():
    return [Registration("example-positive-work", "The hip and ankle motors' positive work, negative work charged "
                         "at absorbed (default 0) per joule (example plugin package)", PositiveWork)]
