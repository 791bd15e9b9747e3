"""The One Phase strategy: each step's problem solved directly from the blended initial guess (DECISIONS §7).

With ``phase="second"`` (the default) this is the thesis's One Phase method and the baseline that
decrease-and-conquer is compared against: the full 4-DOF problem with push-off, heel strike and ground reactions.
``phase="first"`` walks with the 2-DOF First Phase problem alone, which is what the thesis's Chapter 2 evaluates.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.walk import StepOutcome, WalkProblem, WalkResult, solve_with_retries, walk_step_by_step


class OnePhase:
    name = "one-phase"

    def __init__(self, phase: str = "second") -> None:
        if phase not in ("first", "second"):
            raise ValueError(f"phase = {phase!r}: expected 'first' (2-DOF) or 'second' (4-DOF)")
        self.phase = phase

    def solve(self, problem: WalkProblem, on_step: Callable[[StepOutcome], None] | None = None) -> WalkResult:
        built = problem.transcription.build(problem.structure(self.phase))

        def solve_step(problem: WalkProblem, index: int, state: np.ndarray) -> StepOutcome:
            return solve_with_retries(problem, index, built, problem.step_data(index, state), phase=self.phase)

        return walk_step_by_step(problem, self.name, solve_step, on_step, phase=self.phase)


@hookimpl
def register_strategies():
    return [Registration("one-phase", "Each step's 4-DOF problem solved directly from the blended guess "
                         "(the thesis's One Phase baseline)", OnePhase)]
