"""The built-in objectives: the thesis's net power, the actuators' work and the squared torques.

``net-power`` is the thesis's cost (:class:`gaitbench.problem.objective.NetPower`, the core's default). It is the total
variation of the robot's mechanical energy and does not see torque (docs/deviations.md, "Net hip power"), so the
other two are what locomotion research compares gaits on. Their derivations are in docs/objectives.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from gaitbench import Registration, hookimpl
from gaitbench.problem.objective import NetPower, Objective

MARGARIA_POSITIVE_EFFICIENCY = 0.25
MARGARIA_NEGATIVE_EFFICIENCY = 1.2
"""Muscle's efficiency for positive and negative work (Margaria 1968): 25 % and −120 %, so a joule of positive work
costs 4 J and a joule of negative work 1/1.2 J."""


@dataclass(frozen=True)
class ActuatorWork(Objective):
    """Σ_j ∫ |τ_j ω_j| dt over the real actuators, and the push-off actuator's |work|.

    The hip motor acts between the legs (torque τ_h on the swing leg, −τ_h on the stance leg, rate
    ω_h = q̇_sw − q̇_st); the ankle acts between the stance foot, at rest on the ground, and the stance leg (ω_a = q̇_st).
    Their generalised forces on the absolute angles are τ_st = τ_a − τ_h and τ_sw = τ_h, so τ_h = τ_sw and
    τ_a = τ_st + τ_sw; the two powers sum to τ_st q̇_st + τ_sw q̇_sw, the net power, but opposing powers now cost.
    ``margaria``: positive work costs 1/0.25, negative work 1/1.2 per joule (metabolic energy).
    """

    name: ClassVar[str] = "actuator-work"
    channels: ClassVar[tuple[str, ...]] = ("hip", "ankle")
    margaria: bool = False

    @property
    def positive_weight(self) -> float:
        return 1 / MARGARIA_POSITIVE_EFFICIENCY if self.margaria else 1.0

    @property
    def negative_weight(self) -> float:
        return 1 / MARGARIA_NEGATIVE_EFFICIENCY if self.margaria else 1.0

    def powers(self, dq_st: Any, dq_sw: Any, tau_st: Any, tau_sw: Any) -> list[Any]:
        hip = tau_sw * (dq_sw - dq_st)
        ankle = (tau_st + tau_sw) * dq_st
        return [hip, ankle]


@dataclass(frozen=True)
class TorqueSquared(Objective):
    """c ∫ τᵀτ dt, with c in W/(N·m)² so that it is an energy and a COT can be reported, and the push-off
    actuator's |work|, an impulse having no squared force.

    c is ``motor_constant`` (a motor's winding resistance over its torque constant squared, R/k_t², makes c τᵀτ its
    Joule heating) or, unset, the robot's own scale 1/(M g l √(l/g)): torques in units of M g l over times in units
    of √(l/g), so that walkers of different sizes compare.
    """

    name: ClassVar[str] = "torque-squared"
    motor_constant: float | None = None

    def __post_init__(self) -> None:
        if self.motor_constant is not None and not self.motor_constant > 0:
            raise ValueError(f"motor_constant = {self.motor_constant}: expected a positive number (W/(N·m)²)")

    def smooth_rate(self, dq_st: Any, dq_sw: Any, tau_st: Any, tau_sw: Any, robot: Any) -> Any:
        if self.motor_constant is not None:
            scale = self.motor_constant
        else:
            mass, leg, g = robot[0] + robot[1] + robot[2], robot[3], robot[7]
            scale = 1 / (mass * leg * (g * leg) ** 0.5)  # 1 / (M g l √(l/g))
        return scale * (tau_st * tau_st + tau_sw * tau_sw)


@hookimpl
def register_objectives():
    return [
        Registration("net-power", "the thesis's cost: ∫|τ1 q̇1 + τ2 q̇2| dt + push-off energy, the total variation of "
                     "the mechanical energy (default)", NetPower),
        Registration("actuator-work", "Σ_j ∫|τ_j ω_j| dt of the hip and ankle motors on their joint rates, plus "
                     "the push-off's work; margaria=true weighs positive/negative work by 25 %/−120 %", ActuatorWork),
        Registration("torque-squared", "c ∫ τᵀτ dt (c = 1/(M g l √(l/g)) or motor_constant) plus the push-off's "
                     "work", TorqueSquared),
    ]
