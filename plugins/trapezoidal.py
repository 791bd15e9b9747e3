"""Trapezoidal direct collocation: the second collocation scheme of DECISIONS §6.

States are collocated at the nodes only: the defects x_{k+1} − x_k − h/2 (f_k + f_{k+1}) are the trapezoid rule
applied to ẋ = f(x, u), second order. Controls are piecewise linear. The interpolant is the standard one (Betts,
*Practical Methods for Optimal Control*): per interval the state is the quadratic whose slope is linear between
f_k and f_{k+1}, so it passes through both nodes at a solution.

The hip energy is Simpson's rule on each interval with the interpolant's own midpoint, q̇_mid = (q̇_k + q̇_k+1)/2
+ (h/8)(q̈_k − q̈_k+1) and τ_mid = (τ_k + τ_k+1)/2 (the Hermite midpoint, which the quadratic passes through at a
solution). The interpolant's power is cubic on an interval, so this integrates it exactly, and |P| exactly
wherever P keeps its sign. The trapezoid rule on the nodes alone, which the defects suggest, sees nothing between
them, and the net-power cost let the optimizer make P vanish at every node while the trajectory it describes
costs hundreds of joules (forward, N = 20: objective 0, verified 690 J on step 1; docs/deviations.md).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.gait_problem import PARAMETER_LAYOUT, StepStructure
from gaitbench.mechanics import BipedFunctions
from gaitbench.nlp import NLPBuilder
from gaitbench.transcription import (
    Discretization,
    Interpolant,
    StepSymbols,
    Transcription,
    absolute_power,
    collocation_variables,
    locate_interval,
    sample_seed,
    state_derivative,
)
from plugins.hermite_simpson import midpoint_power_split

ROBOT, TIME_STEP = PARAMETER_LAYOUT["robot"], PARAMETER_LAYOUT["time_step"]


class Trapezoidal(Transcription):
    name = "trapezoidal"

    def discretize(self, structure: StepStructure, builder: NLPBuilder, symbols: StepSymbols,
                   model: BipedFunctions) -> Discretization:
        n = structure.n_nodes
        states, controls = collocation_variables(structure, builder)
        h = symbols.time_step
        dynamics = state_derivative(model)
        slopes = dynamics.map(n)(states, controls, ca.repmat(symbols.robot, 1, n))
        builder.constrain("dynamics", states[:, 1:] - states[:, :-1] - h / 2 * (slopes[:, :-1] + slopes[:, 1:]))
        builder.constrain("initial_state", states[:, 0] - symbols.initial_state)

        power_nodes = absolute_power(builder, structure, "power_nodes", controls, states[2:4, :])
        if structure.options.absolute_value == "slack":
            # |P| at the interpolant's midpoints, split as in absolute_power and declared per interval.
            positive = builder.variable("power_midpoints_positive", (1, n - 1), 0.0, np.inf)
            negative = builder.variable("power_midpoints_negative", (1, n - 1), 0.0, np.inf)
            interval = [states[:, :-1], states[:, 1:], controls[:, :-1], controls[:, 1:]]
            builder.constrain_intervals(["power_midpoints_split"], midpoint_power_split(dynamics),
                                        [*interval, positive, negative], symbols.vector)
            power_mid = positive + negative
        else:
            mid_states = 0.5 * (states[:, :-1] + states[:, 1:]) + h / 8 * (slopes[:, :-1] - slopes[:, 1:])
            mid_controls = 0.5 * (controls[:, :-1] + controls[:, 1:])
            power_mid = absolute_power(builder, structure, "power_midpoints", mid_controls, mid_states[2:4, :])
        hip_energy = h / 6 * (ca.sum2(power_nodes[:, :-1] + power_nodes[:, 1:]) + 4 * ca.sum2(power_mid))

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
                              accelerations=[slopes[2:4, k] for k in range(n)], hip_energy=hip_energy,
                              decode=decode, interpolant=interpolant, guess=guess)


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
