"""Equations of motion from a Lagrangian, symbolically, so no matrix is ever transcribed by hand.

The thesis prints several expanded matrices with errors (docs/model.md §1–2); deriving M, C and G from the
kinetic and potential energies removes that whole class of mistakes.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca


@dataclass(frozen=True)
class EquationsOfMotion:
    """M(q) q̈ + C(q, q̇) q̇ + G(q) = generalized forces, as CasADi SX expressions."""

    mass: ca.SX
    coriolis: ca.SX
    gravity: ca.SX
    mass_derivative: ca.SX  # Ṁ along q̇, for the passivity property Ṁ − 2C skew-symmetric


def derive(q: ca.SX, dq: ca.SX, kinetic: ca.SX, potential: ca.SX) -> EquationsOfMotion:
    """Derive the manipulator form of the Euler–Lagrange equations.

    C is the Christoffel form c_kj = Σ_i ½(∂m_kj/∂q_i + ∂m_ki/∂q_j − ∂m_ij/∂q_k) q̇_i (the thesis's (8.40)
    prints the last sign wrong), which makes Ṁ − 2C skew-symmetric.
    """
    n = q.numel()
    mass = ca.hessian(kinetic, dq)[0]
    mass = ca.simplify(mass)
    gravity = ca.gradient(potential, q)
    dmass = [ca.jacobian(mass[:, j], q) for j in range(n)]  # dmass[j][k, i] = ∂m_kj/∂q_i
    coriolis = ca.SX.zeros(n, n)
    for k in range(n):
        for j in range(n):
            coriolis[k, j] = sum(
                0.5 * (dmass[j][k, i] + dmass[i][k, j] - dmass[j][i, k]) * dq[i] for i in range(n)
            )
    mass_derivative = ca.SX.zeros(n, n)
    for j in range(n):
        mass_derivative[:, j] = ca.mtimes(dmass[j], dq)
    return EquationsOfMotion(mass=mass, coriolis=coriolis, gravity=gravity, mass_derivative=mass_derivative)
