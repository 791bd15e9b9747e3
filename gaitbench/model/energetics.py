"""Energy and cost of transport of a walking step (thesis §3.5.3, (3.73)–(3.79); docs/model.md §5).

E_i = ∫ |τ1 q̇1 + τ2 q̇2| dt + E_PO: every joule through the hip motors costs, whether the motor does positive
or negative work. E_PO, the kinetic-energy increase of the push-off impulse, is a difference of two kinetic
energies and comes from the mechanics module. COT_i = E_i / (M_total g D_i) is dimensionless.

``smooth_abs``, ``hip_power`` and ``hip_energy`` also accept casadi expressions, for NLP objectives.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import casadi
import numpy as np

from gaitbench.model.robot import G_CONST

DEFAULT_SMOOTHING_EPS = 0.1
"""ε of the smoothed |x| for the reported results (thesis §5.1; ε = 1 is the other value it tried)."""


def smooth_abs(x: Any, eps: float = DEFAULT_SMOOTHING_EPS) -> Any:
    """√(x² + ε²): a differentiable |x| for NLP objectives, within ε of |x| and never below it.

    The thesis prints √(x² + ε²)/2 (§3.5.3); the "/2" would halve the cost and is not used (docs/model.md §5).
    """
    return (x * x + eps * eps) ** 0.5


def simpson_weights(n_nodes: int) -> np.ndarray:
    """Quadrature weights for ``n_nodes`` equally spaced nodes at unit spacing (multiply by h).

    Odd n: composite Simpson 1, 4, 2, 4, …, 2, 4, 1 over 3 (4 on even 1-based nodes; the thesis's description
    in (3.77)/(3.78) swaps 2 and 4). Even n ≥ 4 (an odd number of intervals, which Simpson cannot cover):
    composite Simpson on the first n − 4 intervals and Simpson's 3/8 rule on the last 3. n = 2: trapezoid.
    Exact for cubic polynomials whenever n ≥ 3.
    """
    if isinstance(n_nodes, bool) or not isinstance(n_nodes, (int, np.integer)) or n_nodes < 2:
        raise ValueError(f"n_nodes = {n_nodes!r}: quadrature needs an integer number of nodes >= 2")
    if n_nodes == 2:
        return np.array([0.5, 0.5])
    weights = np.zeros(n_nodes)
    n_simpson = n_nodes if n_nodes % 2 == 1 else n_nodes - 3  # nodes covered by composite Simpson
    if n_simpson >= 3:
        weights[:n_simpson] = _composite_simpson(n_simpson)
    if n_nodes % 2 == 0:
        weights[-4:] += np.array([3.0, 9.0, 9.0, 3.0]) / 8.0
    return weights


def _composite_simpson(n_nodes: int) -> np.ndarray:
    weights = np.ones(n_nodes)
    weights[1:-1:2] = 4.0
    weights[2:-1:2] = 2.0
    return weights / 3.0


def hip_power(dq1: Any, dq2: Any, tau1: Any, tau2: Any) -> Any:
    """Mechanical power of the two hip motors, τ1 q̇1 + τ2 q̇2 (thesis (3.75))."""
    return tau1 * dq1 + tau2 * dq2


def hip_energy(
    times_or_h: float | Sequence[float] | np.ndarray, power: Any, smooth: float | None = None
) -> Any:
    """∫ |P| dt over a uniform grid with :func:`simpson_weights` (thesis (3.77), corrected weights).

    ``times_or_h`` is the grid spacing h or the node times (which must be uniformly spaced). With
    ``smooth`` = ε the integrand is :func:`smooth_abs` (for NLP objectives); reported energies use exact |P|.
    ``power`` may be a numpy array or a casadi column vector.
    """
    symbolic = isinstance(power, (casadi.SX, casadi.MX, casadi.DM))
    n_nodes = power.numel() if symbolic else np.asarray(power).size
    h = _uniform_spacing(times_or_h, n_nodes)
    if smooth is not None:
        magnitude = smooth_abs(power, smooth)
    else:
        magnitude = casadi.fabs(power) if symbolic else np.abs(np.asarray(power, dtype=float))
    weights = simpson_weights(n_nodes)
    if symbolic:
        return h * casadi.dot(casadi.DM(weights), casadi.vec(magnitude))
    return float(h * np.dot(weights, np.ravel(magnitude)))


def _uniform_spacing(times_or_h: float | Sequence[float] | np.ndarray, n_nodes: int) -> float:
    if np.ndim(times_or_h) == 0:
        h = float(times_or_h)
        if not np.isfinite(h) or h <= 0:
            raise ValueError(f"grid spacing h = {h}: must be positive and finite")
        return h
    times = np.asarray(times_or_h, dtype=float)
    if times.shape != (n_nodes,):
        raise ValueError(f"got {times.size} node times for {n_nodes} power values")
    steps = np.diff(times)
    h = float(steps.mean()) if steps.size else 0.0
    if h <= 0 or not np.allclose(steps, h, rtol=1e-9, atol=1e-12):
        raise ValueError("node times must be increasing and uniformly spaced for Simpson quadrature")
    return h


def push_off_work(accounting: str, kinetic_gain: Any, foot_velocity: Any, stance_mass: Any) -> Any:
    """What a push-off is charged (J), by ``accounting`` (``ProblemOptions.push_off_cost``).

    ``impulse``: ``kinetic_gain``, the kinetic energy the impulse adds to the robot (E_PO of (3.76), exact).
    ``thesis``: ½ m_stance |v_foot|² of (3.77), the stance leg's mass ``stance_mass`` moving at the stance foot's
    velocity just after the push-off, ``foot_velocity`` (q̇3, q̇4). It counts only the foot's share of the energy
    the impulse gives the whole robot. Works on numbers and casadi expressions.
    """
    if accounting == "impulse":
        return kinetic_gain
    if accounting == "thesis":
        return 0.5 * stance_mass * (foot_velocity[0] ** 2 + foot_velocity[1] ** 2)
    raise ValueError(f"push-off accounting {accounting!r}: expected 'impulse' or 'thesis'")


def cost_of_transport(energy: Any, total_mass: float, chord: float, g: float = G_CONST) -> Any:
    """COT = E / (M_total g D): energy per unit weight and unit distance (thesis (3.79))."""
    if total_mass <= 0 or chord <= 0 or g <= 0:
        raise ValueError(f"total_mass = {total_mass}, chord = {chord}, g = {g}: all must be positive")
    return energy / (total_mass * g * chord)


def average_cot(cots: Sequence[float] | np.ndarray) -> float:
    """ACOT = (1/H) Σ COT_i over the H steps of a walk (thesis §5.2)."""
    values = np.asarray(cots, dtype=float)
    if values.size == 0:
        raise ValueError("average_cot needs at least one step's COT")
    return float(values.mean())


def candidate_cot(pcot: np.ndarray, total_mass: float, chord: float, g: float = G_CONST) -> float:
    """Σ_k PCOT_k / (M_total g D), the thesis's COT of a synthesized candidate (§3.7), from the point
    costs of :meth:`gaitbench.problem.objective.Objective.point_costs`.

    Taken literally this mixes watts (the nodal powers, with no h or quadrature weights) and joules (the
    push-off term), so it is not an energy per weight and distance. It ranks candidates of one step on one
    grid; the COT of a chosen trajectory is recomputed with :func:`hip_energy` and :func:`cost_of_transport`
    (docs/model.md §5).
    """
    return float(cost_of_transport(float(np.sum(pcot)), total_mass, chord, g))
