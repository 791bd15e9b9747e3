"""The thesis's reading of a step's cost: how (3.77)–(3.79) would price a trajectory, as an evaluation mode.

The thesis computes a step's COT from its nodes alone: E_rot = (h/3) Σ_k w_k |τ1,k q̇1,k + τ2,k q̇2,k| over
t_1 … t_N (composite Simpson), E_lin = ½ m_stance |v_foot|² for the push-off, COT = (E_rot + E_lin) / (M g D).
Verification (:mod:`gaitbench.solve.verify`) instead integrates the power of the trajectory's own interpolant on a
fine grid and charges the push-off the kinetic energy its impulse adds; the two differ where the power changes
between the nodes and by the share of the push-off's energy that the stance foot alone does not carry
(docs/deviations.md, "The thesis's reading"). This module computes the thesis's figure for any solved step, so that
a walk can show both. It reads; it is never what a step is optimised for.

Nodes: the trajectory's nodal rates, and its control read at each node time (a piecewise-constant control, DMOC's,
gives the interval starting there, the last node the last interval's). Even N, which composite Simpson cannot
cover and the thesis used without saying how: Simpson's 3/8 rule on the last three intervals
(:func:`gaitbench.model.energetics.simpson_weights`). m_stance, undefined in the thesis: the stance leg's mass.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import asdict, dataclass

import numpy as np

from gaitbench.model.energetics import average_cot, cost_of_transport, hip_energy, hip_power
from gaitbench.model.mechanics import BipedModel
from gaitbench.model.robot import RobotParameters
from gaitbench.problem.gait_problem import StepData
from gaitbench.problem.trajectory import StepTrajectory
from gaitbench.solve.verify import push_off_charge


@dataclass(frozen=True)
class ThesisReading:
    """One step's cost as the thesis computes it."""

    hip_energy: float  # J, (h/3) Σ w_k |P_hip,k| over the nodes
    push_off_energy: float  # J, ½ m_stance |v_foot|² just after the push-off (0 without one)
    cot: float  # (hip_energy + push_off_energy) / (M_total g D)

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def nodal_hip_powers(trajectory: StepTrajectory) -> np.ndarray:
    """τ1 q̇1 + τ2 q̇2 at each node t_1 … t_N (W), signed."""
    tau = np.array([trajectory.control(float(t)) for t in trajectory.times])
    dq = np.asarray(trajectory.dq, dtype=float)
    return np.asarray(hip_power(dq[:, 0], dq[:, 1], tau[:, 0], tau[:, 1]), dtype=float)


def thesis_push_off_energy(trajectory: StepTrajectory, robot: RobotParameters,
                           model: BipedModel | None = None) -> float:
    """½ m_stance |v_foot|² of (3.77): the stance foot's speed just after the step's push-off impulse, at the
    stance leg's mass (:func:`~gaitbench.solve.verify.push_off_charge` under the ``thesis`` accounting).
    ``model``: the robot's 4-DOF model, built when not given."""
    if trajectory.push_off == 0.0:
        return 0.0
    return push_off_charge(model or BipedModel(robot, 4), trajectory, "thesis")


def thesis_reading(trajectory: StepTrajectory, data: StepData, model: BipedModel | None = None) -> ThesisReading:
    """The step's COT by (3.77)–(3.79): nodal |hip power| by composite Simpson over t_1 … t_N, push-off by
    ½ m_stance |v_foot|², over M_total g D. ``model``: the robot's 4-DOF model (reused across steps), built when
    not given and needed."""
    energy = hip_energy(trajectory.times, np.abs(nodal_hip_powers(trajectory)))
    push_off = thesis_push_off_energy(trajectory, data.robot, model)
    cot = cost_of_transport(energy + push_off, data.robot.total_mass, data.chord, data.robot.g)
    return ThesisReading(hip_energy=float(energy), push_off_energy=push_off, cot=float(cot))


def thesis_reading_acot(steps: Iterable[tuple[StepTrajectory, StepData]]) -> float:
    """The walk's ACOT read the thesis's way: the mean of :func:`thesis_reading`'s COT over its steps, given as
    (trajectory, data) pairs of one robot. Pass every step of a complete walk: a partial walk's mean is not its
    ACOT."""
    models: dict[RobotParameters, BipedModel] = {}
    cots = []
    for trajectory, data in steps:
        if data.robot not in models:
            models[data.robot] = BipedModel(data.robot, 4)
        cots.append(thesis_reading(trajectory, data, models[data.robot]).cot)
    return average_cot(cots)
