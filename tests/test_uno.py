"""The uno plugin: the multiplier sign convention, every status, reuse, silence, and whole gait steps."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import unopy
from gait_steps import gait_step
from nlp_problems import (
    ReferenceProblem,
    extended_rosenbrock,
    hs040,
    hs071,
    infeasible,
    nonnegative_projection,
    projection_optimum,
    undefined_at_start,
)

from gaitbench.contracts import WalkProblem
from gaitbench.plugins import load_registry
from gaitbench.solve.evaluation import NLPEvaluator
from gaitbench.solve.walk import solve_and_verify
from gaitbench.solver_result import SolverStatus
from gaitbench_plugins.solvers.ipopt import Ipopt
from gaitbench_plugins.solvers.uno_solver import Uno, gaitbench_status, register_solvers

OPTIMIZATION, SOLUTION = unopy.OptimizationStatus, unopy.SolutionStatus


def _solve(problem: ReferenceProblem, **options):
    return Uno(**options).solve(problem.nlp, problem.parameters, problem.x0)


@pytest.mark.parametrize("preset", ["ipopt", "filtersqp", "funnelsqp"])
def test_multipliers_are_casadis_and_the_hessian_gets_them_in_casadis_sign(preset: str, monkeypatch):
    """Uno's Lagrangian is σf − yᵀc; declared MULTIPLIER_POSITIVE, the model gets λ = −y, CasADi's sign, in the
    Hessian callback and in the result. HS071's multipliers are IPOPT's (−0.5523, 0.1615): the product
    inequality g ≥ 25 is active with λ < 0 in ∇f + Jᵀλ + λ_x = 0."""
    seen = []
    hessian_values = NLPEvaluator.hessian_values

    def recording(self, x, sigma, multipliers):
        seen.append(np.array(multipliers))
        return hessian_values(self, x, sigma, multipliers)

    monkeypatch.setattr(NLPEvaluator, "hessian_values", recording)
    problem = hs071()
    reference = Ipopt().solve(problem.nlp, problem.parameters, problem.x0)
    result = _solve(problem, preset=preset)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.message == "Uno: SUCCESS, FEASIBLE_KKT_POINT"
    assert result.objective == pytest.approx(problem.f_star, rel=1e-7)
    np.testing.assert_allclose(result.multipliers, reference.multipliers, rtol=1e-5, atol=1e-8)
    np.testing.assert_allclose(result.multipliers, [-0.55229366, 0.16146857], rtol=1e-5)
    np.testing.assert_allclose(seen[-1], result.multipliers, rtol=1e-2)  # the last Hessian was near the end
    assert result.iterations <= 10  # with the constraints' curvature reversed (Uno's default sign) it takes 59


def test_the_stationarity_residual_vanishes_with_the_returned_multipliers():
    """∇f + Jᵀλ_g is zero at an optimum with no active bound (HS040: equalities only)."""
    problem = hs040()
    result = _solve(problem)
    evaluator = NLPEvaluator(problem.nlp, problem.parameters)
    residual = evaluator.gradient(result.x) + evaluator.jacobian(result.x).T @ result.multipliers
    assert np.abs(residual).max() < 1e-7


@pytest.mark.parametrize(("optimization", "solution", "status"), [
    (OPTIMIZATION.SUCCESS, SOLUTION.FEASIBLE_KKT_POINT, SolverStatus.CONVERGED),
    (OPTIMIZATION.SUCCESS, SOLUTION.INFEASIBLE_STATIONARY_POINT, SolverStatus.INFEASIBLE),
    (OPTIMIZATION.SUCCESS, SOLUTION.FEASIBLE_FJ_POINT, SolverStatus.ERROR),
    (OPTIMIZATION.SUCCESS, SOLUTION.FEASIBLE_SMALL_STEP, SolverStatus.ERROR),
    (OPTIMIZATION.SUCCESS, SOLUTION.INFEASIBLE_SMALL_STEP, SolverStatus.ERROR),
    (OPTIMIZATION.SUCCESS, SOLUTION.UNBOUNDED_OBJECTIVE, SolverStatus.ERROR),
    (OPTIMIZATION.SUCCESS, SOLUTION.DIVERGING_ITERATE, SolverStatus.ERROR),
    (OPTIMIZATION.ITERATION_LIMIT, SOLUTION.NOT_OPTIMAL, SolverStatus.ITERATION_LIMIT),
    (OPTIMIZATION.TIME_LIMIT, SOLUTION.NOT_OPTIMAL, SolverStatus.TIME_LIMIT),
    (OPTIMIZATION.EVALUATION_ERROR, SOLUTION.NOT_OPTIMAL, SolverStatus.ERROR),
    (OPTIMIZATION.ALGORITHMIC_ERROR, SOLUTION.NOT_OPTIMAL, SolverStatus.ERROR),
    (OPTIMIZATION.USER_TERMINATION, SOLUTION.NOT_OPTIMAL, SolverStatus.ERROR),
])
def test_status_mapping(optimization, solution, status):
    assert gaitbench_status(optimization, solution) is status


def test_iteration_limit():
    result = _solve(hs071(), max_iterations=2)
    assert result.status is SolverStatus.ITERATION_LIMIT
    assert result.message == "Uno: ITERATION_LIMIT, NOT_OPTIMAL"
    assert result.iterations == 2


def test_time_limit_is_checked_once_per_iteration():
    problem = extended_rosenbrock(1000)
    result = _solve(problem, time_limit_s=1e-6)
    assert result.status is SolverStatus.TIME_LIMIT
    assert result.message == "Uno: TIME_LIMIT, NOT_OPTIMAL"
    assert result.iterations == 1
    assert _solve(problem).iterations > 10


@pytest.mark.parametrize("preset", ["ipopt", "filtersqp"])
def test_infeasible_problem_is_reported_as_infeasible(preset: str):
    result = _solve(infeasible(), preset=preset)
    assert result.status is SolverStatus.INFEASIBLE
    assert result.message == "Uno: SUCCESS, INFEASIBLE_STATIONARY_POINT"
    assert result.constraint_violation == pytest.approx(0.5, abs=1e-6)


def test_nan_at_the_starting_point_is_an_error():
    result = _solve(undefined_at_start())
    assert result.status is SolverStatus.ERROR
    assert result.message == ("Uno: EVALUATION_ERROR, NOT_OPTIMAL (A numerical error was encountered while "
                              "evaluating a gradient)")


def test_an_algorithmic_error_names_uno_s_reason():
    """HiGHS solves only convex QPs; HS071's Lagrangian Hessian is indefinite. The reason is taken from Uno's log,
    which is kept (not printed) at print_level 0."""
    result = _solve(hs071(), preset="filtersqp", QP_solver="HiGHS")
    assert result.status is SolverStatus.ERROR
    assert result.message == ("Uno: ALGORITHMIC_ERROR, NOT_OPTIMAL (HiGHS encountered negative curvature, which it "
                              "cannot handle. Terminating.)")


def test_bad_input_is_an_error_not_an_exception():
    problem = hs071()
    result = Uno().solve(problem.nlp, problem.parameters, np.zeros(3))
    assert result.status is SolverStatus.ERROR
    assert result.message == "Uno: ValueError: the initial guess has 3 values, the NLP 4 variables"


def test_an_exception_in_a_callback_is_an_error_and_the_next_solve_is_unaffected(monkeypatch):
    problem = hs071()

    def failing(*args):
        raise RuntimeError("Hessian unavailable")

    with monkeypatch.context() as patch:
        patch.setattr(NLPEvaluator, "hessian_values", failing)
        result = _solve(problem)
    assert result.status is SolverStatus.ERROR
    assert result.message == "Uno: RuntimeError: Hessian unavailable"
    assert _solve(problem).converged
    assert len(problem.nlp.solver_cache) == 1


def test_uno_options_pass_through_and_bad_ones_are_rejected_when_built():
    problem = hs071()
    assert _solve(problem, preset="filtersqp", TR_radius=1, QP_solver="BQPD").converged  # 1 is given as 1.0
    assert _solve(problem, preset="ipopt", linear_solver="SSIDS").converged
    with pytest.raises(ValueError, match="Uno has no option no_such_option"):
        Uno(no_such_option=1)
    with pytest.raises(ValueError, match="Uno rejects option TR_radius='large'"):
        Uno(TR_radius="large")
    with pytest.raises(ValueError, match="linear_solver = 'MA57': this Uno build offers MUMPS, SSIDS"):
        Uno(linear_solver="MA57")  # Uno itself would crash the process
    with pytest.raises(ValueError, match="preset = 'filterslp'"):
        Uno(preset="filterslp")


def test_gaitbench_rejects_a_bad_option_on_the_command_line():
    registry = load_registry()
    with pytest.raises(ValueError):
        registry.create("solver", "uno", QP_solver="qpOASES")


def test_resolving_with_new_parameters_reuses_the_built_model():
    problem = nonnegative_projection(2.0)
    nlp, solver = problem.nlp, Uno()
    for target in (2.0, -1.0):
        result = solver.solve(nlp, [target], problem.x0)
        f_star, x_star = projection_optimum(target)
        assert result.status is SolverStatus.CONVERGED, result.message
        assert result.objective == pytest.approx(f_star, abs=1e-6)
        np.testing.assert_allclose(result.x, x_star, atol=1e-6)
    assert len(nlp.solver_cache) == 1
    np.testing.assert_allclose(result.multipliers, [-2.0], atol=1e-6)  # ∇f + λ∇g = 0 at x = 0, p = -1
    Uno(preset="filtersqp").solve(nlp, [2.0], problem.x0)
    assert len(nlp.solver_cache) == 2  # other options, another build


def test_nominal_scaling_returns_the_unscaled_point_and_multipliers():
    problem = hs071()
    plain, scaled = _solve(problem), _solve(problem, scaling="nominal")
    assert scaled.converged
    np.testing.assert_allclose(scaled.x, plain.x, rtol=1e-6)
    np.testing.assert_allclose(scaled.multipliers, plain.multipliers, rtol=1e-5)


def test_evaluations_and_timings_are_reported():
    result = _solve(hs071())
    assert set(result.evaluations) == {"f", "g", "grad_f", "jac_g", "hess_l"}
    assert 0.0 < result.function_time_s < result.wall_time_s


def _run(print_level: int) -> subprocess.CompletedProcess:
    script = ("from nlp_problems import hs071; from gaitbench_plugins.solvers.uno_solver import Uno; p = hs071(); "
              f"assert Uno(print_level={print_level}).solve(p.nlp, p.parameters, p.x0).converged")
    return subprocess.run([sys.executable, "-c", script], cwd=Path(__file__).parent, capture_output=True, text=True)


def test_print_level_zero_is_silent_and_one_prints_the_log():
    silent, verbose = _run(0), _run(1)
    assert (silent.returncode, silent.stdout, silent.stderr) == (0, "", "")
    assert verbose.returncode == 0
    assert "Uno 2.9" in verbose.stdout and "Feasible KKT point" in verbose.stdout


def test_standard_error_written_by_compiled_code_during_a_quiet_solve_is_discarded():
    """BQPD's Fortran writes workspace warnings to standard error (on HS, N = 50 with ``preset=filtersqp``); at
    print_level 0 the solve discards file descriptor 2 and flushes libgfortran's buffers before restoring it."""
    script = ("import os\nfrom gaitbench.solve.silence import quiet_stderr\n"
              "from gaitbench_plugins.solvers.uno_solver import _flush_fortran_units\n"
              "with quiet_stderr(True):\n    os.write(2, b'from C')\n    _flush_fortran_units()\n"
              "os.write(2, b'after')")
    run = subprocess.run([sys.executable, "-c", script], cwd=Path(__file__).parent, capture_output=True, text=True)
    assert (run.returncode, run.stderr) == (0, "after")


@pytest.mark.parametrize("transcription", ["dmoc", "hermite-simpson"])
def test_one_gait_step_reaches_ipopts_optimum(transcription: str):
    problem = gait_step(transcription, 20)
    result = _solve(problem, time_limit_s=60)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.objective == pytest.approx(problem.f_star, rel=1e-6)
    assert result.constraint_violation <= 1e-7


@pytest.mark.parametrize("transcription", ["dmoc", "hermite-simpson"])
def test_the_second_step_of_a_forward_walk_converges(transcription: str):
    """Step 2 starts from step 1's heel strike, far from the blended guess: where a first wiring of Uno (Uno's
    default sign for the Hessian's multipliers) stopped at its iteration limit. Checked against IPOPT's COT."""
    registry = load_registry()
    experiment = registry.create("experiment", "forward")
    walk = WalkProblem(experiment, registry.create("transcription", transcription), Uno(time_limit_s=60), 20,
                       steps=2)
    built = walk.transcription.build(walk.structure("second"))
    state = np.asarray(experiment.initial_state)[[0, 1, 4, 5]]
    for index in (1, 2):
        outcome = solve_and_verify(walk, index, built, walk.step_data(index, state))
        assert outcome.solved, outcome.message
        state = outcome.next_state
    assert outcome.verification.max_defect < 1e-8


def test_registers_the_uno_solver():
    (registration,) = register_solvers()
    assert registration.name == "uno" and registration.factory is Uno
