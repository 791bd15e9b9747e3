"""Multi-step walking: H per-step problems chained through the end-of-step events.

Each step starts from the heel-strike map (after push-off, in the second phase) of the previous step's solution
(DECISIONS §7). A step whose geometry is infeasible or whose solve fails ends the walk with its reason; the steps
solved before it are kept.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gaitbench.energetics import average_cot
from gaitbench.experiment import Experiment
from gaitbench.gait_problem import ProblemOptions, StepData, StepStructure
from gaitbench.mechanics import BipedModel
from gaitbench.solver import Solver, SolverResult
from gaitbench.transcription import StepTrajectory, Transcription
from gaitbench.verify import StepVerification, verify_step


@dataclass
class StepOutcome:
    index: int
    stance: int
    status: str  # a SolverStatus value, or "infeasible_geometry"
    message: str
    solver_result: SolverResult | None = None
    trajectory: StepTrajectory | None = None
    verification: StepVerification | None = None

    @property
    def solved(self) -> bool:
        return self.verification is not None

    def as_dict(self) -> dict:
        result, check = self.solver_result, self.verification
        return {
            "index": self.index,
            "stance": self.stance,
            "status": self.status,
            "message": self.message,
            "cot": check.cot if check else None,
            "objective": result.objective if result else None,
            "solve_time_s": result.wall_time_s if result else None,
            "function_time_s": result.function_time_s if result else None,
            "iterations": result.iterations if result else None,
            "constraint_violation": result.constraint_violation if result else None,
            "max_defect": check.max_defect if check else None,
            "resim_error": check.resim_error if check else None,
            "resim_max_error": check.resim_max_error if check else None,
            "hip_energy": check.hip_energy if check else None,
            "push_off_energy": check.push_off_energy if check else None,
            "push_off_impulse": self.trajectory.push_off if self.trajectory else None,
        }


@dataclass
class WalkResult:
    experiment: str
    transcription: str
    solver: str
    strategy: str
    N: int
    phase: str
    requested_steps: int
    steps: list[StepOutcome] = field(default_factory=list)
    wall_time_s: float = 0.0

    @property
    def failure(self) -> str | None:
        failed = [step for step in self.steps if not step.solved]
        return f"step {failed[0].index}: {failed[0].message}" if failed else None

    @property
    def complete(self) -> bool:
        return len(self.steps) == self.requested_steps and all(step.solved for step in self.steps)

    @property
    def acot(self) -> float | None:
        """Average verified COT over the walk; ``None`` unless every requested step was solved."""
        return average_cot([step.verification.cot for step in self.steps]) if self.complete else None

    def as_dict(self) -> dict:
        return {
            "experiment": self.experiment,
            "transcription": self.transcription,
            "solver": self.solver,
            "strategy": self.strategy,
            "N": self.N,
            "phase": self.phase,
            "requested_steps": self.requested_steps,
            "complete": self.complete,
            "acot": self.acot,
            "failure": self.failure,
            "wall_time_s": self.wall_time_s,
            "steps": [step.as_dict() for step in self.steps],
        }

    def save(self, path: str | Path) -> Path:
        """Write the result as JSON and the trajectories beside it as NPZ (referenced from the JSON)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        arrays = {}
        for step in self.steps:
            if step.trajectory is not None:
                prefix = f"step{step.index:02d}"
                arrays |= {
                    f"{prefix}_t": step.trajectory.times,
                    f"{prefix}_q": step.trajectory.q,
                    f"{prefix}_dq": step.trajectory.dq,
                    f"{prefix}_tau": step.trajectory.tau,
                    f"{prefix}_tau_t": step.trajectory.control_times,
                    f"{prefix}_push_off": np.array([step.trajectory.push_off]),
                }
        data = self.as_dict()
        if arrays:
            npz = path.with_suffix(".npz")
            np.savez_compressed(npz, **arrays)
            data["trajectories"] = npz.name
        path.write_text(json.dumps(data, indent=2, default=_json_default))
        return path


def solve_walk(
    experiment: Experiment,
    transcription: Transcription,
    solver: Solver,
    n_nodes: int,
    *,
    steps: int | None = None,
    phase: str = "second",
    options: ProblemOptions | None = None,
    on_step: Callable[[StepOutcome], None] | None = None,
) -> WalkResult:
    """Solve the experiment's walk one phase, step by step (the thesis's One Phase method when ``phase='second'``)."""
    n_steps = experiment.n_steps if steps is None else steps
    if not 1 <= n_steps <= experiment.n_steps:
        raise ValueError(f"steps = {steps}: the {experiment.name} experiment has {experiment.n_steps} steps")
    options = options or ProblemOptions(limits=experiment.limits)
    structure = StepStructure(phase, n_nodes, options)
    model = BipedModel(experiment.robot, 4 if phase == "second" else 2)
    walk = WalkResult(
        experiment=experiment.name,
        transcription=transcription.name,
        solver=solver.name,
        strategy="one-phase",
        N=n_nodes,
        phase=phase,
        requested_steps=n_steps,
    )
    started = time.perf_counter()
    checks = experiment.feasibility()
    state = np.asarray(experiment.initial_state)[[0, 1, 4, 5]]
    for index in range(1, n_steps + 1):
        outcome = _solve_step(experiment, transcription, solver, structure, model, index, state, checks[index - 1])
        walk.steps.append(outcome)
        if on_step:
            on_step(outcome)
        if not outcome.solved:
            break
        state = next_step_state(model, outcome.trajectory)
    walk.wall_time_s = time.perf_counter() - started
    return walk


def _solve_step(experiment, transcription, solver, structure, model, index, state, check) -> StepOutcome:
    stance = experiment.stance_leg(index)
    if not check.ok:
        return StepOutcome(index, stance, "infeasible_geometry", "; ".join(check.problems))
    step = experiment.terrain.steps[index - 1]
    data = StepData(experiment.robot, stance, state, step.D, step.theta, experiment.time_step(structure.n_nodes))
    built = transcription.build(structure)
    result = solver.solve(built.nlp, data.parameter_vector(), built.initial_guess(data))
    if not result.converged:
        return StepOutcome(index, stance, result.status.value, f"{result.status.value}: {result.message}", result)
    trajectory = built.trajectory(result.x, data)
    verification = verify_step(built, result.x, data, trajectory, model)
    return StepOutcome(index, stance, result.status.value, result.message, result, trajectory, verification)


def next_step_state(model: BipedModel, trajectory: StepTrajectory) -> np.ndarray:
    """(q1, q2, q̇1, q̇2) at the start of the next step: push-off (4 DOF), then heel strike and the role swap."""
    q, dq = trajectory.q[-1], trajectory.dq[-1]
    if model.dof == 4:
        q, dq = np.r_[q, 0.0, 0.0], np.r_[dq, 0.0, 0.0]
        dq, _ = model.push_off(q, dq, trajectory.push_off, trajectory.stance)
    strike = model.heel_strike(q, dq, trajectory.stance)
    return np.r_[strike.q[:2], strike.dq[:2]]


def _json_default(value):
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"cannot serialize {type(value).__name__}")
