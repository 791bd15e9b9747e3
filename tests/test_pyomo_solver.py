"""The pyomo solver plugin: an exact CasADi → Pyomo translation, ripopt (bundled) on it, and every failure status."""

from __future__ import annotations

import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from gait_steps import gait_step
from nlp_problems import (
    STANDARD_PROBLEMS,
    ReferenceProblem,
    extended_rosenbrock,
    hs071,
    nonnegative_projection,
    projection_optimum,
    undefined_at_start,
)

import gaitbench_plugins.solvers.pyomo_solver.solver as pyomo_solver
from gaitbench.plugins import load_registry
from gaitbench.problem.nlp import NLP
from gaitbench.solver_result import SolverStatus
from gaitbench_plugins.solvers.ipopt import Ipopt
from gaitbench_plugins.solvers.pyomo_solver import PyomoSolver, UnsupportedOperationError, translate


def _solve(problem: ReferenceProblem, **options):
    return PyomoSolver(**options).solve(problem.nlp, problem.parameters, problem.x0)


def _assert_translation_is_exact(nlp: NLP, points: np.ndarray, parameters: np.ndarray, lift_threshold: int) -> None:
    translation = translate(nlp, lift_threshold)
    for x in points:
        f, g = translation.evaluate(x, parameters)
        f_casadi = float(nlp.functions.objective(x, parameters))
        g_casadi = nlp.constraint_values(x, parameters)
        assert f == pytest.approx(f_casadi, rel=1e-13, abs=1e-13)
        scale = max(1.0, np.max(np.abs(g_casadi), initial=0.0))
        np.testing.assert_allclose(g, g_casadi, rtol=1e-13, atol=1e-12 * scale)


def _conditional_nlp() -> NLP:
    """Every piecewise operation the translation maps (min, max, |·|, sign, floor, if-else, comparisons, logic)."""
    x, p = ca.SX.sym("x", 3), ca.SX.sym("p", 2)
    f = (ca.fmax(x[0], x[1]) + ca.fmin(x[1] * x[2], p[0]) + ca.fabs(x[2] - 1) + ca.sign(x[0] - 0.3)
         + ca.if_else(x[0] > p[1], x[1] ** 2, ca.exp(x[2])) + ca.floor(x[1]) + ca.logic_and(x[0] > 0, x[1] < 1)
         + ca.logic_or(x[0] == x[1], x[2] != 0) + ca.logic_not(x[0] <= 0.1) + x[0] ** p[0] + ca.log(1 + x[1] ** 2)
         + ca.tanh(x[1]) + ca.atan(x[2]) + 1 / (2 + x[0] ** 2) + ca.cosh(x[1] / 3) + (x[0] ** 2 + 1) ** 1.5)
    g = ca.vertcat(x[0] + x[1], ca.sqrt(1 + x[2] ** 2), 0, p[0] * 3)
    return NLP(x=x, p=p, f=f, g=g, lbx=np.full(3, -5.0), ubx=np.full(3, 5.0), lbg=np.array([-1, 0, 0, 1.0]),
               ubg=np.array([np.inf, 10, 0, 9.0]), variable_blocks={}, constraint_blocks={})


@pytest.mark.parametrize("problem", STANDARD_PROBLEMS, ids=lambda problem: problem.name)
def test_translation_equals_casadi_on_the_standard_problems(problem: ReferenceProblem):
    points = problem.x0 + np.random.default_rng(0).normal(size=(5, problem.x0.size))
    _assert_translation_is_exact(problem.nlp, points, problem.parameters, lift_threshold=0)


@pytest.mark.parametrize("lift_threshold", [0, 20])
def test_translation_equals_casadi_on_a_gait_step(lift_threshold: int):
    """Exact with shared subexpressions as named expressions, and with the largest lifted into variables (on
    DMOC's former midpoint rule, where lifting adds fewer rows than the NLP has variables)."""
    problem = gait_step("dmoc", 20, quadrature="midpoint")
    points = problem.x_star + 0.05 * np.random.default_rng(1).normal(size=(3, problem.x0.size))
    _assert_translation_is_exact(problem.nlp, points, problem.parameters, lift_threshold)
    if lift_threshold:
        # Some shared subexpressions are lifted, not all: the heel-strike solve behind the lift-off row alone
        # shares hundreds of small ones, which stay named expressions.
        lifted = len(translate(problem.nlp, lift_threshold).lifted)
        assert 0 < lifted < len(translate(problem.nlp, 1).lifted)


def test_translation_maps_piecewise_and_logical_operations_exactly():
    nlp = _conditional_nlp()
    points = np.random.default_rng(2).uniform(-2, 2, size=(200, 3))
    points[::4, 0] = 0.3  # on the kinks and ties: sign(0), x0 == x1, x0 <= 0.1, x0 > p1, floor(1), x2 != 0
    points[1::4, 1] = points[1::4, 0]
    points[2::4] = 0.1, 1.0, 0.0
    points[3::4, 0] = 0.4
    _assert_translation_is_exact(nlp, points, np.array([2.0, 0.4]), lift_threshold=0)
    positive = np.abs(points)  # x0 ** p0 with p0 = 1.5 is real
    positive[::4, 0] = 0.3
    _assert_translation_is_exact(nlp, positive, np.array([1.5, 0.4]), lift_threshold=0)


def test_an_operation_without_a_pyomo_equivalent_is_named():
    x = ca.SX.sym("x", 2)
    nlp = NLP(x=x, p=ca.SX.sym("p", 0), f=ca.atan2(x[0], x[1]), g=ca.SX(0, 1), lbx=np.full(2, -1.0),
              ubx=np.ones(2), lbg=np.zeros(0), ubg=np.zeros(0), variable_blocks={}, constraint_blocks={})
    with pytest.raises(UnsupportedOperationError, match="OP_ATAN2"):
        translate(nlp)
    result = PyomoSolver().solve(nlp, [], [0.5, 0.5])
    assert result.status is SolverStatus.ERROR
    assert "OP_ATAN2 has no Pyomo equivalent" in result.message


def test_ripopt_solves_hs071_with_ipopt_multipliers():
    problem = hs071()
    result = _solve(problem)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.message == "pyomo/ripopt: optimal ripopt 0.8.2: Optimal Solution Found"
    assert abs(result.objective - problem.f_star) <= 1e-6 * problem.f_star
    assert result.constraint_violation <= 1e-6  # ripopt relaxes bounds by 1e-8 relative, like IPOPT: 25 · 1e-8
    np.testing.assert_allclose(result.x, problem.x_star, atol=1e-6)
    assert 5 <= result.iterations <= 20
    assert (result.function_time_s, result.evaluations) == (0.0, {})
    reference = Ipopt().solve(problem.nlp, problem.parameters, problem.x0)
    np.testing.assert_allclose(result.multipliers, reference.multipliers, atol=1e-6)  # CasADi's sign convention


def test_ripopt_solves_the_dmoc_gait_step_to_ipopts_optimum():
    """On DMOC's Boole step; on its former midpoint rule ripopt ends at another local minimum (1.7634 against
    IPOPT's 1.6593), where SQP and scipy's trust-constr end too."""
    problem = gait_step("dmoc", 20)
    result = _solve(problem)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert abs(result.objective - problem.f_star) <= 1e-6
    assert result.constraint_violation <= 1e-6
    assert 20 <= result.iterations <= 300  # 246 measured on the Boole step
    assert result.multipliers.shape == (problem.nlp.n_constraints,)  # the lifting constraints' are left out


@pytest.mark.slow
def test_ripopt_solves_the_hermite_simpson_gait_step_to_ipopts_optimum():
    problem = gait_step("hermite-simpson", 20)
    result = _solve(problem)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert abs(result.objective - problem.f_star) <= 1e-6


def test_resolving_with_new_parameters_reuses_the_translated_model(monkeypatch: pytest.MonkeyPatch):
    translations = []

    def counting_translate(*args, **kwargs):
        translations.append(args)
        return translate(*args, **kwargs)

    monkeypatch.setattr(pyomo_solver, "translate", counting_translate)
    problem = nonnegative_projection(2.0)
    nlp, solver = problem.nlp, PyomoSolver()
    for target in (2.0, -1.0):
        result = solver.solve(nlp, [target], problem.x0)
        f_star, x_star = projection_optimum(target)
        assert result.status is SolverStatus.CONVERGED, result.message
        assert result.objective == pytest.approx(f_star, abs=1e-6)
        np.testing.assert_allclose(result.x, x_star, atol=1e-6)
    assert len(translations) == 1
    assert len(nlp.solver_cache) == 1
    np.testing.assert_allclose(result.multipliers, [-2.0], atol=1e-6)  # ∇f + λ∇g = 0 at x = 0, p = -1


def test_the_model_is_shared_by_solver_options_and_keyed_by_the_translation():
    problem = nonnegative_projection(2.0)
    for solver in (PyomoSolver(), PyomoSolver(mu_strategy="monotone"), PyomoSolver(lift_threshold=0)):
        assert solver.solve(problem.nlp, problem.parameters, problem.x0).converged
    assert len(problem.nlp.solver_cache) == 2


def test_iteration_limit():
    result = _solve(hs071(), max_iterations=2)
    assert result.status is SolverStatus.ITERATION_LIMIT
    assert result.message.startswith("pyomo/ripopt: maxIterations")
    assert "Maximum Number of Iterations Exceeded" in result.message
    assert 1 <= result.iterations <= 2  # ripopt 0.8.2 reports one iteration fewer than its max_iter


def test_time_limit_of_the_executable():
    result = _solve(extended_rosenbrock(1000), time_limit_s=1e-6)
    assert result.status is SolverStatus.TIME_LIMIT
    assert "Maximum CPU Time Exceeded" in result.message
    assert result.iterations == 0


@pytest.fixture
def fake_executable(tmp_path: Path):
    """An AMPL-style executable ``name`` that reports a version and then hangs."""

    def make(name: str) -> Path:
        path = tmp_path / name
        path.write_text('#!/bin/sh\nif [ "$1" = "-v" ]; then echo "fake 1.2.3"; exit 0; fi\nexec sleep 30\n')
        path.chmod(0o755)
        return path

    return make


def test_an_executable_that_ignores_the_time_limit_is_killed(fake_executable):
    problem = hs071()
    result = PyomoSolver(executable=str(fake_executable("snopt")), time_limit_s=0.2).solve(
        problem.nlp, problem.parameters, problem.x0)
    assert result.status is SolverStatus.TIME_LIMIT
    assert "killed at the time limit" in result.message
    assert result.wall_time_s < 5
    np.testing.assert_array_equal(result.x, problem.x0)


def test_shared_options_use_each_executables_own_names(fake_executable):
    snopt = PyomoSolver(executable=str(fake_executable("snopt")), max_iterations=7, time_limit_s=5.0,
                        superbasics_limit=500, scale=True)
    assert snopt.solver_options == {"major_iterations_limit": 7, "time_limit": 5.0,
                                    "major_optimality_tolerance": 1e-8, "outlev": 0, "superbasics_limit": 500,
                                    "scale": "yes"}
    assert snopt.lift_threshold == 0  # an ASL executable gets the exact NLP with defined variables
    knitro = PyomoSolver(executable=str(fake_executable("knitroampl")), tolerance=1e-6)
    assert knitro.solver_options == {"maxit": 3000, "opttol": 1e-6, "outlev": 0}
    assert PyomoSolver(executable=str(fake_executable("mysolver")), custom=1).solver_options == {"custom": 1}
    assert PyomoSolver().solver_options == {"max_iter": 3000, "tol": 1e-8, "print_level": 0}


def test_missing_executable_says_what_was_looked_for_and_how_to_install_one(monkeypatch: pytest.MonkeyPatch,
                                                                             tmp_path: Path):
    with pytest.raises(ValueError, match=r"'no-such-nl-solver' on PATH.*pip install pyomo-ripopt.*snopt"):
        PyomoSolver(executable="no-such-nl-solver")
    with pytest.raises(ValueError, match="does not exist or is not executable"):
        PyomoSolver(executable=str(tmp_path / "bin" / "snopt"))
    monkeypatch.setitem(sys.modules, "pyomo_ripopt", None)  # as if pyomo-ripopt were not installed
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(ValueError, match=r"pyomo_ripopt is not installed.*'ripopt' on PATH.*idaes get-extensions"):
        PyomoSolver()


def test_unknown_option_is_an_error_naming_it():
    result = _solve(hs071(), no_such_option=1)
    assert result.status is SolverStatus.ERROR
    assert "unknown option 'no_such_option'" in result.message


def test_nan_at_the_starting_point_is_an_error():
    result = _solve(undefined_at_start())
    assert result.status is SolverStatus.ERROR
    assert "Evaluation Error" in result.message


def test_print_level_zero_is_silent_and_positive_echoes_the_log(capfd: pytest.CaptureFixture):
    problem = hs071()
    assert _solve(problem).converged
    assert capfd.readouterr() == ("", "")
    assert _solve(problem, print_level=5).converged
    assert "Number of Iterations" in capfd.readouterr().out


def test_registered_as_a_solver_plugin(tmp_path: Path):
    # a plugin directory loads files, not packages: this one registers the package's plugin
    plugin = "from gaitbench_plugins.solvers.pyomo_solver import register_solvers  # noqa: F401\n"
    (tmp_path / "pyomo_plugin.py").write_text(plugin)
    registry = load_registry([tmp_path], use_entry_points=False)
    assert registry.names("solver") == ["pyomo"]
    solver = registry.create("solver", "pyomo", max_iterations=5)
    assert solver.name == "pyomo"
    assert solver.solver_options["max_iter"] == 5
