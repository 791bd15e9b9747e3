"""The SQP solver plugin: every QP backend, both Hessians and both globalisations, the QP interface (warm starts,
multiplier signs, dense and sparse matrices, backend errors, the fallback backend), infeasibility, the second-order
correction, the log, the remedies, and the gait steps and walks."""

from __future__ import annotations

import subprocess
import sys
from functools import cache
from pathlib import Path
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest
import qpsolvers
import scipy.sparse as sp
from gait_steps import FORMER_QUADRATURE, gait_step
from nlp_problems import (
    STANDARD_PROBLEMS,
    ReferenceProblem,
    hs039,
    hs071,
    hs076,
    infeasible,
    nonnegative_projection,
    rosenbrock,
    undefined_at_start,
)
from saved_qps import clarabel_objective, saved_qp

from gaitbench.contracts import WalkProblem
from gaitbench.plugins import load_registry
from gaitbench.problem.nlp import NLP, NLPBuilder
from gaitbench.solve.evaluation import Deadline, NLPEvaluator
from gaitbench.solver_result import SolverStatus
from gaitbench_plugins.solvers.ipopt import Ipopt
from gaitbench_plugins.solvers.sqp import SQP
from gaitbench_plugins.solvers.sqp.backends import _BACKEND_OPTIONS, QPBackends
from gaitbench_plugins.solvers.sqp.iterate import least_squares_multipliers
from gaitbench_plugins.solvers.sqp.solver import LONG_BUDGET
from gaitbench_plugins.solvers.sqp.subproblems import Subproblems


def _solve(problem: ReferenceProblem, **options):
    return SQP(**options).solve(problem.nlp, problem.parameters, problem.x0)


def _assert_optimal(result, problem: ReferenceProblem, tolerance: float = 1e-6) -> None:
    assert result.status is SolverStatus.CONVERGED, result.message
    assert abs(result.objective - problem.f_star) <= tolerance * max(1.0, abs(problem.f_star))
    assert result.constraint_violation <= 1e-7


@pytest.mark.parametrize("backend", qpsolvers.available_solvers)
def test_every_installed_backend_solves_a_constrained_problem(backend: str):
    """HS071 has an equality, an inequality and bounds on every variable, so it exercises A, G and the box."""
    problem = hs071()
    result = _solve(problem, qp_solver=backend)
    _assert_optimal(result, problem)
    np.testing.assert_allclose(result.x, problem.x_star, atol=1e-5)
    assert result.evaluations["qp"] >= result.iterations > 0
    assert f"({backend}: " in result.message


_ACCURATE_BACKENDS = [name for name in qpsolvers.available_solvers if name != "highs"]
"""HiGHS is left out of the standard problems: on free variables its QP solver ends in a solve error ("claims
optimality, but with primal infeasibilities": HS040), and near HS038's optimum it returns a zero step although the
gradient is not zero."""


@pytest.mark.parametrize("backend", _ACCURATE_BACKENDS)
@pytest.mark.parametrize("problem", STANDARD_PROBLEMS, ids=lambda problem: problem.name)
def test_standard_problems_with_every_accurate_backend(problem: ReferenceProblem, backend: str):
    _assert_optimal(_solve(problem, qp_solver=backend), problem)


_HS039_BFGS = pytest.mark.xfail(strict=True, reason=(
    "measured: BFGS 14 iterations with either merit (it converges one iteration earlier on the QP's fresh "
    "multipliers), exact 14 with the filter and 17 with the l1 merit, whose Levenberg-Marquardt damping (kept for the "
    "gait steps) delays the exact Newton steps; before both changes 10 and 14 against 15"))


@pytest.mark.parametrize("merit", ["l1", "filter"])
@pytest.mark.parametrize("problem", [hs071(), pytest.param(hs039(), marks=_HS039_BFGS), hs076(), rosenbrock()],
                         ids=lambda problem: problem.name)
def test_exact_hessian_takes_fewer_iterations_than_bfgs(problem: ReferenceProblem, merit: str):
    exact = _solve(problem, merit=merit)
    bfgs = _solve(problem, merit=merit, hessian="bfgs")
    _assert_optimal(exact, problem)
    _assert_optimal(bfgs, problem)
    assert exact.iterations < bfgs.iterations
    assert exact.evaluations["hess_l"] == exact.iterations
    assert "hess_l" not in bfgs.evaluations  # BFGS never evaluates the Hessian


@pytest.mark.parametrize("problem", STANDARD_PROBLEMS, ids=lambda problem: problem.name)
def test_filter_and_l1_merit_reach_the_same_optimum(problem: ReferenceProblem):
    l1, filtered = _solve(problem, merit="l1"), _solve(problem, merit="filter")
    _assert_optimal(l1, problem)
    _assert_optimal(filtered, problem)
    np.testing.assert_allclose(l1.x, filtered.x, atol=1e-6)


def test_multipliers_follow_casadis_sign_convention():
    """∇f + Jᵀλ_g + λ_x = 0: at x = 0 of min (x + 1)² s.t. x ≥ 0 the lower side is active with λ = −2."""
    np.testing.assert_allclose(_solve(nonnegative_projection(-1.0)).multipliers, [-2.0], atol=1e-8)
    problem = hs071()
    reference = Ipopt().solve(problem.nlp, problem.parameters, problem.x0)
    np.testing.assert_allclose(_solve(problem).multipliers, reference.multipliers, rtol=1e-5)


def test_unknown_backend_is_a_value_error_listing_the_available_ones():
    with pytest.raises(ValueError, match="unknown QP solver 'no-such-qp'") as raised:
        SQP(qp_solver="no-such-qp")
    for name in qpsolvers.available_solvers:
        assert name in str(raised.value)


@pytest.mark.parametrize("option, value", [("hessian", "sr1"), ("merit", "augmented-lagrangian"),
                                           ("tolerance", 0.0), ("max_iterations", -1)])
def test_other_bad_options_are_value_errors(option: str, value):
    with pytest.raises(ValueError):
        SQP(**{option: value})


def _spy(monkeypatch: pytest.MonkeyPatch) -> list[dict]:
    """Record every ``qpsolvers.solve_problem`` call (keyword arguments and the matrix types) and pass it on."""
    calls = []
    solve_problem = qpsolvers.solve_problem

    def spy(problem, solver, initvals=None, **kwargs):
        calls.append({"solver": solver, "initvals": initvals, "P": type(problem.P), "A": type(problem.A), **kwargs})
        return solve_problem(problem, solver, initvals=initvals, **kwargs)

    monkeypatch.setattr(qpsolvers, "solve_problem", spy)
    return calls


@pytest.mark.parametrize("backend", ["osqp", "proxqp", "daqp"])
def test_warm_start_passes_the_previous_step_to_backends_that_use_it(monkeypatch, backend: str):
    calls = _spy(monkeypatch)
    result = _solve(hs071(), qp_solver=backend)
    assert result.converged, result.message
    assert len(calls) == result.evaluations["qp"] > 2
    assert calls[0]["initvals"] is None
    assert all(call["initvals"] is not None and call["initvals"].shape == (4,) for call in calls[1:])
    if backend == "proxqp":  # the duals too: y for the sphere equality, z for the product row and the 4 bounds
        assert "y" not in calls[0] and "z" not in calls[0]
        assert all(call["y"].shape == (1,) and call["z"].shape == (5,) for call in calls[1:])


@pytest.mark.parametrize("backend", ["clarabel", "piqp", "quadprog", "highs"])
def test_backends_without_warm_start_are_never_given_initial_values(monkeypatch, backend: str):
    calls = _spy(monkeypatch)
    assert _solve(hs071(), qp_solver=backend).converged
    assert calls and all(call["initvals"] is None for call in calls)


def test_time_left_reaches_backends_with_a_time_limit(monkeypatch):
    """So one slow QP cannot overrun the solve's limit (HiGHS spends minutes on the first QP of a gait step)."""
    calls = _spy(monkeypatch)
    assert _solve(hs071(), qp_solver="clarabel", time_limit_s=60.0).converged
    assert all(0 < call["time_limit"] <= 60.0 for call in calls)
    assert _solve(hs071(), qp_solver="piqp", time_limit_s=60.0).converged  # PIQP has no such option
    assert all("time_limit" not in call for call in calls if call["solver"] == "piqp")


def test_qp_tolerance_reaches_the_backend(monkeypatch):
    calls = _spy(monkeypatch)
    assert _solve(hs071(), qp_solver="clarabel", qp_tolerance=1e-9).converged
    assert all(call["tol_gap_abs"] == call["tol_gap_rel"] == call["tol_feas"] == 1e-9 for call in calls)


def test_dense_only_backends_get_dense_matrices_and_sparse_ones_csc(monkeypatch):
    calls = _spy(monkeypatch)
    assert _solve(hs071(), qp_solver="quadprog").converged
    assert _solve(hs071(), qp_solver="clarabel").converged
    for call in calls:
        if call["solver"] == "quadprog":
            assert call["P"] is call["A"] is np.ndarray
        else:
            assert call["P"].__name__.startswith("csc") and call["A"].__name__.startswith("csc")


@pytest.mark.parametrize("merit", ["l1", "filter"])
@pytest.mark.parametrize("backend", ["clarabel", "daqp"])
def test_infeasible_problem_is_reported_with_the_backends_status(merit: str, backend: str):
    result = _solve(infeasible(), merit=merit, qp_solver=backend)
    assert result.status is SolverStatus.INFEASIBLE, result.message
    assert f"the QP subproblem failed ({backend}: " in result.message
    assert "a local minimiser of the constraint violation 1 (ℓ1)" in result.message
    assert result.constraint_violation == pytest.approx(0.5, abs=1e-6)  # x = 1/2 violates both rows by 1/2


def test_nan_at_the_starting_point_is_an_error_not_an_exception():
    result = _solve(undefined_at_start())
    assert result.status is SolverStatus.ERROR
    assert "not finite at the initial point" in result.message


def test_wrong_initial_guess_size_is_an_error():
    result = SQP().solve(hs071().nlp, hs071().parameters, np.zeros(3))
    assert result.status is SolverStatus.ERROR
    assert "3 values" in result.message


def test_iteration_limit():
    result = _solve(hs071(), max_iterations=2)
    assert result.status is SolverStatus.ITERATION_LIMIT
    assert result.iterations == 2
    assert result.evaluations["hess_l"] == 2


def test_time_limit():
    """Checked once per iteration, from the starting point on, which takes longer to evaluate than 1 µs."""
    problem = rosenbrock()
    result = _solve(problem, time_limit_s=1e-6)
    assert result.status is SolverStatus.TIME_LIMIT
    assert result.iterations == 0
    assert _solve(problem).iterations > 5


def _maratos() -> NLP:
    """min 2(x² + y² − 1) − x on the unit circle: near the solution (1, 0) full SQP steps increase both f and the
    violation (Nocedal & Wright, Example 15.4), so without a correction the merit rejects them."""
    b = NLPBuilder()
    x = b.variable("x", (2, 1))
    b.constrain("circle", x[0] ** 2 + x[1] ** 2 - 1)
    return b.build(ca.SX.sym("p", 0), 2 * (x[0] ** 2 + x[1] ** 2 - 1) - x[0])


@pytest.mark.parametrize("merit", ["l1", "filter"])
def test_second_order_correction_keeps_full_steps_on_the_maratos_example(merit: str, capsys):
    nlp, start = _maratos(), [np.cos(0.1), np.sin(0.1)]
    corrected = SQP(merit=merit, print_level=1).solve(nlp, [], start)
    log = capsys.readouterr().out.splitlines()
    plain = SQP(merit=merit, second_order_correction=False).solve(nlp, [], start)
    for result in (corrected, plain):
        assert result.converged, result.message
        np.testing.assert_allclose(result.x, [1.0, 0.0], atol=1e-8)
        np.testing.assert_allclose(result.multipliers, [-1.5], atol=1e-8)
    assert corrected.iterations < plain.iterations
    first_step = log[3].split()
    assert first_step[0] == "1" and first_step[4] == "1.00e+00" and first_step[-1] == "s"


def test_iteration_log(capsys):
    result = _solve(hs071(), print_level=1)
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "SQP (exact Hessian, l1 merit, QP backend piqp): 4 variables, 2 constraints"
    assert lines[1].split() == ["iter", "objective", "violation", "kkt", "alpha", "penalty", "qp_ms", "reg"]
    rows = lines[2:-1]
    assert [int(row.split()[0]) for row in rows] == list(range(result.iterations + 1))
    assert float(rows[-1].split()[1]) == pytest.approx(result.objective, rel=1e-7)
    assert lines[-1] == result.message


def test_print_level_zero_is_silent_even_for_backends_that_print():
    """In a fresh process: HiGHS prints its banner from C on its first use in a process and OSQP notes about
    polishing, whatever their verbosity settings."""
    script = ("from nlp_problems import hs071; from gaitbench_plugins.solvers.sqp import SQP; p = hs071(); "
              "assert all(SQP(qp_solver=b).solve(p.nlp, p.parameters, p.x0).converged "
              "for b in ('highs', 'osqp', 'clarabel'))")
    run = subprocess.run([sys.executable, "-c", script], cwd=Path(__file__).parent, capture_output=True, text=True)
    assert (run.returncode, run.stdout, run.stderr) == (0, "", "")


def test_resolving_with_new_parameters():
    problem = nonnegative_projection(2.0)
    solver = SQP()
    for target, x_star, lam in ((2.0, 2.0, 0.0), (-1.0, 0.0, -2.0)):
        result = solver.solve(problem.nlp, [target], problem.x0)
        assert result.converged, result.message
        np.testing.assert_allclose(result.x, [x_star], atol=1e-8)
        np.testing.assert_allclose(result.multipliers, [lam], atol=1e-8)


@pytest.mark.parametrize("transcription", ["dmoc", "hermite-simpson"])
@pytest.mark.parametrize("backend", ["clarabel", "daqp"])
def test_gait_step_reaches_ipopts_optimum_from_near_it(transcription: str, backend: str):
    """As a walk re-solves a step from a neighbouring solution: IPOPT's optimum perturbed by 1 %. Measured on the
    former hip-energy rules: on DMOC's default (Boole) step clarabel's line search fails near the optimum."""
    problem = gait_step(transcription, 20, quadrature=FORMER_QUADRATURE[transcription])
    start = problem.x_star * (1 + 0.01 * np.random.default_rng(0).standard_normal(problem.x_star.size))
    result = SQP(qp_solver=backend).solve(problem.nlp, problem.parameters, start)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert abs(result.objective - problem.f_star) <= 1e-6 * problem.f_star
    assert result.constraint_violation <= 1e-8
    assert result.iterations <= 25


@pytest.mark.parametrize("transcription", ["dmoc", "hermite-simpson"])
def test_sparse_least_squares_multipliers_equal_the_dense_ones_on_a_gait_step(transcription: str):
    """The first multipliers come from a sparse augmented system instead of a dense least squares: on a gait step's
    equality rows (at the guess and at IPOPT's optimum) both give the same λ, and a repeated row, which makes the
    system singular, still gets the dense minimum-norm answer."""
    problem = gait_step(transcription, 20)
    nlp = problem.nlp
    equality = np.flatnonzero(nlp.lbg == nlp.ubg)
    evaluator = NLPEvaluator(nlp, problem.parameters)
    for x in (problem.x0, problem.x_star):
        jacobian = sp.csr_matrix(evaluator.jacobian(x))[equality]
        grad = evaluator.gradient(x)
        dense = -np.linalg.lstsq(jacobian.toarray().T, grad, rcond=None)[0]
        np.testing.assert_allclose(least_squares_multipliers(jacobian, grad), dense, rtol=1e-6,
                                   atol=1e-9 * max(1.0, np.max(np.abs(dense))))
        repeated = sp.vstack([jacobian, jacobian[:1]], format="csr")
        dense = -np.linalg.lstsq(repeated.toarray().T, grad, rcond=None)[0]
        np.testing.assert_allclose(least_squares_multipliers(repeated, grad), dense, atol=1e-9)


def test_gait_step_from_the_transcriptions_guess_ends_at_another_local_minimum():
    """From the standard guess (zero torques) the SQP converges, but to a different KKT point than IPOPT's, 6.2 %
    dearer (1.7615 against 1.6593): the gait NLPs are not convex; ripopt and scipy's trust-constr land at 1.7634.
    (Measured on DMOC's former midpoint rule; on its Boole step daqp's QPs fail.)"""
    problem = gait_step("dmoc", 20, quadrature="midpoint")
    result = _solve(problem, qp_solver="daqp")
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.constraint_violation <= 1e-8
    assert problem.f_star < result.objective < 1.08 * problem.f_star



def _reversed_steps(monkeypatch: pytest.MonkeyPatch, when, scale: float = 1.0) -> list[int]:
    """Every QP step the solve takes where ``when(run)`` holds is reversed and multiplied by ``scale`` (an ascent
    direction, as an inexact QP gives at a point more stationary than its accuracy); returns the iterations where
    that happened."""
    reversed_at = []
    exact = Subproblems._qp

    def inexact(self, model, g, warm):
        outcome = exact(self, model, g, warm)
        if outcome.solved and when(self):
            reversed_at.append(self.iteration)
            outcome.x = -scale * outcome.x
        return outcome

    monkeypatch.setattr(Subproblems, "_qp", inexact)
    return reversed_at


def test_a_non_descent_qp_step_at_the_acceptable_level_ends_the_solve_there(monkeypatch):
    """Forward DMOC N = 100, step 1 used to spend 270 iterations past f = 1.366059e-4 on such steps, moving x by
    rounding while the QP's noisy multipliers kept the residual just above the acceptable level."""
    problem = hs071()
    reversed_at = _reversed_steps(monkeypatch, lambda run: run.acceptable > 0)
    result = _solve(problem, qp_solver="clarabel", acceptable_tolerance=1e-3)  # hs071 passes 1e-6 in one step
    assert reversed_at, "the solve never reached the acceptable level"
    assert result.status is SolverStatus.CONVERGED, result.message
    assert "no descent direction" in result.message
    assert result.iterations == reversed_at[0]
    assert result.constraint_violation <= 1e-3
    assert abs(result.objective - problem.f_star) <= 1e-4 * problem.f_star


def test_a_non_descent_qp_step_short_of_the_acceptable_level_is_no_convergence(monkeypatch):
    reversed_at = _reversed_steps(monkeypatch, lambda run: run.iteration >= 1)
    result = _solve(hs071(), qp_solver="clarabel", acceptable_tolerance=1e-3)
    assert reversed_at
    assert result.status is not SolverStatus.CONVERGED, result.message


def test_steps_that_move_the_merit_only_by_rounding_end_the_solve_after_15_iterations(monkeypatch):
    """Forward step 2, DMOC N = 25 (from IPOPT's step 1) used to take 2,850 such steps to its iteration limit."""
    _reversed_steps(monkeypatch, lambda run: run.iteration >= 1, scale=1e-14)  # moves within φ's rounding slack
    result = _solve(hs071(), qp_solver="clarabel", max_iterations=200)
    assert result.status is SolverStatus.ERROR, result.message
    assert "rounding" in result.message
    assert result.iterations <= 20


def test_elastic_steps_that_move_the_merit_only_by_rounding_end_the_solve_after_15_iterations(monkeypatch):
    """Upward slope, HS N = 100, step 11, on Clarabel's QPs: from iteration 250 every QP failed, and elastic steps at
    α ~ 1e-8 went on to the iteration limit, one second each (2,217 s); they count as stalled steps too. Here: min
    x₀ + x₁ on the circle x₀² + x₁² = 2 from a feasible, non-stationary point, every QP failing and every elastic
    step moving x within φ's rounding."""
    b = NLPBuilder()
    x = b.variable("x", (2, 1))
    b.constrain("circle", x[0] ** 2 + x[1] ** 2 - 2)
    nlp = b.build(ca.SX.sym("p", 0), x[0] + x[1])
    exact_qp, exact_elastic = Subproblems._qp, Subproblems._elastic_qp

    def failing(self, model, g, warm):
        outcome = exact_qp(self, model, g, warm)
        outcome.solved = False
        return outcome

    def rounding(self, *args, **kwargs):
        outcome = exact_elastic(self, *args, **kwargs)
        outcome.x = 1e-16 * outcome.x
        return outcome

    monkeypatch.setattr(Subproblems, "_qp", failing)
    monkeypatch.setattr(Subproblems, "_elastic_qp", rounding)
    result = SQP(qp_solver="clarabel", max_iterations=200).solve(nlp, np.zeros(0), np.array([np.sqrt(2.0), 0.0]))
    assert result.status is SolverStatus.ERROR, result.message
    assert "rounding" in result.message
    assert result.iterations <= 16


@pytest.mark.slow
def test_forward_dmoc_step_at_n_100_stops_where_the_qp_accuracy_is_spent():
    """433 iterations before the non-descent test (270 of them at f = 1.366059e-4), 147 with it."""
    registry = load_registry()
    problem = WalkProblem(registry.create("experiment", "forward"), registry.create("transcription", "dmoc"),
                          Ipopt(), 100)
    built = problem.transcription.build(problem.structure("second"))
    data = problem.step_data(1, problem.start_state())
    result = SQP().solve(built.nlp, data.parameter_vector(), built.initial_guess(data))
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.iterations <= 200
    assert result.constraint_violation <= 1e-8
    assert result.objective <= 1.3661e-4


@pytest.mark.slow
def test_a_stationary_infeasible_iterate_is_projected_onto_the_constraints():
    """Forward HS N = 50, step 4, from the state an ``sqp`` walk reached it in (IPOPT: 347 iterations, f = 0.2130).
    The ℓ1 merit trades feasibility for f along the cost's flat valley (violation up to 20 by iteration 20); by
    iteration ~200 the iterate is stationary (KKT residual ~1e-8) and the full steps that slide along the continuum
    of optima lower the violation by only 2 % each. Projected only below the acceptable level, it reached the
    500-iteration limit at violation 7e-5 (converged at 667 with a limit of 3000); projected at any violation,
    it converges at iteration 209."""
    registry = load_registry()
    problem = WalkProblem(registry.create("experiment", "forward"), registry.create("transcription", "hermite-simpson"),
                          Ipopt(), 50)
    built = problem.transcription.build(problem.structure("second", walked=True))
    data = problem.step_data(4, np.array([-np.pi / 6, np.pi / 6, 0.24373434, -0.88345295]))
    result = SQP().solve(built.nlp, data.parameter_vector(), built.initial_guess(data))
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.iterations <= 300
    assert result.constraint_violation <= 1e-8
    assert result.objective < 0.2130


@cache
def _forward_walk(solver: str, transcription: str, n_nodes: int, steps: int):
    """The forward experiment's first steps, one phase, as ``gaitbench solve`` walks them (verified, retried)."""
    registry = load_registry()
    problem = WalkProblem(registry.create("experiment", "forward"), registry.create("transcription", transcription),
                          registry.create("solver", solver, time_limit_s=60), n_nodes, steps=steps)
    return registry.create("strategy", "one-phase").solve(problem)


def _walks_to_ipopts_acot(transcription: str, n_nodes: int, steps: int) -> None:
    """The issue's bar: a complete walk whose verified ACOT is at most 5 % above IPOPT's (the thesis cost has a
    continuum of optima, so lower is fine)."""
    walk, reference = _forward_walk("sqp", transcription, n_nodes, steps), _forward_walk("ipopt", transcription,
                                                                                         n_nodes, steps)
    assert walk.complete, walk.failure
    assert reference.complete, reference.failure
    assert walk.acot <= 1.05 * reference.acot
    assert max(step.verification.max_defect for step in walk.steps) < 1e-7


@pytest.mark.parametrize("transcription", ["dmoc", "hermite-simpson"])
def test_a_two_step_forward_walk_at_ipopts_acot_or_lower(transcription: str):
    """Step 2 starts from step 1's heel strike, far from the blended guess, and costs real work (COT ≈ 0.05)."""
    _walks_to_ipopts_acot(transcription, 20, 2)


@pytest.mark.slow
@pytest.mark.parametrize("n_nodes", [20, 50])
@pytest.mark.parametrize("transcription", ["dmoc", "hermite-simpson"])
def test_a_three_step_forward_walk_at_ipopts_acot_or_lower(transcription: str, n_nodes: int):
    """The issue's done-when walks (``gaitbench solve -e forward -s sqp --steps 3``)."""
    _walks_to_ipopts_acot(transcription, n_nodes, 3)


def test_the_last_resorts_are_the_crawl_floor_then_a_longer_budget_with_the_same_options():
    from gaitbench_plugins.solvers.sqp.hessian import CRAWL_SHIFT_FLOOR, SHIFT_FLOOR

    solver = SQP(qp_solver="clarabel", merit="filter", tolerance=1e-7)
    [(floor_name, floor), (budget_name, budget)] = solver.last_resorts()
    assert (floor_name, budget_name) == ("crawl-floor", "more-iterations")
    assert floor.crawl_shift_floor == CRAWL_SHIFT_FLOOR < solver.crawl_shift_floor == SHIFT_FLOOR
    assert budget.max_iterations == LONG_BUDGET > solver.max_iterations == floor.max_iterations
    for variant in (floor, budget):
        assert (variant.qp_solver, variant.merit, variant.tolerance) == ("clarabel", "filter", 1e-7)
    assert [name for name, _ in floor.last_resorts()] == ["more-iterations"]
    assert [name for name, _ in budget.last_resorts()] == ["crawl-floor"]
    with pytest.raises(ValueError, match="crawl_shift_floor"):
        SQP(crawl_shift_floor=1e-8)


def test_remedies_are_other_paths_clarabel_from_any_start_the_filter_from_a_seed_and_keep_the_options():
    solver = SQP(max_iterations=77, qp_tolerance=1e-9)
    (name, clarabel), = solver.remedies()
    (seed_name, filter_), = solver.seed_remedies()
    assert (name, seed_name) == ("clarabel", "filter")
    assert (filter_.merit, filter_.qp_solver) == ("filter", "piqp")
    assert (clarabel.qp_solver, clarabel.fallback_qp_solver) == ("clarabel", "piqp")
    assert all(v.max_iterations == 77 and v.qp_tolerance == 1e-9 for v in (clarabel, filter_))
    assert clarabel.remedies() == [] and filter_.seed_remedies() == []
    # on from where its budget ran out, with the crawl floor; the same solve if it has it already
    (name, continuation), = solver.continuations()
    assert (name, continuation.crawl_shift_floor, continuation.max_iterations) == ("continue-crawl-floor", 1e-12, 77)
    assert continuation.continuations() == [("continue", continuation)]


def test_a_failed_qp_is_solved_again_by_the_fallback_backend(monkeypatch):
    """PIQP stops at its iteration limit on some convexified gait QPs that Clarabel solves; the fallback keeps the
    iteration going."""
    calls = []
    original = qpsolvers.solve_problem

    def failing_piqp(problem, solver, **options):
        calls.append(solver)
        if solver == "piqp":
            return qpsolvers.Solution(problem)  # found = None: not solved
        return original(problem, solver=solver, **options)

    monkeypatch.setattr(qpsolvers, "solve_problem", failing_piqp)
    problem = hs071()
    result = _solve(problem, qp_solver="piqp", fallback_qp_solver="clarabel")
    assert result.status is SolverStatus.CONVERGED, result.message
    assert abs(result.objective - problem.f_star) <= 1e-6 * abs(problem.f_star)
    assert set(calls) == {"piqp", "clarabel"}
    monkeypatch.setattr(qpsolvers, "solve_problem", failing_piqp)
    assert _solve(problem, qp_solver="piqp", fallback_qp_solver="none").status is not SolverStatus.CONVERGED


def test_piqp_solves_a_gait_qp_on_which_its_finer_regularisation_diverges():
    """A QP of `sqp`'s forward HS N = 50 walk (step 2; n = 695, a convexification shift of ~1e-10·max|H|). PIQP
    with its own settings reaches its solution by iteration ~20, lowers its regularisation to 1e-13 to meet the
    1e-10 tolerance, diverges and ends at its limit; with the backends' floor of 1e-10 it solves it, to the
    objective Clarabel finds to five digits (docs/decisions/0002-qp-backends.md)."""
    problem = saved_qp("sqp_gait_qp_piqp_finetune")
    evaluator = SimpleNamespace(evaluations={"qp": 0})  # the one part of an NLPEvaluator the backends use
    backends = QPBackends("piqp", None, 1e-10, Deadline(None), evaluator)
    solved = backends.solve(problem, None, {"flags": "", "qp_time": 0.0})
    assert solved.solved, solved.status
    assert evaluator.evaluations["qp"] == 1  # PIQP alone: no fallback was given
    objective = 0.5 * solved.x @ problem.P @ solved.x + problem.q @ solved.x
    assert objective == pytest.approx(clarabel_objective(problem), rel=1e-5)
    without_floor = qpsolvers.solve_problem(problem, solver="piqp", eps_abs=1e-10, eps_rel=1e-10,
                                            **_BACKEND_OPTIONS["piqp"])  # every setting of sqp's call but the floor
    assert not without_floor.found  # the saved QP still shows the failure the floor avoids


def test_piqp_solves_again_without_its_equilibration_a_gait_qp_it_fails_with_it():
    """A QP of `sqp`'s forward step 2 at HS N = 50 (n = 695) that PIQP, equilibrated, ends at its iteration limit.
    The backends try it again without the equilibration, before any fallback, and solve it to Clarabel's objective
    (docs/decisions/0002-qp-backends.md)."""
    problem = saved_qp("sqp_gait_qp_piqp_preconditioner")
    evaluator = SimpleNamespace(evaluations={"qp": 0})
    log = {"flags": "", "qp_time": 0.0}
    solved = QPBackends("piqp", None, 1e-10, Deadline(None), evaluator).solve(problem, None, log)
    assert solved.solved, solved.status
    assert (evaluator.evaluations["qp"], log["flags"]) == (2, "u")  # the equilibrated call failed; the retry solved
    objective = 0.5 * solved.x @ problem.P @ solved.x + problem.q @ solved.x
    assert objective == pytest.approx(clarabel_objective(problem), rel=1e-5)
    assert np.max(problem.G @ solved.x - problem.h) <= 1e-9
    assert np.max(np.abs(problem.A @ solved.x - problem.b)) <= 1e-9


def test_once_the_retry_settings_solve_a_qp_the_backend_failed_they_go_first_on_the_next_qps():
    """PIQP fails the late steps' QPs in runs. After its unequilibrated retry solved the saved QP that the
    equilibrated PIQP fails, the next QP (here the same one) goes to the unequilibrated PIQP first, once the crawl
    has shown (``swap``): one call, not two."""
    problem = saved_qp("sqp_gait_qp_piqp_preconditioner")
    evaluator = SimpleNamespace(evaluations={"qp": 0})
    backends = QPBackends("piqp", None, 1e-10, Deadline(None), evaluator)
    backends.swap = True
    first, second = {"flags": "", "qp_time": 0.0}, {"flags": "", "qp_time": 0.0}
    assert backends.solve(problem, None, first).solved and evaluator.evaluations["qp"] == 2
    again = backends.solve(problem, None, second)
    assert again.solved and (evaluator.evaluations["qp"], second["flags"]) == (3, "u")
    assert backends.order.retry_first("piqp")


def test_the_backend_settings_go_first_again_when_a_qp_fails_under_the_retry_settings_that_they_solve(monkeypatch):
    """The order of the calls, scripted: which settings solve each QP. The swap back comes with the first QP that
    the retry settings fail and the backend's own settings solve; a QP both fail leaves the order as it was. Before
    the crawl (``swap`` off) the backend's own settings always go first."""
    from gaitbench.solve.qp import RETRY_SETTINGS
    from gaitbench_plugins.solvers.sqp.backends import QPOutcome

    def solves():  # per QP, the settings that solve it
        return iter([{"retry"}, {"retry"}, set(), {"own"}, {"own", "retry"}])
    calls = []
    current = {}

    def call(self, solver, problem, warm, log, extra=None):
        settings = "retry" if extra == RETRY_SETTINGS["piqp"] else "own"
        calls.append(settings)
        return QPOutcome(settings in current["solves"], "scripted")

    monkeypatch.setattr(QPBackends, "_call", call)
    def order(swap: bool) -> list[tuple[str, ...]]:
        backends = QPBackends("piqp", None, 1e-10, Deadline(None), SimpleNamespace(evaluations={"qp": 0}))
        backends.swap = swap
        orders = []
        for current["solves"] in solves():
            calls.clear()
            backends.solve(None, None, {"flags": "", "qp_time": 0.0})
            orders.append(tuple(calls))
        return orders

    assert order(True) == [("own", "retry"), ("retry",), ("retry", "own"), ("retry", "own"), ("own",)]
    assert order(False) == [("own", "retry"), ("own", "retry"), ("own", "retry"), ("own",), ("own",)]


def test_registered_as_a_solver_plugin(tmp_path: Path):
    """Through a plugin directory holding only a file that registers this plugin (a package, which a plugin directory
    does not load itself), so the test does not depend on the installed entry points."""
    registration = "from gaitbench_plugins.solvers.sqp import register_solvers  # noqa: F401\n"
    (tmp_path / "sqp_plugin.py").write_text(registration)
    registry = load_registry([tmp_path], use_entry_points=False)
    assert registry.names("solver") == ["sqp"]
    solver = registry.create("solver", "sqp", qp_solver="daqp", hessian="bfgs", merit="filter")
    assert (solver.name, solver.qp_solver, solver.hessian, solver.merit) == ("sqp", "daqp", "bfgs", "filter")


def test_print_level_two_names_the_blocks_that_hold_the_violation_and_the_step(capsys):
    """Below each iteration's line: the violated constraint blocks with their part of the ℓ1 merit, and the variable
    blocks the last step moved (how the late-step crawl was read, docs/decisions/0003-sqp-late-step-crawl.md)."""
    start = np.array([2.0, 0.0])  # off the unit circle by x² + y² − 1 = 3
    result = SQP(print_level=2).solve(_maratos(), [], start)
    assert result.converged, result.message
    lines = capsys.readouterr().out.splitlines()[2:-1]
    rows, where = lines[0::2], lines[1::2]
    assert len(rows) == len(where) == result.iterations + 1
    assert where[0].split() == ["violation:", "circle", "3.0e+00", "(merit", "0.0e+00);", "step:", "none"]
    first_step = np.linalg.norm(SQP(max_iterations=1).solve(_maratos(), [], start).x - start)
    assert where[1].endswith(f"step: x {first_step:.1e}")
    last = where[-1].split()
    assert last[1] == "circle" and float(last[2]) < 1e-8 < float(where[-2].split()[2])


def test_released_linear_variables_lose_the_shift_and_get_a_step_bound():
    """The release behind the end of the late-step crawl: a variable with an empty Hessian column loses the shift,
    the others keep it, and the QP bounds its step by LINEAR_STEP·(1 + |x_i|) inside its own bounds."""
    from gaitbench_plugins.solvers.sqp.hessian import LINEAR_STEP, Model, convexify, release_linear_variables

    H = sp.csc_matrix(np.array([[2.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]))
    jacobian = sp.csr_matrix(np.array([[1.0, 1.0, -1.0]]))
    model, _ = convexify(H, 1e-3, 1.0, jacobian, lambda: (np.zeros(0, dtype=int), np.zeros(0, dtype=int)))
    released = release_linear_variables(model, H)
    assert model.shift == pytest.approx(1e-3)
    assert released.linear.tolist() == [False, True, True]
    assert released.P.diagonal().tolist() == pytest.approx([2.0 + 1e-3, 0.0, 0.0])
    assert sp.csc_matrix(released.curvature).diagonal().tolist() == pytest.approx([2.0 + 1e-3, 0.0, 0.0])
    assert release_linear_variables(Model(H, H, np.zeros(0, dtype=int), np.zeros(0), 0.0), H).linear is None

    lin = SimpleNamespace(bounds=lambda x: (np.array([-5.0, -5.0, -0.5]), np.array([5.0, 5.0, 5.0])))
    iterate = SimpleNamespace(lin=lin, x=np.array([1.0, 3.0, 0.5]), n=3)
    lb, ub = Subproblems._step_bounds(iterate, released)
    assert lb.tolist() == pytest.approx([-5.0, -4.0 * LINEAR_STEP, -0.5])
    assert ub.tolist() == pytest.approx([5.0, 4.0 * LINEAR_STEP, 1.5 * LINEAR_STEP])
    assert Subproblems._step_bounds(iterate, model)[0].tolist() == [-5.0, -5.0, -0.5]


def test_the_crawl_floor_lowers_the_shift_floor_once_the_shift_sits_at_its_floor():
    """``crawl_shift_floor``: before the crawl shows the shift's floor is SHIFT_FLOOR·max|H|, after it the crawl
    floor (by default SHIFT_FLOOR still); a shift between the two still counts as at the floor (the crawl goes on),
    one above SHIFT_FLOOR's ends it."""
    from gaitbench_plugins.solvers.sqp.hessian import CRAWL_SHIFT_FLOOR, SHIFT_FLOOR, hessian_scale
    from gaitbench_plugins.solvers.sqp.run import Run
    from gaitbench_plugins.solvers.sqp.subproblems import _FLOOR_ITERATIONS

    nlp = _split_power()
    x = np.zeros(nlp.n_variables)
    x[nlp.variable_blocks["u"]] = [1.5, 2.0]
    default = Run(SQP(), NLPEvaluator(nlp, np.zeros(0)), x, Deadline(None))
    default.at_floor = _FLOOR_ITERATIONS
    scale = hessian_scale(sp.csc_matrix(default.evaluator.hessian_lagrangian(default.x, 1.0, default.lam)))
    assert default._model().shift == pytest.approx(SHIFT_FLOOR * scale)
    run = Run(SQP(crawl_shift_floor=CRAWL_SHIFT_FLOOR), NLPEvaluator(nlp, np.zeros(0)), x, Deadline(None))
    assert run._model().shift == pytest.approx(SHIFT_FLOOR * scale) and run.at_floor == 1
    run.at_floor = _FLOOR_ITERATIONS
    assert run._model().shift == pytest.approx(CRAWL_SHIFT_FLOOR * scale) and run.at_floor == _FLOOR_ITERATIONS + 1
    run.shift, run.shift_growth = 10 * CRAWL_SHIFT_FLOOR * scale, 1.0
    assert run._model().shift == pytest.approx(10 * CRAWL_SHIFT_FLOOR * scale)
    assert run.at_floor == _FLOOR_ITERATIONS + 2
    run.shift = 10 * SHIFT_FLOOR * scale
    assert run._model().shift == pytest.approx(10 * SHIFT_FLOOR * scale) and run.at_floor == 0
    run.shift = 0.0
    assert run._model().shift == pytest.approx(SHIFT_FLOOR * scale)  # no longer crawling: the usual floor


def test_a_row_whose_gradient_vanishes_brings_a_capped_multiplier_into_the_hessian(monkeypatch):
    """The crossing's clearance (docs/decisions/0006-sqp-clearance-saddle.md): the product
    c = u₀u₁ ≥ 0 at u₀ = 0 is active with a gradient of norm |u₁|, here 1e-4. Its multiplier enters the Hessian
    capped at DEGENERATE_MULTIPLIER_CAP, with its sign; a row with an O(1) gradient keeps its multiplier, and so
    do the iterate's multipliers (the QP, the merit's weights and the KKT test use them)."""
    from gaitbench_plugins.solvers.sqp.hessian import DEGENERATE_MULTIPLIER_CAP
    from gaitbench_plugins.solvers.sqp.run import Run

    b = NLPBuilder()
    u = b.variable("u", (2, 1))
    b.constrain("crossing", u[0] * u[1], 0.0, np.inf)
    b.constrain("plain", u[0] ** 2 + u[1], 0.0, np.inf)
    nlp = b.build(ca.SX.sym("p", 0), (u[0] - 1) ** 2 + (u[1] - 1) ** 2)
    run = Run(SQP(), NLPEvaluator(nlp, np.zeros(0)), np.array([0.0, 1e-4]), Deadline(None))
    run.lam = np.array([-5e4, -5e4])
    seen = []
    hessian = run.evaluator.hessian_lagrangian
    monkeypatch.setattr(run.evaluator, "hessian_lagrangian",
                        lambda x, sigma, lam: seen.append(np.array(lam)) or hessian(x, sigma, lam))
    run._model()
    assert seen[-1].tolist() == [-DEGENERATE_MULTIPLIER_CAP, -5e4]
    assert run.lam.tolist() == [-5e4, -5e4] and "c" in run.log["flags"]
    run.lam, run.log["flags"] = np.array([-0.9 * DEGENERATE_MULTIPLIER_CAP, -5e4]), ""
    run._model()  # below the cap nothing changes
    assert seen[-1].tolist() == [-0.9 * DEGENERATE_MULTIPLIER_CAP, -5e4] and "c" not in run.log["flags"]


def test_a_row_whose_gradient_vanishes_is_posed_at_unit_norm_with_its_multiplier_scaled_back():
    """The crossing's clearance again: c = u₀u₁ ≥ 0 at u = (0, 1e-7) has a gradient of norm 1e-7, and the cost
    (u₀ + 1)² pushes against it with force 2, so its multiplier is −2/1e-7 = −2e7. The QP poses the row scaled by
    1e6 (the scale's limit; its dual there is 20), the multiplier comes back as −2e7, and the trust test reads the
    QP's own dual: the QP is not taken for a nearly inconsistent one (its multiplier is above 1e6). Only once the
    crawl shows: before it the QPs are posed as they are."""
    from gaitbench_plugins.solvers.sqp.run import Run
    from gaitbench_plugins.solvers.sqp.subproblems import _FLOOR_ITERATIONS

    b = NLPBuilder()
    u = b.variable("u", (2, 1))
    b.constrain("crossing", u[0] * u[1], 0.0, np.inf)
    b.constrain("plain", u[1], 0.0, np.inf)
    nlp = b.build(ca.SX.sym("p", 0), (u[0] + 1) ** 2 + (u[1] - 1) ** 2)
    run = Run(SQP(), NLPEvaluator(nlp, np.zeros(0)), np.array([0.0, 1e-7]), Deadline(None))
    model = run._model()
    assert run._qp(model, run.g, None).scale is None
    run.at_floor = _FLOOR_ITERATIONS
    model = run._model()
    outcome = run._qp(model, run.g, None)
    assert outcome.solved and outcome.scale.tolist() == pytest.approx([1e6, 1.0])
    assert outcome.z[0] == pytest.approx(20.0, rel=1e-6)
    assert run._multipliers(outcome, model)[0] == pytest.approx(-2e7, rel=1e-6)
    run.lam = np.zeros(2)
    assert run._optimality_step() is None and "e" not in run.log["flags"]  # a QP step, not an elastic one


def test_a_warm_start_carries_its_duals_into_the_row_scale_of_the_qp_it_starts():
    """ProxQP starts from the previous QP's duals. Where that QP posed the crossing's row unscaled and this one at
    unit norm (the crawl has begun between them), the dual the backend gets is the multiplier over this QP's scale,
    not the other QP's dual: a factor of 1e6 apart on that row."""
    from gaitbench_plugins.solvers.sqp.run import Run
    from gaitbench_plugins.solvers.sqp.subproblems import _FLOOR_ITERATIONS

    b = NLPBuilder()
    u = b.variable("u", (2, 1))
    b.constrain("crossing", u[0] * u[1], 0.0, np.inf)
    b.constrain("plain", u[1], 0.0, np.inf)
    nlp = b.build(ca.SX.sym("p", 0), (u[0] + 1) ** 2 + (u[1] - 1) ** 2)
    run = Run(SQP(qp_solver="proxqp"), NLPEvaluator(nlp, np.zeros(0)), np.array([0.0, 1e-7]), Deadline(None))
    unscaled = run._qp(run._model(), run.g, None)
    assert unscaled.solved and unscaled.scale is None and unscaled.z[0] == pytest.approx(2e7, rel=1e-4)
    given = []
    solve = run.backends.solve
    run.backends.solve = lambda problem, warm, log: given.append(warm) or solve(problem, warm, log)
    run.at_floor = _FLOOR_ITERATIONS
    scaled = run._qp(run._model(), run.g, unscaled)
    assert scaled.solved and scaled.scale.tolist() == pytest.approx([1e6, 1.0])
    assert given[0].z[0] == pytest.approx(20.0, rel=1e-4) and given[0].z[1] == unscaled.z[1]
    assert run.lin.multipliers(given[0]) == pytest.approx(run.lin.multipliers(unscaled))
    assert run.lin.rescaled(scaled, None).z[0] == pytest.approx(scaled.z[0] * 1e6)


def _split_power() -> NLP:
    """A charged power P = u₀u₁ split as s⁺ − s⁻ (the gait steps' form), a second split that costs nothing to raise
    along its row, and a slack that enters two rows: only the first is a slack pair."""
    b = NLPBuilder()
    u = b.variable("u", (2, 1))
    positive = b.variable("positive", (1, 1), lower=0.0)
    negative = b.variable("negative", (1, 1), lower=0.0)
    free = b.variable("free", (2, 1), lower=0.0)
    shared = b.variable("shared", (1, 1), lower=0.0)
    b.constrain("split", u[0] * u[1] - positive + negative)
    b.constrain("free_split", u[0] - u[1] - free[0] + free[1])
    b.constrain("shared_rows", ca.vertcat(u[0] + shared, u[1] - 2 * shared), -np.inf, 10.0)
    objective = (u[0] - 2) ** 2 + (u[1] - 1) ** 2 + 3 * positive + 0.5 * negative + shared
    return b.build(ca.SX.sym("p", 0), objective)


def test_slack_pairs_are_reset_to_the_cheapest_values_that_satisfy_their_row():
    """A magical step (plugins/solvers/sqp/slacks.py): the pair's row holds exactly afterwards, with one slack at
    its bound, and the objective falls by the cost the reset saves."""
    from gaitbench_plugins.solvers.sqp.linearization import Linearization
    from gaitbench_plugins.solvers.sqp.slacks import SlackPairs

    nlp = _split_power()
    evaluator = NLPEvaluator(nlp, np.zeros(0))
    lin = Linearization(nlp)
    index = np.arange(nlp.n_variables)
    u, positive, negative = (index[nlp.variable_blocks[name]] for name in ("u", "positive", "negative"))
    x = np.zeros(nlp.n_variables)
    x[u] = [1.5, 2.0]
    pairs = SlackPairs.find(evaluator, lin, evaluator.gradient(x), sp.csr_matrix(evaluator.jacobian(x)))
    assert (pairs.down.tolist(), pairs.up.tolist()) == (positive.tolist(), negative.tolist())
    split = np.arange(nlp.n_constraints)[nlp.constraint_blocks["split"]]
    for power_slacks, expected in (((1.0, 0.4), (3.0, 0.0)), ((0.0, 5.0), (3.0, 0.0))):
        x[positive], x[negative] = power_slacks
        reset = pairs.reset(x, evaluator.constraints(x), lin)
        assert (reset[positive].item(), reset[negative].item()) == pytest.approx(expected)
        assert evaluator.constraints(reset)[split].item() == pytest.approx(0.0, abs=1e-15)
        others = np.setdiff1d(index, [*positive, *negative])
        np.testing.assert_array_equal(reset[others], x[others])
    x[u] = [-1.5, 2.0]  # P = −3, held by both slacks above their cheapest values
    x[positive], x[negative] = 1.0, 4.0
    reset = pairs.reset(x, evaluator.constraints(x), lin)
    assert (reset[positive].item(), reset[negative].item()) == pytest.approx((0.0, 3.0))
    assert evaluator.objective(x) - evaluator.objective(reset) == pytest.approx(3 * 1.0 + 0.5 * 1.0)


@pytest.mark.parametrize("floor_iterations", [0, 20])
def test_slack_pairs_are_reset_only_once_the_shift_sits_at_its_floor(monkeypatch, floor_iterations: int):
    """The reset is for the late-step crawl: before the shift has sat at its floor for 20 iterations it never runs,
    so the first steps' paths are those without it (on this small problem the solve ends before that). Where it
    runs (the floor count set to 0 here), a reset point holds its split row exactly and never has a higher merit."""
    import gaitbench_plugins.solvers.sqp.subproblems as subproblems
    from gaitbench_plugins.solvers.sqp.linesearch import LineSearch

    monkeypatch.setattr(subproblems, "_FLOOR_ITERATIONS", floor_iterations)
    nlp = _split_power()
    split = np.arange(nlp.n_constraints)[nlp.constraint_blocks["split"]]
    resets = []
    original = LineSearch._reset_slacks

    def spy(self, trial):
        point = original(self, trial)
        if point is not trial:
            resets.append((self._phi(trial) - self._phi(point), abs(point.g[split].item())))
        return point

    monkeypatch.setattr(LineSearch, "_reset_slacks", spy)
    result = SQP().solve(nlp, [], np.zeros(nlp.n_variables))
    assert result.converged, result.message
    if floor_iterations:
        assert resets == []
    else:
        assert resets
        assert all(fall >= 0 and violation <= 1e-12 for fall, violation in resets)
    u = result.x[nlp.variable_blocks["u"]]
    power = u[0] * u[1]
    assert result.x[nlp.variable_blocks["positive"]].item() == pytest.approx(max(power, 0.0), abs=1e-7)
    assert result.x[nlp.variable_blocks["negative"]].item() == pytest.approx(max(-power, 0.0), abs=1e-7)


def test_a_slack_reset_that_would_raise_the_merit_or_comes_before_the_crawl_is_not_taken():
    """``LineSearch._reset_slacks`` on one point: taken once the shift has sat at its floor, with the ℓ1 merit, where
    it lowers φ; the point itself before the crawl, where covering the power costs more than the merit's weights
    save, and with the filter."""
    from gaitbench_plugins.solvers.sqp.run import Run
    from gaitbench_plugins.solvers.sqp.subproblems import _FLOOR_ITERATIONS

    nlp = _split_power()
    split = np.arange(nlp.n_constraints)[nlp.constraint_blocks["split"]]
    x = np.zeros(nlp.n_variables)
    x[nlp.variable_blocks["u"]] = [1.5, 2.0]  # P = 3, held by neither slack
    run = Run(SQP(), NLPEvaluator(nlp, np.zeros(0)), x, Deadline(None))
    trial = run._trial(x)
    run.weights = np.full(nlp.n_constraints, 10.0)  # above the slacks' costs: covering P lowers φ
    assert run._reset_slacks(trial) is trial
    run.at_floor = _FLOOR_ITERATIONS
    reset = run._reset_slacks(trial)
    assert reset.g[split].item() == pytest.approx(0.0, abs=1e-15) and run._phi(reset) < run._phi(trial)
    run.weights = np.zeros(nlp.n_constraints)  # φ = f, which covering P raises by 3·3
    assert run._reset_slacks(trial) is trial
    filtered = Run(SQP(merit="filter"), NLPEvaluator(nlp, np.zeros(0)), x, Deadline(None))
    filtered.at_floor = _FLOOR_ITERATIONS
    assert filtered._reset_slacks(trial) is trial


def test_a_row_the_qp_keeps_off_its_bound_leaves_the_working_set():
    """Rows near their bound (docs/decisions/0003-sqp-late-step-crawl.md): x₀ = ½ ties down the Hessian's negative
    curvature, so P needs the augmentation, and the row x₁ ≤ 1 starts 9e-7 below its bound with the cost pushing it
    there at 1e-5. In the working set by nearness alone, its term max|H|·d₁² = 1e4·d₁² held each step to 1e-9, and the
    solve ended after 14 iterations by the stall rule, the KKT residual at 1e-5; once five QP steps have left it inside,
    it leaves the working set, the next step reaches its bound and gives it the cost's push as its multiplier."""
    from gaitbench_plugins.solvers.sqp.subproblems import _INSIDE_STEPS

    b = NLPBuilder()
    x = b.variable("x", (3, 1))
    b.constrain("tie", x[0], 0.5, 0.5)
    b.constrain("row", x[1], -np.inf, 1.0)
    nlp = b.build(ca.SX.sym("p", 0), -50 * x[0] ** 2 + 5e3 * x[2] ** 2 - 1e-5 * x[1])
    result = SQP(max_iterations=100).solve(nlp, np.zeros(0), np.array([0.5, 1.0 - 9e-7, 0.0]))
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.iterations == _INSIDE_STEPS
    assert result.multipliers[1] == pytest.approx(1e-5, rel=1e-6)


def test_infeasible_only_where_the_violation_cannot_decrease():
    """x₂ = x₁² and x₂ = 2 − x₁² from (0, 5), maximising x₂ hard: the elastic QP, which still weighs the objective,
    predicts no decrease of the violation (8) at the start; the restoration, on the violation alone, brings it down
    to x = (0, 2), a stationary point of the violation on the symmetry line x₁ = 0, before calling it infeasible."""
    from gaitbench.problem.nlp import NLPBuilder
    from gaitbench_plugins.solvers.sqp import SQP

    b = NLPBuilder()
    x = b.variable("x", (2, 1))
    b.constrain("a", x[1] - x[0] ** 2)
    b.constrain("b", x[1] + x[0] ** 2 - 2)
    nlp = b.build(ca.SX.sym("p", 0), -1e4 * x[1])
    result = SQP().solve(nlp, np.zeros(0), np.array([0.0, 5.0]))
    assert result.status == SolverStatus.INFEASIBLE, result.message
    np.testing.assert_allclose(result.x, [0.0, 2.0], atol=1e-4)
    off_the_line = SQP().solve(nlp, np.zeros(0), np.array([0.3, 5.0]))
    assert off_the_line.status == SolverStatus.CONVERGED and np.allclose(off_the_line.x, [1.0, 1.0], atol=1e-6)
