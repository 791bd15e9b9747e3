"""The warm-start strategy: One Phase started from the First Phase trajectory (the usual coarse-model warm start).

Each step first solves the 2-DOF First Phase problem, then the 4-DOF Second Phase problem from the same initial
state with the First Phase trajectory as its initial guess. Decrease-and-conquer also starts from the First Phase;
comparing the two separates what its synthesis adds from what a good initial guess adds.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.contracts import WalkProblem
from gaitbench.solve.walk import solve_with_retries, walk_step_by_step
from gaitbench.walk_types import StepOutcome, WalkResult


class WarmStart:
    name = "warm-start"

    def solve(self, problem: WalkProblem, on_step: Callable[[StepOutcome], None] | None = None) -> WalkResult:
        first = problem.transcription.build(problem.structure("first"))
        second = problem.transcription.build(problem.structure("second"))

        def solve_step(problem: WalkProblem, index: int, state: np.ndarray) -> StepOutcome:
            data = problem.step_data(index, state)
            coarse = solve_with_retries(problem, index, first, data, phase="first")
            if not coarse.solved:
                coarse.message = f"First Phase: {coarse.message}"
                return coarse
            outcome = solve_with_retries(problem, index, second, data, seed=coarse.trajectory.seed(), phase="second")
            retries = coarse.details.get("retries", []) + outcome.details.get("retries", [])
            outcome.details = {**outcome.details, "first_phase": coarse.summary(), "retries": retries}
            return outcome

        return walk_step_by_step(problem, self.name, solve_step, on_step)


@hookimpl
def register_strategies():
    return [Registration("warm-start", "One Phase started from the First Phase (2-DOF) trajectory",
                         WarmStart)]
