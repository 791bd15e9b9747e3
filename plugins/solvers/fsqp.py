"""Feasible SQP (FSQP), the thesis's Appendix D solver for the Discrete-Mechanics problems.

Why this method: every iterate satisfies the inequality constraints (joint, torque and velocity limits, foot
clearance), so even a run that is stopped early returns an admissible trajectory; and every subproblem is an
equality-constrained QP, i.e. one sparse KKT linear system, so no QP solver is needed. Equalities are handled by the
Mayne–Polak relaxation: each is oriented so that it is ≤ 0 at the start and is kept ≤ 0, while the exact penalty
F_c = f − c Σ_E c_j drives it to zero. Feasible descent directions follow Panier–Tits, and an arc search with a
second-order correction avoids the Maratos effect. H is a damped BFGS matrix or the convexified exact Hessian.

The steps follow the corrected pseudo-code of the thesis digest (shared/spec/thesis/appBCD-solvers.md §2.3):
Step 1 approximate active set with ε-halving, Step 2 least-squares multipliers and penalty update, Step 3 the
directions d0, d1 (or the d2/d3 combination) and the correction d̃, Step 4 the arc search, Step 5 BFGS. gaitbench's
``lbg ≤ g ≤ ubg, lbx ≤ x ≤ ubx`` becomes the thesis form: every finite one-sided bound of g or x is an inequality
row ``c_j(x) ≤ 0`` (the bounds of x are linear rows), every row with ``lbg == ubg`` (and every fixed variable) an
equality row, sign-oriented at the starting point. The deviations from the thesis that its literal form needs to
converge at all are listed in :class:`FSQP`; each was found on the Hock–Schittkowski problems of the test suite.
All linear algebra is sparse, except the BFGS matrix, dense n × n as in the thesis (a KKT matrix that is then mostly
dense is factorized densely).

That literal form (``subproblem="equality"``) stalls on the gait NLPs: its near-active set leaves out far bounds that
its steps then cross, and the arc search cuts every step to ~1e-9 (forward step 1, HS, N = 20: "no feasible descent
direction" at iteration 97, the equalities never below 1.09). The default ``subproblem="qp"`` keeps the family's
structure — a feasible start, feasible iterates, an exact penalty on the equalities, an arc search with a
second-order correction — with a QP over every linearised row (sparse, through ``qpsolvers``) for d0 and ``sqp``'s
convexified exact Hessian; see :class:`FSQP`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import qpsolvers
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from gaitbench import Registration, hookimpl
from gaitbench.problem.nlp import NLP
from gaitbench.solve.evaluation import Deadline, NLPEvaluator, error_result, solver_result
from gaitbench.solve.qp import INACCURATE_STATUSES, backend_status
from gaitbench.solve.silence import quiet_stdout
from gaitbench.solve.solver import SolverResult, SolverStatus

_MAX_GRADIENT = 100.0
"""Gradient-based scaling target (IPOPT's ``nlp_scaling_max_gradient``): rows whose gradient at the start exceeds
it in the max-norm are scaled down to it, so ε0 and the margins ‖d0‖^ν mean the same on every row."""

_DENSE_FRACTION = 0.2
"""A KKT matrix with more than this fraction of nonzeros (a dense BFGS block) is factorized by dense LU."""

_AUGMENTATION = 1e2
"""ρ̄ of the exact-Hessian convexification H + ρ̄ ÂᵀÂ + δI, relative to the Hessian's largest diagonal entry."""

_SHIFT_RANGE = (1e-8, 1e10)
"""Smallest and largest shift δ of the exact-Hessian convexification, relative to its largest diagonal entry."""

_PUSH = 1e-8
"""The start is pushed this far (relative) inside its bounds: a start exactly on several bounds at once (HS071's
x0 is on four) has dependent active gradients, which ε-halving can only remove from rows strictly inside."""

_FEASIBILITY_MARGIN = 1e-8
"""Phase 1 aims every violated or nearly violated inequality row this far inside (scaled units). It is tiny on
purpose: on a DMOC gait step, a margin of 1e-4 moved the positions enough to raise the dynamics residual to 26."""

_ROUNDING = 1e-15
"""The arc search gives up when t‖d‖∞ ≤ this × (1 + ‖x‖∞): the trial no longer differs from x but for rounding."""


_QP_SOLVERS = ("piqp", "clarabel")
"""Backends of the ``qp`` subproblem, in turn: PIQP, the fastest on the gait QPs (docs/solvers.md, ``sqp``), then
Clarabel, which solves the convexified QPs PIQP stops on."""

_ACTIVE = 1e-6
"""A row is held by a QP step when c_j + ∇c_jᵀd ≥ −this (scaled units), and a bound row is near when c_j ≥ −this:
the rows whose augmentation is constant on the QP's feasible set, and the working set's bounds."""

_EQUALITY_START = 1e-6
"""Phase 1 of the ``qp`` subproblem ends when the equality rows are within this of 0 (scaled units)."""

_ACCEPTABLE_TOLERANCE = 1e-6
_ACCEPTABLE_ITERATIONS = 15
"""IPOPT's acceptable level: a KKT error below ``_ACCEPTABLE_TOLERANCE`` for this many iterations in a row is
converged; on the flat valleys of the thesis cost the last digits of the tolerance cost hundreds of iterations."""


class _Breakdown(Exception):
    """A failure of the method at the current iterate (not a bug): it becomes an ERROR with that iterate."""


@dataclass
class IterationRecord:
    """One iterate x_k and what iteration k computed there (the rows of the ``print_level ≥ 1`` log)."""

    phase: str
    """"feasibility" (phase 1, Gauss–Newton on the inequality violation) or "main"."""
    iteration: int
    merit: float
    """Main phase: F_c(x_k) = f + c Σ_E |c_j| (scaled units); phase 1: ½‖max(c_I, 0)‖²."""
    d0_norm: float
    """‖d0‖ (phase 1: the length of the Gauss–Newton step)."""
    step: float
    """The accepted arc-search step t_k (NaN for the last iterate)."""
    penalty: float
    """c_k (NaN in phase 1)."""
    active: int
    """|J_k|: near-active inequalities plus equalities (phase 1: the rows of the Gauss–Newton step)."""
    max_violation: float
    """The NLP's largest constraint or bound violation at x_k, in its own units."""
    direction: str
    """"d1" (the feasible direction passed the descent test), "d3" (the Panier–Tits combination), "gn" (phase 1)."""
    x: np.ndarray
    """The NLP's variables at x_k."""


@dataclass
class _Outcome:
    status: SolverStatus
    message: str
    x: np.ndarray
    iterations: int
    multipliers: np.ndarray | None
    """Multipliers u of the thesis-form rows (∇f + Σ u_j ∇c_j = 0, scaled units), when d0 was computed."""


class _NLPForm:
    """A gaitbench NLP in the thesis's form: rows c_j(x) ≤ 0 first (general, then bounds), equalities c_j(x) = 0 last.

    c(x) = r ⊙ (S_g g(x) + S_x x + o) with sparse selection matrices S_g, S_x holding each row's sign, offsets o
    from the bounds, and row factors r: the gradient-based scaling times the orientation sign of the equalities.
    The objective is scaled by ``objective_scale``.
    """

    def __init__(self, evaluator: NLPEvaluator, x: np.ndarray, scaling: str) -> None:
        nlp = evaluator.nlp
        self.evaluator = evaluator
        self.n = nlp.n_variables
        lbg, ubg, lbx, ubx = (np.asarray(v, dtype=float).ravel() for v in (nlp.lbg, nlp.ubg, nlp.lbx, nlp.ubx))
        equal, fixed = lbg == ubg, lbx == ubx
        g_blocks = [(np.flatnonzero(~equal & np.isfinite(ubg)), 1.0, ubg),
                    (np.flatnonzero(~equal & np.isfinite(lbg)), -1.0, lbg)]
        x_blocks = [(np.flatnonzero(~fixed & np.isfinite(ubx)), 1.0, ubx),
                    (np.flatnonzero(~fixed & np.isfinite(lbx)), -1.0, lbx)]
        blocks = [("g", *block) for block in g_blocks] + [("x", *block) for block in x_blocks]
        blocks += [("g", np.flatnonzero(equal), 1.0, lbg), ("x", np.flatnonzero(fixed), 1.0, lbx)]
        self.n_general = sum(index.size for index, _, _ in g_blocks)
        self.n_equal_g = int(np.count_nonzero(equal))
        self.n_inequalities = self.n_general + sum(index.size for index, _, _ in x_blocks)
        self.m = sum(index.size for _, index, _, _ in blocks)
        rows, start = {"g": ([], [], []), "x": ([], [], [])}, 0
        offset = np.zeros(self.m)
        for source, index, sign, bound in blocks:
            row = np.arange(start, start + index.size)
            rows[source][0].append(row)
            rows[source][1].append(index)
            rows[source][2].append(np.full(index.size, sign))
            offset[row] = -sign * bound[index]
            start += index.size
        self.select_g, self.select_x = (
            sp.csr_matrix((np.concatenate(v), (np.concatenate(r), np.concatenate(c))), shape=(self.m, size))
            for (r, c, v), size in ((rows["g"], nlp.n_constraints), (rows["x"], self.n)))
        self.offset = offset
        self.lbx, self.ubx, self.free = lbx, ubx, ~fixed
        self.row_factor = np.ones(self.m)
        self.objective_scale = 1.0
        if scaling == "gradient":
            gradient = evaluator.gradient(x)
            jacobian = self.select_g @ evaluator.jacobian(x) + self.select_x
            self.objective_scale = _gradient_scale(np.max(np.abs(gradient), initial=0.0))
            self.row_factor = _gradient_scale(abs(jacobian).max(axis=1).toarray().ravel())

    @property
    def equalities(self) -> slice:
        return slice(self.n_inequalities, self.m)

    def orient(self, x: np.ndarray) -> None:
        """Flip each equality row that is positive at x, so that c_j(x) ≤ 0 holds for every row there."""
        self.flip(self.n_inequalities + np.flatnonzero(self.constraints(x)[self.equalities] > 0))

    def flip(self, rows: np.ndarray) -> None:
        self.row_factor[rows] *= -1

    def admissible(self, x: np.ndarray) -> bool:
        """Within the variable bounds: the cheap, linear rows, checked before the NLP is evaluated."""
        free = self.free
        return bool(np.all(x[free] <= self.ubx[free]) and np.all(x[free] >= self.lbx[free]))

    def objective(self, x: np.ndarray) -> float:
        return self.objective_scale * self.evaluator.objective(x)

    def gradient(self, x: np.ndarray) -> np.ndarray:
        return self.objective_scale * self.evaluator.gradient(x)

    def constraints(self, x: np.ndarray) -> np.ndarray:
        g = self.evaluator.constraints(x) if self.evaluator.m else np.zeros(0)
        return self.row_factor * (self.select_g @ g + self.select_x @ x + self.offset)

    def jacobian(self, x: np.ndarray) -> sp.csr_matrix:
        jacobian = self.select_g @ self.evaluator.jacobian(x) if self.evaluator.m else sp.csr_matrix((self.m, self.n))
        return sp.diags(self.row_factor) @ (jacobian + self.select_x).tocsr()

    def hessian(self, x: np.ndarray, u: np.ndarray, sigma: float = 1.0) -> sp.csc_matrix:
        """∇²(σ f̂ + Σ u_j c_j): only the rows on g are curved."""
        multipliers = self.select_g.T @ (self.row_factor * u)
        return self.evaluator.hessian_lagrangian(x, sigma * self.objective_scale, multipliers)

    def nlp_multipliers(self, u: np.ndarray) -> np.ndarray:
        """λ_g in CasADi's convention (∇f + Jᵀλ_g + λ_x = 0) from the thesis-form multipliers u."""
        return self.select_g.T @ (self.row_factor * u) / self.objective_scale

    def max_violation(self, c: np.ndarray) -> float:
        """The NLP's largest violation in its own units, from the row values c."""
        inequalities = slice(0, self.n_inequalities)
        excess = np.abs(c) / np.abs(self.row_factor)
        excess[inequalities] = np.maximum(c[inequalities], 0.0) / self.row_factor[inequalities]
        return float(np.max(excess, initial=0.0))


class FSQP:
    """Feasible SQP after the thesis's Appendix D, with damped BFGS or the convexified exact Hessian.

    Shared options: ``max_iterations`` (500, the digest's k_max; phase-1 iterations count too), ``time_limit_s``
    (None; checked every iteration and at every arc-search trial), ``tolerance`` (1e-8: converged when ‖d0‖₂ and the
    largest equality residual are both ≤ tolerance, in scaled units — d0 = 0 exactly at a KKT point, thesis
    Lemma 2; the digest's 1e-6 left HS039's equalities violated by 1e-7, and 1e-8 costs about one more iteration
    where the rate is superlinear), ``print_level`` (0 silent, ≥ 1 one line per iteration: F_c, ‖d0‖, step t,
    penalty c_k, |J_k|, the NLP's largest violation, the direction taken).

    Method parameters, with the digest's [S] defaults (the thesis gives no values):

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

    Deviations from the literal thesis, each found necessary during development (the examples name the test problem
    that failed without it, measured with the version of the time):

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
      a Levenberg–Marquardt damping set by the merit's actual against predicted decrease.
    - The merit is f + Σ_E w_j|c_j| with Powell's per-row weights (``sqp``'s), raised together when d would not
      decrease it by ½dᵀHd: one penalty c ≥ max|π| + ρ dwarfed the gait objective (f ~ 1e-5) and every curvature
      error in the equalities cut the step.
    - d̃ = s − d, s the QP again with the rows linearised at x + d (second-order correction); the arc x + t d + t²d̃
      is searched with every inequality row ≤ ``tolerance`` (scaled units) and Armijo on the merit.
    - Converged when IPOPT's scaled KKT error, with the QP's multipliers, is below ``tolerance``, or below 1e-6 for
      15 iterations (IPOPT's acceptable level).
    - Phase 1 projects onto every linearised row, equalities too (a QP: least-norm step within the bounds; the
      Gauss–Newton step when that QP is inconsistent), until the inequalities hold and the equalities are within
      1e-6, so that the first QP is consistent.

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

    name = "fsqp"

    def __init__(self, max_iterations: int = 500, time_limit_s: float | None = None, tolerance: float = 1e-8,
                 print_level: int = 0, hessian: str = "exact", alpha: float = 0.1, beta: float = 0.5,
                 nu: float = 2.5, delta: float = 2.2, tau: float = 2.5, theta: float = 0.8, xi: float = 1e-3,
                 epsilon0: float = 1.0, epsilon: float = 1.0, rho: float = 1.0, max_halvings: int = 50,
                 rank_tolerance: float = 1e-6, equality_margin: float = 0.1, h0_scaling: str | float = "auto",
                 scaling: str = "gradient", subproblem: str = "qp") -> None:
        if subproblem not in ("qp", "equality"):
            raise ValueError(f"subproblem must be 'qp' or 'equality', not {subproblem!r}")
        if hessian not in ("bfgs", "exact"):
            raise ValueError(f"hessian must be 'bfgs' or 'exact', not {hessian!r}")
        if subproblem == "qp" and hessian != "exact":
            raise ValueError("the 'qp' subproblem takes the exact Hessian; BFGS needs subproblem='equality'")
        if scaling not in ("gradient", "none"):
            raise ValueError(f"scaling must be 'gradient' or 'none', not {scaling!r}")
        if h0_scaling != "auto" and not (isinstance(h0_scaling, int | float) and h0_scaling > 0):
            raise ValueError(f"h0_scaling must be 'auto' or a positive number, not {h0_scaling!r}")
        if not (0 < alpha < 0.5 and 0 < beta < 1 and nu > 2 and 2 < delta < nu and 2 < tau < 3 and 0 < theta < 1
                and xi > 0 and epsilon0 > 0 and epsilon > 0 and rho > 0 and equality_margin > 0):
            raise ValueError("FSQP needs α ∈ (0, ½), β, θ ∈ (0, 1), ν > 2, δ ∈ (2, ν), τ ∈ (2, 3) and positive ξ, "
                             "ε0, ε, ρ and equality_margin")
        self.max_iterations = int(max_iterations)
        self.time_limit_s = time_limit_s
        self.tolerance = float(tolerance)
        self.print_level = int(print_level)
        self.hessian = hessian
        self.alpha, self.beta, self.nu, self.delta, self.tau = alpha, beta, nu, delta, tau
        self.theta, self.xi, self.epsilon0, self.epsilon, self.rho = theta, xi, epsilon0, epsilon, rho
        self.max_halvings = int(max_halvings)
        self.rank_tolerance = float(rank_tolerance)
        self.equality_margin = float(equality_margin)
        self.h0_scaling = h0_scaling
        self.scaling = scaling
        self.subproblem = subproblem
        self.log: list[IterationRecord] = []
        """The iterates of the last solve, both phases, in order."""

    def solve(self, nlp: NLP, parameters: np.ndarray, initial_guess: np.ndarray) -> SolverResult:
        """Phase 1 if the start violates an inequality, then FSQP; every failure becomes a status."""
        deadline = Deadline(self.time_limit_s)
        x0 = np.asarray(initial_guess, dtype=float).ravel()
        self.log = []
        try:
            evaluator = NLPEvaluator(nlp, parameters)
            if x0.size != nlp.n_variables:
                raise ValueError(f"the initial guess has {x0.size} values, the NLP {nlp.n_variables} variables")
            return self._solve(evaluator, _push_inside(x0, nlp.lbx, nlp.ubx), deadline)
        except Exception as error:  # the Solver protocol reports failures, it never raises them
            return error_result(error, x0, deadline)

    def _solve(self, evaluator: NLPEvaluator, x: np.ndarray, deadline: Deadline) -> SolverResult:
        form = _NLPForm(evaluator, x, self.scaling)
        outcome = self._feasibility(form, x, deadline)
        if outcome.status is not SolverStatus.CONVERGED:
            return solver_result(outcome.status, f"FSQP feasibility phase: {outcome.message}", outcome.x, evaluator,
                                 outcome.iterations, deadline)
        form.orient(outcome.x)
        minimize = self._minimize_qp if self.subproblem == "qp" else self._minimize
        outcome = minimize(form, outcome.x, deadline, outcome.iterations)
        multipliers = None if outcome.multipliers is None else form.nlp_multipliers(outcome.multipliers)
        return solver_result(outcome.status, f"FSQP: {outcome.message}", outcome.x, evaluator, outcome.iterations,
                             deadline, multipliers)

    def _limit_reached(self, deadline: Deadline, iteration: int) -> tuple[SolverStatus, str] | None:
        """The time or iteration limit with its message, once reached: checked first by every loop of the method."""
        if deadline.expired():
            return SolverStatus.TIME_LIMIT, f"time limit of {self.time_limit_s} s reached"
        if iteration >= self.max_iterations:
            return SolverStatus.ITERATION_LIMIT, f"iteration limit of {self.max_iterations} reached"
        return None

    def _feasibility(self, form: _NLPForm, x: np.ndarray, deadline: Deadline) -> _Outcome:
        """Phase 1: damped Gauss–Newton on ½‖max(c_I, 0)‖² until every inequality row holds (see the class); with
        the ``qp`` subproblem on ½‖max(c_I, 0)‖² + ½‖c_E‖², until the equalities are within ``_EQUALITY_START``
        too, so that the first QP's linearisation is consistent."""
        n_ineq = form.n_inequalities
        with_equalities = self.subproblem == "qp"

        def violation_of(c_all: np.ndarray) -> float:
            value = 0.5 * np.sum(np.maximum(c_all[:n_ineq], 0.0) ** 2)
            return value + (0.5 * np.sum(c_all[n_ineq:] ** 2) if with_equalities else 0.0)

        def unfinished(c_all: np.ndarray) -> bool:
            return bool(np.any(c_all[:n_ineq] > 0) or
                        (with_equalities and np.max(np.abs(c_all[n_ineq:]), initial=0.0) > _EQUALITY_START))

        c_all = form.constraints(x)
        iteration = 0
        while np.all(np.isfinite(c_all)) and unfinished(c_all):
            c = c_all[:n_ineq]
            if limit := self._limit_reached(deadline, iteration):
                return _Outcome(*limit, x, iteration, None)
            violation = violation_of(c_all)
            rows = np.flatnonzero(c > -_FEASIBILITY_MARGIN)
            target = c[rows] + _FEASIBILITY_MARGIN
            residual = np.maximum(c[rows], 0.0)
            if with_equalities:
                rows = np.concatenate([rows, np.arange(n_ineq, form.m)])
                target = np.concatenate([target, c_all[n_ineq:]])
                residual = np.concatenate([residual, c_all[n_ineq:]])
            jacobian = form.jacobian(x)[rows]
            if not np.all(np.isfinite(jacobian.data)):
                return _Outcome(SolverStatus.ERROR, f"NaN or infinite derivatives at iteration {iteration}", x,
                                iteration, None)
            stalled = None
            if np.linalg.norm(jacobian.T @ residual) <= 1e-10 * max(1.0, np.sqrt(2 * violation)):
                stalled = "the violation is stationary"
            else:
                direction = self._projection(form, x, c_all) if with_equalities else None
                if direction is None:
                    normal = (jacobian @ jacobian.T).tocsc()
                    normal += sp.eye(rows.size, format="csc") * 1e-10 * max(1.0, float(normal.diagonal().max()))
                    direction = -jacobian.T @ spla.splu(normal).solve(target)
                step = 1.0
                while True:
                    trial = np.clip(x + step * direction, form.lbx, form.ubx)
                    c_trial = form.constraints(trial)
                    if violation_of(c_trial) <= (1 - 1e-4 * step) * violation:
                        break
                    step *= 0.5
                    if step < 1e-10:
                        stalled = "no step reduces the violation"
                        break
            if stalled is not None:
                if np.all(c <= 0):  # only the equalities are left: the main phase drives them to 0
                    break
                return self._infeasible(form, x, c, iteration, stalled)
            self._record("feasibility", iteration, violation, float(np.linalg.norm(direction)), step, np.nan,
                         rows.size, form.max_violation(c_all), "gn", x)
            x, c_all = trial, c_trial
            iteration += 1
        if not np.all(np.isfinite(c_all)):
            return _Outcome(SolverStatus.ERROR, "NaN or infinite g at the starting point", x, iteration, None)
        return _Outcome(SolverStatus.CONVERGED, "feasible", x, iteration, None)

    @staticmethod
    def _projection(form: _NLPForm, x: np.ndarray, c_all: np.ndarray) -> np.ndarray | None:
        """The least-norm step onto every linearised row within the bounds (a QP: Newton's method for the
        feasibility problem, where the clipped Gauss–Newton step crept along the bounds for hundreds of iterations
        on HS, N = 20); None when the linearisation is inconsistent."""
        jacobian = form.jacobian(x)
        general, equal = np.arange(form.n_general), form.n_inequalities + np.arange(form.n_equal_g)
        try:
            solution = _solve_qp(qpsolvers.Problem(
                sp.eye(form.n, format="csc"), np.zeros(form.n),
                jacobian[general].tocsc() if general.size else None,
                -c_all[general] - _FEASIBILITY_MARGIN if general.size else None,
                jacobian[equal].tocsc() if equal.size else None, -c_all[equal] if equal.size else None,
                np.where(form.free, form.lbx - x, 0.0), np.where(form.free, form.ubx - x, 0.0)))
        except _Breakdown:
            return None
        return solution.x

    @staticmethod
    def _infeasible(form: _NLPForm, x: np.ndarray, c: np.ndarray, iteration: int, reason: str) -> _Outcome:
        worst = float(np.max(np.maximum(c, 0.0) / form.row_factor[: form.n_inequalities]))
        return _Outcome(SolverStatus.INFEASIBLE, f"no point satisfies the inequalities: {reason} at a largest "
                        f"violation of {worst:.3g} (iteration {iteration})", x, iteration, None)

    def _record(self, phase: str, iteration: int, merit: float, d0_norm: float, step: float, penalty: float,
                active: int, max_violation: float, direction: str, x: np.ndarray) -> None:
        if self.print_level >= 1:
            if not self.log or self.log[-1].phase != phase:
                print(f"FSQP {phase} phase")
                label = "F_c" if phase == "main" else "½|c_I+|²"
                print(f"{'iter':>5} {label:>13} {'|d0|':>9} {'step':>9} {'c_k':>9} {'|J|':>5} {'max viol':>9}  dir")
            print(f"{iteration:>5} {merit:>13.6e} {d0_norm:>9.2e} {step:>9.2e} {penalty:>9.2e} {active:>5} "
                  f"{max_violation:>9.2e}  {direction}")
        self.log.append(IterationRecord(phase, iteration, merit, d0_norm, step, penalty, active, max_violation,
                                        direction, x.copy()))

    def _minimize(self, form: _NLPForm, x: np.ndarray, deadline: Deadline, iteration: int) -> _Outcome:
        """Steps 1–5 from a point x whose inequality rows are ≤ 0, counting iterations from ``iteration``."""
        n, m, n_ineq, equalities = form.n, form.m, form.n_inequalities, form.equalities
        f, c = form.objective(x), form.constraints(x)
        if not (np.isfinite(f) and np.all(np.isfinite(c))):
            return _Outcome(SolverStatus.ERROR, "NaN or infinite f or g at the starting point", x, iteration, None)
        bfgs = _BFGS(n, self.h0_scaling) if self.hessian == "bfgs" else None
        penalty, shift, d0_norm, u = self.rho, 0.0, np.inf, None
        blocking = np.zeros(0, dtype=int)
        x_old = lagrangian_gradient = None  # the last iterate and ∇f + Jᵀu there, for the BFGS update

        def merit(f_value: float, c_value: np.ndarray) -> float:
            """F_c = f − c Σ_E c_j, i.e. f + c Σ_E |c_j| on oriented rows: the ℓ1 exact penalty."""
            return f_value + penalty * np.sum(np.abs(c_value[equalities]))

        def outcome(status: SolverStatus, message: str) -> _Outcome:
            return _Outcome(status, message, x, iteration, u)

        def record(step: float, active: int, direction: str) -> None:
            self._record("main", iteration, merit(f, c), d0_norm, step, penalty, active, form.max_violation(c),
                         direction, x)

        try:
            while True:
                if limit := self._limit_reached(deadline, iteration):
                    return outcome(*limit)
                gradient, jacobian = form.gradient(x), form.jacobian(x)
                if not (np.all(np.isfinite(gradient)) and np.all(np.isfinite(jacobian.data))):
                    return outcome(SolverStatus.ERROR, f"NaN or infinite derivatives at iteration {iteration}")
                if bfgs is not None and x_old is not None:  # Step 5 of the last iteration, now that ∇ is known
                    bfgs.update(x - x_old, gradient + jacobian.T @ u - lagrangian_gradient)

                # Step 2, first half: least-squares multipliers π (11.8), which Step 1 uses too.
                pi = _least_squares_multipliers(jacobian, gradient, c, n_ineq)
                # Step 1 (11.7), with deviations 1 and 7.
                near = c.copy()
                inside = -c[:n_ineq]
                leaving = (np.abs(pi[:n_ineq]) < inside) | ((pi[:n_ineq] < 0) & (inside > self.tolerance))
                near[:n_ineq][leaving] = -np.inf
                active = self._active_set(jacobian, near, n_ineq, min(self.epsilon0, d0_norm), blocking)
                # Step 2: penalty update (11.9), then ∇F_c.
                largest = np.max(np.abs(pi[equalities]), initial=0.0)
                if penalty < largest + self.rho:
                    penalty = max(largest + self.rho, penalty + self.epsilon)
                merit_gradient = gradient - penalty * np.asarray(jacobian[equalities].sum(axis=0)).ravel()
                rows, c_active, is_equality = jacobian[active], c[active], active >= n_ineq
                if bfgs is not None:
                    hessian, augmentation = bfgs.matrix, 0.0
                else:
                    hessian, augmentation, shift = self._convexified_hessian(form, x, pi, rows, shift)

                # Step 3.1: d0 (11.10); near-active rows with π_j < 0 are relaxed to ∇c_jᵀd = π_j.
                a = np.where(~is_equality & (pi[active] < 0), -pi[active], c_active)
                k0 = _Factorization(_kkt(hessian, rows))
                solution = k0.solve(-np.concatenate([merit_gradient, a]))
                d0, u_active = solution[:n], solution[n:]
                if augmentation:  # the multipliers of ∇²L rather than of the augmented H
                    u_active = u_active - augmentation * a / _row_norms(rows) ** 2
                u = np.zeros(m)
                u[active] = u_active
                u[equalities] -= penalty  # the original problem's multipliers: ũ_j − c on the equalities
                d0_norm = float(np.linalg.norm(d0))
                if d0_norm <= self.tolerance and np.max(np.abs(c[equalities]), initial=0.0) <= self.tolerance:
                    record(np.nan, active.size, "-")
                    return outcome(SolverStatus.CONVERGED, f"‖d0‖ = {d0_norm:.2e} ≤ {self.tolerance:g} after "
                                   f"{iteration} iterations")

                # Step 3.2: d1 (11.12)-(11.13), else the d2/d3 combination (11.14)-(11.17); deviations 2-4.
                d1 = k0.solve(-np.concatenate([merit_gradient, a + self._margins(d0_norm, self.nu, c_active,
                                                                                 is_equality)]))[:n]
                slope1 = merit_gradient @ d1
                if slope1 < 0 and slope1 <= -self.xi * _power(float(np.linalg.norm(d1)), self.delta):
                    d, direction = d1, "d1"
                else:
                    k1 = _Factorization(_kkt(hessian, rows, c_active))
                    rhs = -np.concatenate([merit_gradient, np.zeros(active.size)])
                    pi_tilde = k1.solve(rhs)[n:]
                    rhs[n:] = np.minimum(pi_tilde, 0.0)  # −V, V_j = −π̃_j where π̃_j ≤ 0
                    d3 = k1.solve(rhs)[:n]
                    slope3 = merit_gradient @ d3
                    if slope3 >= 0:
                        raise _Breakdown(f"no feasible descent direction (∇F_cᵀd3 = {slope3:.2e} ≥ 0) at iteration "
                                         f"{iteration} although ‖d0‖ = {d0_norm:.2e}")
                    weight = 1.0 if slope1 <= self.theta * slope3 else (1 - self.theta) * slope3 / (slope3 - slope1)
                    d, direction = min(-slope3, 1.0) * ((1 - weight) * d3 + weight * d1), "d3"

                # Step 3.3: second-order correction d̃ (11.18), dropped if longer than d or not computable.
                d_norm = float(np.linalg.norm(d))
                correction = np.zeros(n)
                c_ahead = form.constraints(x + d)[active]
                if np.all(np.isfinite(c_ahead)):
                    target = c_ahead + (a - c_active) + self._margins(d_norm, self.tau, c_active, is_equality)
                    correction = k0.solve(-np.concatenate([merit_gradient + hessian @ d, target]))[:n]
                    if np.linalg.norm(correction) > d_norm:
                        correction = np.zeros(n)

                # Step 4: arc search on x + t d + t² d̃ (11.19)-(11.20): inequality rows ≤ 0, Armijo on F_c.
                current, slope, step = merit(f, c), merit_gradient @ d, 1.0
                while True:
                    if deadline.expired():
                        return outcome(SolverStatus.TIME_LIMIT,
                                       f"time limit of {self.time_limit_s} s reached in the arc search")
                    trial = x + step * d + step ** 2 * correction
                    if form.admissible(trial):
                        c_trial = form.constraints(trial)
                        # NaN compares False, so a trial where g is undefined is rejected like an infeasible one.
                        if np.all(c_trial[:n_ineq] <= 0) and np.all(np.isfinite(c_trial)):
                            f_trial = form.objective(trial)
                            if merit(f_trial, c_trial) <= current + self.alpha * step * slope:
                                break
                    rejected = trial
                    step *= self.beta
                    if step * np.max(np.abs(d)) <= _ROUNDING * (1 + np.max(np.abs(x))):
                        raise _Breakdown(f"arc search found no acceptable step at iteration {iteration} "
                                         f"(‖d0‖ = {d0_norm:.2e}, ∇F_cᵀd = {slope:.2e})")
                record(step, active.size, direction)
                if np.max(np.abs(trial - x)) <= _ROUNDING * (1 + np.max(np.abs(x))):
                    raise _Breakdown(f"no progress at iteration {iteration}: the accepted step leaves x unchanged "
                                     f"(‖d‖ = {d_norm:.2e}, ‖d0‖ = {d0_norm:.2e})")
                blocking = np.zeros(0, dtype=int)
                if step < 1:
                    with np.errstate(invalid="ignore"):  # NaN rows do not block
                        blocking = np.flatnonzero(form.constraints(rejected)[:n_ineq] > 0)

                # Step 5 needs the derivatives at the new point: the BFGS update opens the next iteration.
                x_old, lagrangian_gradient = x, gradient + jacobian.T @ u
                x, f, c = trial, f_trial, c_trial
                crossed = n_ineq + np.flatnonzero(c[equalities] > 0)
                if crossed.size:  # deviation 5: re-orient the equality rows that crossed zero
                    form.flip(crossed)
                    c[crossed] *= -1
                    u[crossed] *= -1
                iteration += 1
        except _Breakdown as breakdown:
            return outcome(SolverStatus.ERROR, str(breakdown))

    def _minimize_qp(self, form: _NLPForm, x: np.ndarray, deadline: Deadline, iteration: int) -> _Outcome:
        """FSQP with the ``qp`` subproblem (see the class docstring), from x with every inequality row ≤ 0."""
        n, m, n_ineq = form.n, form.m, form.n_inequalities
        general, equal = np.arange(form.n_general), n_ineq + np.arange(form.n_equal_g)
        f, c = form.objective(x), form.constraints(x)
        if not (np.isfinite(f) and np.all(np.isfinite(c))):
            return _Outcome(SolverStatus.ERROR, "NaN or infinite f or g at the starting point", x, iteration, None)
        weights, damping, d_norm, u, streak = np.zeros(equal.size), 0.0, np.nan, np.zeros(m), 0
        working = equal  # the rows whose normals may convexify H: the equalities and the last QP's active rows

        def merit(f_value: float, c_value: np.ndarray) -> float:
            """f + Σ_E w_j |c_j|: the ℓ1 exact penalty, Mayne–Polak's F_c with a weight per row."""
            return f_value + weights @ np.abs(c_value[equal])

        def outcome(status: SolverStatus, message: str) -> _Outcome:
            return _Outcome(status, message, x, iteration, u)

        def record(step: float, direction: str) -> None:
            self._record("main", iteration, merit(f, c), d_norm, step, np.max(weights, initial=0.0), working.size,
                         form.max_violation(c), direction, x)

        try:
            while True:
                if limit := self._limit_reached(deadline, iteration):
                    return outcome(*limit)
                gradient, jacobian = form.gradient(x), form.jacobian(x)
                if not (np.all(np.isfinite(gradient)) and np.all(np.isfinite(jacobian.data))):
                    return outcome(SolverStatus.ERROR, f"NaN or infinite derivatives at iteration {iteration}")
                multipliers = u
                # d0: the QP over every linearised row; equalities as equalities, which gives the same step as
                # Mayne–Polak's inequalities with ∇F_c (the penalty term is constant on their linearisation).
                rows_g, rows_e = jacobian[general], jacobian[equal]
                lower = np.where(form.free, form.lbx - x, 0.0)
                upper = np.where(form.free, form.ubx - x, 0.0)
                for _ in range(2):  # once more, convexified over the rows the QP holds, if rows it left were in W
                    hessian, augmentation, base = self._qp_hessian(form, x, multipliers, jacobian[working], damping)
                    qp = qpsolvers.Problem(hessian, gradient, rows_g.tocsc() if general.size else None,
                                           -c[general] if general.size else None,
                                           rows_e.tocsc() if equal.size else None, -c[equal] if equal.size else None,
                                           lower, upper)
                    solution = _solve_qp(qp)
                    d = np.clip(x + solution.x, form.lbx, form.ubx) - x  # the QP's bounds hold to its tolerance
                    linear = c + jacobian @ d
                    held = np.intersect1d(working, np.flatnonzero(linear >= -_ACTIVE))  # kept at their bound
                    held = np.union1d(held, np.intersect1d(working, equal))
                    loose = np.setdiff1d(working, held)
                    if not (augmentation and loose.size):
                        break
                    working = held
                u = np.zeros(m)
                u[general] = solution.z if general.size else 0.0
                u[equal] = solution.y if equal.size else 0.0
                bound_multipliers = solution.z_box
                if augmentation:  # the multipliers of ∇²L rather than of the augmented H (rows held in the QP)
                    rows_held = jacobian[held]
                    u[held] += augmentation * (rows_held @ d) / _row_norms(rows_held) ** 2
                    u[general] = np.maximum(u[general], 0.0)
                # Powell's weights (``sqp``'s): one per equality row, following its multiplier, raised together when
                # d would not decrease the merit by ½dᵀHd. A single c ≥ max|u_E| + ρ dwarfed the objective (f ~ 1e-5
                # on the forward step), so every equality's curvature error cut the arc search.
                weights = np.maximum(np.abs(u[equal]), (weights + np.abs(u[equal])) / 2)
                residual = np.sum(np.abs(c[equal]))
                excess = gradient @ d + 0.5 * d @ (hessian @ d) - weights @ np.abs(c[equal])
                if excess > 0 and residual > 0:
                    weights = weights + 2 * excess / residual
                d_norm = float(np.linalg.norm(d))

                # Convergence: IPOPT's scaled KKT test with the QP's multipliers, or its acceptable level.
                # ∇f + Jᵀu + z = −(H_base d + ρ Σ_loose â âᵀd) by the QP's stationarity, with the corrected u
                normals = sp.diags(1 / _row_norms(jacobian[loose])) @ jacobian[loose] if loose.size else None
                curvature = base @ d + (augmentation * (normals.T @ (normals @ d)) if normals is not None else 0.0)
                stationarity = np.max(np.abs(curvature), initial=0.0)
                complementarity = np.max(np.abs(u[general]) * np.minimum(1.0, -c[general]), initial=0.0)
                scale = max(1.0, (np.sum(np.abs(u)) + np.sum(np.abs(bound_multipliers))) / (100 * (m + n)))
                violation = max(np.max(c[general], initial=0.0), np.max(np.abs(c[equal]), initial=0.0))
                error = max(stationarity / scale, complementarity / scale, violation)
                streak = streak + 1 if error <= _ACCEPTABLE_TOLERANCE else 0
                if error <= self.tolerance or (d_norm <= self.tolerance and violation <= self.tolerance):
                    record(np.nan, "-")
                    return outcome(SolverStatus.CONVERGED, f"KKT error {error:.2e} ≤ {self.tolerance:g} after "
                                   f"{iteration} iterations")
                if streak >= _ACCEPTABLE_ITERATIONS:
                    record(np.nan, "-")
                    return outcome(SolverStatus.CONVERGED, f"acceptable level: KKT error {error:.2e} for "
                                   f"{streak} iterations")

                # Second-order correction against the Maratos effect (the equalities' curvature).
                correction = self._bend(form, x, d, qp, general, equal, d_norm)

                # Arc search on x + t d + t² d̃: inequality rows stay ≤ tolerance, Armijo on the ℓ1 merit.
                current = merit(f, c)
                slope = gradient @ d - weights @ np.abs(c[equal])
                step = 1.0
                while True:
                    if deadline.expired():
                        return outcome(SolverStatus.TIME_LIMIT,
                                       f"time limit of {self.time_limit_s} s reached in the arc search")
                    trial = np.clip(x + step * d + step ** 2 * correction, form.lbx, form.ubx)
                    c_trial = form.constraints(trial)
                    if np.all(np.isfinite(c_trial)) and np.all(c_trial[:n_ineq] <= self.tolerance):
                        f_trial = form.objective(trial)
                        if merit(f_trial, c_trial) <= current + self.alpha * step * min(slope, 0.0):
                            break
                    step *= self.beta
                    if step * np.max(np.abs(d)) <= _ROUNDING * (1 + np.max(np.abs(x))):
                        if error <= _ACCEPTABLE_TOLERANCE:
                            return outcome(SolverStatus.CONVERGED, f"acceptable level: KKT error {error:.2e}, no "
                                           "further progress")
                        raise _Breakdown(f"arc search found no acceptable step at iteration {iteration} "
                                         f"(‖d‖ = {d_norm:.2e}, slope {slope:.2e}, KKT error {error:.2e})")
                record(step, "qp" if not correction.any() else "qp+soc")
                # Levenberg–Marquardt damping, as ``sqp``'s: set by the merit's actual against predicted decrease;
                # a cut step or a poor ratio says the model reaches too far.
                size = max(1.0, float(np.max(np.abs(base.diagonal()), initial=0.0)))
                predicted = -slope - 0.5 * d @ (base @ d)
                ratio = (current - merit(f_trial, c_trial)) / predicted if predicted > 0 else 1.0
                if step < 1 or ratio < 0.25:
                    damping = min(max(4 * damping, _SHIFT_RANGE[0] * size), size)
                elif ratio >= 0.75:
                    damping /= 2
                x, f, c = trial, f_trial, c_trial
                bounds_near = np.arange(form.n_general, n_ineq)[c[form.n_general:n_ineq] >= -_ACTIVE]
                working = np.concatenate([general[u[general] > 0], bounds_near, equal])
                iteration += 1
        except _Breakdown as breakdown:
            return outcome(SolverStatus.ERROR, str(breakdown))

    @staticmethod
    def _qp_hessian(form: _NLPForm, x: np.ndarray, u: np.ndarray, rows: sp.csr_matrix,
                    damping: float) -> tuple[sp.csc_matrix, float, sp.csc_matrix]:
        """∇²L(x, u⁺) + δI made positive definite as ``sqp`` does: δ = max(damping, 1e-10 max|H|), then the least
        ρ max|H| Σ â âᵀ (ρ = 1, 10, …, 10⁴; â the working rows, normalized) that factorizes, then ρ = 100 with a
        shift growing ×4. Returns H, the augmentation's factor (for the multiplier correction) and H without the
        augmentation (for the KKT test)."""
        multipliers = u.copy()
        multipliers[: form.n_inequalities] = np.maximum(multipliers[: form.n_inequalities], 0.0)
        lagrangian = form.hessian(x, multipliers)
        if not np.all(np.isfinite(lagrangian.data)):
            raise _Breakdown("NaN or infinite Hessian of the Lagrangian")
        size = max(1.0, float(np.max(np.abs(lagrangian.data), initial=0.0)))
        shift = max(damping, 1e-10 * size)
        shifted = (lagrangian + shift * sp.eye(form.n)).tocsc()
        if _positive_definite(shifted):
            return shifted, 0.0, shifted
        normals = sp.diags(1 / _row_norms(rows)) @ rows
        gram = (normals.T @ normals).tocsc()
        for rho in (1.0, 10.0, 100.0, 1e3, 1e4):
            augmented = (shifted + rho * size * gram).tocsc()
            if _positive_definite(augmented):
                return augmented, rho * size, shifted
        augmentation, shift = 100.0 * size, max(shift, 1e-8 * size)
        while shift <= _SHIFT_RANGE[1] * size:
            base = (lagrangian + shift * sp.eye(form.n)).tocsc()
            candidate = (base + augmentation * gram).tocsc()
            if _positive_definite(candidate):
                return candidate, augmentation, base
            shift *= 4
        raise _Breakdown("the Hessian of the Lagrangian cannot be made positive definite")

    @staticmethod
    def _bend(form: _NLPForm, x: np.ndarray, d: np.ndarray, qp: qpsolvers.Problem, general: np.ndarray,
              equal: np.ndarray, d_norm: float) -> np.ndarray:
        """The second-order correction d̃ = s − d, s the QP again with every row linearised at x + d
        (c(x + d) − ∇c d + ∇c s), so that the arc x + t d + t² d̃ is x + s at t = 1; zero when that QP fails or d̃
        is longer than d. (Holding the inequalities ‖d‖^τ inside, as the thesis's d̃ does, made this QP jump.)"""
        ahead = form.constraints(x + d)
        if not np.all(np.isfinite(ahead)):
            return np.zeros(form.n)
        h = None if qp.G is None else -(ahead[general] - qp.G @ d)
        b = None if qp.A is None else -(ahead[equal] - qp.A @ d)
        try:
            s = _solve_qp(qpsolvers.Problem(qp.P, qp.q, qp.G, h, qp.A, b, qp.lb, qp.ub)).x
        except _Breakdown:
            return np.zeros(form.n)
        correction = np.clip(x + s, form.lbx, form.ubx) - x - d
        if np.linalg.norm(correction) > d_norm:
            return np.zeros(form.n)
        return correction

    def _margins(self, norm: float, power: float, c_active: np.ndarray, equality: np.ndarray) -> np.ndarray:
        """The interior margin ‖·‖^power of d1 and d̃ per active row (deviation 4)."""
        margin = _power(norm, power)
        return np.where(equality, np.minimum(margin, self.equality_margin * np.abs(c_active)), margin)

    def _active_set(self, jacobian: sp.csr_matrix, near: np.ndarray, n_ineq: int, epsilon: float,
                    blocking: np.ndarray) -> np.ndarray:
        """Step 1: J = {j ∈ I: near_j ≥ −ε} ∪ blocking ∪ E, ε halved until the gradients are independent; the
        blocking rows are dropped again if even the smallest ε leaves J dependent."""
        equalities = np.arange(n_ineq, near.size)
        for forced in (blocking, blocking[:0]):
            eps = epsilon
            for _ in range(self.max_halvings + 1):
                active = np.concatenate([np.union1d(np.flatnonzero(near[:n_ineq] >= -eps), forced), equalities])
                if _full_row_rank(jacobian[active], self.rank_tolerance):
                    return active
                eps /= 2
            if not forced.size:
                break
        raise _Breakdown(f"the gradients of the active constraints are linearly dependent (LICQ fails) after "
                         f"{self.max_halvings} halvings of ε")

    def _convexified_hessian(self, form: _NLPForm, x: np.ndarray, pi: np.ndarray, rows: sp.csr_matrix,
                             shift: float) -> tuple[sp.csc_matrix, float, float]:
        """∇²L(x, π⁺) made positive definite: (H, ρ, δ) of H = ∇²L + ρ ÂᵀÂ + δI (see the class docstring)."""
        multipliers = pi.copy()
        multipliers[: form.n_inequalities] = np.maximum(multipliers[: form.n_inequalities], 0.0)
        lagrangian = form.hessian(x, multipliers)
        if not np.all(np.isfinite(lagrangian.data)):
            raise _Breakdown("NaN or infinite Hessian of the Lagrangian")
        if _positive_definite(lagrangian):
            return lagrangian, 0.0, 0.0
        scale = max(1.0, float(np.max(np.abs(lagrangian.diagonal()), initial=0.0)))
        normalized = sp.diags(1 / _row_norms(rows)) @ rows
        augmentation = _AUGMENTATION * scale
        augmented = (lagrangian + augmentation * (normalized.T @ normalized)).tocsc()
        if _positive_definite(augmented):
            return augmented, augmentation, 0.0
        low, high = _SHIFT_RANGE
        shift = max(low * scale, shift / 4)
        while shift <= high * scale:
            shifted = (augmented + shift * sp.eye(form.n)).tocsc()
            if _positive_definite(shifted):
                return shifted, augmentation, shift
            shift *= 8
        raise _Breakdown("the Hessian of the Lagrangian cannot be made positive definite")


class _BFGS:
    """Dense damped BFGS (Powell): yᵀs ≥ 0.2 sᵀHs is enforced by mixing y with Hs, so H stays positive definite."""

    def __init__(self, n: int, h0_scaling: str | float) -> None:
        self.matrix = np.eye(n) * (1.0 if h0_scaling == "auto" else float(h0_scaling))
        self.rescale = h0_scaling == "auto"

    def update(self, s: np.ndarray, y: np.ndarray) -> None:
        """The damped update; skipped when sᵀHs vanishes (s below rounding)."""
        if self.rescale and y @ s > 0:
            self.matrix *= (y @ y) / (y @ s)
        self.rescale = False
        hs = self.matrix @ s
        shs, ys = s @ hs, y @ s
        if not shs > 0:
            return
        if ys < 0.2 * shs:
            mix = 0.8 * shs / (shs - ys)
            y = mix * y + (1 - mix) * hs
            ys = y @ s
        self.matrix += np.outer(y, y) / ys - np.outer(hs, hs) / shs


class _Factorization:
    """LU of a KKT matrix: SuperLU when sparse, LAPACK when mostly dense (a BFGS block makes it so)."""

    def __init__(self, matrix: sp.spmatrix) -> None:
        size = matrix.shape[0]
        self.dense = matrix.nnz > _DENSE_FRACTION * size * size
        try:
            if self.dense:
                self.factor = la.lu_factor(matrix.toarray(), check_finite=False)
            else:
                self.factor = spla.splu(sp.csc_matrix(matrix))
        except RuntimeError as error:  # SuperLU: "Factor is exactly singular"
            raise _Breakdown(f"singular KKT matrix ({error})") from error

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        if self.dense:
            solution = la.lu_solve(self.factor, rhs, check_finite=False)
        else:
            solution = self.factor.solve(rhs)
        if not np.all(np.isfinite(solution)):
            raise _Breakdown("singular KKT matrix (non-finite solution)")
        return solution


def _solve_qp(problem: qpsolvers.Problem) -> qpsolvers.Solution:
    """The QP by each of ``_QP_SOLVERS`` in turn until one solves it (or returns a reduced-accuracy optimum)."""
    statuses = []
    for solver in _QP_SOLVERS:
        try:
            with warnings.catch_warnings(), quiet_stdout():
                warnings.simplefilter("ignore")
                solution = qpsolvers.solve_problem(problem, solver=solver)
        except Exception as error:  # a backend that rejects the problem counts as a failed QP
            statuses.append(f"{solver}: {type(error).__name__}")
            continue
        status = backend_status(solution)
        usable = solution.found or status in INACCURATE_STATUSES
        if usable and solution.x is not None and np.all(np.isfinite(solution.x)):
            if solution.z_box is None:
                solution.z_box = np.zeros(problem.P.shape[0])
            return solution
        statuses.append(f"{solver}: {status}")
    raise _Breakdown(f"the QP subproblem failed ({'; '.join(statuses)})")


def _power(norm: float, power: float) -> float:
    """‖·‖^p as the thesis uses it for ‖·‖ ≤ 1, linear beyond (deviation 4)."""
    return min(norm ** power, norm)


def _push_inside(x: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """x projected onto the bounds and pushed inside by min(p max(1, |bound|), p (upper − lower)), p = ``_PUSH``."""
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    with np.errstate(invalid="ignore"):  # inf − inf on infinite bounds, discarded by np.where
        room = np.where(np.isfinite(upper - lower), _PUSH * (upper - lower), np.inf)
        low = np.where(np.isfinite(lower), lower + np.minimum(_PUSH * np.maximum(1.0, np.abs(lower)), room), lower)
        high = np.where(np.isfinite(upper), upper - np.minimum(_PUSH * np.maximum(1.0, np.abs(upper)), room), upper)
    return np.clip(np.clip(x, low, high), lower, upper)


def _kkt(hessian, rows: sp.csr_matrix, lower: np.ndarray | None = None) -> sp.csc_matrix:
    """[[H, Aᵀ], [A, diag(lower) or 0]] with A's rows the active gradients (the thesis's A is its transpose)."""
    if rows.shape[0] == 0:
        return sp.csc_matrix(hessian)
    corner = sp.diags(lower) if lower is not None else sp.csr_matrix((rows.shape[0], rows.shape[0]))
    return sp.bmat([[sp.csr_matrix(hessian), rows.T], [rows, corner]], format="csc")


def _least_squares_multipliers(jacobian: sp.csr_matrix, gradient: np.ndarray, c: np.ndarray,
                               n_ineq: int) -> np.ndarray:
    """π = −(NᵀN + D)⁻¹Nᵀ∇f (11.8) over all rows, D = c_j² on the inequalities; a 1e-12 relative ridge keeps it
    defined where exactly active gradients are dependent."""
    if c.size == 0:
        return np.zeros(0)
    weights = np.zeros(c.size)
    weights[:n_ineq] = c[:n_ineq] ** 2
    normal = (jacobian @ jacobian.T + sp.diags(weights)).tocsc()
    normal += sp.eye(c.size, format="csc") * 1e-12 * max(1.0, float(normal.diagonal().max()))
    return -spla.splu(normal).solve(jacobian @ gradient)


def _symmetric_pivots(matrix: sp.spmatrix) -> np.ndarray | None:
    """Pivots of LDLᵀ of a symmetric matrix (SuperLU, symmetric ordering, diagonal pivots); None if it needed
    off-diagonal pivots or is exactly singular."""
    try:
        lu = spla.splu(sp.csc_matrix(matrix), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})
    except RuntimeError:
        return None
    if not np.array_equal(lu.perm_r, lu.perm_c):
        return None
    return lu.U.diagonal()


def _positive_definite(matrix: sp.spmatrix) -> bool:
    pivots = _symmetric_pivots(matrix)
    scale = max(1.0, float(np.max(np.abs(matrix.diagonal()), initial=0.0)))
    return pivots is not None and bool(np.all(pivots > 1e-12 * scale))


def _full_row_rank(rows: sp.csr_matrix, tolerance: float) -> bool:
    """Whether the active gradients are independent: pivots of the normalized Gram matrix ≥ tolerance²."""
    count, n = rows.shape
    if count == 0:
        return True
    norms = _row_norms(rows)
    if count > n or np.any(norms == 0):
        return False
    normalized = sp.diags(1 / norms) @ rows
    pivots = _symmetric_pivots(normalized @ normalized.T)
    return pivots is not None and bool(np.all(pivots >= tolerance ** 2))


def _row_norms(rows: sp.csr_matrix) -> np.ndarray:
    return np.sqrt(np.asarray(rows.multiply(rows).sum(axis=1)).ravel())


def _gradient_scale(gradient_max: np.ndarray | float):
    """Factors that bring gradient max-norms above the target down to it; 1 elsewhere (also for NaN)."""
    gradient_max = np.asarray(gradient_max, dtype=float)
    large = np.isfinite(gradient_max) & (gradient_max > _MAX_GRADIENT)
    return np.where(large, _MAX_GRADIENT / np.where(large, gradient_max, 1.0), 1.0)


@hookimpl
def register_solvers():
    return [Registration("fsqp", "Feasible SQP (thesis App. D): feasible iterates, arc search, BFGS or exact Hessian",
                         FSQP)]
