"""Discrete mechanics and optimal control (DMOC): the thesis's DM transcription in its consistent form.

The configuration is discretized, not the state: positions q_k at the nodes, the midpoint discrete Lagrangian
L_d(q_k, q_{k+1}) = h L((q_k + q_{k+1})/2, (q_{k+1} − q_k)/h) on each interval, and one constant torque τ_k per
interval whose discrete forces are f_k^± = (h/2) τ_k (docs/model.md §6; thesis §2.3 and §8.2 with the
corrected "+" sign of (8.49)). The dynamics are a momentum balance at every node: the momentum arriving from the
interval before (the forced discrete Legendre transform p_k⁺ = D2 L_d(q_{k−1}, q_k) + (h/2) τ_{k−1}) equals the
momentum leaving into the interval after (p_k⁻ = −D1 L_d(q_k, q_{k+1}) − (h/2) τ_k). At the two ends the
continuous momenta M(q) q̇ of the boundary velocities take their place ((8.58), (8.60) corrected), so the
heel-strike and push-off maps act on true velocities.

The hip energy (the objective's running cost, :mod:`gaitbench.problem.objective`; below for the default ``net-power``)
integrates each interval's own power P_k(s) = τ_k·q̇(s) by Boole's rule, at the nodes and at ¼, ½
and ¾ of the interval, weights 7, 32, 12, 32, 7 over 90 (``interval_motion``). The velocities at the interval's ends
are its forced discrete Legendre transforms, the momenta with which its discrete forces f_k^± = (h/2) τ_k act at
its two nodes (equal to the node velocities by the discrete Euler–Lagrange equations); inside, the velocity is that
of the cubic Hermite positions through them, the interpolant verification and tracking use. With τ_k constant that
power is a quadratic in time, so the rule integrates it exactly: its signed sum is the interval's discrete work
τ_k·(q_k+1 − q_k) = h τ_k·v_k, what the midpoint discrete Lagrangian accounts for, and its |P| is the energy
wherever the power keeps its sign in the interval.

Why not the discrete Lagrangian's midpoint rule Σ h |τ_k·v_k| (``quadrature="midpoint"``, docs/model.md §5 read
literally)? It measures that net work, |∫P|, not ∫|P|. The net-power cost is blind to torques orthogonal to the
velocity, and the optimizer used the difference to accelerate the legs for free: on the forward walk's step 2 at
N = 20, torques up to 2700 N·m whose power is −4900 W at one end of an interval, +5050 W at the other and zero at its
midpoint. The robot re-simulated under those torques does pay for them: on the same step at N = 50 the objective
was 38 J, the interpolant's hip energy 386 J and the re-simulated robot's 387 J (COT 0.061 against 0.615), and the
gap grew with N. The interpolant was not at fault, since the re-simulation agrees with it; piecewise-linear
positions (velocity v_k on each interval) would have made the verified energy equal the old objective by hiding
an energy the robot spends. Simpson's rule on the same power (``quadrature="simpson"``) closed the gap on the
forward walk but not where the optimum lives on the cost of accelerating with constant torques: there the power
is nearly linear through zero at each interval's midpoint (zero net work), which Simpson charges two thirds of
(upward slope, step 1: gaps of 30 %). Boole's five points charge it within 2.2 %: gaps ≤ 1 % on the forward walk,
≤ 6 % on the upward slope's cheaper steps (docs/convergence.md).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.model.mechanics import BipedFunctions
from gaitbench.problem.gait_problem import N_STEP_PARAMETERS, PARAMETER_LAYOUT, StepStructure
from gaitbench.problem.nlp import NLPBuilder
from gaitbench.problem.step_cost import QUADRATURE_RULES, interval_running_costs, running_cost
from gaitbench.problem.trajectory import Interpolant, cubic_hermite, locate_interval, sample_seed
from gaitbench.problem.transcription import (
    Discretization,
    StepSymbols,
    Transcription,
    angle_box,
    checked_quadrature,
)

TIME_STEP = PARAMETER_LAYOUT["time_step"]


QUADRATURES = ("boole", "simpson", "midpoint")


class DiscreteMechanics(Transcription):
    name = "dmoc"

    def __init__(self, quadrature: str = "boole") -> None:
        super().__init__()
        self.quadrature = checked_quadrature(quadrature, QUADRATURES)

    def discretize(self, structure: StepStructure, builder: NLPBuilder, symbols: StepSymbols,
                   model: BipedFunctions) -> Discretization:
        n = structure.n_nodes
        limits = structure.options.limits
        q = builder.variable("positions", (2, n), *angle_box(structure))
        dq_start = builder.variable("start_velocity", (2, 1), -limits.dq_max, limits.dq_max)
        dq_end = builder.variable("end_velocity", (2, 1), -limits.dq_max, limits.dq_max)
        tau = builder.variable("torques", (2, n - 1), -limits.tau_max, limits.tau_max)
        h, robot = symbols.time_step, symbols.robot

        slopes = _discrete_lagrangian_slopes(model).map(n - 1)
        d1, d2 = slopes(q[:, :-1], q[:, 1:], ca.repmat(h, 1, n - 1), ca.repmat(robot, 1, n - 1))
        momentum = _momentum(model)
        arriving = ca.horzcat(momentum(q[:, 0], dq_start, robot), d2 + h / 2 * tau)
        leaving = ca.horzcat(-d1 - h / 2 * tau, momentum(q[:, -1], dq_end, robot))
        # Node by node in g's order: the start node, the interior nodes as one function of their neighbourhood
        # (which gives the NLP its per-node structure, so IPOPT's derivatives come from that function), the end node.
        builder.constrain("dynamics", arriving[:, 0] - leaving[:, 0])
        builder.constrain_intervals(["dynamics"], momentum_balance(model),
                                    [q[:, :-2], q[:, 1:-1], q[:, 2:], tau[:, :-1], tau[:, 1:]], symbols.vector)
        builder.constrain("dynamics", arriving[:, -1] - leaving[:, -1])
        builder.constrain("initial_state", ca.vertcat(q[:, 0], dq_start) - symbols.initial_state)

        # DMOC velocities live on the intervals (thesis §8.3.2); the thesis bounds these finite differences.
        v = (q[:, 1:] - q[:, :-1]) / h
        builder.constrain("velocity_bounds", v, -limits.dq_max, limits.dq_max)
        if self.quadrature == "midpoint":
            cost = h * ca.sum2(running_cost(builder, structure, "power_intervals", v, tau, robot))
        else:
            rule = QUADRATURE_RULES[self.quadrature]
            points, weights = (0.0, *rule.points, 1.0), (rule.end_weight, *rule.weights, rule.end_weight)
            rates = interval_running_costs(builder, structure, "power_intervals", interval_motion(model, points),
                                           [q[:, :-1], q[:, 1:], tau], symbols.vector)
            cost = h * ca.sum2(ca.mtimes(ca.DM(weights).T, rates))

        # Node velocities M(q_k)⁻¹ p_k⁺ (thesis (8.50)–(8.52)); the boundary velocities themselves at the two ends.
        interior = _velocity(model).map(n - 2)(q[:, 1:-1], arriving[:, 1:-1], ca.repmat(robot, 1, n - 2))
        velocities = ca.horzcat(dq_start, interior, dq_end)
        nodal_velocities = ca.Function("nodal_velocities", [q, dq_start, dq_end, tau, symbols.vector], [velocities])
        # Central second differences at the interior nodes; none at the two ends, which lack a neighbour.
        accelerations = [None] + [(v[:, k] - v[:, k - 1]) / h for k in range(1, n - 1)] + [None]

        def nodes(blocks, p):
            qs = np.reshape(blocks["positions"], (2, n), order="F")
            taus = np.reshape(blocks["torques"], (2, n - 1), order="F")
            dqs = np.asarray(nodal_velocities(qs, blocks["start_velocity"], blocks["end_velocity"], taus, p))
            return qs, dqs, taus

        def decode(blocks, p):
            qs, dqs, taus = nodes(blocks, p)
            return qs.T, dqs.T, taus.T, np.arange(n - 1) * p[TIME_STEP]

        def interpolant(blocks, p):
            return dmoc_interpolant(*nodes(blocks, p), p[TIME_STEP])

        def guess(seed, p):
            h = p[TIME_STEP]
            q_guess, dq_guess, _ = sample_seed(seed, np.arange(n) * h)
            _, _, tau_guess = sample_seed(seed, (np.arange(n - 1) + 0.5) * h)  # the interval's forcing
            return {"positions": q_guess.flatten(order="F"), "start_velocity": dq_guess[:, 0],
                    "end_velocity": dq_guess[:, -1], "torques": tau_guess.flatten(order="F")}

        return Discretization(positions=q, velocities=velocities, accelerations=accelerations,
                              running_cost=cost, decode=decode, interpolant=interpolant, guess=guess)


def _discrete_lagrangian_slopes(model: BipedFunctions) -> ca.Function:
    """(q_a, q_b, h, p) -> (D1 L_d, D2 L_d) of the midpoint discrete Lagrangian (App. A (8.44), α = ½)."""
    q_a, q_b, h, p = ca.SX.sym("q_a", 2), ca.SX.sym("q_b", 2), ca.SX.sym("h"), ca.SX.sym("p", 8)
    q_mid, v = (q_a + q_b) / 2, (q_b - q_a) / h
    discrete_lagrangian = h * (model.kinetic_energy(q_mid, v, p) - model.potential_energy(q_mid, p))
    return ca.Function("discrete_lagrangian_slopes", [q_a, q_b, h, p],
                       [ca.gradient(discrete_lagrangian, q_a), ca.gradient(discrete_lagrangian, q_b)])


def momentum_balance(model: BipedFunctions) -> ca.Function:
    """The forced discrete Euler–Lagrange equation at an interior node k, arriving minus leaving momentum, as a
    function of (q_k−1, q_k, q_k+1, τ_k−1, τ_k): D2 L_d(q_k−1, q_k) + (h/2) τ_k−1 + D1 L_d(q_k, q_k+1) + (h/2) τ_k."""
    q_before, q_node, q_after = ca.SX.sym("q_before", 2), ca.SX.sym("q_node", 2), ca.SX.sym("q_after", 2)
    tau_before, tau_after = ca.SX.sym("tau_before", 2), ca.SX.sym("tau_after", 2)
    p = ca.SX.sym("p", N_STEP_PARAMETERS)
    robot, h = p[PARAMETER_LAYOUT["robot"]], p[TIME_STEP]
    slopes = _discrete_lagrangian_slopes(model)
    _, arriving = slopes(q_before, q_node, h, robot)
    leaving, _ = slopes(q_node, q_after, h, robot)
    balance = (arriving + h / 2 * tau_before) - (-leaving - h / 2 * tau_after)
    return ca.Function("dmoc_momentum_balance", [ca.vertcat(q_before, q_node, q_after, tau_before, tau_after), p],
                       [balance])


def interval_motion(model: BipedFunctions, points: tuple[float, ...] = (0.0, 0.5, 1.0)) -> ca.Function:
    """(q̇, τ_k) of one interval's interpolant at the fractions ``points`` of the interval, stacked, from
    (q_k, q_k+1, τ_k): where the objective's running cost is read (the hip power τ_k·q̇ under ``net-power``).

    The end velocities are the interval's own forced discrete Legendre transforms, M(q_k)⁻¹ (−D1 L_d − (h/2) τ_k)
    and M(q_k+1)⁻¹ (D2 L_d + (h/2) τ_k), which the discrete Euler–Lagrange equations make the node velocities;
    inside, the velocity is that of the cubic Hermite positions through them (at the midpoint
    (3/2) v_k − (q̇_k + q̇_k+1)/4). With τ_k constant a power is a quadratic on the interval.
    """
    q_a, q_b, tau = ca.SX.sym("q_a", 2), ca.SX.sym("q_b", 2), ca.SX.sym("tau", 2)
    p = ca.SX.sym("p", N_STEP_PARAMETERS)
    robot, h = p[PARAMETER_LAYOUT["robot"]], p[TIME_STEP]
    d1, d2 = _discrete_lagrangian_slopes(model)(q_a, q_b, h, robot)
    dq_start = ca.solve(model.mass(q_a, robot), -d1 - h / 2 * tau)
    dq_end = ca.solve(model.mass(q_b, robot), d2 + h / 2 * tau)
    motion = []
    for s in points:
        motion += [cubic_hermite(q_a, q_b, h * dq_start, h * dq_end, s)[1] / h, tau]
    return ca.Function("dmoc_interval_motion", [ca.vertcat(q_a, q_b, tau), p], [ca.vertcat(*motion)])


def _momentum(model: BipedFunctions) -> ca.Function:
    """(q, q̇, p) -> ∂L/∂q̇ = M(q) q̇, the continuous Legendre transform."""
    q, dq, p = ca.SX.sym("q", 2), ca.SX.sym("dq", 2), ca.SX.sym("p", 8)
    return ca.Function("momentum", [q, dq, p], [ca.mtimes(model.mass(q, p), dq)])


def _velocity(model: BipedFunctions) -> ca.Function:
    """(q, p_k, p) -> M(q)⁻¹ p_k, the velocity of a node momentum."""
    q, momentum, p = ca.SX.sym("q", 2), ca.SX.sym("momentum", 2), ca.SX.sym("p", 8)
    return ca.Function("velocity", [q, momentum, p], [ca.solve(model.mass(q, p), momentum)])


def dmoc_interpolant(positions: np.ndarray, velocities: np.ndarray, torques: np.ndarray, h: float) -> Interpolant:
    """Cubic Hermite positions through (q_k, q̇_k) with their derivative as velocity; piecewise-constant torques."""
    n = positions.shape[1]

    def state(t):
        k, s = locate_interval(t, h, n)
        slopes = h * velocities[:, k], h * velocities[:, k + 1]
        q, dq_ds = cubic_hermite(positions[:, k], positions[:, k + 1], *slopes, s)
        return q, dq_ds / h

    def control(t):
        return torques[:, locate_interval(t, h, n)[0]]

    return Interpolant(state=state, control=control)


@hookimpl
def register_transcriptions():
    return [Registration("dmoc", "Discrete mechanics (DMOC): midpoint discrete Lagrangian, forced discrete "
                         "Euler–Lagrange equations, constant torque per interval (second order)", DiscreteMechanics)]
