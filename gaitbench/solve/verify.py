"""Verification of every solved step: is it a trajectory of the robot, and what does it really cost?

The optimizer's objective is not trusted for reporting (docs/model.md §5): the COT is recomputed from the trajectory's
own interpolant on a fine grid with the step's objective (:mod:`gaitbench.problem.objective`) read exactly (|·| without
slacks or smoothing), and the trajectory is re-simulated with the core simulator driven
by its controls from its initial state.

The objective is still compared with the verified COT: a transcription whose cost quadrature sees less than its
trajectory does lets the optimizer exploit the difference (the net-power cost makes opposing torques free wherever
the quadrature does not look), and the two then disagree. ``objective_gap`` measures it, and ``objective_agrees``
says whether it is within :data:`~gaitbench.acceptance.OBJECTIVE_RTOL` (with the absolute floor
:data:`~gaitbench.acceptance.OBJECTIVE_ATOL`).
"""

from __future__ import annotations

import math

import numpy as np

from gaitbench.acceptance import OBJECTIVE_RTOL, StepVerification, objective_gap
from gaitbench.model.energetics import cost_of_transport, hip_energy, push_off_work
from gaitbench.model.mechanics import BipedModel
from gaitbench.model.robot import RobotParameters
from gaitbench.model.simulate import OpenLoop, simulate
from gaitbench.problem.gait_problem import StepData, role_robot_vector
from gaitbench.problem.objective import Objective
from gaitbench.problem.trajectory import StepTrajectory
from gaitbench.problem.transcription import TranscribedStep

SAMPLES_PER_INTERVAL = 16
INSIDE = 1e-9
"""How far inside an interval (relative to its length) the fine grid reads the controls at its two ends: on the
interval's own side of a jump at a node (DMOC's piecewise-constant torques), within ~1e-9 of the end otherwise."""


def verify_step(
    built: TranscribedStep, x: np.ndarray, data: StepData, trajectory: StepTrajectory, model: BipedModel
) -> StepVerification:
    """``model`` is the 4-DOF model for second-phase steps (push-off acts) and the 2-DOF model otherwise."""
    p = data.parameter_vector()
    # the |P| slacks settled, as the objective is valued: they stand for the cost, not for the motion
    settled = built.settle_slacks(x, p)
    violations = built.nlp.block_violations(settled, p) | built.nlp.bound_violations(settled)
    max_defect = violations.pop("dynamics")
    # NaN, a constraint that cannot be evaluated at this point, counts as the worst violation
    violations = {name: math.inf if math.isnan(value) else value for name, value in violations.items()}
    violated = max(violations, key=violations.get, default=None)
    max_violation = violations[violated] if violated is not None else 0.0

    energy, push_off_energy, cot = trajectory_cost(trajectory, built.structure.objective, data.robot, data.chord,
                                                   model, built.structure.options.push_off_cost)

    resim = resimulate(trajectory, data, model)
    reached = min(len(resim.q), len(trajectory.q))  # fewer nodes when the integration failed inside the step
    errors = np.abs(np.hstack([resim.q[:reached, :2] - trajectory.q[:reached],
                               resim.dq[:reached, :2] - trajectory.dq[:reached]])).max(axis=1)
    errors = np.r_[errors, np.full(len(trajectory.q) - reached, np.inf)]  # a motion the robot could not follow
    objective_cot = built.objective_cot(x, data) if built.cost_of_transport is not None else None
    gap = None if objective_cot is None else objective_gap(float(cot), objective_cot)
    return StepVerification(
        max_defect=float(max_defect),
        max_violation=float(max_violation),
        violated=violated if max_violation > 0 else None,
        resim_error=float(errors[-1]),
        resim_max_error=float(errors.max()),
        hip_energy=float(energy),
        push_off_energy=float(push_off_energy),
        cot=float(cot),
        objective_cot=objective_cot,
        objective_gap=gap,
        objective_agrees=None if gap is None else bool(abs(gap) <= OBJECTIVE_RTOL),
    )


def trajectory_cost(trajectory: StepTrajectory, objective: Objective, robot: RobotParameters, chord: float,
                    model: BipedModel, push_off_cost: str) -> tuple[float, float, float]:
    """What a step's trajectory costs under ``objective``, read exactly from its interpolant: the running cost on a
    fine grid (J), what the push-off is charged (J; 4-DOF ``model`` only) and the COT of both over the chord."""
    energy = fine_grid_running_cost(trajectory, objective, role_robot_vector(robot, trajectory.stance))
    push_off_energy = push_off_charge(model, trajectory, push_off_cost) if model.dof == 4 else 0.0
    cot = cost_of_transport(energy + objective.event_cost(push_off_energy), robot.total_mass, chord, robot.g)
    return energy, push_off_energy, cot


def push_off_charge(model: BipedModel, trajectory: StepTrajectory, accounting: str) -> float:
    """What the step's push-off is charged (J) under ``accounting`` (``ProblemOptions.push_off_cost``): the kinetic
    energy the impulse adds to the robot, or the thesis's ½ m_stance |v_foot|² (:func:`push_off_work`)."""
    foot = np.zeros(2)
    dq_plus, gain = model.push_off(np.r_[trajectory.q[-1], foot], np.r_[trajectory.dq[-1], foot],
                                   trajectory.push_off, trajectory.stance)
    stance_mass = role_robot_vector(model.robot, trajectory.stance)[0]
    return float(push_off_work(accounting, gain, np.ravel(dq_plus)[2:4], stance_mass))


def fine_grid_running_cost(trajectory: StepTrajectory, objective: Objective, robot: np.ndarray,
                           samples_per_interval: int = SAMPLES_PER_INTERVAL) -> float:
    """∫ r dt of the objective's running cost (exact, ∫ |τ·q̇| dt under ``net-power``) from the interpolant,
    Simpson on a grid ``samples_per_interval`` times finer than the nodes; ``robot`` in role order.

    Each interval is integrated on its own, its ends read just inside it (:data:`INSIDE`): controls may jump at
    the nodes (DMOC's are piecewise constant), and one composite rule across the step would read the power at a
    node with the next interval's torque on both sides (3 % of the energy of DMOC's forward step 2 at N = 50).
    """
    times = trajectory.times
    fractions = np.clip(np.linspace(0.0, 1.0, samples_per_interval + 1), INSIDE, 1.0 - INSIDE)
    energy = 0.0
    for start, end in zip(times[:-1], times[1:], strict=True):
        samples = start + (end - start) * fractions
        tau = np.array([trajectory.control(t) for t in samples])
        dq = np.array([trajectory.state(t)[1] for t in samples])
        rate = objective.rate(dq, tau, trajectory.stance, robot)
        energy += hip_energy((end - start) / samples_per_interval, rate)
    return energy


def resimulate(trajectory: StepTrajectory, data: StepData, model: BipedModel):
    """The step re-simulated from its initial state under its own controls, sampled at its nodes."""
    q0, dq0 = trajectory.q[0], trajectory.dq[0]
    if model.dof == 4:
        q0, dq0 = np.r_[q0, 0.0, 0.0], np.r_[dq0, 0.0, 0.0]
    control = OpenLoop(lambda t, step: trajectory.control(t), [trajectory.push_off if model.dof == 4 else 0.0])
    walk = simulate(model, [data.slope], q0, dq0, control, first_stance=data.stance, step_times=[trajectory.times])
    return walk.steps[0]
