"""The IPOPT solver plugin: known optima, every failure status, solver reuse across parameters, reported stats."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
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

from gaitbench.options import OptionError
from gaitbench.plugins import load_registry
from gaitbench.solve.solver import section_solver
from gaitbench.solver_result import SolverStatus
from gaitbench_plugins.solvers.ipopt import Ipopt


def _solve(problem: ReferenceProblem, **options):
    return Ipopt(**options).solve(problem.nlp, problem.parameters, problem.x0)


@pytest.mark.parametrize("problem", STANDARD_PROBLEMS, ids=lambda problem: problem.name)
def test_standard_problems_reach_their_published_optimum(problem: ReferenceProblem):
    result = _solve(problem)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert abs(result.objective - problem.f_star) <= 1e-6 * max(1.0, abs(problem.f_star))
    assert result.constraint_violation <= 1e-7
    if problem.x_star is not None:  # published solutions are rounded to about seven digits
        np.testing.assert_allclose(result.x, problem.x_star, atol=1e-6)


def test_infeasible_problem_is_reported_as_infeasible():
    result = _solve(infeasible())
    assert result.status is SolverStatus.INFEASIBLE
    assert result.message == "IPOPT: Infeasible_Problem_Detected"
    assert result.constraint_violation == pytest.approx(0.5, abs=1e-6)  # the least infeasible point, x = 1/2


def test_nan_at_the_starting_point_is_an_error_not_an_exception():
    result = _solve(undefined_at_start())
    assert result.status is SolverStatus.ERROR
    assert result.message == "IPOPT: Invalid_Number_Detected"
    assert np.isnan(result.objective)


def test_exceptions_inside_casadi_become_errors():
    problem = hs071()
    result = Ipopt().solve(problem.nlp, problem.parameters, np.zeros(3))  # HS071 has four variables
    assert result.status is SolverStatus.ERROR
    assert "mismatching shape" in result.message


def test_unknown_ipopt_option_is_an_error_naming_it():
    result = _solve(hs071(), no_such_option=1)
    assert result.status is SolverStatus.ERROR
    assert "No such IPOPT option: no_such_option" in result.message


def test_iteration_limit():
    result = _solve(hs071(), max_iterations=2)
    assert result.status is SolverStatus.ITERATION_LIMIT
    assert result.message == "IPOPT: Maximum_Iterations_Exceeded"
    assert result.iterations == 2


def test_time_limit():
    """IPOPT checks max_wall_time once per iteration, starting with the initial point, so a limit of 1 µs on a
    problem that is not solved there stops at iteration 0 every time (unlimited, it takes ~20 iterations)."""
    problem = extended_rosenbrock(1000)
    result = _solve(problem, time_limit_s=1e-6)
    assert result.status is SolverStatus.TIME_LIMIT
    assert result.message == "IPOPT: Maximum_WallTime_Exceeded"
    assert result.iterations == 0
    assert _solve(problem).iterations > 10


def test_resolving_with_new_parameters_reuses_the_built_solver(monkeypatch: pytest.MonkeyPatch):
    builds = []

    def counting_nlpsol(*args, **kwargs):
        builds.append(args)
        return nlpsol(*args, **kwargs)

    nlpsol = ca.nlpsol
    monkeypatch.setattr(ca, "nlpsol", counting_nlpsol)
    problem = nonnegative_projection(2.0)
    nlp, solver = problem.nlp, Ipopt()
    seen = []
    for target in (2.0, -1.0):
        result = solver.solve(nlp, [target], problem.x0)
        f_star, x_star = projection_optimum(target)
        assert result.status is SolverStatus.CONVERGED, result.message
        assert result.objective == pytest.approx(f_star, abs=1e-6)
        np.testing.assert_allclose(result.x, x_star, atol=1e-6)
        assert len(nlp.solver_cache) == 1
        seen.append(next(iter(nlp.solver_cache.values())))
    assert len(builds) == 1
    assert seen[0] is seen[1]
    np.testing.assert_allclose(result.multipliers, [-2.0], atol=1e-6)  # ∇f + λ∇g = 0 at x = 0, p = -1


def test_cache_is_keyed_by_options():
    problem = nonnegative_projection(2.0)
    for solver in (Ipopt(), Ipopt(), Ipopt(mu_strategy="adaptive")):
        assert solver.solve(problem.nlp, problem.parameters, problem.x0).converged
    assert len(problem.nlp.solver_cache) == 2


def test_evaluations_and_timings_are_reported():
    problem = hs071()
    result = _solve(problem)
    assert set(result.evaluations) == {"f", "g", "grad_f", "jac_g", "hess_l"}
    assert all(count > 0 for count in result.evaluations.values())
    assert result.evaluations["hess_l"] == result.iterations
    assert 0.0 < result.function_time_s < result.wall_time_s
    assert result.multipliers.shape == (problem.nlp.n_constraints,)


def test_print_level_zero_is_silent():
    """In a fresh process, since IPOPT prints its banner only on the first solve of a process."""
    script = "from nlp_problems import hs071; from gaitbench_plugins.solvers.ipopt import Ipopt; p = hs071(); " \
             "assert Ipopt().solve(p.nlp, p.parameters, p.x0).converged"
    run = subprocess.run([sys.executable, "-c", script], cwd=Path(__file__).parent, capture_output=True, text=True)
    assert (run.returncode, run.stdout, run.stderr) == (0, "", "")


def test_registered_as_a_solver_plugin():
    registry = load_registry()
    assert "ipopt" in registry.names("solver")
    assert isinstance(registry.create("solver", "ipopt", max_iterations=5), Ipopt)


def test_section_options_apply_to_the_sectional_solver_only():
    """``section_options`` are IPOPT options over the solver's own for decrease and conquer's sectional NLPs; the
    step solver keeps its own, and the core's :func:`section_solver` finds the variant."""
    solver = Ipopt(tolerance=1e-7, section_options={"mu_strategy": "adaptive", "tol": 1e-6})
    sections = section_solver(solver)
    assert sections is solver.for_sections() and sections is not solver
    assert (sections.options["ipopt"]["mu_strategy"], sections.options["ipopt"]["tol"]) == ("adaptive", 1e-6)
    assert "mu_strategy" not in solver.options["ipopt"] and solver.options["ipopt"]["tol"] == 1e-7
    assert sections.for_sections() is sections  # its own sections: the same options
    problem = hs071()
    assert sections.solve(problem.nlp, problem.parameters, problem.x0).converged
    unchanged = Ipopt(section_options={})
    assert section_solver(unchanged) is unchanged
    plain = object()  # a solver without for_sections solves sections itself
    assert section_solver(plain) is plain


def test_sections_get_adaptive_mu_by_default_and_steps_do_not():
    solver = Ipopt()
    assert solver.for_sections().options["ipopt"]["mu_strategy"] == "adaptive"
    assert solver.for_sections().options["ipopt"]["mu_oracle"] == "quality-function"
    assert "mu_strategy" not in solver.options["ipopt"]
    assert [name for name, _ in solver.remedies()] == ["adaptive-mu"]  # the steps' remedy stays


def test_a_section_option_ipopt_refuses_is_named_under_section_options():
    with pytest.raises(OptionError, match=r"^section_options\.mu_strategy: IPOPT rejects mu_strategy = 'adaptiv'"):
        Ipopt.check_options({"section_options": {"mu_strategy": "adaptiv"}})
    with pytest.raises(OptionError, match="section_options: expected a table of IPOPT options"):
        Ipopt.check_options({"section_options": 1})
    Ipopt.check_options({"section_options": {"nlp_scaling_obj_target_gradient": 1.0}})
