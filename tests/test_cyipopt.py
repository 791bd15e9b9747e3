"""The cyipopt plugin: the same IPOPT iterations as the ``ipopt`` plugin, every status, reuse, and silence."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cyipopt
import numpy as np
import pytest
from gait_steps import gait_step
from nlp_problems import (
    STANDARD_PROBLEMS,
    ReferenceProblem,
    extended_rosenbrock,
    hs071,
    infeasible,
    nonnegative_projection,
    projection_optimum,
    undefined_at_start,
)

from gaitbench.solve.evaluation import NLPEvaluator
from gaitbench.solver_result import SolverStatus
from gaitbench_plugins.solvers.cyipopt_solver import CyIpopt, register_solvers
from gaitbench_plugins.solvers.ipopt import Ipopt


def _solve(problem: ReferenceProblem, **options):
    return CyIpopt(**options).solve(problem.nlp, problem.parameters, problem.x0)


@pytest.mark.parametrize("problem", [hs071(), gait_step("dmoc", 20, quadrature="midpoint")],
                         ids=lambda problem: problem.name)
def test_same_iterations_point_and_multipliers_as_the_ipopt_plugin(problem: ReferenceProblem):
    """Both paths run IPOPT 3.14 with MUMPS, but different builds (cyipopt's wheel: 3.14.11, CasADi's: 3.14.19),
    so on a problem as delicate as the Hermite–Simpson step they can part after ~100 iterations in the last
    digits (108 against 109 iterations, the same optimum); on these they agree exactly. DMOC's Boole step is as
    delicate (205 against 222), so the step here is its former midpoint rule."""
    reference = Ipopt().solve(problem.nlp, problem.parameters, problem.x0)
    result = _solve(problem)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.message == "cyipopt: Solve_Succeeded"
    assert result.iterations == reference.iterations
    assert result.objective == pytest.approx(reference.objective, rel=1e-12)
    np.testing.assert_allclose(result.x, reference.x, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(result.multipliers, reference.multipliers, rtol=1e-6, atol=1e-8)  # the same signs


@pytest.mark.parametrize("problem", STANDARD_PROBLEMS, ids=lambda problem: problem.name)
def test_standard_problems_reach_their_published_optimum(problem: ReferenceProblem):
    result = _solve(problem)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert abs(result.objective - problem.f_star) <= 1e-6 * max(1.0, abs(problem.f_star))
    assert result.constraint_violation <= 1e-7


def test_iteration_limit():
    result = _solve(hs071(), max_iterations=2)
    assert result.status is SolverStatus.ITERATION_LIMIT
    assert result.message == "cyipopt: Maximum_Iterations_Exceeded"
    assert result.iterations == 2


def test_time_limit_is_ipopts_wall_time_limit():
    """IPOPT checks max_wall_time once per iteration from the initial point on, as in the ``ipopt`` plugin's test."""
    problem = extended_rosenbrock(1000)
    result = _solve(problem, time_limit_s=1e-6)
    assert result.status is SolverStatus.TIME_LIMIT
    assert result.message == "cyipopt: Maximum_WallTime_Exceeded"  # status -5, missing from cyipopt's own table
    assert result.iterations == 0
    assert _solve(problem).iterations > 10


def test_infeasible_problem_is_reported_as_infeasible_with_ipopts_iteration_count():
    """IPOPT ends this one in its restoration phase, whose iterations the callback sees shifted by one."""
    result = _solve(infeasible())
    assert result.status is SolverStatus.INFEASIBLE
    assert result.message == "cyipopt: Infeasible_Problem_Detected"
    assert result.constraint_violation == pytest.approx(0.5, abs=1e-6)
    assert result.iterations == Ipopt().solve(infeasible().nlp, [], infeasible().x0).iterations == 6


def test_nan_at_the_starting_point_is_an_error():
    result = _solve(undefined_at_start())
    assert result.status is SolverStatus.ERROR
    assert result.message == "cyipopt: Invalid_Number_Detected"
    assert np.isnan(result.objective)


def test_bad_input_is_an_error_not_an_exception():
    problem = hs071()
    result = CyIpopt().solve(problem.nlp, problem.parameters, np.zeros(3))
    assert result.status is SolverStatus.ERROR
    assert result.message == "cyipopt: ValueError: Wrong length of x0."


def test_an_exception_in_a_callback_is_an_error_and_the_next_solve_is_unaffected(monkeypatch):
    """Left to cyipopt, an exception in ``hessian`` is lost (IPOPT goes on with stale values for 3000 iterations)
    and one in any other callback is raised again by every later solve of the cached problem."""
    problem = hs071()

    def failing(*args):
        raise RuntimeError("Hessian unavailable")

    with monkeypatch.context() as patch:
        patch.setattr(NLPEvaluator, "hessian_values", failing)
        result = _solve(problem)
    assert result.status is SolverStatus.ERROR
    assert result.message == "cyipopt: RuntimeError: Hessian unavailable"
    assert result.iterations == 0
    with monkeypatch.context() as patch:
        patch.setattr(NLPEvaluator, "constraints", failing)
        assert _solve(problem).message == "cyipopt: RuntimeError: Hessian unavailable"
    assert _solve(problem).converged
    assert len(problem.nlp.solver_cache) == 1


def test_ipopt_options_pass_through_and_a_rejected_one_is_named():
    problem = hs071()
    rejected = _solve(problem, no_such_option=1)
    assert rejected.status is SolverStatus.ERROR
    assert rejected.message == "cyipopt: ValueError: IPOPT rejects option no_such_option=1"
    assert _solve(problem, acceptable_tol=1, mu_strategy="adaptive").converged  # 1 is given to IPOPT as 1.0


def test_resolving_with_new_parameters_reuses_the_built_problem(monkeypatch: pytest.MonkeyPatch):
    builds = []

    class CountingProblem(cyipopt.Problem):
        def __init__(self, *args, **kwargs):
            builds.append(kwargs)
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(cyipopt, "Problem", CountingProblem)
    problem = nonnegative_projection(2.0)
    nlp, solver = problem.nlp, CyIpopt()
    for target in (2.0, -1.0):
        result = solver.solve(nlp, [target], problem.x0)
        f_star, x_star = projection_optimum(target)
        assert result.status is SolverStatus.CONVERGED, result.message
        assert result.objective == pytest.approx(f_star, abs=1e-6)
        np.testing.assert_allclose(result.x, x_star, atol=1e-6)
    assert len(builds) == 1 and len(nlp.solver_cache) == 1
    np.testing.assert_allclose(result.multipliers, [-2.0], atol=1e-6)  # ∇f + λ∇g = 0 at x = 0, p = -1
    CyIpopt(mu_strategy="adaptive").solve(nlp, [2.0], problem.x0)
    assert len(builds) == 2 and len(nlp.solver_cache) == 2  # other options, another build


def test_evaluations_and_timings_are_reported():
    problem = hs071()
    result = _solve(problem)
    assert set(result.evaluations) == {"f", "g", "grad_f", "jac_g", "hess_l"}
    assert result.evaluations["hess_l"] == result.iterations
    assert 0.0 < result.function_time_s < result.wall_time_s


def _run(print_level: int) -> subprocess.CompletedProcess:
    script = ("from nlp_problems import hs071; from gaitbench_plugins.solvers.cyipopt_solver import CyIpopt; "
              f"p = hs071(); assert CyIpopt(print_level={print_level}).solve(p.nlp, p.parameters, p.x0).converged")
    return subprocess.run([sys.executable, "-c", script], cwd=Path(__file__).parent, capture_output=True, text=True)


def test_print_level_zero_is_silent_and_one_prints_the_log():
    """In fresh processes, since IPOPT prints its banner only on the first solve of a process."""
    silent, verbose = _run(0), _run(5)
    assert (silent.returncode, silent.stdout, silent.stderr) == (0, "", "")
    assert verbose.returncode == 0
    assert "Ipopt" in verbose.stdout and "EXIT: Optimal Solution Found." in verbose.stdout


def test_registers_the_cyipopt_solver():
    (registration,) = register_solvers()
    assert registration.name == "cyipopt" and registration.factory is CyIpopt
