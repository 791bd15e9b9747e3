"""Hermite–Simpson direct collocation: the thesis's DC transcription (App. A (8.71)–(8.94)).

States are C¹ piecewise-cubic Hermite polynomials through the nodes with the dynamics' slopes there; controls are
piecewise linear. The only dynamic constraints are the Simpson defects, equivalent to collocation at interval
midpoints.

The hip energy integrates the interpolant's power (cubic velocities times linear torques: a quartic on each
interval) by Boole's rule, the nodes and ¼, ½, ¾ of the interval, exact for the quartic. ``quadrature="simpson"``
is Simpson's rule on each interval, its two nodes and its Hermite midpoint (the former default, not the thesis's
rule): its three points leave quartics that vanish at them unseen, and the net-power optimizer finds such powers, so the
verified COT exceeds the objective, on the upward slope by 33–51 % at every N from 10 to 160 (docs/convergence.md;
``objective_gap`` reports it per step). Boole's rule keeps the gap within 3.2 % there and 1.2 % on the forward walk,
and with the retry ladder every walk of the study completes with it. ``quadrature="nodal-simpson"`` is the thesis's
(3.77) as printed: composite Simpson over the nodes t_1 … t_N alone
(:func:`~gaitbench.model.energetics.simpson_weights`, Simpson's 3/8 rule on the last three intervals for even N). It
sees nothing between the nodes, and the optimizer puts every node's power at zero (docs/deviations.md, "Hip-energy
quadrature"): it is an evaluation mode (:mod:`gaitbench.solve.thesis_reading`), offered as an objective only to show
that.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.model.energetics import simpson_weights
from gaitbench.problem.gait_problem import N_STEP_PARAMETERS, PARAMETER_LAYOUT
from gaitbench.problem.step_cost import QUADRATURE_RULES, interval_running_costs, running_cost
from gaitbench.problem.trajectory import Interpolant, cubic_hermite, locate_interval, sample_seed
from gaitbench.problem.transcription import (
    Discretization,
    Transcription,
    checked_quadrature,
    collocation_variables,
    state_derivative,
)

QUADRATURES = ("simpson", "boole", "nodal-simpson")


class HermiteSimpson(Transcription):
    name = "hermite-simpson"

    def __init__(self, quadrature: str = "boole") -> None:
        super().__init__()
        self.quadrature = checked_quadrature(quadrature, QUADRATURES)

    def discretize(self, structure, builder, symbols, model):
        n = structure.n_nodes
        states, controls = collocation_variables(structure, builder)
        h = symbols.time_step
        dynamics = state_derivative(model)
        slopes = dynamics.map(n)(states, controls, ca.repmat(symbols.robot, 1, n))
        left, right = states[:, :-1], states[:, 1:]
        interval = [left, right, controls[:, :-1], controls[:, 1:]]
        builder.constrain_intervals(["dynamics"], simpson_defect(dynamics), interval, symbols.vector)
        builder.constrain("initial_state", states[:, 0] - symbols.initial_state)

        power_nodes = running_cost(builder, structure, "power_nodes", states[2:4, :], controls, symbols.robot)
        if self.quadrature == "boole":
            rule = QUADRATURE_RULES["boole"]
            interior = interval_running_costs(builder, structure, "power_interior",
                                              interior_motion(dynamics, rule.points), interval, symbols.vector)
            cost = h * (rule.end_weight * ca.sum2(power_nodes[:, :-1] + power_nodes[:, 1:])
                        + ca.sum2(ca.mtimes(ca.DM(rule.weights).T, interior)))
        elif self.quadrature == "nodal-simpson":
            cost = h * ca.mtimes(power_nodes, ca.DM(simpson_weights(n)))
        else:
            power_mid = interval_running_costs(builder, structure, "power_midpoints", midpoint_motion(dynamics),
                                               interval, symbols.vector)
            cost = h / 6 * (ca.sum2(power_nodes[:, :-1] + power_nodes[:, 1:]) + 4 * ca.sum2(power_mid))

        def unpack(blocks):
            return (np.reshape(blocks["states"], (4, n), order="F"),
                    np.reshape(blocks["torques"], (2, n), order="F"))

        def decode(blocks, p):
            xs, us = unpack(blocks)
            return xs[:2].T, xs[2:].T, us.T, np.arange(n) * p[14]

        def interpolant(blocks, p):
            xs, us = unpack(blocks)
            fs = np.asarray(dynamics.map(n)(xs, us, np.repeat(p[0:8, None], n, axis=1)))
            return hermite_interpolant(xs, fs, us, p[14])

        def guess(seed, p):
            q, dq, tau = sample_seed(seed, np.arange(n) * p[14])
            return {"states": np.vstack([q, dq]).flatten(order="F"), "torques": tau.flatten(order="F")}

        accelerations = [slopes[2:4, k] for k in range(n)]
        return Discretization(positions=states[:2, :], velocities=states[2:4, :], accelerations=accelerations,
                              running_cost=cost, decode=decode, interpolant=interpolant, guess=guess)


def _interval(dynamics: ca.Function):
    """One interval's symbols (x_k, x_k+1, u_k, u_k+1, p), its end slopes and its Hermite midpoint (8.80)."""
    left, right, u_left, u_right = ca.SX.sym("x_k", 4), ca.SX.sym("x_k1", 4), ca.SX.sym("u_k", 2), ca.SX.sym("u_k1", 2)
    p = ca.SX.sym("p", N_STEP_PARAMETERS)
    robot, h = p[PARAMETER_LAYOUT["robot"]], p[PARAMETER_LAYOUT["time_step"]]
    f_left, f_right = dynamics(left, u_left, robot), dynamics(right, u_right, robot)
    mid_state = 0.5 * (left + right) + h / 8 * (f_left - f_right)
    mid_control = 0.5 * (u_left + u_right)
    return ca.vertcat(left, right, u_left, u_right), p, f_left, f_right, mid_state, mid_control


def simpson_defect(dynamics: ca.Function) -> ca.Function:
    """The Simpson defect of one interval (8.79), with the Hermite midpoint state substituted."""
    z, p, f_left, f_right, mid_state, mid_control = _interval(dynamics)
    left, right = z[0:4], z[4:8]
    h = p[PARAMETER_LAYOUT["time_step"]]
    f_mid = dynamics(mid_state, mid_control, p[PARAMETER_LAYOUT["robot"]])
    defect = right - left - h / 6 * (f_left + 4 * f_mid + f_right)
    return ca.Function("hermite_simpson_defect", [z, p], [defect])


def midpoint_motion(dynamics: ca.Function) -> ca.Function:
    """(q̇, τ) at one interval's Hermite midpoint (8.80), as a function of (x_k, x_k+1, u_k, u_k+1) and p: where
    Simpson's rule reads the running cost inside the interval."""
    z, p, _, _, mid_state, mid_control = _interval(dynamics)
    return ca.Function("hermite_simpson_midpoint_motion", [z, p], [ca.vertcat(mid_state[2:4], mid_control)])


def interior_motion(dynamics: ca.Function, points: tuple[float, ...]) -> ca.Function:
    """(q̇, τ) of one interval's interpolant (cubic Hermite states, linear controls) at the fractions ``points`` of
    the interval, stacked, as a function of (x_k, x_k+1, u_k, u_k+1) and p."""
    z, p, f_left, f_right, _, _ = _interval(dynamics)
    left, right, u_left, u_right = z[0:4], z[4:8], z[8:10], z[10:12]
    h = p[PARAMETER_LAYOUT["time_step"]]
    motion = []
    for s in points:
        state, _ = cubic_hermite(left, right, h * f_left, h * f_right, s)
        motion += [state[2:4], (1 - s) * u_left + s * u_right]
    return ca.Function("hermite_interior_motion", [z, p], [ca.vertcat(*motion)])


def hermite_interpolant(states: np.ndarray, slopes: np.ndarray, controls: np.ndarray, h: float) -> Interpolant:
    """Cubic Hermite states through (x_k, f_k) and piecewise-linear controls (8.73)–(8.78)."""
    n = states.shape[1]

    def state(t):
        k, s = locate_interval(t, h, n)
        x, _ = cubic_hermite(states[:, k], states[:, k + 1], h * slopes[:, k], h * slopes[:, k + 1], s)
        return x[:2], x[2:]

    def control(t):
        k, s = locate_interval(t, h, n)
        return (1 - s) * controls[:, k] + s * controls[:, k + 1]

    return Interpolant(state=state, control=control)


@hookimpl
def register_transcriptions():
    return [Registration("hermite-simpson", "Hermite–Simpson direct collocation: cubic states, linear controls, "
                         "midpoint defects (the thesis's DC)", HermiteSimpson)]
