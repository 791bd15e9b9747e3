"""Grid continuation: a step on N nodes started from the same step solved on a coarser grid.

A step's NLP on a fine grid has many more local optima within reach of the blended guess than on a coarse one, and
the optimizer's path, not the problem, then decides which it ends in: the same stairs walk costs three to five times
more at N = 180 than at N = 40 from the blended guess. The coarse grid's optimum, interpolated onto the fine grid
(through its transcription's own interpolant, :meth:`~gaitbench.problem.trajectory.StepTrajectory.seed`), starts
the fine solve in the basin that the coarse grid found, and the fine solve then corrects its discretization.

``start = "best"`` solves both ways and keeps the cheaper verified motion, so a step is never dearer than the
blended start alone would have made it; it costs both solves.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gaitbench.acceptance import Thresholds, step_failures
from gaitbench.contracts import WalkProblem
from gaitbench.problem.trajectory import Seed
from gaitbench.problem.transcription import TranscribedStep
from gaitbench.solve.walk import solve_with_retries
from gaitbench.walk_types import StepOutcome

STARTS = ("blended", "continuation", "best")
"""How a One Phase step is started: the blended guess; the step solved on ``coarse_nodes`` nodes first; or both,
keeping the cheaper verified motion."""


class GridContinuation:
    """Solves one walk's steps from a coarse grid's solution; the coarse NLP is built once per walk."""

    def __init__(self, problem: WalkProblem, built: TranscribedStep, coarse_nodes: int) -> None:
        self.coarse_problem = replace(problem, n_nodes=coarse_nodes, checkpoint=None)
        self.coarse_built = problem.transcription.build(replace(built.structure, n_nodes=coarse_nodes))
        self.built = built

    def seed(self, index: int, state: np.ndarray) -> tuple[Seed | None, dict]:
        """Step ``index``'s solution from ``state`` on the coarse grid as a seed, and what happened, for the step's
        ``details["start"]``; no seed when the coarse step does not solve."""
        coarse = solve_with_retries(self.coarse_problem, index, self.coarse_built,
                                    self.coarse_problem.step_data(index, state), phase=self.built.structure.phase)
        note = {"coarse": {"nodes": self.coarse_problem.n_nodes, **coarse.summary()}}
        if not coarse.solved:
            return None, {**note, "used": "blended", "why": f"the coarse step did not solve ({coarse.status})"}
        return coarse.trajectory.seed(), {**note, "used": "continuation"}

    def solve(self, problem: WalkProblem, index: int, state: np.ndarray) -> StepOutcome:
        """Step ``index`` from ``state`` on N nodes, started from the coarse grid's solution (from the blended
        guess when the coarse step does not solve, which ``details["start"]`` then says)."""
        seed, note = self.seed(index, state)
        outcome = solve_with_retries(problem, index, self.built, problem.step_data(index, state), seed=seed,
                                     phase=self.built.structure.phase)
        outcome.details = {**outcome.details, "start": note}
        return outcome


def cheaper_motion(candidates: dict[str, StepOutcome], n_nodes: int) -> tuple[str, StepOutcome]:
    """The name and outcome of the cheapest candidate that passes verification's thresholds; else the cheapest
    solved one; else the first (a failure the walk stops on)."""
    limits = Thresholds.for_nodes(n_nodes)
    solved = [(name, outcome) for name, outcome in candidates.items() if outcome.solved]
    passing = [(name, outcome) for name, outcome in solved if not step_failures(outcome.verification, limits)]
    if not solved:
        return next(iter(candidates.items()))
    return min(passing or solved, key=lambda pair: pair[1].verification.cot)


def best_start(problem: WalkProblem, index: int, state: np.ndarray, blended: StepOutcome,
               continuation: GridContinuation) -> StepOutcome:
    """The cheaper verified motion of the blended start (``blended``, already solved) and the grid continuation,
    with both candidates' summaries in ``details["start"]``; the blended start alone once the walk's time has run
    out (a second start begun after the deadline could run a whole solve's limit past it)."""
    if problem.out_of_time:
        blended.details = {**blended.details, "start": {"used": "blended", "why": "the walk's time ran out"}}
        return blended
    seed, note = continuation.seed(index, state)
    if seed is None:
        blended.details = {**blended.details, "start": note}
        return blended
    continued = solve_with_retries(problem, index, continuation.built, problem.step_data(index, state), seed=seed,
                                   phase=continuation.built.structure.phase)
    name, chosen = cheaper_motion({"blended": blended, "continuation": continued}, problem.n_nodes)
    chosen.details = {**chosen.details, "start": {**note, "used": name,
                                                  "candidates": {"blended": blended.summary(),
                                                                 "continuation": continued.summary()}}}
    return chosen
