"""The FSQP solver plugin: what is specific to a feasible method — iterates that keep the inequalities, the
feasibility phase, equality orientation and the penalty — plus its two Hessians, log, limits and multipliers.

Most tests pin the thesis-literal ``equality`` subproblem (``_solve``'s default here); the ``qp`` subproblem, the
plugin's default, is tested by name, on HS071 and on real gait steps."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from gait_steps import gait_step
from nlp_problems import ReferenceProblem, hs071, hs076, infeasible, nonnegative_projection, undefined_at_start
from saved_qps import clarabel_objective, saved_qp

import gaitbench_plugins.solvers.fsqp as fsqp
import gaitbench_plugins.solvers.fsqp.qp as fsqp_qp
import gaitbench_plugins.solvers.fsqp.solver as fsqp_solver
from gaitbench.plugins import load_registry
from gaitbench.problem.nlp import NLPBuilder
from gaitbench.solve.evaluation import Deadline, NLPEvaluator
from gaitbench.solve.qp import RetryOrder
from gaitbench.solver_result import SolverStatus
from gaitbench_plugins.solvers.fsqp import FSQP
from gaitbench_plugins.solvers.fsqp.form import NLPForm
from gaitbench_plugins.solvers.fsqp.hessian import qp_hessian
from gaitbench_plugins.solvers.ipopt import Ipopt


def _solve(problem: ReferenceProblem, x0=None, **options):
    options.setdefault("subproblem", "equality")
    solver = FSQP(**options)
    result = solver.solve(problem.nlp, problem.parameters, problem.x0 if x0 is None else x0)
    return solver, result


def _inequalities_hold(problem: ReferenceProblem, x: np.ndarray) -> bool:
    """Every bound and every inequality row (lbg < ubg) of the NLP holds exactly at x."""
    nlp = problem.nlp
    g = nlp.constraint_values(x, problem.parameters)
    rows = nlp.lbg < nlp.ubg
    return bool(np.all(g[rows] >= nlp.lbg[rows]) and np.all(g[rows] <= nlp.ubg[rows])
                and np.all(x >= nlp.lbx) and np.all(x <= nlp.ubx))


def _inequality_excess(problem: ReferenceProblem, x: np.ndarray) -> float:
    """How far x is outside the NLP's bounds and inequality rows (lbg < ubg), in the NLP's units."""
    nlp = problem.nlp
    g = nlp.constraint_values(x, problem.parameters)
    rows = nlp.lbg < nlp.ubg
    return float(max(np.max(nlp.lbg[rows] - g[rows], initial=0.0), np.max(g[rows] - nlp.ubg[rows], initial=0.0),
                     np.max(nlp.lbx - x, initial=0.0), np.max(x - nlp.ubx, initial=0.0)))


def _circle_point() -> ReferenceProblem:
    """min (x − 2)² s.t. x² = 1: x* = 1, where ∇f + λ∇g = 0 gives λ = 1."""
    b = NLPBuilder()
    x = b.variable("x", (1, 1))
    b.constrain("circle", x ** 2 - 1)
    return ReferenceProblem("circle-point", b.build(ca.SX.sym("p", 0), (x - 2) ** 2), np.zeros(0), np.array([3.0]),
                            1.0, np.array([1.0]))


@pytest.mark.parametrize("hessian", ["bfgs", "exact"])
def test_both_hessians_reach_hs071s_optimum(hessian: str):
    problem = hs071()
    _, result = _solve(problem, hessian=hessian)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.objective == pytest.approx(problem.f_star, abs=1e-6)
    assert result.constraint_violation <= 1e-7
    np.testing.assert_allclose(result.x, problem.x_star, atol=1e-5)
    assert result.iterations <= 30  # measured: 22 (bfgs), 21 (exact)
    assert ("hess_l" in result.evaluations) == (hessian == "exact")


def test_every_iterate_satisfies_the_inequalities():
    """HS071 starts on four bounds with its product inequality active; every iterate keeps them all, while the
    sphere equality, violated by 12 at the start, is only reached in the limit."""
    problem = hs071()
    solver, result = _solve(problem)
    assert result.converged
    iterates = [record.x for record in solver.log]
    assert len(iterates) == result.iterations + 1
    assert all(_inequalities_hold(problem, x) for x in iterates)
    violations = [record.max_violation for record in solver.log]
    assert violations[0] == pytest.approx(12.0, abs=1e-3) and violations[-1] <= 1e-7


def test_feasibility_phase_repairs_an_infeasible_start():
    problem = hs076()
    start = np.full(4, 1.5)  # violates two of HS076's three inequalities
    assert not _inequalities_hold(problem, start)
    solver, result = _solve(problem, x0=start)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.objective == pytest.approx(problem.f_star, abs=1e-6)
    phases = [record.phase for record in solver.log]
    assert phases[0] == "feasibility" and phases[-1] == "main"
    assert phases == sorted(phases)  # "feasibility" < "main": phase 1 only at the start
    assert all(_inequalities_hold(problem, record.x) for record in solver.log if record.phase == "main")
    assert result.iterations == len(solver.log) - 1  # phase-1 iterations count toward the limit


def test_no_feasible_start_is_infeasible_and_names_the_phase():
    _, result = _solve(infeasible())
    assert result.status is SolverStatus.INFEASIBLE
    assert result.message.startswith("FSQP feasibility phase: no point satisfies the inequalities")
    assert result.constraint_violation == pytest.approx(0.5, abs=1e-6)  # the least violating x = 1/2


@pytest.mark.parametrize("start", [3.0, 0.5])
def test_equalities_are_oriented_to_be_nonpositive_at_the_start(start: float):
    """x² − 1 is +8 at x = 3 and −0.75 at x = 0.5: either way F_c = f + c |x² − 1| at the start, the solution is
    x = 1 and the reported multiplier is in the NLP's own sign convention."""
    problem = _circle_point()
    solver, result = _solve(problem, x0=np.array([start]))
    assert result.status is SolverStatus.CONVERGED, result.message
    np.testing.assert_allclose(result.x, [1.0], atol=1e-8)
    np.testing.assert_allclose(result.multipliers, [1.0], atol=1e-6)
    first = solver.log[0]
    assert first.merit == pytest.approx((start - 2) ** 2 + first.penalty * abs(start ** 2 - 1))


def test_penalty_never_decreases_and_ends_above_the_equality_multiplier():
    """Step 2: c_k = max(max_E |π_j| + ρ, c_{k−1} + ε) whenever c_{k−1} < max_E |π_j| + ρ, else c_{k−1}."""
    problem = hs071()  # unscaled: its gradients are below the scaling threshold
    rho, epsilon = 0.5, 0.25
    solver, result = _solve(problem, rho=rho, epsilon=epsilon)
    assert result.converged
    penalties = [record.penalty for record in solver.log]
    assert penalties == sorted(penalties)
    assert penalties[0] >= rho + epsilon
    sphere = result.multipliers[1]
    assert penalties[-1] >= abs(sphere) + rho - 1e-6
    assert len(set(penalties)) < len(penalties)  # it settles: the thesis's Lemma 4


def test_multipliers_follow_casadis_sign_convention():
    _, result = _solve(nonnegative_projection(-1.0))
    assert result.converged
    np.testing.assert_allclose(result.multipliers, [-2.0], atol=1e-6)  # ∇f + λ∇g = 0 at x = 0, p = −1
    problem = hs071()
    _, result = _solve(problem)
    reference = Ipopt().solve(problem.nlp, problem.parameters, problem.x0)
    np.testing.assert_allclose(result.multipliers, reference.multipliers, atol=1e-5)


def test_iteration_log_has_one_line_per_iterate(capsys: pytest.CaptureFixture[str]):
    solver, result = _solve(hs076(), x0=np.full(4, 1.5), print_level=1)
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "FSQP feasibility phase"
    main = lines.index("FSQP main phase")
    assert lines[main + 1].split() == ["iter", "F_c", "|d0|", "step", "c_k", "|J|", "max", "viol", "dir"]
    rows = [line.split() for line in lines if line.split()[0].isdigit()]
    assert len(rows) == len(solver.log) == result.iterations + 1
    assert [int(row[0]) for row in rows] == list(range(result.iterations + 1))
    assert rows[-1][-1] == "-" and rows[-1][3] == "nan"  # the converged iterate takes no step


def test_print_level_zero_is_silent(capsys: pytest.CaptureFixture[str]):
    _solve(hs076(), x0=np.full(4, 1.5))
    assert capsys.readouterr().out == ""


def test_iteration_limit():
    solver, result = _solve(hs071(), max_iterations=2)
    assert result.status is SolverStatus.ITERATION_LIMIT
    assert result.message == "FSQP: iteration limit of 2 reached"
    assert result.iterations == 2 and len(solver.log) == 2
    assert _inequalities_hold(hs071(), result.x)  # a stopped run still returns an admissible point


def test_time_limit_before_the_first_iteration():
    _, result = _solve(hs071(), time_limit_s=1e-9)
    assert result.status is SolverStatus.TIME_LIMIT
    assert result.message == "FSQP: time limit of 1e-09 s reached"
    assert result.iterations == 0


def test_time_limit_inside_the_arc_search(monkeypatch: pytest.MonkeyPatch):
    """The deadline is checked at every arc-search trial, not only once per iteration."""

    class ExpiresOnSecondCheck(Deadline):
        checks = 0

        def expired(self) -> bool:
            self.checks += 1
            return self.checks >= 2  # 1: iteration 0 starts; 2: the first trial of its arc search

    monkeypatch.setattr(fsqp_solver, "Deadline", ExpiresOnSecondCheck)
    _, result = _solve(hs071(), time_limit_s=60.0)
    assert result.status is SolverStatus.TIME_LIMIT
    assert result.message == "FSQP: time limit of 60.0 s reached in the arc search"
    assert result.iterations == 0


def test_nan_and_exceptions_are_errors():
    _, result = _solve(undefined_at_start())
    assert result.status is SolverStatus.ERROR
    assert result.message == "FSQP: NaN or infinite f or g at the starting point"
    problem = hs071()
    result = FSQP().solve(problem.nlp, problem.parameters, np.zeros(3))
    assert result.status is SolverStatus.ERROR
    assert "3 values" in result.message


def test_bad_options_are_rejected_when_built():
    with pytest.raises(ValueError, match="hessian must be"):
        FSQP(hessian="newton")
    with pytest.raises(ValueError, match="δ ∈ \\(2, ν\\)"):
        FSQP(nu=2.5, delta=3.0)


def test_gait_step_iterates_stay_admissible():
    """The DMOC step's standard guess violates foot clearance and the approach condition; phase 1 repairs them and
    every main-phase iterate keeps all 299 inequality rows (joint, torque, velocity limits, clearance)."""
    problem = gait_step("dmoc", 20)
    assert not _inequalities_hold(problem, problem.x0)
    solver, result = _solve(problem, max_iterations=12)
    assert result.status is SolverStatus.ITERATION_LIMIT, result.message
    main = [record.x for record in solver.log if record.phase == "main"]
    assert solver.log[0].phase == "feasibility" and len(solver.log) == 12 and len(main) >= 5
    assert all(_inequalities_hold(problem, x) for x in main)


def test_qp_subproblem_reaches_hs071s_optimum_through_feasible_iterates():
    problem = hs071()
    solver, result = _solve(problem, subproblem="qp")
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.objective == pytest.approx(problem.f_star, abs=1e-6)
    np.testing.assert_allclose(result.x, problem.x_star, atol=1e-5)
    assert all(_inequality_excess(problem, record.x) <= 1e-8 for record in solver.log if record.phase == "main")


def test_qp_subproblem_takes_the_exact_hessian_only():
    with pytest.raises(ValueError, match="exact Hessian"):
        FSQP(hessian="bfgs")


def test_qp_subproblem_solves_a_forward_gait_step_to_ipopts_optimum():
    """Forward step 1, HS, N = 20, with the tie-break: phase 1 makes the standard guess feasible (equalities too),
    then every main iterate keeps the inequality rows, to the tolerance the arc search allows (1e-8 in scaled units)."""
    problem = gait_step("hermite-simpson", 20, "forward")
    solver, result = _solve(problem, subproblem="qp", time_limit_s=60)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.objective <= problem.f_star * (1 + 1e-3)
    assert result.constraint_violation <= 1e-6
    assert solver.log[0].phase == "feasibility"
    assert all(_inequality_excess(problem, record.x) <= 1e-6 for record in solver.log if record.phase == "main")


def test_qp_hessian_shifts_no_more_than_the_least_shift_that_convexifies():
    """A direction with slight negative curvature (−1e-9) that no working row covers needs a shift just above 1e-9.
    The shift sets the QP's step on the thesis cost's flat valleys, so it must stay near that least one (within the
    ×4 grid), not jump to 1e-8·max|H|: that made forward step 2 (HS, N = 50) crawl to the iteration limit."""
    _, augmentation, base = _qp_hessian_of(-1e-9)
    assert augmentation > 0
    assert 0 < base[1, 1] <= 3e-9


def test_qp_hessian_leaves_a_flat_direction_nearly_unshifted():
    """No curvature along x₂: the shift is the QP's only curvature there, so it must be tiny (1e-14·max|H|), not the
    1e-10·max|H| the pivot test used to demand."""
    _, augmentation, base = _qp_hessian_of(0.0)
    assert augmentation == 0
    assert 0 < base[1, 1] <= 1e-12


def _qp_hessian_of(curvature: float):
    """qp_hessian of min ½x₁² + ½ curvature·x₂² s.t. x₁ = 0, at 0, without damping."""
    b = NLPBuilder()
    x = b.variable("x", (2, 1))
    b.constrain("line", x[0])
    nlp = b.build(ca.SX.sym("p", 0), 0.5 * x[0] ** 2 + 0.5 * curvature * x[1] ** 2)
    at = np.zeros(2)
    form = NLPForm(NLPEvaluator(nlp, np.zeros(0)), at, "gradient")
    return qp_hessian(form, at, np.zeros(form.m), form.jacobian(at)[form.equalities], 0.0)


def test_registered_as_a_solver_plugin():
    (registration,) = fsqp.register_solvers()
    assert registration.name == "fsqp" == FSQP.name
    assert isinstance(registration.factory(max_iterations=5), FSQP)


@pytest.mark.slow
def test_qp_subproblem_walks_forward_step_2_dmoc_n50_to_ipopts_cot():
    """Forward step 2, DMOC, N = 50, from the state fsqp's own step 1 ends in: the step where the 3-step walk used to
    stop (iteration limit, crawling by ~1.5e-7 of merit per iteration, then a KKT test that never passed). Both
    solvers from the same guess on the same NLP; fsqp's verified COT at most 5 % above IPOPT's."""
    from gaitbench.contracts import WalkProblem
    from gaitbench.problem.gait_problem import ProblemOptions
    from gaitbench.solve.walk import solve_and_verify

    registry = load_registry()
    experiment, transcription = registry.create("experiment", "forward"), registry.create("transcription", "dmoc")
    options = ProblemOptions(limits=experiment.limits)
    walk = WalkProblem(experiment, transcription, FSQP(), 50, steps=3, options=options)
    built = transcription.build(walk.structure("second", walked=True))
    first = solve_and_verify(walk, 1, built, walk.step_data(1, walk.start_state()))
    assert first.solved, first.message
    data = walk.step_data(2, first.next_state)
    step = solve_and_verify(walk, 2, built, data)
    assert step.solved, step.message
    assert step.solver_result.iterations <= 500
    reference = solve_and_verify(WalkProblem(experiment, transcription, Ipopt(), 50, steps=3, options=options), 2,
                                 built, data)
    assert reference.solved, reference.message
    assert step.verification.cot <= 1.05 * reference.verification.cot


@pytest.mark.slow
@pytest.mark.parametrize("transcription", ["dmoc", "hermite-simpson"])
def test_fsqp_walks_three_forward_steps_at_n20_within_5_percent_of_ipopt(transcription):
    """The solvers issue's walk: forward, 3 steps, N = 20, default options; fsqp's verified ACOT at most 5 % above
    IPOPT's (measured: DMOC 0.0512 against 0.0566, HS 0.0505 against 0.0501; HS step 3 needs 702 iterations)."""
    from gaitbench.contracts import WalkProblem
    from gaitbench.solve.one_phase import OnePhase

    registry = load_registry()
    experiment = registry.create("experiment", "forward")

    def walk(solver):
        return OnePhase().solve(WalkProblem(experiment, registry.create("transcription", transcription), solver, 20,
                                            steps=3))

    ours, reference = walk(FSQP()), walk(Ipopt())
    assert ours.complete and reference.complete, (ours.failure, reference.failure)
    assert all(step.verification.max_defect < 1e-6 for step in ours.steps)
    assert ours.acot <= 1.05 * reference.acot


def _recorded_qp_calls(monkeypatch) -> list[tuple[str, int | None, bool]]:
    """The list that every ``qpsolvers`` call of ``fsqp``'s QPs is recorded in from now on: (backend, PIQP's
    ``preconditioner_iter`` if set, solved)."""
    calls = []
    solve_problem = fsqp_qp.qpsolvers.solve_problem

    def recorded(qp, solver, **settings):
        solution = solve_problem(qp, solver=solver, **settings)
        calls.append((solver, settings.get("preconditioner_iter"), solution.found))
        return solution

    monkeypatch.setattr(fsqp_qp.qpsolvers, "solve_problem", recorded)
    return calls


def test_a_gait_qp_piqp_fails_is_solved_by_piqp_without_its_equilibration_before_clarabel(monkeypatch):
    """The saved forward-step QP that PIQP, equilibrated, ends at its iteration limit: the ``qp`` subproblem's
    second turn, PIQP without the equilibration, solves it to Clarabel's objective, and Clarabel is not called
    (docs/decisions/0002-qp-backends.md)."""
    problem = saved_qp("sqp_gait_qp_piqp_preconditioner")
    calls = _recorded_qp_calls(monkeypatch)
    solution = fsqp_qp.solve_qp(problem, RetryOrder())
    assert calls == [("piqp", None, False), ("piqp", 0, True)]
    objective = 0.5 * solution.x @ problem.P @ solution.x + problem.q @ solution.x
    assert objective == pytest.approx(clarabel_objective(problem), rel=1e-5)


def test_after_the_retry_settings_solve_a_qp_piqp_failed_they_go_first_on_the_next_qps_of_the_solve(monkeypatch):
    """PIQP fails the gait QPs in runs (docs/decisions/0002-qp-backends.md): once
    the unequilibrated PIQP has solved the saved QP the equilibrated one fails, the solve's next QP (here the same
    one) goes to the unequilibrated PIQP first: one call, not two. A new solve starts from PIQP's own settings."""
    problem = saved_qp("sqp_gait_qp_piqp_preconditioner")
    calls = _recorded_qp_calls(monkeypatch)
    order = RetryOrder()
    fsqp_qp.solve_qp(problem, order)
    fsqp_qp.solve_qp(problem, order)
    assert calls == [("piqp", None, False), ("piqp", 0, True), ("piqp", 0, True)]
    calls.clear()
    fsqp_qp.solve_qp(problem, RetryOrder())
    assert calls == [("piqp", None, False), ("piqp", 0, True)]


def test_phase_one_takes_an_elastic_step_where_the_projection_leaves_the_bounds(monkeypatch: pytest.MonkeyPatch):
    """x² = 1 within −2 ≤ x ≤ 2 from x = 0.01: the linearised row asks for d ≈ 50, beyond the bound, so the least-norm
    projection has no solution, and phase 1 steps by the elastic QP, not by the Gauss–Newton step that ignores the
    bounds."""
    b = NLPBuilder()
    x = b.variable("x", (1, 1), -2.0, 2.0)
    b.constrain("circle", x ** 2 - 1)
    nlp = b.build(ca.SX.sym("p", 0), (x - 2) ** 2)
    calls = []
    solve_problem = fsqp_qp.qpsolvers.solve_problem

    def recorded(problem, solver, **settings):
        calls.append((solver, problem.P.shape[0]))
        return solve_problem(problem, solver=solver, **settings)

    monkeypatch.setattr(fsqp_qp.qpsolvers, "solve_problem", recorded)
    solver = FSQP(subproblem="qp")
    result = solver.solve(nlp, np.zeros(0), np.array([0.01]))
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.x == pytest.approx([1.0], abs=1e-6)
    # the projection, which PIQP, PIQP retried and Clarabel fail; then the elastic QP, over d and the residual e
    assert calls[:4] == [("piqp", 1), ("piqp", 1), ("clarabel", 1), ("piqp", 2)]
    phase_one = [record for record in solver.log if record.phase == "feasibility"]
    assert phase_one[0].step < 1  # the elastic step reaches the bound, and the line search takes part of it


@pytest.mark.parametrize(("name", "objective", "rows", "x0", "optimum"), [
    # a flat direction: one QP step reaches the bound; the QP's bound multiplier belongs to x + d, not to x
    ("linear to its bound", lambda x: -x[0], lambda x: [], [0.5], -1.0),
    # the gait steps' power split P = s⁺ − s⁻, cost s⁺ + s⁻: both parts start far above zero
    ("power split", lambda x: x[1] + x[2], lambda x: [("split", x[0] - x[1] + x[2], 0.0, 0.0), ("P", x[0], 0.3, 0.3)],
     [0.3, 0.8, 0.5], 0.3),
])
def test_the_qp_subproblem_is_not_converged_before_the_optimum(name, objective, rows, x0, optimum):
    """Where the exact Hessian has no curvature the QP steps straight to a bound and its stationarity identity at x
    holds to rounding: only the bound multipliers' complementarity at x shows that x is not optimal (both were
    reported converged at their starting points)."""
    b = NLPBuilder()
    x = b.variable("x", (len(x0), 1), 0.0 if len(x0) > 1 else 0.0, 10.0 if len(x0) > 1 else 1.0)
    for row, expression, lower, upper in rows(x):
        b.constrain(row, expression, lower, upper)
    nlp = b.build(ca.SX.sym("p", 0), objective(x))
    result = FSQP().solve(nlp, np.zeros(0), np.array(x0, dtype=float))
    assert result.status == SolverStatus.CONVERGED, result.message
    assert result.objective == pytest.approx(optimum, abs=1e-7), name
    functions = nlp.functions
    jacobian = np.asarray(ca.DM(functions.jacobian(result.x, np.zeros(0))))
    residual = np.asarray(functions.gradient(result.x, np.zeros(0))).ravel() + jacobian.T @ result.multipliers
    interior = (result.x > nlp.lbx + 1e-6) & (result.x < nlp.ubx - 1e-6)
    assert np.max(np.abs(residual[interior]), initial=0.0) < 1e-7  # the multipliers returned are those of x*
