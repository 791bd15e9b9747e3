"""The One Phase strategy: each step's problem solved directly from the blended initial guess (docs/model.md §7).

With ``phase="second"`` (the default) this is the thesis's One Phase method and the baseline that
decrease-and-conquer is compared against: the full 4-DOF problem with push-off, heel strike and ground reactions.
``phase="first"`` walks with the 2-DOF First Phase problem alone, which is what the thesis's Chapter 2 evaluates.
``look_ahead=H`` solves each step together with the next H − 1 and commits it alone (docs/model.md §7); H = 1, the
default, is the thesis's greedy walk. With ``back_up`` (the default), a step the solver cannot solve is first taken
for a dead end that the step before walked into: that step is solved again looking one step further ahead (H + 1)
and the walk goes on from there. With ``rescue`` (the default), a step that still fails is solved on coarser grids
from the same state (:func:`~gaitbench.solve.rescue.coarse_grid_rescue`) before the walk stops. A walk that completes
without them is the same walk with them.

``start`` picks where each step's solve begins (:mod:`gaitbench.solve.continuation`): the blended guess (the
thesis's One Phase, the default), the same step solved first on ``coarse_nodes`` nodes (``continuation``), or both,
keeping the cheaper verified motion (``best``). Walks of at most ``coarse_nodes`` nodes start from the blended guess.

It lives in the core, registered by ``plugins/strategies/one_phase.py``, because other strategies build on it
(whole-walk's ``guess="one-phase"``) and plugins use each other only through the core.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from gaitbench.contracts import WalkProblem
from gaitbench.solve.continuation import STARTS, GridContinuation, best_start
from gaitbench.solve.rescue import coarse_grid_rescue
from gaitbench.solve.walk import solve_with_retries, walk_step_by_step
from gaitbench.solve.walk_chain import LookAhead
from gaitbench.walk_types import StepOutcome, WalkResult


class OnePhase:
    name = "one-phase"

    def __init__(self, phase: str = "second", look_ahead: int = 1, back_up: bool = True, rescue: bool = True,
                 start: str = "blended", coarse_nodes: int = 40) -> None:
        if phase not in ("first", "second"):
            raise ValueError(f"phase = {phase!r}: expected 'first' (2-DOF) or 'second' (4-DOF)")
        if int(look_ahead) != look_ahead or look_ahead < 1:
            raise ValueError(f"look_ahead = {look_ahead!r}: expected a whole number of steps, at least 1")
        if look_ahead > 1 and phase != "second":
            raise ValueError("look_ahead > 1 chains steps through push-off and heel strike: it needs phase = 'second'")
        self.phase = phase
        self.look_ahead = int(look_ahead)
        self.back_up = bool(back_up) and phase == "second"
        self.rescue = bool(rescue)
        if start not in STARTS:
            raise ValueError(f"start = {start!r}: expected one of {', '.join(STARTS)}")
        if start != "blended" and look_ahead > 1:
            raise ValueError(f"start = {start!r} starts single steps: it needs look_ahead = 1")
        if int(coarse_nodes) != coarse_nodes or coarse_nodes < 5:
            raise ValueError(f"coarse_nodes = {coarse_nodes!r}: expected a whole number of nodes, at least 5")
        self.start = start
        self.coarse_nodes = int(coarse_nodes)

    def solve(self, problem: WalkProblem, on_step: Callable[[StepOutcome], None] | None = None) -> WalkResult:
        built = problem.transcription.build(problem.structure(self.phase, walked=True))
        window = LookAhead(built, self.look_ahead)
        backing = LookAhead(built, self.look_ahead + 1, fallback=False)
        continued = self.start != "blended" and problem.n_nodes > self.coarse_nodes
        continuation = GridContinuation(problem, built, self.coarse_nodes) if continued else None

        def solve_step(problem: WalkProblem, index: int, state: np.ndarray) -> StepOutcome:
            if self.look_ahead > 1:
                return window.solve_step(problem, index, state)
            data = problem.step_data(index, state)
            if continuation is not None and self.start == "continuation":
                outcome = continuation.solve(problem, index, state)
            else:
                outcome = solve_with_retries(problem, index, built, data, phase=self.phase)
                if continuation is not None:
                    outcome = best_start(problem, index, state, outcome, continuation)
            seed = backing.seed_for(state)
            if outcome.solved or seed is None:
                return outcome
            # Just backed up: the window that re-solved the previous step solved this one too; start from it.
            retry = solve_with_retries(problem, index, built, data, seed=seed)
            rungs = outcome.details.get("retries", []) + [{"remedy": "look-ahead-seed", **retry.summary()}]
            chosen = retry if retry.solved else outcome
            chosen.details = {**chosen.details, "retries": rungs}
            return chosen

        def back_up(problem: WalkProblem, index: int, state: np.ndarray, replaced: StepOutcome) -> StepOutcome:
            return backing.solve_step(problem, index, state, replaced.verified.trajectory.seed())

        def rescue(problem: WalkProblem, index: int, state: np.ndarray, failed: StepOutcome) -> StepOutcome:
            return coarse_grid_rescue(problem, index, state, failed, built)

        # a window starts from the previous window's later steps, which a checkpoint does not keep
        return walk_step_by_step(problem, self.name, solve_step, on_step, phase=self.phase,
                                 back_up=back_up if self.back_up else None, resumable=self.look_ahead == 1,
                                 rescue=rescue if self.rescue and self.look_ahead == 1 else None)
