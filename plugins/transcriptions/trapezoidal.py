"""Trapezoidal direct collocation: the second collocation scheme of docs/model.md §6.

States are collocated at the nodes only: the defects x_{k+1} − x_k − h/2 (f_k + f_{k+1}) are the trapezoid rule
applied to ẋ = f(x, u), second order. Controls are piecewise linear. The interpolant is the standard one (Betts,
*Practical Methods for Optimal Control*): per interval the state is the quadratic whose slope is linear between
f_k and f_{k+1}, so it passes through both nodes at a solution.

The hip energy (the objective's running cost, :mod:`gaitbench.problem.objective`) integrates the interpolant's own power
by Boole's rule on each interval: at the nodes and at ¼, ½ and ¾ of the interval (the quadratic states there, the
linear torques), weights 7, 32, 12, 32, 7 over 90. The power
(quadratic velocities times linear torques) is a cubic on an interval, which the rule integrates exactly, so the
objective is the energy verification measures wherever the power keeps its sign. ``quadrature="trapezoid"`` is the
trapezoid rule on the nodes alone, the quadrature the defects suggest: it sees nothing between the nodes, and the
net-power optimizer made the power vanish at every node while the trajectory cost hundreds of joules (forward,
N = 20: objective 0, verified 690 J on step 1). ``quadrature="simpson"`` adds the interpolant's midpoint, which
still leaves a cubic that vanishes at its three points unseen: gaps of up to 5 % on the forward walk and 50 % on the
upward slope, against 3 % and 12 % with Boole, with which IPOPT solves about as many steps (38 against 40 of 52 in
eight forward and upward-slope walks, N = 20 … 160; docs/convergence.md).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.model.mechanics import BipedFunctions
from gaitbench.problem.gait_problem import N_STEP_PARAMETERS, PARAMETER_LAYOUT, StepStructure
from gaitbench.problem.nlp import NLPBuilder
from gaitbench.problem.step_cost import QUADRATURE_RULES, interval_running_costs, running_cost
from gaitbench.problem.trajectory import Interpolant, locate_interval, sample_seed
from gaitbench.problem.transcription import (
    Discretization,
    StepSymbols,
    Transcription,
    checked_quadrature,
    collocation_variables,
    state_derivative,
)

ROBOT, TIME_STEP = PARAMETER_LAYOUT["robot"], PARAMETER_LAYOUT["time_step"]


QUADRATURES = ("boole", "simpson", "trapezoid")


class Trapezoidal(Transcription):
    name = "trapezoidal"

    def __init__(self, quadrature: str = "boole") -> None:
        super().__init__()
        self.quadrature = checked_quadrature(quadrature, QUADRATURES)

    def discretize(self, structure: StepStructure, builder: NLPBuilder, symbols: StepSymbols,
                   model: BipedFunctions) -> Discretization:
        n = structure.n_nodes
        states, controls = collocation_variables(structure, builder)
        h = symbols.time_step
        dynamics = state_derivative(model)
        slopes = dynamics.map(n)(states, controls, ca.repmat(symbols.robot, 1, n))
        builder.constrain("dynamics", states[:, 1:] - states[:, :-1] - h / 2 * (slopes[:, :-1] + slopes[:, 1:]))
        builder.constrain("initial_state", states[:, 0] - symbols.initial_state)

        power_nodes = running_cost(builder, structure, "power_nodes", states[2:4, :], controls, symbols.robot)
        rule = QUADRATURE_RULES[self.quadrature]
        cost = h * rule.end_weight * ca.sum2(power_nodes[:, :-1] + power_nodes[:, 1:])
        if rule.points:
            interval = [states[:, :-1], states[:, 1:], controls[:, :-1], controls[:, 1:]]
            interior = interval_running_costs(builder, structure, "power_interior",
                                              interior_motion(dynamics, rule.points), interval, symbols.vector)
            cost += h * ca.sum2(ca.mtimes(ca.DM(rule.weights).T, interior))

        def unpack(blocks):
            return (np.reshape(blocks["states"], (4, n), order="F"),
                    np.reshape(blocks["torques"], (2, n), order="F"))

        def decode(blocks, p):
            xs, us = unpack(blocks)
            return xs[:2].T, xs[2:].T, us.T, np.arange(n) * p[TIME_STEP]

        def interpolant(blocks, p):
            xs, us = unpack(blocks)
            fs = np.asarray(dynamics.map(n)(xs, us, np.repeat(p[ROBOT, None], n, axis=1)))
            return trapezoidal_interpolant(xs, fs, us, p[TIME_STEP])

        def guess(seed, p):
            q, dq, tau = sample_seed(seed, np.arange(n) * p[TIME_STEP])
            return {"states": np.vstack([q, dq]).flatten(order="F"), "torques": tau.flatten(order="F")}

        return Discretization(positions=states[:2, :], velocities=states[2:4, :],
                              accelerations=[slopes[2:4, k] for k in range(n)], running_cost=cost,
                              decode=decode, interpolant=interpolant, guess=guess)


def interior_motion(dynamics: ca.Function, points: tuple[float, ...]) -> ca.Function:
    """(q̇, τ) of one interval's interpolant (below) at the fractions ``points`` of the interval, stacked, as a
    function of (x_k, x_k+1, u_k, u_k+1) and p."""
    left, right = ca.SX.sym("x_k", 4), ca.SX.sym("x_k1", 4)
    u_left, u_right = ca.SX.sym("u_k", 2), ca.SX.sym("u_k1", 2)
    p = ca.SX.sym("p", N_STEP_PARAMETERS)
    robot, h = p[ROBOT], p[TIME_STEP]
    f_left, f_right = dynamics(left, u_left, robot), dynamics(right, u_right, robot)
    motion = []
    for s in points:
        dq = left[2:4] + f_left[2:4] * s * h + s**2 * h / 2 * (f_right[2:4] - f_left[2:4])
        motion += [dq, (1 - s) * u_left + s * u_right]
    return ca.Function("trapezoidal_interior_motion", [ca.vertcat(left, right, u_left, u_right), p],
                       [ca.vertcat(*motion)])


def trapezoidal_interpolant(states: np.ndarray, slopes: np.ndarray, controls: np.ndarray, h: float) -> Interpolant:
    """x(t) = x_k + f_k s + s²/(2h) (f_{k+1} − f_k), s = t − t_k, and piecewise-linear controls."""
    n = states.shape[1]

    def locate(t):
        k, fraction = locate_interval(t, h, n)
        return k, fraction * h

    def state(t):
        k, s = locate(t)
        x = states[:, k] + slopes[:, k] * s + s**2 / (2 * h) * (slopes[:, k + 1] - slopes[:, k])
        return x[:2], x[2:]

    def control(t):
        k, s = locate(t)
        return controls[:, k] + s / h * (controls[:, k + 1] - controls[:, k])

    return Interpolant(state=state, control=control)


@hookimpl
def register_transcriptions():
    return [Registration("trapezoidal", "Trapezoidal direct collocation: defects at the nodes, quadratic states, "
                         "linear controls (second order)", Trapezoidal)]
