"""The whole-walk strategy: all H steps of an experiment in one NLP, linked through push-off and heel strike.

The thesis optimizes step by step, each step greedily from where the previous one ended. Here the walk's ACOT is
minimized as a whole: step i's initial state is not a parameter but the push-off and heel-strike map of step
i − 1's final state and impulse, written symbolically into step i's parameters. Every step keeps its own
transcription variables and constraints (one built step NLP, called H times), so the result is directly
comparable with the per-step strategies and is verified step by step in the same way. It is the reference they
are measured against.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.contracts import WalkProblem
from gaitbench.solve.one_phase import OnePhase
from gaitbench.solve.verify import verify_step
from gaitbench.solve.walk import next_step_state
from gaitbench.solve.walk_chain import WalkChain
from gaitbench.walk_types import StepOutcome, WalkResult


class WholeWalk:
    """Options: ``guess`` ("blended", the default: every step from the blended guess of docs/model.md §7, the
    experiment's initial state mirrored for Leg-2 stance steps; "one-phase": start from the One Phase walk, a
    feasible point of this NLP, so the optimizer improves on it)."""

    name = "whole-walk"

    def __init__(self, guess: str = "blended") -> None:
        if guess not in ("one-phase", "blended"):
            raise ValueError(f"guess = {guess!r}: expected 'one-phase' or 'blended'")
        self.guess = guess

    def solve(self, problem: WalkProblem, on_step: Callable[[StepOutcome], None] | None = None) -> WalkResult:
        started = time.perf_counter()
        walk = problem.result(self.name)
        for check in problem.feasibility()[: problem.n_steps]:
            if not check.ok:
                walk.steps.append(StepOutcome(check.step, problem.experiment.stance_leg(check.step),
                                              "infeasible_geometry", "; ".join(check.problems)))
                walk.wall_time_s = time.perf_counter() - started
                return walk
        built = problem.transcription.build(problem.structure("second"))
        chain = WalkChain(built, problem.experiment.stance_leg(1), problem.n_steps)
        start = problem.start_state()
        parameters = chain.parameters(problem, 1, start)
        guess, guess_details = self._initial_guess(problem, chain, start)
        result = problem.solver.solve(chain.nlp, parameters, guess)
        walk.strategy_details = {"guess": self.guess, **guess_details, "solver": result.summary(),
                                 "variables": chain.nlp.n_variables, "constraints": chain.nlp.n_constraints}
        if not result.converged:
            walk.steps.append(StepOutcome(1, problem.experiment.stance_leg(1), result.status.value,
                                          f"whole walk: {result.status.value}: {result.message}", result))
            walk.wall_time_s = time.perf_counter() - started
            return walk
        model = problem.model("second")
        for index, (x, data) in enumerate(chain.steps(problem, 1, result.x, parameters), start=1):
            trajectory = built.trajectory(x, data)
            verification = verify_step(built, x, data, trajectory, model)
            outcome = StepOutcome(index, data.stance, result.status.value, result.message, None, trajectory,
                                  verification, next_state=next_step_state(model, trajectory))
            walk.steps.append(outcome)
            if on_step:
                on_step(outcome)
        walk.wall_time_s = time.perf_counter() - started
        return walk

    def _initial_guess(self, problem: WalkProblem, chain: WalkChain, start: np.ndarray) -> tuple[np.ndarray, dict]:
        if self.guess == "one-phase":
            baseline = OnePhase().solve(replace(problem, checkpoint=None))  # a guess: never the case's checkpoint
            if baseline.complete:
                states = [start] + [step.next_state for step in baseline.steps[:-1]]
                known = [(state, step.trajectory.seed()) for state, step in zip(states, baseline.steps, strict=True)]
                return chain.guess(problem, 1, known), {"guess_acot": baseline.acot}
            return chain.guess(problem, 1, [(start, None)]), {"guess_acot": None, "guess_failure": baseline.failure}
        return chain.guess(problem, 1, [(start, None)]), {}


@hookimpl
def register_strategies():
    return [Registration("whole-walk", "All H steps in one NLP linked through push-off and heel strike: the "
                         "walk's ACOT optimized as a whole (reference for the per-step strategies)", WholeWalk)]
