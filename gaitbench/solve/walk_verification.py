"""A walk verified as one motion: each step it reports is a motion of the robot, and each starts where the step
before left the robot.

Each step is re-simulated from its own start state (:func:`gaitbench.solve.verify.verify_step`), not the walk as a
whole from step 1: an open-loop run across eleven steps measures the gait's instability, not the solution's
accuracy. What ties the steps together is the join check: step i must start from the post-impact state of step
i − 1 (push-off, then heel strike, applied to its end; for step 1, the walk's start state). The mismatch there, and
the mechanical energy that appears at the join (energy the robot never paid for), are recorded per step and per
walk. :func:`verify_walk` is what ``gaitbench solve``, the suite runner and ``gaitbench verify`` all call; the
thresholds are in :mod:`gaitbench.acceptance`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from itertools import takewhile

import numpy as np

from gaitbench.acceptance import Thresholds, join_failure, judged_gap, step_failures
from gaitbench.contracts import Strategy, WalkProblem
from gaitbench.model.energetics import average_cot
from gaitbench.model.experiment import Experiment
from gaitbench.model.mechanics import BipedModel
from gaitbench.model.robot import RobotParameters
from gaitbench.plugins import PluginRegistry, load_registry
from gaitbench.problem.gait_problem import StepData, StepStructure
from gaitbench.problem.trajectory import StepTrajectory
from gaitbench.solve.thesis_reading import thesis_reading_acot
from gaitbench.solve.verify import verify_step
from gaitbench.solve.walk import next_step_state
from gaitbench.solve.walk_file import WalkFile
from gaitbench.walk_types import StepCheck, StepOutcome, WalkResult, WalkVerification


def verify_walk(walk: WalkResult, start_state: np.ndarray, robot: RobotParameters) -> WalkVerification:
    """Check the steps ``walk`` reports (:attr:`StepOutcome.verified`: decrease and conquer's polished or complete
    motion, not its patchwork) against :class:`Thresholds` for its N, each step's objective gap against the larger
    of its COT and the walk's mean step COT, and each step's start against the post-impact state of the one before
    (``start_state``, leg order (q1, q2, q̇1, q̇2), for step 1), applied here to the step's own trajectory: what a
    strategy says it handed on is not trusted."""
    limits = Thresholds.for_nodes(walk.N)
    energy = BipedModel(robot, 2)  # both feet on the ground at a join: the 2-DOF model's energies
    impact = BipedModel(robot, 4) if walk.phase == "second" else energy  # push-off is the 4-DOF model's
    expected = np.asarray(start_state, dtype=float)
    motions = list(takewhile(lambda motion: motion.solved, (step.verified for step in walk.steps)))
    walk_cot = average_cot([motion.verification.cot for motion in motions]) if motions else None
    checks, reasons = [], []
    for step, motion in zip(walk.steps, motions, strict=False):  # the steps after the first unsolved are not checked
        trajectory, check = motion.trajectory, motion.verification
        start = np.r_[trajectory.q[0], trajectory.dq[0]]
        mismatch = float(np.max(np.abs(start - expected)))
        appeared = (energy.total_energy(start[:2], start[2:], step.stance)
                    - energy.total_energy(expected[:2], expected[2:], step.stance))
        failures = step_failures(check, limits, walk_cot)
        joined = join_failure(mismatch, limits)
        failures += [joined] if joined else []
        checks.append(StepCheck(step.index, check.cot, check.max_defect, check.resim_error,
                                judged_gap(check, walk_cot), mismatch, float(appeared), tuple(failures)))
        reasons += [f"step {step.index}: {failure}" for failure in failures]
        expected = next_step_state(impact, trajectory)
    if not walk.complete:
        reasons.insert(0, f"incomplete walk ({walk.failure or 'fewer steps than requested'})")
    acot = average_cot([check.cot for check in checks]) if walk.complete else None
    return WalkVerification(not reasons, tuple(reasons), acot, limits, tuple(checks))


def solve_verified(strategy: Strategy, problem: WalkProblem,
                   on_step: Callable[[StepOutcome], None] | None = None) -> WalkResult:
    """``strategy``'s walk of ``problem``, verified as one motion (its ``verification``): what ``gaitbench solve``
    and the suite runner both run."""
    walk = strategy.solve(problem, on_step=on_step)
    walk.experiment_options, walk.strategy_options = dict(problem.experiment_options), dict(problem.strategy_options)
    walk.transcription_options = dict(problem.transcription_options)
    walk.verification = verify_walk(walk, problem.start_state(), problem.experiment.robot)
    walk.thesis_reading_acot = thesis_reading_of(walk, problem.experiment)
    return walk


def thesis_reading_of(walk: WalkResult, experiment: Experiment) -> float | None:
    """The walk's ACOT as the thesis would have computed it (:mod:`gaitbench.solve.thesis_reading`), of the figure
    the thesis would have reported: each step's own trajectory, so decrease and conquer's patchworks, the claim;
    None unless the walk is complete."""
    if not walk.complete:
        return None
    return thesis_reading_acot((step.trajectory, _step_data(experiment, step, step.trajectory))
                               for step in walk.steps)


def _step_data(experiment: Experiment, step: StepOutcome, trajectory: StepTrajectory) -> StepData:
    """The numbers of step ``step`` of ``experiment`` as ``trajectory`` walked it: its start state and time step."""
    geometry = experiment.terrain.steps[step.index - 1]
    return StepData(experiment.robot, step.stance, np.r_[trajectory.q[0], trajectory.dq[0]], geometry.D,
                    geometry.theta, float(trajectory.times[1] - trajectory.times[0]),
                    previous_slope=experiment.terrain.ground_behind(step.index))


def reverify(walk_file: WalkFile, registry: PluginRegistry | None = None) -> WalkResult:
    """The walk of a walk file verified again from its stored trajectories alone: each reported step's defect,
    re-simulation and COT recomputed under the walk's own transcription, problem options and objective, then the
    whole walk checked (:func:`verify_walk`, in the returned walk's ``verification``). Nothing the file says about
    its own verification is trusted."""
    registry = registry or load_registry()
    walk, experiment = walk_file.result(registry)
    options = walk_file.problem_options(experiment)
    transcription = registry.create("transcription", walk.transcription, **walk.transcription_options)
    built = transcription.build(StepStructure(walk.phase, walk.N, options, walk_file.objective(registry)))
    model = BipedModel(experiment.robot, 4 if walk.phase == "second" else 2)
    for step in walk.steps:
        motion = step.verified
        trajectory = motion.trajectory
        data = _step_data(experiment, step, trajectory)
        check = verify_step(built, built.variables(trajectory, data), data, trajectory, model)
        if walk_file.version is None:  # its problem options unrecorded, today's defaults stand in: not its limits
            check = replace(check, max_violation=None, violated=None)
        motion.verification = check
    walk.verification = verify_walk(walk, experiment.start_state(options.start_pose), experiment.robot)
    walk.thesis_reading_acot = thesis_reading_of(walk, experiment)
    return walk
