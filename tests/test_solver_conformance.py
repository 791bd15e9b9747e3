"""Every registered solver plugin against the same contract: published optima, limits, failures as statuses, and
a one-step gait problem solved to IPOPT's optimum.

A solver that cannot meet a check is listed in ``KNOWN_SHORTFALLS`` with the measured reason; those cases are
strict xfails, so the list stays true: a shortfall that goes away fails the run until it is removed here.
"""

from __future__ import annotations

import numpy as np
import pytest
from gait_steps import gait_step
from nlp_problems import STANDARD_PROBLEMS, ReferenceProblem, extended_rosenbrock, hs071

from gaitbench.plugins import load_registry
from gaitbench.solver_result import SolverStatus

REGISTRY = load_registry()
SOLVERS = REGISTRY.names("solver")
GAIT_STEPS = [("dmoc", 20), ("hermite-simpson", 20)]

_PHASE_ONE = ("FSQP's phase 1 (projections onto every linearised row, equalities too) stalls on this step's "
              "standard guess: iteration limit with inequality and equality rows still violated (ℓ1 violation ~0.5)")
KNOWN_SHORTFALLS: dict[tuple[str, str], str] = {
    ("sqp", "gait-dmoc-20"): "converges (KKT residual ~1e-9) to another local minimum, |f - f*|/f* = 6.4e-3",
    ("sqp", "gait-hermite-simpson-20"): "converges to another local minimum, |f - f*|/f* = 4.8e-3",
    ("fsqp", "gait-hermite-simpson-20"): _PHASE_ONE,
}
"""(solver, check or problem name) → why it fails, as measured."""


def _case(solver: str, name: str, *values):
    reason = KNOWN_SHORTFALLS.get((solver, name))
    marks = [pytest.mark.xfail(strict=True, reason=reason)] if reason else []
    return pytest.param(solver, *values, id=f"{solver}-{name}", marks=marks)


def _solve(solver: str, problem: ReferenceProblem, **options):
    return REGISTRY.create("solver", solver, **options).solve(problem.nlp, problem.parameters, problem.x0)


@pytest.mark.parametrize(("solver", "problem"),
                         [_case(s, p.name, p) for s in SOLVERS for p in STANDARD_PROBLEMS])
def test_reaches_the_published_optimum(solver: str, problem: ReferenceProblem):
    result = _solve(solver, problem)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert abs(result.objective - problem.f_star) <= 1e-5 * max(1.0, abs(problem.f_star)), result.objective
    assert result.constraint_violation <= 1e-6
    assert result.iterations >= 0 and result.wall_time_s > 0


@pytest.mark.parametrize("solver", [_case(s, "iteration-limit") for s in SOLVERS])
def test_iteration_limit_is_a_status(solver: str):
    result = _solve(solver, hs071(), max_iterations=1)
    assert result.status is SolverStatus.ITERATION_LIMIT, result.message
    assert result.iterations <= 1


@pytest.mark.parametrize("solver", [_case(s, "time-limit") for s in SOLVERS])
def test_time_limit_is_a_status(solver: str):
    result = _solve(solver, extended_rosenbrock(500), time_limit_s=1e-6)
    assert result.status is SolverStatus.TIME_LIMIT, result.message


@pytest.mark.parametrize("solver", [_case(s, "bad-input") for s in SOLVERS])
def test_bad_input_is_an_error_status_not_an_exception(solver: str):
    problem = hs071()
    result = REGISTRY.create("solver", solver).solve(problem.nlp, problem.parameters, np.zeros(3))
    assert result.status is SolverStatus.ERROR
    assert result.message


@pytest.mark.parametrize(("solver", "transcription", "n_nodes"),
                         [_case(s, f"gait-{t}-{n}", t, n) for s in SOLVERS for t, n in GAIT_STEPS])
def test_one_gait_step_reaches_ipopts_optimum(solver: str, transcription: str, n_nodes: int):
    problem = gait_step(transcription, n_nodes)
    result = _solve(solver, problem, max_iterations=3000, time_limit_s=120)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.objective == pytest.approx(problem.f_star, rel=1e-4)
    assert result.constraint_violation <= 1e-6
