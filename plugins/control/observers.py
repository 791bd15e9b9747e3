"""Velocity and disturbance observers of the thesis's §4.3 in their working form (docs/model.md §9).

The printed pair (4.40)–(4.41) diverges: E is undefined and one term is dimensionally inconsistent
(docs/tracking.md). Its structure is kept and it is driven by the model-predicted acceleration
â = M⁻¹(B τ − C(q, q̂̇) q̂̇ − G − d̂) (with the stance foot held, the repaired variant of docs/tracking.md):

- velocity observer  q̂̇ = z + L q,  ż = â − L q̂̇   (so d/dt q̂̇ = â + L (q̇ − q̂̇));
- disturbance observer  d̂ = p − Φ q̂̇,  ṗ = Φ â   (so d/dt d̂ = −Φ L (q̇ − q̂̇)).

With a constant disturbance the estimation errors obey q̃̈ + L q̃̇ + Φ L M⁻¹ q̃ = 0, stable for every l, φ > 0.

Estimates live on the leg angles q1, q2: the held stance foot's rates are known zeros and a disturbance on it is
absorbed by the ground reaction (thesis §4.3). The tracking loop maps the velocity estimate through the same push-off
and heel-strike maps as the robot and keeps the disturbance estimate (leg labels are fixed, so a leg's friction
stays that leg's); ``reset`` then re-initialises z and p so that the estimates are exactly those mapped values.
Re-initialising matters: z = q̂̇ − L q would otherwise carry the pre-impact configuration.

Gains (docs/model.md §8: lost). l = 500 s⁻¹ puts the velocity observer's fast pole a decade above the controllers'
30 rad/s. φ = 2000 N·m·s/rad: the slow pole of s² + l s + φ l / m is ≈ φ / m, about 30 s⁻¹ along the forward
robot's heaviest leg-angle direction (m ≈ 68 kg·m²), so a constant disturbance is learned within ~0.15 s, a fifth of
a step; along the light swing direction (m ≈ 5 kg·m²) the pair is underdamped (ζ ≈ 0.56) but fast.
"""

from __future__ import annotations

import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.control.dynamics import held_foot_acceleration
from gaitbench.model.mechanics import BipedModel
from gaitbench.step_info import StepInfo

DEFAULT_L = 500.0
DEFAULT_PHI = 2000.0


def _positive(value: float, name: str) -> float:
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"{name} = {value!r}: observer gains must be positive")
    return value


def _predicted_acceleration(model: BipedModel, q: np.ndarray, velocity: np.ndarray, tau: np.ndarray,
                            disturbance: np.ndarray, step: StepInfo) -> np.ndarray:
    """â of the leg angles: the held-foot model at the estimated velocity, applied torques minus d̂."""
    dq = np.zeros(model.dof)
    dq[:2] = velocity
    return held_foot_acceleration(model, q, dq, tau - disturbance, step.stance)[:2]


class IdealObserver:
    """The true velocities and no disturbance estimate: the reference case of exact state feedback."""

    size = 0

    def __init__(self, model: BipedModel) -> None:
        self.model = model

    def reset(self, q: np.ndarray, dq: np.ndarray, velocity: np.ndarray, disturbance: np.ndarray,
              step: StepInfo) -> np.ndarray:
        return np.zeros(0)

    def estimate(self, state: np.ndarray, q: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.array(dq[:2], dtype=float), np.zeros(2)

    def derivative(self, state, q, dq, tau, step) -> np.ndarray:
        return np.zeros(0)


class VelocityObserver:
    """The velocity observer alone (thesis (4.40), working form): no disturbance estimate (d̂ = 0), so a disturbance
    biases q̂̇ by about M⁻¹ d / l."""

    size = 2

    def __init__(self, model: BipedModel, l: float = DEFAULT_L) -> None:  # noqa: E741 - the thesis's symbol
        self.model, self.gain = model, _positive(l, "l")

    def reset(self, q: np.ndarray, dq: np.ndarray, velocity: np.ndarray, disturbance: np.ndarray,
              step: StepInfo) -> np.ndarray:
        return np.asarray(velocity, dtype=float) - self.gain * q[:2]

    def estimate(self, state: np.ndarray, q: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return state + self.gain * q[:2], np.zeros(2)

    def derivative(self, state, q, dq, tau, step) -> np.ndarray:
        velocity = state + self.gain * q[:2]
        return _predicted_acceleration(self.model, q, velocity, tau, np.zeros(2), step) - self.gain * velocity


class DisturbanceObserver:
    """The disturbance observer alone (thesis (4.41), working form) on measured velocities, i.e. with a velocity
    sensor: d̂ = p − Φ q̇, ṗ = Φ â, so d/dt d̂ = Φ M⁻¹ (d − d̂)."""

    size = 2

    def __init__(self, model: BipedModel, phi: float = DEFAULT_PHI) -> None:
        self.model, self.gain = model, _positive(phi, "phi")

    def reset(self, q: np.ndarray, dq: np.ndarray, velocity: np.ndarray, disturbance: np.ndarray,
              step: StepInfo) -> np.ndarray:
        # its velocity estimate is the sensor's, so p = d̂ + Φ q̇ with the measured q̇ keeps d̂ across the impact
        return np.asarray(disturbance, dtype=float) + self.gain * np.asarray(dq[:2], dtype=float)

    def estimate(self, state: np.ndarray, q: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.array(dq[:2], dtype=float), state - self.gain * dq[:2]

    def derivative(self, state, q, dq, tau, step) -> np.ndarray:
        disturbance = state - self.gain * dq[:2]
        return self.gain * _predicted_acceleration(self.model, q, dq[:2], tau, disturbance, step)


class ThesisObserver:
    """Both observers coupled as the thesis uses them (§4.3): the velocity observer's â includes d̂, and the
    disturbance observer reads the estimated velocity. State (z, p)."""

    size = 4

    def __init__(self, model: BipedModel, l: float = DEFAULT_L, phi: float = DEFAULT_PHI) -> None:  # noqa: E741
        self.model = model
        self.velocity_gain, self.disturbance_gain = _positive(l, "l"), _positive(phi, "phi")

    def reset(self, q: np.ndarray, dq: np.ndarray, velocity: np.ndarray, disturbance: np.ndarray,
              step: StepInfo) -> np.ndarray:
        velocity = np.asarray(velocity, dtype=float)
        return np.r_[velocity - self.velocity_gain * q[:2],
                     np.asarray(disturbance, dtype=float) + self.disturbance_gain * velocity]

    def estimate(self, state: np.ndarray, q: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        velocity = state[:2] + self.velocity_gain * q[:2]
        return velocity, state[2:] - self.disturbance_gain * velocity

    def derivative(self, state, q, dq, tau, step) -> np.ndarray:
        velocity, disturbance = self.estimate(state, q, dq)
        predicted = _predicted_acceleration(self.model, q, velocity, tau, disturbance, step)
        return np.r_[predicted - self.velocity_gain * velocity, self.disturbance_gain * predicted]


@hookimpl
def register_observers():
    return [
        Registration("ideal", "True velocities, no disturbance estimate (exact state feedback)", IdealObserver),
        Registration("velocity", "Velocity observer q̂̇ = z + L q driven by the model-predicted acceleration "
                     "(thesis (4.40), working form)", VelocityObserver),
        Registration("disturbance", "Disturbance observer d̂ = p − Φ q̇ on measured velocities (thesis (4.41), "
                     "working form)", DisturbanceObserver),
        Registration("thesis", "Velocity and disturbance observers coupled as in the thesis §4.3 (working form, "
                     "docs/model.md §9)", ThesisObserver),
    ]
