"""The held-foot dynamics of the swing phase, shared by the closed loop and the model-based plugins.

During swing the stance foot is held, so the leg angles are fully actuated: computed torque is rows 1–2 of
M q̈ + C q̇ + G, and the plant's accelerations solve the 2×2 leg block. Both need M, C and G at the same
configuration several times per right-hand-side call, so :class:`ModelTerms` evaluates them once per configuration.
"""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from gaitbench.model.mechanics import BipedModel
from gaitbench.model.numeric import NumericFunction


def inverse_dynamics(model: BipedModel, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, stance: int) -> np.ndarray:
    """Hip torques that give the leg accelerations ``ddq`` with the stance foot held: rows 1–2 of M q̈ + C q̇ + G.

    With the foot held, q̈3 = q̈4 = 0, and rows 3–4 only fix the ground reaction; this is computed torque on the
    constrained model and equals collocated PFL with the exact contact force (docs/tracking.md).
    """
    mass, coriolis, gravity = model_terms(model)(q, dq, stance)
    return (mass @ ddq + coriolis @ dq + gravity)[:2]


def held_foot_acceleration(model: BipedModel, q: np.ndarray, dq: np.ndarray, tau: np.ndarray,
                           stance: int) -> np.ndarray:
    """q̈ with the stance foot held (q̇3 = q̇4 = 0) under hip torques ``tau``: M11 q̈_a = τ − (C q̇ + G)_a, q̈_na = 0.

    The same accelerations as the model's constrained forward dynamics (the KKT system of docs/model.md §2), from the
    memoized terms, which the loop's controller and observer need anyway.
    """
    mass, coriolis, gravity = model_terms(model)(q, dq, stance)
    ddq = np.zeros(model.dof)
    ddq[:2] = np.linalg.solve(mass[:2, :2], tau - (coriolis @ dq + gravity)[:2])
    return ddq


class ModelTerms:
    """M(q), C(q, q̇) and G(q) of a model from one CasADi call per configuration, memoized on the last one.

    In the closed loop's right-hand side the plant (true velocity), the controller and the observer (estimated
    velocity) all need the terms at the same configuration, and a CasADi call from Python costs far more than the
    arithmetic. C is linear in q̇ (Christoffel form), so the call returns Γ(q) = ∂ vec C / ∂q̇ and C(q, v) = Γ(q) v
    for any velocity v is a matrix product.
    """

    def __init__(self, model: BipedModel) -> None:
        n = model.dof
        self.dof, self.parameters = n, model.parameters
        self._functions = {}
        for stance in (1, 2):
            raw = model.functions(stance)
            q, dq, p = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("p", len(model.parameters))
            christoffel = ca.substitute(ca.jacobian(ca.vec(raw.coriolis(q, dq, p)), dq), dq, ca.SX.zeros(n))
            outputs = ca.vertcat(ca.vec(raw.mass(q, p)), ca.vec(christoffel), raw.gravity(q, p))
            self._functions[stance] = NumericFunction(ca.Function(f"terms_{stance}", [q, p], [outputs]))
        self._key: bytes | None = None
        self._terms: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def __call__(self, q: np.ndarray, dq: np.ndarray, stance: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        q = np.asarray(q, dtype=float)
        key = bytes([stance]) + q.tobytes()
        if key != self._key:
            n = self.dof
            values = self._functions[stance](q, self.parameters)
            self._key = key
            self._terms = (values[: n * n].reshape(n, n, order="F"),
                           values[n * n: n * n * (n + 1)].reshape(n * n, n, order="F"), values[n * n * (n + 1):])
        mass, christoffel, gravity = self._terms
        coriolis = (christoffel @ np.asarray(dq, dtype=float)).reshape(self.dof, self.dof, order="F")
        return mass, coriolis, gravity


@functools.cache
def model_terms(model: BipedModel) -> ModelTerms:
    """The (cached) :class:`ModelTerms` of a model."""
    return ModelTerms(model)
