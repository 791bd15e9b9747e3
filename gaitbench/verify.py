"""Verification of every solved step: is it a trajectory of the robot, and what does it really cost?

The optimizer's objective is not trusted for reporting (DECISIONS §5): the COT is recomputed from the trajectory's
own interpolant on a fine grid with exact |power|, and the trajectory is re-simulated with the core simulator driven
by its controls from its initial state.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from gaitbench.energetics import cost_of_transport, hip_energy, hip_power
from gaitbench.gait_problem import StepData
from gaitbench.mechanics import BipedModel
from gaitbench.simulate import OpenLoop, simulate
from gaitbench.transcription import StepTrajectory, TranscribedStep

SAMPLES_PER_INTERVAL = 16


@dataclass(frozen=True)
class StepVerification:
    max_defect: float  # largest violation of the transcription's dynamics constraints
    resim_error: float  # largest state error (angles in rad, rates in rad/s) at the step's end
    resim_max_error: float  # largest state error at any node along the step
    hip_energy: float  # J, exact |power| on a fine grid of the interpolant
    push_off_energy: float  # J
    cot: float

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def verify_step(
    built: TranscribedStep, x: np.ndarray, data: StepData, trajectory: StepTrajectory, model: BipedModel
) -> StepVerification:
    """``model`` is the 4-DOF model for second-phase steps (push-off acts) and the 2-DOF model otherwise."""
    p = data.parameter_vector()
    max_defect = built.nlp.block_violations(x, p)["dynamics"]

    energy = fine_grid_hip_energy(trajectory)
    push_off_energy = 0.0
    q_end, dq_end = trajectory.q[-1], trajectory.dq[-1]
    if model.dof == 4:
        foot = np.zeros(2)
        _, push_off_energy = model.push_off(np.r_[q_end, foot], np.r_[dq_end, foot], trajectory.push_off, data.stance)
    cot = cost_of_transport(energy + push_off_energy, data.robot.total_mass, data.chord, data.robot.g)

    resim = resimulate(trajectory, data, model)
    errors = np.abs(np.hstack([resim.q[:, :2] - trajectory.q, resim.dq[:, :2] - trajectory.dq])).max(axis=1)
    return StepVerification(
        max_defect=float(max_defect),
        resim_error=float(errors[-1]),
        resim_max_error=float(errors.max()),
        hip_energy=float(energy),
        push_off_energy=float(push_off_energy),
        cot=float(cot),
    )


def fine_grid_hip_energy(trajectory: StepTrajectory, samples_per_interval: int = SAMPLES_PER_INTERVAL) -> float:
    """∫ |τ·q̇| dt from the interpolant, Simpson on a grid ``samples_per_interval`` times finer than the nodes."""
    n_samples = samples_per_interval * (len(trajectory.times) - 1) + 1
    times = np.linspace(0.0, trajectory.duration, n_samples)
    tau = np.array([trajectory.control(t) for t in times])
    dq = np.array([trajectory.state(t)[1] for t in times])
    power = hip_power(dq[:, 0], dq[:, 1], tau[:, 0], tau[:, 1])
    return hip_energy(times, power)


def resimulate(trajectory: StepTrajectory, data: StepData, model: BipedModel):
    """The step re-simulated from its initial state under its own controls, sampled at its nodes."""
    q0, dq0 = trajectory.q[0], trajectory.dq[0]
    if model.dof == 4:
        q0, dq0 = np.r_[q0, 0.0, 0.0], np.r_[dq0, 0.0, 0.0]
    control = OpenLoop(lambda t, step: trajectory.control(t), [trajectory.push_off if model.dof == 4 else 0.0])
    walk = simulate(model, [data.slope], q0, dq0, control, first_stance=data.stance, step_times=[trajectory.times])
    return walk.steps[0]
