"""The worked solver-plugin example of docs/solvers.md, loaded the way a user loads it: from a plugin directory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from gait_steps import FORMER_QUADRATURE, gait_step

from gaitbench.cli.main import main
from gaitbench.plugins import load_registry
from gaitbench.solver_result import SolverStatus

EXAMPLES = Path(__file__).parents[1] / "examples" / "plugins"


@pytest.fixture(scope="module")
def example_solver():
    registry = load_registry([EXAMPLES], use_entry_points=False)
    assert not registry.problems, registry.problems
    return lambda **options: registry.create("solver", "scipy-trust-constr", **options)


def test_the_example_reaches_ipopts_optimum_on_a_gait_step(example_solver):
    """Started near IPOPT's optimum: from the standard guess trust-constr converges to other local minima of these
    non-convex steps (HS 2.1777 against IPOPT's 1.7736; DMOC 1.7634 against 1.6593, where SQP and ripopt end too)."""
    problem = gait_step("hermite-simpson", 20, quadrature=FORMER_QUADRATURE["hermite-simpson"])
    start = problem.x_star * (1 + 1e-3 * np.random.default_rng(5).standard_normal(problem.x_star.size))
    result = example_solver().solve(problem.nlp, problem.parameters, start)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.objective == pytest.approx(problem.f_star, rel=1e-4)
    assert result.constraint_violation < 1e-6
    assert result.evaluations["hess_l"] > 0 and 0 < result.function_time_s < result.wall_time_s


def test_the_example_honours_the_shared_limits(example_solver):
    problem = gait_step("dmoc", 20)
    limited = example_solver(max_iterations=5).solve(problem.nlp, problem.parameters, problem.x0)
    assert (limited.status, limited.iterations) == (SolverStatus.ITERATION_LIMIT, 5)
    timed = example_solver(time_limit_s=1e-3).solve(problem.nlp, problem.parameters, problem.x0)
    assert timed.status is SolverStatus.TIME_LIMIT
    assert timed.iterations <= 2


def test_the_example_runs_from_the_command_line():
    result = CliRunner().invoke(main, ["--plugins-dir", str(EXAMPLES), "solve", "-e", "upward-slope", "-t", "dmoc",
                                       "-s", "scipy-trust-constr", "--N", "10", "--steps", "1",
                                       "-o", "max_iterations=3"])
    assert result.exit_code == 1, result.output
    assert "dmoc + scipy-trust-constr" in result.output
    assert "iteration_limit: scipy trust-constr" in result.output
