"""Disturbances for closed-loop tracking: the thesis's actuator friction, none, and an external push.

Each is built as ``factory(experiment, **options)`` and returns generalized forces on the left-hand side of
M q̈ + C q̇ + G + d = B τ + Sᵀ f (the sign the thesis's "+ d̂" in its laws implies, thesis §4.3).
"""

from __future__ import annotations

import math

import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.model.experiment import Experiment
from gaitbench.step_info import StepInfo


class NoDisturbance:
    """The exact model: no disturbance at all."""

    def __init__(self, experiment: Experiment) -> None:
        self.experiment = experiment

    def force(self, t: float, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> np.ndarray:
        return np.zeros(len(q))

    def impulse(self, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> np.ndarray:
        return np.zeros(len(q))


class Friction:
    """Steady-state actuator friction per generalized coordinate j (thesis §5.1; docs/model.md §9):

    D_j(q̇) = [F_cj + (F_sj − F_cj) exp(−|q̇_j / v_sj|^n)] sgn(q̇_j) + f_vj q̇_j, with each experiment's values
    (:class:`gaitbench.model.experiment.FrictionParameters`) and n = 2.

    The sign is smoothed as tanh(q̇ / ``smoothing``) for integration (``smoothing`` in rad/s for the hip joints,
    m/s for the linear joints; 1e-3 by default, well below the Stribeck velocities of 0.03–0.25). The hip joints
    (j = 1, 2) act as continuous torques on the absolute leg angles, where the thesis applies them. The linear
    push-off joints (j = 3, 4) carry values the thesis gives in impulse units (N·s, multiples of the step's h): they
    act as an impulse with the push-off, evaluated at the stance foot's post-push-off velocity. During swing the held
    foot does not move, so they vanish there. ``scale`` multiplies every coefficient (0 switches friction off).
    """

    def __init__(self, experiment: Experiment, smoothing: float = 1e-3, scale: float = 1.0) -> None:
        if experiment.friction is None:
            raise ValueError(f"experiment {experiment.name!r} has no friction parameters; use disturbance 'none' or "
                             "give the experiment FrictionParameters")
        if not smoothing > 0:
            raise ValueError(f"smoothing = {smoothing}: expected a positive velocity")
        if not scale >= 0:
            raise ValueError(f"scale = {scale}: expected a non-negative factor")
        self.parameters, self.smoothing, self.scale = experiment.friction, float(smoothing), float(scale)

    def _law(self, velocity: np.ndarray, h: float, joints: slice) -> np.ndarray:
        c = {key: value[joints] for key, value in self.parameters.joint_coefficients(h).items()}
        stribeck = c["Fc"] + (c["Fs"] - c["Fc"]) * np.exp(-np.abs(velocity / c["vs"]) ** self.parameters.n)
        return self.scale * (stribeck * np.tanh(velocity / self.smoothing) + c["fv"] * velocity)

    def force(self, t: float, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> np.ndarray:
        d = np.zeros(len(q))
        d[:2] = self._law(np.asarray(dq[:2], dtype=float), step.time_step, slice(0, 2))
        return d

    def impulse(self, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> np.ndarray:
        d = np.zeros(len(q))
        if len(q) == 4:
            d[2:] = self._law(np.asarray(dq[2:], dtype=float), step.time_step, slice(2, 4))
        return d


class Push:
    """An external force on the hip or the swing foot: a half-sine pulse of peak ``force`` (N) lasting ``duration``
    (s), starting ``time`` s into step ``step``, in the direction ``angle`` (rad from +x, counter-clockwise: 0 pushes
    forward, π backward, −π/2 down). ``point`` is ``"hip"`` or ``"swing-foot"``. The half-sine keeps the force
    continuous, so the integrator does not have to find its edges.
    """

    def __init__(self, experiment: Experiment, force: float = 100.0, duration: float = 0.1, time: float = 0.2,
                 step: int = 1, angle: float = 0.0, point: str = "hip") -> None:
        if point not in ("hip", "swing-foot"):
            raise ValueError(f"point = {point!r}: expected 'hip' or 'swing-foot'")
        if not duration > 0 or not time >= 0:
            raise ValueError(f"duration = {duration}, time = {time}: expected duration > 0 and time ≥ 0")
        if not 1 <= int(step) <= experiment.n_steps:
            raise ValueError(f"step = {step}: the {experiment.name} experiment has {experiment.n_steps} steps")
        self.peak, self.duration, self.start, self.step = float(force), float(duration), float(time), int(step)
        self.direction = np.array([math.cos(angle), math.sin(angle)])
        self.point, self.leg = point, experiment.robot.l

    def external_force(self, t: float, step: StepInfo) -> np.ndarray:
        """The pushing force (x, y) in N at local time ``t``."""
        elapsed = t - self.start
        if step.index != self.step or not 0 <= elapsed <= self.duration:
            return np.zeros(2)
        return self.peak * math.sin(math.pi * elapsed / self.duration) * self.direction

    def force(self, t: float, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> np.ndarray:
        push = self.external_force(t, step)
        jacobian = np.zeros((2, len(q)))  # ∂(point)/∂q in Convention A (docs/model.md §1)
        st, sw = step.stance - 1, 2 - step.stance
        jacobian[:, st] = -self.leg * math.cos(q[st]), -self.leg * math.sin(q[st])
        if self.point == "swing-foot":
            jacobian[:, sw] = self.leg * math.cos(q[sw]), self.leg * math.sin(q[sw])
        if len(q) == 4:
            jacobian[:, 2:] = np.eye(2)
        return -jacobian.T @ push

    def impulse(self, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> np.ndarray:
        return np.zeros(len(q))


@hookimpl
def register_disturbances():
    return [
        Registration("none", "No disturbance: the exact model", NoDisturbance),
        Registration("friction", "Coulomb, static, viscous and Stribeck actuator friction with the experiment's "
                     "values (thesis §5.1, n = 2)", Friction),
        Registration("push", "External half-sine push on the hip or swing foot at a given step and time", Push),
    ]
