"""The objective's cost as a step NLP charges it: |P| by slack splitting, and the quadrature of its running cost.

Transcriptions call :func:`running_cost` (at nodes) and :func:`interval_running_costs` (at points inside each
interval, by a rule of :data:`QUADRATURE_RULES`); the transcription base charges the push-off's work with
:func:`charged`. Every method thus prices a step by the same rules, on its own interpolant.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from gaitbench.model.energetics import smooth_abs
from gaitbench.problem.gait_problem import PARAMETER_LAYOUT, StepStructure
from gaitbench.problem.nlp import NLPBuilder


def running_cost(builder: NLPBuilder, structure: StepStructure, name: str, dq: ca.SX, tau: ca.SX,
                 robot: ca.SX) -> ca.SX:
    """The objective's running cost (:mod:`gaitbench.problem.objective`) at each column of the role-order rates and
    torques ``dq``, ``tau`` (2 × n), as a 1 × n row: its charged powers by :func:`charged`, plus its smooth rate."""
    objective = structure.objective
    args = (dq[0, :], dq[1, :], tau[0, :], tau[1, :])
    charges = charged(builder, structure, name, ca.vertcat(*objective.powers(*args)))
    rate = charges if charges.shape[0] <= 1 else ca.sum1(charges)
    smooth = objective.smooth_rate(*args, robot)
    return _plus(rate, smooth)


def charged(builder: NLPBuilder, structure: StepStructure, name: str, powers: ca.SX) -> ca.SX:
    """w⁺ max(P, 0) + w⁻ max(−P, 0) for each entry of ``powers`` (any shape), the weights the objective's, as the
    NLP sees it by ``structure.options.absolute_value``.

    ``slack`` (default): P = s⁺ − s⁻ with s± ≥ 0 as new variables (blocks ``name_positive``, ``name_negative``, the
    constraint ``name_split``) and the charge w⁺ s⁺ + w⁻ s⁻, exact at any optimum and smooth for the solver.
    ``smooth``: the thesis's √(P² + ε²) for |P| (docs/model.md §5), whose kink of curvature 1/ε makes interior-point
    solvers crawl; kept to reproduce the thesis.
    """
    if powers.numel() == 0:
        return powers
    objective = structure.objective
    positive_weight, negative_weight = objective.positive_weight, objective.negative_weight
    if structure.options.absolute_value == "smooth":
        magnitude = smooth_abs(powers, structure.options.smoothing_eps)
        if positive_weight == negative_weight:
            return _scaled(magnitude, positive_weight)
        return ((positive_weight + negative_weight) / 2 * magnitude
                + (positive_weight - negative_weight) / 2 * powers)
    positive = builder.variable(f"{name}_positive", powers.shape, 0.0, np.inf)
    negative = builder.variable(f"{name}_negative", powers.shape, 0.0, np.inf)
    builder.constrain(f"{name}_split", powers - positive + negative)
    return _scaled(positive, positive_weight) + _scaled(negative, negative_weight)


def _scaled(values: ca.SX, weight: float) -> ca.SX:
    return values if weight == 1.0 else weight * values


def _plus(values: ca.SX, more: ca.SX | None) -> ca.SX:
    if more is None:
        return values
    return more if values.numel() == 0 else values + more


def _channel_sum(charges: ca.SX, channels: int) -> ca.SX:
    """Rows i·c … i·c + c − 1 of ``charges`` (point-major, c = ``channels``) summed: one row per point."""
    if channels == 1 or charges.numel() == 0:
        return charges
    return ca.vertcat(*[ca.sum1(charges[i * channels:(i + 1) * channels, :])
                        for i in range(charges.shape[0] // channels)])


@dataclass(frozen=True)
class QuadratureRule:
    """An interpolatory rule on one interval, as fractions of it: the weight of each of its two ends and its
    interior points with their weights (the weights sum to 1)."""

    end_weight: float
    points: tuple[float, ...]
    weights: tuple[float, ...]


QUADRATURE_RULES = {
    "trapezoid": QuadratureRule(1 / 2, (), ()),
    "simpson": QuadratureRule(1 / 6, (1 / 2,), (4 / 6,)),
    "boole": QuadratureRule(7 / 90, (1 / 4, 1 / 2, 3 / 4), (32 / 90, 12 / 90, 32 / 90)),
}
"""Rules for the hip energy ∫|τ·q̇| dt of one interval, applied to the power of the transcription's own interpolant.

``boole`` (the default of every transcription) is exact for polynomials of degree 5. Each interpolant's power is a
polynomial on an interval (DMOC: quadratic, trapezoidal: cubic, Hermite–Simpson: quartic), so Boole's rule is its
exact energy wherever the power keeps its sign, and with five points no nonzero power of those degrees vanishes at
all of them. Rules with fewer points than that let the net-power optimizer put the power's zeros on the points
(docs/deviations.md, "Hip-energy quadrature"); where the power changes sign inside an interval every rule is
approximate, and Boole's is within 2.2 % for the sign change at the midpoint that zero net work on an interval
makes (a linear power through zero there)."""


def interval_running_costs(builder: NLPBuilder, structure: StepStructure, name: str, motion: ca.Function,
                           variables: list[ca.SX], parameters: ca.SX) -> ca.SX:
    """The objective's running cost at m points of each interval, as an m × M matrix.

    ``motion(z_k, p)`` gives the role-order (q̇_st, q̇_sw, τ_st, τ_sw) at the m points stacked (4m × 1); z_k stacks
    column k of each of ``variables``. The charged powers are split as in :func:`charged`, declared per interval,
    so that the NLP gets its per-interval Hessian.
    """
    objective = structure.objective
    n_intervals, m = variables[0].shape[1], motion.size1_out(0) // 4
    c = len(objective.channels)
    n_z = motion.size1_in(0)
    z, p = ca.SX.sym("z", n_z), ca.SX.sym("p", motion.size1_in(1))
    values = motion(z, p)
    powers, smooth = [], []
    for i in range(m):
        args = (values[4 * i], values[4 * i + 1], values[4 * i + 2], values[4 * i + 3])
        powers += objective.powers(*args)
        rate = objective.smooth_rate(*args, p[PARAMETER_LAYOUT["robot"]])
        if rate is not None:
            smooth.append(rate)
    stacked = ca.repmat(parameters, 1, n_intervals)
    smooth_rates = (ca.Function(f"{name}_smooth", [z, p], [ca.vertcat(*smooth)]).map(n_intervals)(
        ca.vertcat(*variables), stacked) if smooth else None)
    if not powers:
        return smooth_rates
    power_function = ca.Function(f"{name}_powers", [z, p], [ca.vertcat(*powers)])
    if structure.options.absolute_value != "slack":
        charges = charged(builder, structure, name, power_function.map(n_intervals)(ca.vertcat(*variables), stacked))
        return _plus(_channel_sum(charges, c), smooth_rates)
    rows = c * m
    positive = builder.variable(f"{name}_positive", (rows, n_intervals), 0.0, np.inf)
    negative = builder.variable(f"{name}_negative", (rows, n_intervals), 0.0, np.inf)
    split_z = ca.SX.sym("z", n_z + 2 * rows)
    split = ca.Function(f"{name}_split", [split_z, p], [power_function(split_z[:n_z], p)
                                                          - split_z[n_z:n_z + rows] + split_z[n_z + rows:]])
    builder.constrain_intervals([f"{name}_split"], split, [*variables, positive, negative], parameters)
    charges = (_scaled(positive, objective.positive_weight) + _scaled(negative, objective.negative_weight))
    return _plus(_channel_sum(charges, c), smooth_rates)
