"""Tracking controllers of the thesis's Chapter 4 (§4.1–4.2; docs/model.md §9), and a PD baseline.

Each is built as ``factory(model, reference, **options)`` and tracks :class:`gaitbench.control.reference.Reference`.

Gains (docs/model.md §8: the thesis's values were lost). The model-based laws impose ë + K_v ė + K_p e = 0 on each
leg; the defaults K_p = 900 s⁻², K_v = 60 s⁻¹ make it critically damped at ω_n = 30 rad/s (4.8 Hz): well above the
gait's content (a 0.73 s step, 1.4 Hz), so the reference is followed closely, and a decade below what a 1 kHz
servo loop or the observers' fast poles (l = 500 s⁻¹) can support, so sampling and estimation stay out of the way.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.control.dynamics import inverse_dynamics, model_terms
from gaitbench.control.reference import Reference
from gaitbench.model.mechanics import BipedModel
from gaitbench.step_info import StepInfo

DEFAULT_KP = 900.0
"""s⁻²: ω_n² with ω_n = 30 rad/s."""
DEFAULT_KV = 60.0
"""s⁻¹: 2 ζ ω_n with ζ = 1 (critically damped, no overshoot)."""


def _gain(value: float | Sequence[float], name: str) -> np.ndarray:
    gain = np.broadcast_to(np.asarray(value, dtype=float), (2,)).copy()
    if not np.all(np.isfinite(gain)) or np.any(gain <= 0):
        raise ValueError(f"{name} = {value!r}: gains must be positive (s² + K_v s + K_p Hurwitz, thesis §4.2)")
    return gain


class ComputedTorque:
    """Computed torque control (thesis (4.6), (4.22), (4.38)) with the disturbance estimate added.

    Swing: with the stance foot held, the leg angles are fully actuated, and the law is
    τ = [M(q) v + C(q, q̂̇) q̂̇ + G(q)]₁,₂ + d̂ with v = (q̈_d − K_v(q̂̇ − q̇_d) − K_p(q − q_d), 0, 0): the fully actuated
    model of the push-off phase with the foot's rows left to the ground reaction. Push-off: the thesis's fully
    actuated law in impulse form asks for the generalized impulse M(q)(q̇_d⁺ − q̂̇⁻); the only actuator is the scalar
    impulse along the stance leg (docs/model.md §3), so its M⁻¹-weighted projection on that axis is applied,
    F = (J M⁻¹ Jᵀ)⁻¹ J (q̇_d⁺ − q̂̇⁻) (the impulse form of thesis §4.2.2). On the reference it is exactly the planned
    impulse.
    """

    def __init__(self, model: BipedModel, reference: Reference, kp: float | Sequence[float] = DEFAULT_KP,
                 kv: float | Sequence[float] = DEFAULT_KV) -> None:
        self.model, self.reference = model, reference
        self.kp, self.kv = _gain(kp, "kp"), _gain(kv, "kv")

    def command(self, t: float, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> np.ndarray:
        """The outer loop v_a = q̈_d − K_v ė − K_p e ((4.15), with the estimated velocity in ė)."""
        q_d, dq_d, ddq_d = self.reference.desired(step, t)
        return ddq_d - self.kv * (dq[:2] - dq_d) - self.kp * (q[:2] - q_d)

    def torque(self, t: float, q: np.ndarray, dq: np.ndarray, disturbance: np.ndarray, step: StepInfo) -> np.ndarray:
        v = self.reference.full(step, self.command(t, q, dq, step))
        return inverse_dynamics(self.model, q, dq, v, step.stance) + disturbance

    def push_off(self, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> float:
        target = self.reference.post_push_off_velocity(step)
        stance = step.stance - 1
        axis = np.zeros(self.model.dof)
        axis[2:] = -np.sin(q[stance]), np.cos(q[stance])
        mobility = axis @ np.linalg.solve(self.model.mass_matrix(q, step.stance), axis)
        return float(axis @ (target - dq) / mobility)


class PartialFeedbackLinearization:
    """Collocated PFL on q1, q2 (thesis (4.8)–(4.12), (4.24)–(4.28), (4.37), (4.39)) with two corrections of the
    printed law: one C_a q̇_a term and the Schur complement M_a = M11 − M12 M22⁻¹ M21 (docs/tracking.md).

    τ = M_a v_a + C_a q̂̇_a + C_na q̂̇_na + G̃ + M12 M22⁻¹ F + d̂. ``contact_force`` chooses F: ``"constraint"``
    (default) is the exact held-foot force M21 v_a + C21 q̂̇_a + C22 q̂̇_na + G2, which linearizes q̈_a = v_a exactly
    (and makes the law coincide with computed torque, docs/tracking.md); ``"thesis"`` is the closed form (3.39),
    C21 q̇_a + G2, which drops M21 q̈_a and leaves q̈_a = M11⁻¹ M_a v_a — kept to show the thesis's error.
    Heel strike is an instantaneous plastic impact here (docs/model.md §3), on which finite hip torques do no work, so
    the heel-strike PFL is this same law acting from the first instant of the next step. The push-off is not PFL's
    (it is fully actuated): this controller applies the planned impulse.
    """

    def __init__(self, model: BipedModel, reference: Reference, kp: float | Sequence[float] = DEFAULT_KP,
                 kv: float | Sequence[float] = DEFAULT_KV, contact_force: str = "constraint") -> None:
        if contact_force not in ("constraint", "thesis"):
            raise ValueError(f"contact_force = {contact_force!r}: expected 'constraint' (exact) or 'thesis' (3.39)")
        self.model, self.reference, self.contact_force = model, reference, contact_force
        self.outer = ComputedTorque(model, reference, kp, kv)

    def torque(self, t: float, q: np.ndarray, dq: np.ndarray, disturbance: np.ndarray, step: StepInfo) -> np.ndarray:
        v = self.outer.command(t, q, dq, step)
        mass, coriolis, gravity = model_terms(self.model)(q, dq, step.stance)
        if self.model.dof == 2:  # nothing unactuated: PFL is computed torque
            return mass @ v + coriolis @ dq + gravity + disturbance
        a, u = slice(0, 2), slice(2, 4)
        project = mass[a, u] @ np.linalg.inv(mass[u, u])  # M12 M22⁻¹
        mass_a = mass[a, a] - project @ mass[u, a]
        coriolis_a = coriolis[a, a] - project @ coriolis[u, a]
        coriolis_na = coriolis[a, u] - project @ coriolis[u, u]
        gravity_a = gravity[a] - project @ gravity[u]
        force = coriolis[u, a] @ dq[a] + gravity[u]
        if self.contact_force == "constraint":
            force = force + mass[u, a] @ v + coriolis[u, u] @ dq[u]
        return (mass_a @ v + coriolis_a @ dq[a] + coriolis_na @ dq[u] + gravity_a + project @ force
                + disturbance)

    def push_off(self, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> float:
        return self.reference.step(step).push_off


class ThesisControl:
    """The thesis's assignment per phase (§4.1.1): collocated PFL in swing and heel strike, computed torque at the
    fully actuated push-off. Options are those of both: ``kp``, ``kv``, ``contact_force``."""

    def __init__(self, model: BipedModel, reference: Reference, kp: float | Sequence[float] = DEFAULT_KP,
                 kv: float | Sequence[float] = DEFAULT_KV, contact_force: str = "constraint") -> None:
        self.swing = PartialFeedbackLinearization(model, reference, kp, kv, contact_force)
        self.push = ComputedTorque(model, reference, kp, kv)

    def torque(self, t: float, q: np.ndarray, dq: np.ndarray, disturbance: np.ndarray, step: StepInfo) -> np.ndarray:
        return self.swing.torque(t, q, dq, disturbance, step)

    def push_off(self, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> float:
        return self.push.push_off(q, dq, step)


class ProportionalDerivative:
    """Model-free baseline: the plan's own torques as feedforward plus independent PD on each leg angle,
    τ = τ_ref(t) − K_p (q − q_d) − K_d (q̂̇ − q̇_d), and the planned push-off. It ignores the disturbance estimate.

    Defaults K_p = 3000 N·m/rad and K_d = 300 N·m·s/rad: on the forward robot's swing leg (about 6 kg·m² about the
    hip) that is ω_n ≈ 22 rad/s, ζ ≈ 1.1, comparable to the model-based laws; the stance leg, ten times heavier,
    gets only ω_n ≈ 7 rad/s, which is the point of comparing with a model-based law.
    """

    def __init__(self, model: BipedModel, reference: Reference, kp: float | Sequence[float] = 3000.0,
                 kd: float | Sequence[float] = 300.0) -> None:
        self.reference = reference
        self.kp, self.kd = _gain(kp, "kp"), _gain(kd, "kd")

    def torque(self, t: float, q: np.ndarray, dq: np.ndarray, disturbance: np.ndarray, step: StepInfo) -> np.ndarray:
        q_d, dq_d, _ = self.reference.desired(step, t)
        feedforward = np.asarray(self.reference.step(step).torque(t), dtype=float)
        return feedforward - self.kp * (q[:2] - q_d) - self.kd * (dq[:2] - dq_d)

    def push_off(self, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> float:
        return self.reference.step(step).push_off


@hookimpl
def register_controllers():
    return [
        Registration("computed-torque", "Computed torque on the held-foot model in swing, projected CTC impulse "
                     "at push-off (thesis (4.6), (4.22))", ComputedTorque),
        Registration("pfl", "Collocated partial feedback linearization on q1, q2 with the corrections of "
                            "docs/tracking.md; "
                     "planned push-off (thesis (4.12), (4.28))", PartialFeedbackLinearization),
        Registration("thesis", "The thesis's per-phase assignment: PFL in swing and heel strike, computed torque at "
                     "push-off", ThesisControl),
        Registration("pd", "Baseline: planned torques plus independent PD on each leg angle, planned push-off",
                     ProportionalDerivative),
    ]
