"""The coarse-grid rescue: a walk's last try at a step that every rung of the retry ladder and the back-up left
unsolved (docs/solvers.md, "Retries").

A step that IPOPT cannot solve on N nodes from every seed the walk has often solves on a coarser grid from the same
state, and that solution seeds the N-node step well enough. It is a rung after every other, because the coarse
step's optimum, not the walk's own seeds, then picks the N-node step's: a walk that completes without it is the same
walk with it. One Phase uses it for its step, decrease-and-conquer for its First Phase.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gaitbench.contracts import WalkProblem
from gaitbench.problem.transcription import TranscribedStep
from gaitbench.solve.walk import solve_with_retries
from gaitbench.walk_types import StepOutcome

COARSE_GRIDS = (3 / 4, 1 / 2)
"""The grids, as fractions of N, that :func:`coarse_grid_rescue` solves a stopped step on, finest first. Measured on
the two `thesis-all` walks that stopped after every rung and the back-up (docs/decisions/0008-retry-ladder.md):

- stairs, OP-DM, N = 200, step 8 (IPOPT ends in restoration from the blended and the First-Phase seeds): from the
  same state the step solves at 150, 100 and 67 nodes, and seeded from the 150- or the 100-node solution the 200-node
  step converges (from 50 nodes it does not);
- stairs, D&C-DC, N = 130, step 5's First Phase (infeasible after adaptive μ and the small μ₀): it solves at 98
  nodes, and the 130-node First Phase seeded from that converges."""

MIN_COARSE_NODES = 5
"""No coarser grid than this: a step of fewer nodes says too little about the trajectory to seed it."""


def coarse_grid_rescue(problem: WalkProblem, index: int, state: np.ndarray, failed: StepOutcome,
                       built: TranscribedStep) -> StepOutcome:
    """Step ``index``'s problem ``built`` (either phase) from ``state`` solved on each of the :data:`COARSE_GRIDS`
    (with the retry ladder) and the N-node problem started from that solution, until one solves.

    Each grid tried is appended to the step's ``details["retries"]`` as ``coarse-seed-<nodes>``; a rescued step
    records the failure it replaces in ``details["rescued_from"]``. When no grid solves it, ``failed`` is returned
    with those attempts added.
    """
    phase = built.structure.phase
    attempts, grids = [], []  # every rung tried; each grid's own result, for the message
    for fraction in COARSE_GRIDS:
        n_nodes = round(fraction * problem.n_nodes)
        if not MIN_COARSE_NODES <= n_nodes < problem.n_nodes or problem.out_of_time:
            continue
        coarse_problem = replace(problem, n_nodes=n_nodes, checkpoint=None)
        coarse_built = problem.transcription.build(replace(built.structure, n_nodes=n_nodes))
        coarse = solve_with_retries(coarse_problem, index, coarse_built, coarse_problem.step_data(index, state),
                                    phase=phase)
        remedy = f"coarse-seed-{n_nodes}"
        if not coarse.solved:
            attempts.append({"remedy": remedy, **coarse.summary(), "failed_in": f"{n_nodes}-node step"})
            grids.append(f"{remedy} {coarse.status}")
            continue
        outcome = solve_with_retries(problem, index, built, problem.step_data(index, state),
                                     seed=coarse.trajectory.seed(), phase=phase, reseed=False)
        attempts.append({"remedy": remedy, **outcome.summary()})
        grids.append(f"{remedy} {outcome.status}")
        attempts += [{**rung, "remedy": f"{remedy}+{rung['remedy']}"} for rung in outcome.details.get("retries", [])]
        if outcome.solved:
            outcome.details = {**outcome.details, "retries": failed.details.get("retries", []) + attempts,
                               "rescued_from": {"message": failed.message, **failed.summary(),
                                                **({"back_up": failed.details["back_up"]}
                                                   if "back_up" in failed.details else {})}}
            return outcome
    if attempts:
        failed.details = {**failed.details, "retries": failed.details.get("retries", []) + attempts}
        failed.message += f" (coarse grids: {', '.join(grids)})"
    return failed
