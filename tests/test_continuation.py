"""Grid continuation (gaitbench.solve.continuation): One Phase steps started from a coarser grid's solution."""

from __future__ import annotations

import numpy as np
import pytest

from gaitbench.acceptance import StepVerification, Thresholds
from gaitbench.contracts import WalkProblem
from gaitbench.plugins import load_registry
from gaitbench.solve.continuation import cheaper_motion
from gaitbench.solve.one_phase import OnePhase
from gaitbench.walk_types import StepOutcome

REGISTRY = load_registry()


def _outcome(cot: float | None, gap: float = 0.0) -> StepOutcome:
    """A step outcome that solved at ``cot`` with objective gap ``gap``, or failed (``cot`` None)."""
    if cot is None:
        return StepOutcome(1, 1, "infeasible", "infeasible")
    check = StepVerification(max_defect=1e-9, resim_error=1e-4, resim_max_error=1e-4, hip_energy=1.0,
                             push_off_energy=0.0, cot=cot, objective_gap=gap)
    return StepOutcome(1, 1, "converged", "", verification=check, next_state=np.zeros(4))


def test_the_cheaper_motion_that_passes_verification_is_kept():
    limit = Thresholds.for_nodes(100).max_objective_gap
    name, _ = cheaper_motion({"blended": _outcome(0.30), "continuation": _outcome(0.25)}, 100)
    assert name == "continuation"
    name, _ = cheaper_motion({"blended": _outcome(0.30), "continuation": _outcome(0.25, gap=2 * limit)}, 100)
    assert name == "blended"  # cheaper, but its optimizer did not measure what it claims
    name, _ = cheaper_motion({"blended": _outcome(None), "continuation": _outcome(0.25, gap=2 * limit)}, 100)
    assert name == "continuation"  # the only motion, though it fails verification: the walk goes on and says so
    name, chosen = cheaper_motion({"blended": _outcome(None), "continuation": _outcome(None)}, 100)
    assert name == "blended" and not chosen.solved


@pytest.mark.parametrize("options, message", [
    ({"start": "coarse"}, "expected one of blended, continuation, best"),
    ({"start": "best", "look_ahead": 2}, "needs look_ahead = 1"),
    ({"start": "continuation", "coarse_nodes": 3}, "at least 5"),
])
def test_start_options_are_checked(options, message):
    with pytest.raises(ValueError, match=message):
        OnePhase(**options)


@pytest.fixture(scope="module")
def forward_problem():
    experiment = REGISTRY.create("experiment", "forward")
    return WalkProblem(experiment, REGISTRY.create("transcription", "hermite-simpson"),
                       REGISTRY.create("solver", "ipopt"), 24, steps=2)


def test_a_continued_walk_starts_each_step_from_the_coarse_grid(forward_problem):
    walk = OnePhase(start="continuation", coarse_nodes=12).solve(forward_problem)
    assert walk.complete, walk.failure
    for step in walk.steps:
        start = step.details["start"]
        assert start["used"] == "continuation"
        assert start["coarse"]["nodes"] == 12 and start["coarse"]["status"] == "converged"


def test_the_best_start_is_no_dearer_than_either_start(forward_problem):
    blended = OnePhase().solve(forward_problem)
    best = OnePhase(start="best", coarse_nodes=12).solve(forward_problem)
    first = best.steps[0]  # both walks start step 1 from the same state
    candidates = first.details["start"]["candidates"]
    assert first.verification.cot == min(candidates["blended"]["cot"], candidates["continuation"]["cot"])
    assert candidates["blended"]["cot"] == pytest.approx(blended.steps[0].verification.cot, rel=1e-9)


def test_a_walk_no_finer_than_the_coarse_grid_starts_from_the_blended_guess(forward_problem):
    walk = OnePhase(start="continuation", coarse_nodes=24).solve(forward_problem)
    assert walk.complete
    assert all("start" not in step.details for step in walk.steps)


def test_no_second_start_begins_after_the_walks_deadline(forward_problem):
    """The blended start solved, the deadline passed: the step keeps the blended motion rather than starting a
    coarse solve and a continued one that could each run a whole solve's limit past the case's time."""
    from dataclasses import replace

    from gaitbench.solve.continuation import best_start

    class Untouched:
        def seed(self, index, state):
            raise AssertionError("a second start began after the deadline")

    late = replace(forward_problem, deadline=0.0)  # time.monotonic() is past it
    blended = _outcome(0.3)
    chosen = best_start(late, 1, np.zeros(4), blended, Untouched())
    assert chosen is blended and chosen.details["start"] == {"used": "blended", "why": "the walk's time ran out"}
