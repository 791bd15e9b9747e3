"""Objectives: the one definition of what a step costs, which the NLP optimises and verification reports.

A step's cost is E = ∫ r dt + e, with the running cost r charged on the swing motion and the event cost e on the
push-off's work W_PO (the kinetic-energy increase of its impulse). COT = E / (M_total g D) for every objective, so
an objective's running cost is in watts. r has two parts:

- *charged powers* P_c (channels: the hip power for ``net-power``; the hip and ankle motors' powers for
  ``actuator-work``), each charged w⁺ max(P, 0) + w⁻ max(−P, 0): the NLP writes this exactly with the slack split
  P = s⁺ − s⁻, s± ≥ 0 (:func:`gaitbench.problem.step_cost.charged`), verification with exact max on a fine grid;
- a *smooth rate* (``torque-squared``), written as it is in both.

The same methods serve SX expressions (inside the NLP) and NumPy arrays (verification, decrease and conquer's point
costs), so the optimised and the reported figure cannot drift apart. Arguments are in role order: the stance leg's
and the swing leg's rate and generalised torque on its absolute angle; ``robot`` is the step's robot vector in role
order (:func:`gaitbench.problem.gait_problem.role_robot_vector`: masses at 0–2, leg length at 3, g at 7).

Objectives are frozen dataclasses: a step's built NLP is cached under a structure that includes its objective, so
equal objectives must compare (and hash) equal. ``net-power`` lives here because it is the core's default
(docs/model.md §5); the other built-in objectives are plugins (``plugins/objectives/energy_costs.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np


@dataclass(frozen=True)
class Objective:
    """The contract of an ``objective`` plugin (see the module docstring). Every method has a default, so an
    objective overrides only what it charges: :meth:`powers` and the weights, or :meth:`smooth_rate`."""

    name: ClassVar[str] = ""
    channels: ClassVar[tuple[str, ...]] = ()
    """Names of the charged powers, in the order :meth:`powers` returns them."""
    signed_event: ClassVar[bool] = False
    """Charge the push-off's work as it is (the thesis's E_PO) instead of by :meth:`charge`."""

    @property
    def positive_weight(self) -> float:
        """Cost per joule of positive work in a charged power (and in the push-off's work)."""
        return 1.0

    @property
    def negative_weight(self) -> float:
        """Cost per joule of negative work (absorbed energy)."""
        return 1.0

    def powers(self, dq_st: Any, dq_sw: Any, tau_st: Any, tau_sw: Any) -> list[Any]:
        """The signed powers of :attr:`channels`."""
        return []

    def smooth_rate(self, dq_st: Any, dq_sw: Any, tau_st: Any, tau_sw: Any, robot: Any) -> Any | None:
        """The part of the running cost that needs no |·| (W), or None."""
        return None

    def charge(self, power: np.ndarray) -> np.ndarray:
        """w⁺ max(P, 0) + w⁻ max(−P, 0), exactly (|P| when both weights are 1)."""
        power = np.asarray(power, dtype=float)
        if self.positive_weight == self.negative_weight == 1.0:
            return np.abs(power)
        return self.positive_weight * np.maximum(power, 0.0) + self.negative_weight * np.maximum(-power, 0.0)

    def rate(self, dq: np.ndarray, tau: np.ndarray, stance: int, robot: np.ndarray) -> np.ndarray:
        """The running cost (W) at samples of leg-order rates and torques, (n, 2) arrays."""
        order = [0, 1] if stance == 1 else [1, 0]  # leg order to role order (stance leg first)
        dq_roles, tau_roles = np.atleast_2d(dq)[:, order], np.atleast_2d(tau)[:, order]
        args = (dq_roles[:, 0], dq_roles[:, 1], tau_roles[:, 0], tau_roles[:, 1])
        total = np.zeros(dq_roles.shape[0])
        for power in self.powers(*args):
            total = total + self.charge(power)
        smooth = self.smooth_rate(*args, robot)
        return total if smooth is None else total + smooth

    def event_cost(self, work: float) -> float:
        """What the push-off's work ``work`` (J) costs."""
        return float(work) if self.signed_event else float(self.charge(work))

    def point_costs(self, dq: np.ndarray, tau: np.ndarray, push_off_work: float, stance: int,
                    robot: np.ndarray) -> np.ndarray:
        """Decrease and conquer's point cost PCOT_k per node (thesis §3.7): the running cost at the nodes,
        the push-off's event cost added at the last node (the thesis's |hip power| + E_PO under ``net-power``)."""
        pcot = self.rate(dq, tau, stance, robot)
        pcot[-1] += self.event_cost(push_off_work)
        return pcot

    def describe(self) -> str:
        """``name`` or ``name(option=value, ...)`` with the options not at their defaults: how results name the
        objective of their numbers."""
        options = ", ".join(f"{item.name}={getattr(self, item.name)}" for item in fields(self)
                            if getattr(self, item.name) != item.default)
        return f"{self.name}({options})" if options else self.name


@dataclass(frozen=True)
class NetPower(Objective):
    """The thesis's cost (3.75), ∫ |τ_st q̇_st + τ_sw q̇_sw| dt + E_PO: the total variation of the mechanical energy
    (docs/deviations.md, "Net hip power"). It does not see torque: opposing torques cost nothing."""

    name: ClassVar[str] = "net-power"
    channels: ClassVar[tuple[str, ...]] = ("hip",)
    signed_event: ClassVar[bool] = True

    def powers(self, dq_st: Any, dq_sw: Any, tau_st: Any, tau_sw: Any) -> list[Any]:
        return [tau_st * dq_st + tau_sw * dq_sw]


NET_POWER = NetPower()
"""The default objective of every step problem."""


@dataclass(frozen=True)
class ControlEffort(Objective):
    """The thesis's First-Phase cost (§2.5), the control effort ∫ (τ1² + τ2²) dt, which it writes as nodal Simpson
    Σ w_k (τ1,k² + τ2,k²) h/3; here the transcription's own quadrature integrates it, as it does every running
    cost. Scaled by 1/(M g l √(l/g)) into watts, which leaves the minimiser unchanged. Not a COT: it has no
    push-off (the First Phase has none) and is what ``first_phase_cost = "effort"`` minimises, never reported."""

    name: ClassVar[str] = "control-effort"

    def smooth_rate(self, dq_st: Any, dq_sw: Any, tau_st: Any, tau_sw: Any, robot: Any) -> Any:
        mass, leg, g = robot[0] + robot[1] + robot[2], robot[3], robot[7]
        return (tau_st * tau_st + tau_sw * tau_sw) / (mass * leg * (g * leg) ** 0.5)


CONTROL_EFFORT = ControlEffort()
"""What the First Phase minimises under ``first_phase_cost = "effort"``."""
