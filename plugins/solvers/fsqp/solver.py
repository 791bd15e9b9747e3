"""The ``fsqp`` solver plugin's face: the two phases of a solve under its options (:mod:`.options`), and the log of its
iterations."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from gaitbench.problem.nlp import NLP
from gaitbench.solve.evaluation import Deadline, NLPEvaluator, error_result, solver_result
from gaitbench.solver_result import SolverResult, SolverStatus
from gaitbench_plugins.solvers.fsqp.equality import minimize
from gaitbench_plugins.solvers.fsqp.feasibility import feasibility, push_inside
from gaitbench_plugins.solvers.fsqp.form import NLPForm
from gaitbench_plugins.solvers.fsqp.options import FSQPOptions
from gaitbench_plugins.solvers.fsqp.outcome import IterationRecord
from gaitbench_plugins.solvers.fsqp.progress import Progress
from gaitbench_plugins.solvers.fsqp.qp_subproblem import minimize_qp


@dataclass(frozen=True, eq=False)
class FSQP(FSQPOptions):
    """Feasible SQP after the thesis's Appendix D, with damped BFGS or the convexified exact Hessian.

    Shared options: ``max_iterations`` (3000, IPOPT's and ``sqp``'s, so the solvers compare on one budget; the
    thesis gives no k_max, and forward step 3 needs 702–818 iterations at
    N = 20–50; phase-1 iterations count too), ``time_limit_s``
    (None; checked every iteration and at every arc-search trial), ``tolerance`` (1e-8: converged when ‖d0‖₂ and the
    largest equality residual are both ≤ tolerance, in scaled units — d0 = 0 exactly at a KKT point, thesis
    Lemma 2; 1e-6 left HS039's equalities violated by 1e-7, and 1e-8 costs about one more iteration
    where the rate is superlinear), ``print_level`` (0 silent, ≥ 1 one line per iteration: F_c, ‖d0‖, step t,
    penalty c_k, |J_k|, the NLP's largest violation, the direction taken; ≥ 2 also the parts of the ``qp``
    subproblem's KKT error and the shift of its H).

    Method parameters, with gaitbench's defaults (the thesis gives no values):

    - ``alpha`` = 0.1 ∈ (0, ½): Armijo fraction of the arc search.
    - ``beta`` = 0.5 ∈ (0, 1): arc-search reduction factor.
    - ``nu`` = 2.5 > 2: d1 bends every active row to c_j + ∇c_jᵀd = −‖d0‖^ν.
    - ``delta`` = 2.2 ∈ (2, ν): d1 is taken if ∇F_cᵀd1 ≤ −ξ‖d1‖^δ (and < 0).
    - ``tau`` = 2.5 ∈ (2, 3): the correction d̃ aims the active rows at −‖d‖^τ.
    - ``theta`` = 0.8 ∈ (0, 1): share of d3's descent that the d1/d3 combination keeps.
    - ``xi`` = 1e-3 > 0: the descent-test factor (undeclared in the thesis).
    - ``epsilon0`` = 1.0: largest active-set tolerance (rows are scaled, see ``scaling``).
    - ``epsilon`` = 1.0: smallest increase of the penalty c when it must grow.
    - ``rho`` = 1.0: the initial penalty c₋₁ and the margin in c ≥ max_E |π_j| + ρ.
    - ``max_halvings`` = 50: Step-1 halvings of ε before the active gradients are declared dependent (LICQ fails).
    - ``rank_tolerance`` = 1e-6: a normalized active gradient closer than this to the span of the others counts as
      dependent in the Step-1 rank test.
    - ``equality_margin`` = 0.1: κ_E, see deviation 4.
    - ``hessian`` = "exact": ∇²L(x, π⁺) from the evaluator at the Step-2 multipliers π (inequality entries clipped
      at 0), convexified as below; or, with ``subproblem="equality"`` only, "bfgs": damped (Powell) BFGS on the
      Lagrangian gradient ∇f + Σ u_j ∇c_j, u the multipliers of d0 (the thesis's undamped update on ∇F_c can lose
      positive definiteness and ignores the constraints' curvature).
    - ``h0_scaling`` = "auto": H0 = I, rescaled to (yᵀy / yᵀs) I before the first update (Shanno–Phua), since the
      NLP's curvature is far from 1; a number γ gives H0 = γ I and no rescaling.
    - ``scaling`` = "gradient": every row (and f) whose gradient max-norm at the start exceeds 100 is scaled down to
      100, as IPOPT does; "none" keeps the NLP's units. The DMOC dynamics rows have gradients of ~7e3.

    Deviations from the literal thesis, each necessary for convergence (the examples name the test problem that
    failed without it):

    1. Step 1: ε_{k,0} = min(ε0, ‖d0^{k−1}‖), and an inequality row is not near-active if its multiplier estimate
       is smaller than its distance (|π_j| < −c_j), or negative while the row is more than ``tolerance`` inside.
       With a fixed ε0, a row inactive at x* but within ε0 keeps ‖d0‖ away from 0 (HS035 and HS076 stall),
       contrary to the thesis's Lemma 7; and a relaxed row inside prescribes ∇c_jᵀd = π_j whatever the objective
       (HS071 with the exact Hessian, from a start 10⁻² inside its bounds, crept for 500 iterations once J had n
       rows; 13 iterations with this rule). Relaxation is kept for rows on their boundary, where leaving J would let
       the step cross them.
    2. A relaxed row keeps its relaxed target a_j in d1 and d̃ (the thesis pins it to the boundary there, so d1
       never approximates d0 and the slow d3 was taken every iteration on HS071).
    3. d1 must have ∇F_cᵀd1 < 0 (a zero d1 passed the printed test: the 1-D projection stalled), and the d3
       combination is scaled by min(1, −∇F_cᵀd3) (the thesis's −∇F_cᵀd3 lengthened d by 10¹⁰ on HS071).
    4. Powers of norms are min(‖·‖^p, ‖·‖): identical for ‖·‖ ≤ 1, where the thesis's analysis lives, but linear
       beyond (‖d0‖^ν bent the rows by 10⁴ on HS039). On equality rows the margins are also at most κ_E |c_j|: a
       margin pushes an equality away from 0, so it must stay below its residual.
    5. Equalities are kept ≤ 0 by re-orientation rather than by the arc search: a trial may cross zero on an
       equality row, the Armijo test uses f + c Σ|c_j| (= F_c on oriented rows), and crossed rows are flipped.
       Inequality rows must stay ≤ 0 as in the thesis. (Not needed on the HS problems; on the DMOC gait step the
       linear power-split rows, exactly 0, became +1e-18 by rounding and the arc search failed at t ~ 1e-19.)
    6. A row that blocked the last arc search (violated at the last rejected trial) joins J at the next iteration,
       unless it makes J rank deficient, as an active-set method adds blocking constraints (HS076: 15 instead of
       23 iterations with BFGS, 7 instead of 26 with the exact Hessian).

    ``subproblem`` = "qp" (the default) or "equality" (the thesis's Steps 1–5 as above). With "qp", each iteration:

    - d0 solves min ½dᵀHd + ∇fᵀd over every linearised row and the bounds (PIQP, Clarabel when PIQP fails). The
      equalities are QP equalities: on their linearisation Mayne–Polak's penalty term is constant, so the step is the
      one their inequality form with ∇F_c gives. H = ∇²L + δI made positive definite as ``sqp`` does it (sparse LDLᵀ
      tests; the least ρ·max|H|·Σ âᵢâᵢᵀ over a working set of equalities, rows with multipliers and bounds within
      1e-6, then a shift), convexified once more over the rows the QP held if it left some of that working set; δ is
      a Levenberg–Marquardt damping set by the merit's actual against predicted decrease. A QP that both backends
      fail on is solved again with δ 100× larger (up to 1e-2·max|H|): with ρ = 10⁴ and δ ~ 1e-8 its conditioning
      reaches ~1e12 on the flat valleys.
    - The merit is f + Σ_E w_j|c_j| with Powell's per-row weights (``sqp``'s), raised together when d would not
      decrease it by ½dᵀHd: one penalty c ≥ max|π| + ρ dwarfed the gait objective (f ~ 1e-5) and every curvature
      error in the equalities cut the step.
    - d̃ = s − d, s the QP again with the rows linearised at x + d (second-order correction); the arc x + t d + t²d̃
      is searched with every inequality row ≤ ``tolerance`` (scaled units) and Armijo on the merit.
    - Converged when IPOPT's scaled KKT error, with the QP's multipliers, is below ``tolerance``, or below 1e-6 for
      15 iterations (IPOPT's acceptable level), or below 1e-6 where the arc search finds no step. The QP's
      multipliers belong to x + d, so its bound multipliers must hold bounds active at x (complementarity at x),
      and the error is also taken with the row multipliers corrected by least squares over the rows the step
      holds (at x; signs and complementarity checked; the multipliers returned are the corrected ones): on the
      flat valleys ‖∇²L d‖ stays ~1e-5 while f no longer moves, which the first test never passes. The QPs are
      solved to 1e-10, as ``sqp``'s, since the test reads stationarity off their optimality conditions.
    - Phase 1 projects onto every linearised row, equalities too (a QP: least-norm step within the bounds; when
      that QP is inconsistent, the bounded Levenberg–Marquardt step on the violation, an elastic QP), until the
      inequalities hold and the equalities are within 1e-6, so that the first QP is consistent.

    The "qp" subproblem takes the exact Hessian only.

    Exact-Hessian convexification: the theory needs H_k ≻ 0. The method tries H = ∇²L, then H + ρ̄ ÂᵀÂ (Â the
    active gradients with rows normalized; ρ̄ = 100 × the largest diagonal entry), then H + ρ̄ ÂᵀÂ + δI with δ growing
    8× from a quarter of the last δ (at least 1e-8, at most 1e10 × the largest diagonal entry). The ÂᵀÂ term is
    constant on the constraint set of every K0 system, so it changes none of d0, d1, d̃ (only their multipliers,
    which are corrected), and a Hessian positive definite on the null space of the active gradients keeps Newton's
    steps. Positive definiteness is tested by a sparse LDLᵀ (SuperLU with diagonal pivots in symmetric mode).

    Step-1 rank test: the Gram matrix of the normalized active gradients is factorized the same way; its pivots are
    the squared distances of each gradient from the span of those eliminated before it, so a pivot below
    ``rank_tolerance``² flags dependence. It is sparse and costs one small factorization per halving.

    Starting point: x0 is projected onto the bounds (pushed 1e-8 inside). If a general inequality is violated there,
    phase 1 takes damped Gauss–Newton steps on ½‖max(c_I, 0)‖²: each the least-norm step that moves every violated
    or nearly violated inequality row (bounds included) just inside in the linearization, projected onto the bounds
    and halved until the violation drops. A stationary violation > 0, or one that no step reduces, is INFEASIBLE.
    The equalities play no part (they are oriented afterwards), so phase 1 may worsen them: on the standard DMOC gait
    guess, whose dynamics rows have gradients of ~7e3, mending the foot clearance raises the dynamics residual from
    16 to 420 (a variant that kept the linearized equalities fixed converged too slowly to be worth it).
    NaN at an iterate is an ERROR; at an arc-search trial it only rejects the trial.
    """

    name: ClassVar[str] = "fsqp"

    log: list[IterationRecord] = field(default_factory=list, init=False, repr=False)
    """The iterates of the last solve, both phases, in order (refilled by each solve)."""

    def solve(self, nlp: NLP, parameters: np.ndarray, initial_guess: np.ndarray) -> SolverResult:
        """Phase 1 if the start violates an inequality, then FSQP; every failure becomes a status."""
        deadline = Deadline(self.time_limit_s)
        x0 = np.asarray(initial_guess, dtype=float).ravel()
        self.log.clear()
        progress = Progress(self.max_iterations, self.time_limit_s, deadline, self.print_level, self.log)
        try:
            evaluator = NLPEvaluator(nlp, parameters)
            if x0.size != nlp.n_variables:
                raise ValueError(f"the initial guess has {x0.size} values, the NLP {nlp.n_variables} variables")
            return self._solve(evaluator, push_inside(x0, nlp.lbx, nlp.ubx), progress)
        except Exception as error:  # the Solver protocol reports failures, it never raises them
            return error_result(error, x0, deadline)

    def _solve(self, evaluator: NLPEvaluator, x: np.ndarray, progress: Progress) -> SolverResult:
        form = NLPForm(evaluator, x, self.scaling)
        outcome = feasibility(progress, form, x, with_equalities=self.subproblem == "qp")
        if outcome.status is not SolverStatus.CONVERGED:
            return solver_result(outcome.status, f"FSQP feasibility phase: {outcome.message}", outcome.x, evaluator,
                                 outcome.iterations, progress.deadline)
        form.orient(outcome.x)
        phase = minimize_qp if self.subproblem == "qp" else minimize
        outcome = phase(self, progress, form, outcome.x, outcome.iterations)
        multipliers = None if outcome.multipliers is None else form.nlp_multipliers(outcome.multipliers)
        return solver_result(outcome.status, f"FSQP: {outcome.message}", outcome.x, evaluator, outcome.iterations,
                             progress.deadline, multipliers)
