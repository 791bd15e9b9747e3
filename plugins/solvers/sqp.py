"""A line-search SQP whose quadratic subproblems go to any backend of the ``qpsolvers`` library.

Why: an active-set method with the exact Hessian converges superlinearly once it has found the active set, which
makes it the natural comparison for IPOPT's interior point on the gait NLPs, and routing every QP through
``qpsolvers`` lets one benchmark compare QP backends (interior point: Clarabel, PIQP; active set: DAQP, quadprog,
HiGHS; ADMM / proximal: OSQP, ProxQP) on exactly the subproblems an SQP produces.

Each iteration solves, at the current x with multipliers λ,

    min ½dᵀPd + ∇fᵀd   s.t.   lbg ≤ g + J d ≤ ubg,   lbx ≤ x + d ≤ ubx

in ``qpsolvers`` form: rows with lbg = ubg become ``A d = b``, every finite side of the other rows a row of
``G d ≤ h`` (upper sides as J, lower sides as −J), the bounds ``lb ≤ d ≤ ub`` (infinite entries stay infinite:
every installed backend accepts them, and PIQP mistakes 1e20 for a real bound). Sparse backends get SciPy CSC
matrices, dense-only ones (DAQP, quadprog) dense arrays; a problem with neither constraints nor bounds is the
Newton system, solved without a backend. The QP duals are the multiplier estimates, in CasADi's sign convention
∇f + Jᵀλ_g + λ_x = 0; the first ones are IPOPT's least-squares estimate for the equality rows.

P must be positive definite for every backend (strictly for quadprog and DAQP). With ``hessian="exact"`` it is the
Hessian H of the Lagrangian, convexified without an eigen-decomposition, each candidate tested by a sparse LDLᵀ
factorisation (``_positive_definite``; the whole model stays sparse, as the Hessian and Jacobian come from CasADi):

1. H + δI, δ = max(δ₀, δ_LM), δ₀ = 1e-10·max(1, max|H|) lifting only exactly singular directions, and δ_LM the
   Levenberg–Marquardt damping below;
2. H + δI + ρ·max(1, max|H|)·Σ_W a_i a_iᵀ/‖a_i‖², ρ = 1, 10, …, 10⁴, the least that factorises, over a working
   set W of constraint normals a_i: the equality rows, the inequality rows that are violated, within 1e-6 of a
   bound or carry a multiplier, and the variables at a bound. For a row active in the QP, a_iᵀd is fixed, so the
   added term is constant on the QP's feasible set: once W is the active set the step is the exact Newton step,
   and by Debreu's lemma such a ρ exists when H is positive definite on the null space of the active constraints.
   The multipliers of rows active in the QP are corrected by ρ·a_iᵀd/‖a_i‖², so they are those of H itself
   (a one-sided row whose corrected multiplier has the wrong sign is not active for H: its multiplier is zero);
3. failing that, the ρ = 100 augmentation plus a shift from max(δ, 1e-8·max(1, max|H|)) growing ×4 until the
   factorisation is positive definite, like IPOPT's inertia correction.

δ_LM, with the ℓ1 merit: the shift of the last iteration times ½ when the full step's actual decrease of φ was at
least ¾ of its model's (−Dφ(d) − ½dᵀ(H + δI)d), times 1 down to ¼, times 4 below ¼ or when the full step was
rejected (from at least 1e-8·max(1, max|H|)). On the gait steps the Lagrangian is indefinite along the flat valleys
of the thesis cost. IPOPT's rule alone (start from a fraction of the last shift) cycled there: the shift fell until
a step was far too long, the violation rose to 1e-2–1, and the next Hessian needed a shift 1000× larger, for
hundreds of iterations (forward HS N = 20, step 3: iteration limit; DMOC N = 100: time limit). The ratio control
converged on all five first steps measured (HS and DMOC, N = 50 and 100; DMOC N = 20) and on 3-step walks.

With ``hessian="bfgs"`` P is a dense damped BFGS matrix (Powell's damping keeps it positive definite), started at
the identity and rescaled by yᵀy/sᵀy at the first update; the Hessian is never evaluated.

Globalisation (``merit``):

- ``"l1"``: the exact penalty φ = f + Σ μ_i viol_i(g), with Powell's per-row weights μ_i = max(|λ_i|,
  (μ_i + |λ_i|)/2) as in SLSQP (raised uniformly when the step would not decrease φ by ½ max(dᵀHd, 0), as the
  Nocedal–Wright rule (18.36) raises a single penalty), and Armijo backtracking (halving) on the directional
  derivative ∇fᵀd − Σ μ_i (viol_i(g) − viol_i(g + J d)). Weights that follow each row's multiplier matter on the
  gait steps, whose rows differ by orders of magnitude in scale: a single penalty set by the largest multiplier
  all but stops progress in f. When the QP fails or its multipliers exceed 1e6 (a nearly inconsistent
  linearisation), the step comes from its elastic version (SNOPT's elastic mode, Fletcher's Sℓ1QP)
  min ½dᵀPd + ∇fᵀd + W·Σ(p + n) s.t. lbg ≤ g + J d − p + n ≤ ubg, the bounds, p, n ≥ 0, W = max(100, 10‖λ‖∞).
- ``"filter"``: the Wächter–Biegler filter line search on (θ = ‖viol(g)‖₁, f), with its switching condition, the
  Armijo condition on f for f-type steps and filter augmentation for h-type steps. A failed QP, multipliers above
  1e6 or a step length below the filter's minimum start the restoration phase.

After an elastic step the multipliers restart from least squares: the ones that made the QP fail would shape the
next Hessians. At a stationary point (KKT residual below ``tolerance``) that is only slightly infeasible (below
``acceptable_tolerance``), one Gauss–Newton projection onto the constraints (the restoration's QP below) is taken
whole when it halves θ.

Restoration phase (the filter's, and the ℓ1 merit's when even the elastic QP fails): Gauss–Newton steps on θ (the
elastic QP with P = I, no objective and W = 1e4, so the least-norm step that reduces the linearised violation most
— a well-conditioned QP whatever the Hessian), each with Armijo backtracking on θ, until θ is below 0.9 times its
value on entry and the point is acceptable to the filter, which holds the iterate restoration started from; the
multipliers then restart from least squares.

Both try one second-order correction against the Maratos effect when the full step is rejected and did not reduce θ:
the QP again, with the constraints linearised as g(x + d) − J d + J s, accepted on the test for α = 1.

INFEASIBLE (local infeasibility): x violates the constraints, and the elastic QP predicts no decrease of θ (x is a
stationary point of the violation) or no step along its direction reduces the merit (θ, in restoration); the
message names the backend status of the QP that failed.

Convergence: the violation (max-norm) below ``tolerance`` and the stationarity/complementarity residual below
``tolerance`` times IPOPT's dual scaling s_d, with the current multipliers or with the ones the QP at x has just
returned; or, as IPOPT's "acceptable" level, both below ``acceptable_tolerance`` for 15 consecutive iterations or
when the iteration cannot continue from such a point. Complementarity is IPOPT's product |μ_i|·d_i near a bound.

QP failures: a QP the backend fails is solved again by ``fallback_qp_solver`` (Clarabel) before it counts as
failed. PIQP, the default, stops at its iteration limit on some convexified gait QPs (eigenvalues from 1e-7 to
5e4 at DMOC, N = 50), which Clarabel solves, if only to its reduced accuracy.

Warm starts, through ``qpsolvers``: the previous step is passed as ``initvals`` to the backends whose ``qpsolvers``
interface uses it (OSQP, ProxQP, DAQP); ProxQP also receives the previous duals (its ``y`` and ``z`` keywords).
Clarabel, PIQP, HiGHS and quadprog start cold (``qpsolvers`` ignores initial values for them, or warns), so they
are never given any.

Options on the command line: ``-s sqp -o qp_solver=daqp -o hessian=bfgs -o merit=filter -o qp_tolerance=1e-9``.
"""

from __future__ import annotations

import itertools
import time
import warnings
from dataclasses import dataclass

import numpy as np
import qpsolvers
import scipy.linalg
import scipy.linalg.lapack
import scipy.sparse as sp
import scipy.sparse.linalg

from gaitbench import Registration, hookimpl
from gaitbench.problem.nlp import NLP
from gaitbench.solve.evaluation import Deadline, NLPEvaluator, error_result, solver_result
from gaitbench.solve.silence import quiet_stdout
from gaitbench.solve.solver import SolverResult, SolverStatus

_TOLERANCE_KEYWORDS: dict[str, tuple[str, ...]] = {
    "clarabel": ("tol_gap_abs", "tol_gap_rel", "tol_feas"),
    "daqp": ("primal_tol",),
    "highs": ("primal_feasibility_tolerance", "dual_feasibility_tolerance"),
    "osqp": ("eps_abs", "eps_rel"),
    "piqp": ("eps_abs", "eps_rel"),
    "proxqp": ("eps_abs", "eps_rel"),
}
"""The backend keywords ``qp_tolerance`` sets. quadprog (a dual active-set method solving to machine precision) has
none, nor have backends not listed here."""

_BACKEND_OPTIONS: dict[str, dict] = {"osqp": {"polishing": True, "max_iter": 20000}}
"""Fixed extra options: OSQP's ADMM alone reaches tight tolerances slowly; its polishing step solves the
identified active set's equality QP exactly."""

_TIME_LIMITED = frozenset({"clarabel", "daqp", "highs", "osqp"})
"""Backends with a ``time_limit`` option (seconds): they get the time left, so one slow QP cannot overrun the
solve's limit (PIQP, ProxQP and quadprog have none, and are only stopped between iterations)."""

_INACCURATE = frozenset({"AlmostSolved", "solved inaccurate"})
"""Statuses ``qpsolvers`` reports as not found whose solutions are still used (Clarabel's and OSQP's reduced-accuracy
optimum): the line search judges the step, and rejecting them would end a solve that is nearly done."""

_PRIMAL_WARM_START = frozenset({"osqp", "proxqp", "daqp"})
"""Backends whose ``qpsolvers`` interface passes ``initvals`` on to the solver."""

_DUAL_WARM_START = frozenset({"proxqp"})
"""Backends that also take dual start values through ``qpsolvers`` (ProxQP's ``y`` and ``z``)."""

_HESSIANS = ("exact", "bfgs")
_MERITS = ("l1", "filter")

_ARMIJO = 1e-4
_MIN_STEP = 1e-10
_RESTORATION_REDUCTION = 0.9
_RESTORATION_WEIGHT = 1e4
"""W in restoration QPs, against ½‖d‖²: exact (θ_lin = 0 when possible) for least-norm multipliers up to 1e4."""
_ACCEPTABLE_ITERATIONS = 15
_TRUSTED_MULTIPLIER = 1e6
"""A QP whose multipliers exceed this is treated like a failed one: its linearisation is nearly inconsistent."""


class SQP:
    """Line-search SQP with QP subproblems solved through ``qpsolvers``; see the module docstring for the method.

    Shared options: ``max_iterations`` (QP-based steps, restoration steps included), ``time_limit_s`` (checked
    once per iteration and passed on to the backends that take one; ``None`` for none), ``tolerance`` (on the
    constraint violation, max-norm, and on the stationarity/complementarity residual scaled as IPOPT does),
    ``print_level`` (≥ 1: one log line per iteration).

    Specific options, with defaults:

    - ``qp_solver="piqp"``: a name in ``qpsolvers.available_solvers``. PIQP (proximal interior point, sparse) is the
      default because it did best on the gait steps: with the exact Hessian and the ℓ1 merit it converged from
      both starts of both N = 20 steps and solved every standard problem, and it takes sparse matrices, so its cost
      grows with the problem's nonzeros rather than with n³. The convexified Hessians of the gait steps are
      ill-conditioned (curvature ~1e-5 along the torques next to augmentation terms ~1e4): DAQP and quadprog are
      exact and fastest while they cope (DAQP: 5 iterations, 0.03 s from near the DMOC optimum, against PIQP's
      31 and 0.25 s at the acceptable level) but cycle or report false infeasibility at N = 50, Clarabel failed one
      N = 20 start, OSQP stops at its iteration limit, ProxQP reports false infeasibility, and HiGHS fails on free
      variables and spends minutes on one gait QP.
    - ``fallback_qp_solver="clarabel"``: the backend that solves again, cold, a QP the first one failed
      (``"none"`` for none).
    - ``qp_tolerance=1e-10``: the backend's accuracy settings (``_TOLERANCE_KEYWORDS``; quadprog has none).
    - ``hessian="exact"``: or ``"bfgs"`` (damped BFGS).
    - ``merit="l1"``: or ``"filter"``.
    - ``second_order_correction=True``: try one second-order correction when the full step is rejected.
    - ``acceptable_tolerance=1e-6``: IPOPT's ``acceptable_tol``: a solve also converges when the violation and the
      KKT residual stay below it for 15 consecutive iterations, or when the iteration cannot continue (QP or line
      search failure) from such a point: interior-point backends are accurate to ~1e-10 relative, which on the
      gait steps (multipliers ~30 times constraint gradients ~7000) bounds the attainable stationarity near 1e-8.

    A bad option value raises ValueError at construction (the CLI reports it).
    """

    name = "sqp"

    def __init__(self, max_iterations: int = 500, time_limit_s: float | None = None, tolerance: float = 1e-8,
                 print_level: int = 0, qp_solver: str = "piqp", qp_tolerance: float = 1e-10,
                 hessian: str = "exact", merit: str = "l1", second_order_correction: bool = True,
                 acceptable_tolerance: float = 1e-6, fallback_qp_solver: str | None = "clarabel") -> None:
        if qp_solver not in qpsolvers.available_solvers:
            raise ValueError(f"unknown QP solver {qp_solver!r}; available: "
                             f"{', '.join(sorted(qpsolvers.available_solvers))}")
        fallback_qp_solver = None if fallback_qp_solver in (None, "none") else fallback_qp_solver
        if fallback_qp_solver is not None and fallback_qp_solver not in qpsolvers.available_solvers:
            raise ValueError(f"unknown fallback QP solver {fallback_qp_solver!r}; available: "
                             f"{', '.join(sorted(qpsolvers.available_solvers))}")
        if hessian not in _HESSIANS:
            raise ValueError(f"unknown hessian {hessian!r}; choose one of {', '.join(_HESSIANS)}")
        if merit not in _MERITS:
            raise ValueError(f"unknown merit {merit!r}; choose one of {', '.join(_MERITS)}")
        if max_iterations < 0 or min(tolerance, qp_tolerance, acceptable_tolerance) <= 0:
            raise ValueError("max_iterations must be ≥ 0, the tolerances > 0")
        self.max_iterations = int(max_iterations)
        self.time_limit_s = time_limit_s
        self.tolerance = float(tolerance)
        self.print_level = int(print_level)
        self.qp_solver = qp_solver
        self.fallback_qp_solver = fallback_qp_solver
        self.qp_tolerance = float(qp_tolerance)
        self.hessian = hessian
        self.merit = merit
        self.second_order_correction = bool(second_order_correction)
        self.acceptable_tolerance = max(float(acceptable_tolerance), self.tolerance)
        self._arguments = {"max_iterations": max_iterations, "time_limit_s": time_limit_s, "tolerance": tolerance,
                           "print_level": print_level, "qp_solver": qp_solver, "qp_tolerance": qp_tolerance,
                           "hessian": hessian, "merit": merit, "second_order_correction": second_order_correction,
                           "acceptable_tolerance": acceptable_tolerance, "fallback_qp_solver": fallback_qp_solver}

    def remedies(self) -> list[tuple[str, SQP]]:
        """Variants for the walk's retry ladder, each another path through the same NLP: the filter instead of the
        ℓ1 merit, and Clarabel's QPs instead of PIQP's. On forward walks they solve steps the default stops on
        (HS N = 20, step 2: the filter; DMOC N = 50, step 2: Clarabel; both at the iteration limit by default)."""
        variants = []
        if self.merit != "filter":
            variants.append(("filter", SQP(**{**self._arguments, "merit": "filter"})))
        if self.qp_solver != "clarabel":
            variants.append(("clarabel", SQP(**{**self._arguments, "qp_solver": "clarabel",
                                                "fallback_qp_solver": self.qp_solver})))
        return variants

    def solve(self, nlp: NLP, parameters: np.ndarray, initial_guess: np.ndarray) -> SolverResult:
        """Solve from ``initial_guess``; every failure, including exceptions, becomes a status."""
        deadline = Deadline(self.time_limit_s)
        x0 = np.asarray(initial_guess, dtype=float).ravel()
        run = None
        try:
            run = _Run(self, NLPEvaluator(nlp, parameters), x0, deadline)
            return run.solve()
        except Exception as error:  # the Solver protocol reports failures, it never raises them
            if run is None:
                return error_result(error, x0, deadline)
            return solver_result(SolverStatus.ERROR, f"SQP: {type(error).__name__}: {error}", run.x,
                                 run.evaluator, run.iteration, deadline, run.lam.copy())


@dataclass
class _QPOutcome:
    """One backend call: the step and duals when ``solved``, the backend's own status either way."""

    solved: bool
    status: str
    x: np.ndarray | None = None
    y: np.ndarray | None = None
    z: np.ndarray | None = None
    z_box: np.ndarray | None = None


@dataclass
class _Model:
    """The QP matrix P of one iteration and how it was made positive definite."""

    P: np.ndarray | sp.csc_matrix
    """Sparse for the exact Hessian, dense for BFGS."""
    curvature: np.ndarray | sp.csc_matrix
    """P without the augmentation: the curvature the ℓ1 weight update may rely on."""
    rows: np.ndarray
    """The rows of g in the augmentation (empty when there is none)."""
    weights: np.ndarray
    """ρ/‖∇g_i‖² for those rows, to correct their multipliers."""
    shift: float


@dataclass
class _Trial:
    """A point of the line search with its objective, constraints and ℓ1 violation θ of g."""

    x: np.ndarray
    f: float
    g: np.ndarray
    theta: float


class _Linearization:
    """The NLP's rows sorted once into QP equalities and the finite sides of the other rows."""

    def __init__(self, nlp: NLP) -> None:
        self.lbg, self.ubg, self.lbx, self.ubx = nlp.lbg, nlp.ubg, nlp.lbx, nlp.ubx
        equal = (nlp.lbg == nlp.ubg) & np.isfinite(nlp.lbg)
        self.equality = np.flatnonzero(equal)
        self.upper = np.flatnonzero(~equal & np.isfinite(nlp.ubg))
        self.lower = np.flatnonzero(~equal & np.isfinite(nlp.lbg))
        self.m = nlp.n_constraints
        self.upper_only = np.setdiff1d(self.upper, self.lower)
        self.lower_only = np.setdiff1d(self.lower, self.upper)
        eq, up, lo = self.equality, self.upper, self.lower
        self.select_equality = sp.csr_matrix((np.ones(eq.size), (np.arange(eq.size), eq)), shape=(eq.size, self.m))
        self.select_inequality = sp.csr_matrix((np.concatenate([np.ones(up.size), -np.ones(lo.size)]),
                                                (np.arange(up.size + lo.size), np.concatenate([up, lo]))),
                                               shape=(up.size + lo.size, self.m))
        """Row selections: the QP's A and G as products with the Jacobian, far cheaper than fancy indexing."""
        self.bounded = bool(np.isfinite(nlp.lbx).any() or np.isfinite(nlp.ubx).any())

    @property
    def unconstrained(self) -> bool:
        return not (self.bounded or self.equality.size or self.upper.size or self.lower.size)

    def violations(self, g: np.ndarray) -> np.ndarray:
        """How far each row is outside lbg ≤ g ≤ ubg."""
        return np.maximum(self.lbg - g, 0.0) + np.maximum(g - self.ubg, 0.0)

    def theta(self, g: np.ndarray) -> float:
        """ℓ1 violation of lbg ≤ g ≤ ubg."""
        return float(np.sum(self.violations(g)))

    def max_violation(self, g: np.ndarray) -> float:
        return float(max(np.max(self.lbg - g, initial=0.0), np.max(g - self.ubg, initial=0.0)))

    def problem(self, P, q: np.ndarray, jacobian: sp.csr_matrix, g: np.ndarray, lb: np.ndarray | None,
                ub: np.ndarray | None, dense: bool) -> qpsolvers.Problem:
        """min ½dᵀPd + qᵀd s.t. lbg ≤ g + jacobian·d ≤ ubg, lb ≤ d ≤ ub, in ``qpsolvers`` form."""
        eq, up, lo = self.equality, self.upper, self.lower
        A = (self.select_equality @ jacobian).tocsc() if eq.size else None
        b = self.lbg[eq] - g[eq] if eq.size else None
        G = (self.select_inequality @ jacobian).tocsc() if up.size + lo.size else None
        h = np.concatenate([self.ubg[up] - g[up], g[lo] - self.lbg[lo]]) if G is not None else None
        if dense:
            P = P.toarray() if sp.issparse(P) else P
            A = None if A is None else A.toarray()
            G = None if G is None else G.toarray()
        else:
            P = sp.csc_matrix(P)
        return qpsolvers.Problem(P, q, G, h, A, b, lb, ub)

    def bounds(self, x: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Bounds on the step d keeping lbx ≤ x + d ≤ ubx (None when no variable is bounded)."""
        if not self.bounded:
            return None, None
        return self.lbx - x, self.ubx - x

    def multipliers(self, outcome: _QPOutcome) -> np.ndarray:
        """λ_g from the QP duals: y for equalities, +z on upper sides, −z on lower sides."""
        lam = np.zeros(self.m)
        if self.equality.size:
            lam[self.equality] = outcome.y
        if self.upper.size or self.lower.size:
            lam[self.upper] += outcome.z[:self.upper.size]
            lam[self.lower] -= outcome.z[self.upper.size:]
        return lam


def _complementarity(multipliers: np.ndarray, values: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> float:
    """max_i |μ_i|·min(1, d_i), d_i the distance to the bound μ_i's sign says is active: zero iff signs and
    complementarity hold. Near a bound it is IPOPT's complementarity product; a multiplier with no bound to hold it
    (d_i = ∞) counts in full, as stationarity. The product, not min(|μ_i|, d_i): on the gait steps (gradients
    ~1e-5) the latter is ~1e-5 at IPOPT's own converged points, and would demand far more than IPOPT does."""
    distance = np.where(multipliers > 0, np.abs(upper - values), np.abs(values - lower))
    return float(np.max(np.abs(multipliers) * np.minimum(distance, 1.0), initial=0.0))


class _Run:
    """The state of one solve."""

    def __init__(self, options: SQP, evaluator: NLPEvaluator, x0: np.ndarray, deadline: Deadline) -> None:
        self.o = options
        self.evaluator = evaluator
        self.deadline = deadline
        nlp = evaluator.nlp
        if x0.size != nlp.n_variables:
            raise ValueError(f"the initial guess has {x0.size} values, the NLP {nlp.n_variables} variables")
        self.lin = _Linearization(nlp)
        self.n, self.m = nlp.n_variables, nlp.n_constraints
        self.dense = options.qp_solver not in qpsolvers.sparse_solvers
        self.iteration = 0
        self.qp_time = 0.0
        self.lam = np.zeros(self.m)
        self.weights = np.zeros(self.m)
        """The ℓ1 merit's weight per row of g."""
        self.filter: list[tuple[float, float]] = []
        self.shift = 0.0
        self.shift_growth = 0.5
        """Factor from the last shift to the first one tried next (``_l1_search``; the filter always halves)."""
        self.bfgs: np.ndarray | None = np.eye(self.n) if options.hessian == "bfgs" else None
        self.bfgs_scaled = False
        self.warm: _QPOutcome | None = None
        self.restoration: tuple[str, float] | None = None
        """(why restoration started, θ on entry) while restoring."""
        self.log = {"alpha": float("nan"), "regularization": 0.0, "qp_time": 0.0, "flags": ""}
        self.acceptable = 0
        """Consecutive iterates at the acceptable level, with their own multipliers or the QP's."""
        self.streak = 0
        """``acceptable`` before this iteration's test."""
        self.x: np.ndarray | None = None
        trial = self._trial(np.clip(x0, nlp.lbx, nlp.ubx))
        if trial is None:
            raise FloatingPointError("the objective or constraints are not finite at the initial point")
        self._accept(trial)
        self.lam = self._least_squares_multipliers()
        theta0 = max(1.0, trial.theta)
        self.theta_max, self.theta_min = 1e4 * theta0, 1e-4 * theta0

    # --- the outer loop -------------------------------------------------------------------------------------

    def solve(self) -> SolverResult:
        if self.o.print_level >= 1:
            print(f"SQP ({self.o.hessian} Hessian, {self.o.merit} merit, QP backend {self.o.qp_solver}): "
                  f"{self.n} variables, {self.m} constraints")
            print(f"{'iter':>5} {'objective':>15} {'violation':>9} {'kkt':>9} {'alpha':>9} {'penalty':>9} "
                  f"{'qp_ms':>8} {'reg':>8}")
        for self.iteration in itertools.count():
            violation, dual, scale = self._kkt()
            self._print(violation, dual)
            if violation <= self.o.tolerance and dual <= self.o.tolerance * scale and self.restoration is None:
                return self._result(SolverStatus.CONVERGED, f"KKT residual {dual:.1e}, violation {violation:.1e}")
            level = self.o.acceptable_tolerance
            if (self.restoration is None and dual <= self.o.tolerance * scale and violation <= level
                    and self._projection_step()):
                continue
            self.streak = self.acceptable
            self.acceptable = self.acceptable + 1 if violation <= level and dual <= level * scale else 0
            if self.acceptable >= _ACCEPTABLE_ITERATIONS:
                return self._result(SolverStatus.CONVERGED, f"acceptable level: KKT residual {dual:.1e}, violation "
                                                            f"{violation:.1e} for {self.acceptable} iterations")
            if self.iteration >= self.o.max_iterations:
                return self._result(SolverStatus.ITERATION_LIMIT,
                                    f"iteration limit {self.o.max_iterations} reached (KKT residual {dual:.1e}, "
                                    f"violation {violation:.1e})")
            if self.deadline.expired():
                return self._result(SolverStatus.TIME_LIMIT, f"time limit {self.o.time_limit_s} s reached")
            self.log = {"alpha": float("nan"), "regularization": 0.0, "qp_time": 0.0, "flags": ""}
            outcome = self._restoration_step() if self.restoration else self._optimality_step()
            if outcome is not None:
                return outcome
        raise AssertionError("unreachable")

    def _kkt(self, lam: np.ndarray | None = None) -> tuple[float, float, float]:
        """(max constraint violation, stationarity/complementarity residual, IPOPT's dual scaling s_d) at x, with
        the multipliers ``lam`` (the current ones by default)."""
        lin = self.lin
        lam = self.lam if lam is None else lam
        bound_multipliers = -(self.grad + self.jac.T @ lam)
        dual = max(_complementarity(bound_multipliers, self.x, lin.lbx, lin.ubx),
                   _complementarity(lam, self.g, lin.lbg, lin.ubg))
        total = np.sum(np.abs(lam)) + np.sum(np.abs(bound_multipliers))
        scale = max(100.0, total / max(1, self.n + self.m)) / 100.0
        return lin.max_violation(self.g), dual, scale

    def _failure(self, detail: str) -> SolverResult:
        """ERROR, or CONVERGED when the iteration cannot continue from a point at the acceptable level."""
        if self.acceptable > 0:
            return self._result(SolverStatus.CONVERGED, f"acceptable level, where {detail}")
        return self._result(SolverStatus.ERROR, detail)

    def _result(self, status: SolverStatus, detail: str) -> SolverResult:
        if status in (SolverStatus.ERROR, SolverStatus.INFEASIBLE) and self.deadline.expired():  # a QP cut short
            status, detail = SolverStatus.TIME_LIMIT, f"time limit {self.o.time_limit_s} s reached ({detail})"
        qps = self.evaluator.evaluations["qp"]
        message = f"SQP: {detail} ({self.o.qp_solver}: {qps} QPs in {self.qp_time:.3f} s)"
        if self.o.print_level >= 1:
            print(message)
        return solver_result(status, message, self.x, self.evaluator, self.iteration, self.deadline, self.lam.copy())

    def _print(self, violation: float, dual: float) -> None:
        if self.o.print_level < 1:
            return
        log = self.log
        penalty = f"{np.max(self.weights, initial=0.0):9.2e}" if self.o.merit == "l1" else f"{'-':>9}"
        alpha = f"{log['alpha']:9.2e}" if np.isfinite(log["alpha"]) else f"{'-':>9}"
        print(f"{self.iteration:5d} {self.f:15.8e} {violation:9.2e} {dual:9.2e} {alpha} {penalty} "
              f"{1e3 * log['qp_time']:8.2f} {log['regularization']:8.1e} {log['flags']}")

    # --- points -----------------------------------------------------------------------------------------------

    def _trial(self, x: np.ndarray) -> _Trial | None:
        """f and g at x, or None where they are not finite (the line search then backtracks)."""
        f = self.evaluator.objective(x)
        g = self.evaluator.constraints(x)
        if not (np.isfinite(f) and np.all(np.isfinite(g))):
            return None
        return _Trial(x, f, g, self.lin.theta(g))

    def _accept(self, trial: _Trial) -> None:
        """Move to ``trial``: derivatives there, and the BFGS update from the previous point with the current λ."""
        grad = self.evaluator.gradient(trial.x)
        jac = sp.csr_matrix(self.evaluator.jacobian(trial.x))
        if not (np.all(np.isfinite(grad)) and np.all(np.isfinite(jac.data))):
            raise FloatingPointError("the derivatives are not finite at an accepted point")
        if self.bfgs is not None and self.x is not None:
            self._update_bfgs(trial.x - self.x, grad + jac.T @ self.lam - self.grad - self.jac.T @ self.lam)
        self.x, self.f, self.g, self.theta, self.grad, self.jac = trial.x, trial.f, trial.g, trial.theta, grad, jac

    def _least_squares_multipliers(self) -> np.ndarray:
        """IPOPT's initial estimate: the equality multipliers minimising ‖∇f + J_Eᵀλ_E‖ (others zero), dropped when
        larger than 1e3. Without it a linear objective would give the first QP no curvature at all."""
        lam = np.zeros(self.m)
        equality = self.lin.equality
        if equality.size:
            estimate = -np.linalg.lstsq(self.jac[equality].toarray().T, self.grad, rcond=None)[0]
            if np.max(np.abs(estimate)) <= 1e3:
                lam[equality] = estimate
        return lam

    def _update_bfgs(self, s: np.ndarray, y: np.ndarray) -> None:
        """Powell's damped BFGS update: keeps the approximation positive definite whatever the curvature."""
        if not self.bfgs_scaled and y @ s > 0:
            self.bfgs = (y @ y) / (y @ s) * np.eye(self.n)
            self.bfgs_scaled = True
        B = self.bfgs
        Bs = B @ s
        sBs = s @ Bs
        if sBs <= 1e-16 * max(1.0, s @ s):
            return
        sy = s @ y
        theta = 1.0 if sy >= 0.2 * sBs else 0.8 * sBs / (sBs - sy)
        r = theta * y + (1 - theta) * Bs
        self.bfgs = B - np.outer(Bs, Bs) / sBs + np.outer(r, r) / (s @ r)

    # --- QP subproblems ----------------------------------------------------------------------------------------

    def _solve_qp(self, problem: qpsolvers.Problem, warm: _QPOutcome | None) -> _QPOutcome:
        """The QP by the chosen backend, and by the fallback backend (cold) when the first one fails."""
        outcome = self._backend_call(self.o.qp_solver, problem, warm)
        fallback = self.o.fallback_qp_solver
        if outcome.solved or fallback is None or fallback == self.o.qp_solver:
            return outcome
        if fallback not in qpsolvers.sparse_solvers and sp.issparse(problem.P):
            problem = qpsolvers.Problem(*(part.toarray() if sp.issparse(part) else part for part in problem.unpack()))
        second = self._backend_call(fallback, problem, None)
        if second.solved:
            self.log["flags"] += "f"
            return second
        return _QPOutcome(False, f"{outcome.status}; {fallback}: {second.status}")

    def _backend_call(self, solver: str, problem: qpsolvers.Problem, warm: _QPOutcome | None) -> _QPOutcome:
        """One backend call, counted in ``evaluations["qp"]`` and timed; backend warnings and exceptions are
        turned into an unsolved outcome with the backend's status."""
        options = dict(_BACKEND_OPTIONS.get(solver, {}))
        options.update({key: self.o.qp_tolerance for key in _TOLERANCE_KEYWORDS.get(solver, ())})
        if self.deadline.time_limit_s is not None and solver in _TIME_LIMITED:
            options["time_limit"] = max(self.deadline.time_limit_s - self.deadline.elapsed_s, 1e-3)
        initvals = None
        if warm is not None and solver in _PRIMAL_WARM_START:
            initvals = warm.x
        if warm is not None and solver in _DUAL_WARM_START:
            if warm.y is not None and warm.y.size:
                options["y"] = warm.y
            z = [part for part in (warm.z, warm.z_box) if part is not None and part.size]
            if z:
                options["z"] = np.concatenate(z)
        start = time.perf_counter()
        try:
            with warnings.catch_warnings(), quiet_stdout():
                warnings.simplefilter("ignore")
                solution = qpsolvers.solve_problem(problem, solver=solver, initvals=initvals, **options)
        except Exception as error:  # a backend that rejects the problem: reported like any failed QP
            return _QPOutcome(False, f"{type(error).__name__}: {error}")
        finally:
            elapsed = time.perf_counter() - start
            self.qp_time += elapsed
            self.log["qp_time"] += elapsed
            self.evaluator.evaluations["qp"] += 1
        status = _backend_status(solution)
        usable = solution.found or status in _INACCURATE
        if not usable or solution.x is None or not np.all(np.isfinite(solution.x)):
            return _QPOutcome(False, status)
        empty = np.zeros(0)
        return _QPOutcome(True, status, np.asarray(solution.x, dtype=float),
                          empty if solution.y is None else np.asarray(solution.y, dtype=float),
                          empty if solution.z is None else np.asarray(solution.z, dtype=float),
                          None if solution.z_box is None else np.asarray(solution.z_box, dtype=float))

    def _model(self) -> _Model:
        """This iteration's QP matrix; see the module docstring for the convexification."""
        if self.bfgs is not None:
            return _Model(self.bfgs, self.bfgs, np.zeros(0, dtype=int), np.zeros(0), 0.0)
        H = sp.csc_matrix(self.evaluator.hessian_lagrangian(self.x, 1.0, self.lam))
        if not np.all(np.isfinite(H.data)):
            raise FloatingPointError("the Hessian of the Lagrangian is not finite")
        scale = max(1.0, float(np.max(np.abs(H.data), initial=0.0)))
        floor = 1e-10 * scale
        damping = self.shift * self.shift_growth  # the Levenberg–Marquardt part (``_l1_search``)
        if self.shift_growth > 1:  # at most max|H|: beyond, a gradient step that only gets shorter
            damping = min(max(damping, 1e-8 * scale), scale)
        floor = max(floor, damping)
        self.shift = damping if damping > 1e-10 * scale else 0.0
        identity = sp.eye(self.n, format="csc")
        regularised = (H + floor * identity).tocsc()
        if _positive_definite(regularised):
            return _Model(regularised, regularised, np.zeros(0, dtype=int), np.zeros(0), floor)
        rows, bounds = self._working_set()
        normals = self.jac[rows]
        inverse_norms = 1.0 / np.maximum(np.asarray(normals.multiply(normals).sum(axis=1)).ravel(), 1e-300)
        at_bound = np.zeros(self.n)
        at_bound[bounds] = 1.0
        gram = (normals.T @ sp.diags(inverse_norms) @ normals + sp.diags(at_bound)).tocsc()
        for rho in (1.0, 1e1, 1e2, 1e3, 1e4):  # the least that works: a large ρ makes the QP ill-conditioned
            P = (regularised + rho * scale * gram).tocsc()
            if _positive_definite(P):
                return _Model(P, regularised, rows, rho * scale * inverse_norms, floor)
        augmentation = 1e2 * scale * gram
        shift = max(floor, 1e-8 * scale)
        while shift <= 1e10 * scale:
            curvature = (H + shift * identity).tocsc()
            P = (curvature + augmentation).tocsc()
            if _positive_definite(P):
                self.shift = shift
                return _Model(P, curvature, rows, 1e2 * scale * inverse_norms, shift)
            shift *= 4
        raise FloatingPointError("no shift up to 1e10·max|H| makes the Hessian of the Lagrangian positive definite")

    def _working_set(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows, bounds) to augment: the equalities, the inequality rows that are violated, within 1e-6 of a bound
        or carry a multiplier, and the variables within 1e-8 of a bound."""
        lin, g, x = self.lin, self.g, self.x
        significant = 1e-6 * max(1.0, float(np.max(np.abs(self.lam), initial=0.0)))  # interior-point duals never
        near = 1e-6 * (1.0 + np.abs(np.where(np.isfinite(lin.ubg), lin.ubg, 0.0)))  # vanish on inactive rows
        upper = lin.upper[(g[lin.upper] >= lin.ubg[lin.upper] - near[lin.upper])
                          | (self.lam[lin.upper] > significant)]
        near = 1e-6 * (1.0 + np.abs(np.where(np.isfinite(lin.lbg), lin.lbg, 0.0)))
        lower = lin.lower[(g[lin.lower] <= lin.lbg[lin.lower] + near[lin.lower])
                          | (self.lam[lin.lower] < -significant)]
        rows = np.unique(np.concatenate([lin.equality, upper, lower]))
        at_bound = (x - lin.lbx <= 1e-8 * (1.0 + np.abs(x))) | (lin.ubx - x <= 1e-8 * (1.0 + np.abs(x)))
        return rows, np.flatnonzero(at_bound)

    def _qp(self, model: _Model, g: np.ndarray, warm: _QPOutcome | None) -> _QPOutcome:
        """The SQP subproblem with the constraints' constant term ``g`` (g(x), or g(x+d) − J d for a correction)."""
        if self.lin.unconstrained:  # the Newton system itself: no backend needed
            P = model.P
            step = (scipy.sparse.linalg.spsolve(sp.csc_matrix(P), -self.grad) if sp.issparse(P)
                    else scipy.linalg.cho_solve(scipy.linalg.cho_factor(P), -self.grad))
            return _QPOutcome(True, "unconstrained", step, np.zeros(0), np.zeros(0), None)
        lb, ub = self.lin.bounds(self.x)
        return self._solve_qp(self.lin.problem(model.P, self.grad, self.jac, g, lb, ub, self.dense), warm)

    def _elastic_qp(self, P, q: np.ndarray, weight: float) -> _QPOutcome:
        """min ½dᵀPd + qᵀd + W·Σ(p + n) s.t. lbg ≤ g + J d − p + n ≤ ubg, bounds on x + d, p, n ≥ 0: always
        feasible, with multipliers bounded by W; the result's ``x`` is d alone."""
        n, m = self.n, self.m
        jacobian = sp.hstack([self.jac, -sp.eye(m), sp.eye(m)], format="csr")
        lb, ub = self.lin.bounds(self.x)
        lb = np.concatenate([np.full(n, -np.inf) if lb is None else lb, np.zeros(2 * m)])
        ub = np.concatenate([np.full(n, np.inf) if ub is None else ub, np.full(2 * m, np.inf)])
        q = np.concatenate([q, np.full(2 * m, weight)])
        P = sp.csc_matrix(P)
        elastic_curvature = 1e-6 * max(1.0, weight, float(np.max(P.diagonal())))  # strictly convex (quadprog)
        P = sp.block_diag([P, elastic_curvature * sp.eye(2 * m)], format="csc")
        outcome = self._solve_qp(self.lin.problem(P, q, jacobian, self.g, lb, ub, self.dense), None)
        if outcome.solved:
            outcome.x = outcome.x[:n]
            outcome.z_box = None if outcome.z_box is None else outcome.z_box[:n]
        return outcome

    # --- iterations --------------------------------------------------------------------------------------------

    def _optimality_step(self) -> SolverResult | None:
        model = self._model()
        self.log["regularization"] = model.shift
        if model.rows.size:
            self.log["flags"] += "a"
        outcome = self._qp(model, self.g, self.warm)
        lam = self._multipliers(outcome, model) if outcome.solved else None
        if lam is None or np.max(np.abs(lam), initial=0.0) > _TRUSTED_MULTIPLIER:
            reason = (f"the QP subproblem failed ({self.o.qp_solver}: {outcome.status})" if lam is None else
                      f"the QP multipliers exceed {_TRUSTED_MULTIPLIER:.0e} (a nearly inconsistent linearisation)")
            if self.o.merit == "filter":
                return self._start_restoration(reason)
            return self._elastic_step(model, reason)
        violation, dual, scale = self._kkt(lam)
        if violation <= self.o.tolerance and dual <= self.o.tolerance * scale:
            # x with the QP's fresh multipliers is a KKT point: on the flat gait costs the line search may find
            # nothing better than rounding at such a point, and the previous multipliers need not show it
            self.lam = lam
            return self._result(SolverStatus.CONVERGED, f"KKT residual {dual:.1e} with the last QP's multipliers, "
                                                        f"violation {violation:.1e}")
        level = self.o.acceptable_tolerance
        if self.acceptable == 0 and violation <= level and dual <= level * scale:
            # the iterate is acceptable with the QP's multipliers: a streak survives the inexact multipliers of one
            # step (DMOC N = 50, step 2: residuals 2e-8, 2e-8, 4e-5, in a cycle, for 400 iterations)
            self.acceptable = self.streak + 1
            if self.acceptable >= _ACCEPTABLE_ITERATIONS:
                self.lam = lam
                return self._result(SolverStatus.CONVERGED, f"acceptable level: KKT residual {dual:.1e} with the "
                                                            f"last QP's multipliers, violation {violation:.1e} for "
                                                            f"{self.acceptable} iterations")
        self.warm = outcome
        d = outcome.x
        if self.o.merit == "l1":
            self._update_weights(model, d, lam)
            accepted = self._l1_search(model, d)
        else:
            accepted = self._filter_search(model, d)
        if accepted is None:
            if self.o.merit == "filter" and self.theta > self.o.tolerance:
                return self._start_restoration("the filter line search found no acceptable step")
            return self._failure("the line search found no acceptable step")
        self._move(accepted, lam, model)
        return None

    def _elastic_step(self, model: _Model, reason: str) -> SolverResult | None:
        """The ℓ1 merit's answer to an unusable QP: the elastic QP's step, or INFEASIBLE when it cannot reduce θ.
        Its multipliers (up to W on relaxed rows) set the merit weights, not the next Hessian."""
        self.log["flags"] += "e"
        weight = max(1e2, 10 * float(np.max(np.abs(self.lam), initial=0.0)))
        outcome = self._elastic_qp(model.P, self.grad, weight)
        if not outcome.solved:  # the restoration's QP, with P = I, is far better conditioned
            return self._start_restoration(f"{reason}, and so did its elastic version ({outcome.status})")
        d = outcome.x
        # Only a clear violation can be a local infeasibility: below the acceptable level a degenerate QP's failure
        # to predict a decrease is rounding (forward HS N = 50, step 2: "infeasible" at θ = 2e-7)
        infeasible = self.lin.max_violation(self.g) > self.o.acceptable_tolerance
        if infeasible and self.theta - self.lin.theta(self.g + self.jac @ d) <= 1e-6 * self.theta:
            return self._infeasible(reason, "its elastic version predicts no decrease of the violation")
        self._update_weights(model, d, self._multipliers(outcome, model))
        accepted = self._l1_search(model, d)
        if accepted is None and infeasible:
            return self._infeasible(reason, "no step along its elastic version's direction reduces the merit")
        if accepted is None:
            return self._failure(f"{reason}, and no step along its elastic version's direction reduces the merit")
        # The multipliers restart from least squares, as after restoration: kept, the ones that made the QP fail
        # would shape every next Hessian (forward HS N = 50, step 2: 500 elastic steps at multipliers ~1e5)
        self._move(accepted, self.lam, model)
        self.lam = self._least_squares_multipliers()
        return None

    def _infeasible(self, reason: str, why: str) -> SolverResult:
        return self._result(SolverStatus.INFEASIBLE, f"{reason}; {why}: a local minimiser of the constraint "
                                                     f"violation {self.theta:.3g} (ℓ1)")

    def _update_weights(self, model: _Model, d: np.ndarray, lam: np.ndarray) -> None:
        """Powell's per-row update μ_i = max(|λ_i|, (μ_i + |λ_i|)/2), as in SLSQP: weights follow the multipliers
        of each row, so neither a badly scaled row nor a past spike dominates the merit for good. When that leaves
        the step without a descent of ½ max(dᵀHd, 0), every weight is raised by the same amount (as the
        Nocedal–Wright rule (18.36) raises a single penalty)."""
        self.weights = np.maximum(np.abs(lam), 0.5 * (self.weights + np.abs(lam)))
        decrease = self.lin.violations(self.g) - self.lin.violations(self.g + self.jac @ d)
        excess = self.grad @ d - self.weights @ decrease + 0.5 * max(d @ model.curvature @ d, 0.0)
        if excess > 0 and decrease.sum() > 0:
            self.weights = self.weights + 1.1 * excess / decrease.sum()

    def _move(self, accepted: tuple[_Trial, _QPOutcome | None], lam: np.ndarray, model: _Model) -> None:
        trial, correction = accepted
        if correction is not None:
            self.warm = correction
            lam = self._multipliers(correction, model)
        self.lam = lam
        self._accept(trial)

    def _multipliers(self, outcome: _QPOutcome, model: _Model) -> np.ndarray:
        """λ_g from the QP duals, with the augmented rows corrected (module docstring)."""
        if self.lin.unconstrained:
            return np.zeros(self.m)
        lam = self.lin.multipliers(outcome)
        if model.rows.size:  # only rows active in this QP: the others keep their (zero) QP multiplier
            lin, rows = self.lin, model.rows
            value = self.g[rows] + self.jac[rows] @ outcome.x
            tolerance = 1e-7 * (1.0 + np.abs(value))
            active = (np.abs(value - lin.ubg[rows]) <= tolerance) | (np.abs(value - lin.lbg[rows]) <= tolerance)
            lam[rows[active]] += model.weights[active] * (value - self.g[rows])[active]
            # A one-sided row the augmented QP holds active where H's own QP would not comes back with a multiplier
            # of the wrong sign (on the gait steps, clearance rows at 1e-2): it is not active for H, so zero.
            lam[lin.upper_only] = np.maximum(lam[lin.upper_only], 0.0)
            lam[lin.lower_only] = np.minimum(lam[lin.lower_only], 0.0)
        return lam

    def _correction(self, model: _Model, d: np.ndarray, trial: _Trial | None) -> tuple[_Trial, _QPOutcome] | None:
        """A second-order correction step from x, when the full step ``trial`` was rejected and did not reduce θ."""
        if not self.o.second_order_correction or trial is None or trial.theta < self.theta:
            return None
        outcome = self._qp(model, trial.g - self.jac @ d, self.warm)
        if not outcome.solved:
            return None
        corrected = self._trial(self._clip(self.x + outcome.x))
        return None if corrected is None else (corrected, outcome)

    def _clip(self, x: np.ndarray) -> np.ndarray:
        """Keep an inexact QP step inside the variable bounds, which the NLP functions may rely on."""
        return np.clip(x, self.lin.lbx, self.lin.ubx)

    def _l1_search(self, model: _Model, d: np.ndarray):
        """Armijo backtracking on φ = f + Σ μ_i·viol_i(g); returns (point, correction QP or None) or None."""
        def phi(point: _Trial | _Run) -> float:
            return point.f + self.weights @ self.lin.violations(point.g)

        merit = phi(self)
        derivative = self.grad @ d - self.weights @ (self.lin.violations(self.g)
                                                     - self.lin.violations(self.g + self.jac @ d))
        # rounding in φ itself: in f, and in each g_i (relative to its magnitude) times its weight
        slack = 10 * np.finfo(float).eps * (max(1.0, abs(self.f)) + self.weights @ (1.0 + np.abs(self.g)))
        # Levenberg–Marquardt control of the shift: the ratio of φ's actual to its model's decrease for the full
        # step says whether the shifted model was trusted too much (a ratio below ¼ doubles the next shift) or not
        predicted = -derivative - 0.5 * (d @ (model.curvature @ d))
        alpha = 1.0
        while alpha >= _MIN_STEP:
            trial = self._trial(self._clip(self.x + alpha * d))
            accepted = trial is not None and phi(trial) <= merit + _ARMIJO * alpha * derivative + slack
            if alpha == 1.0:  # a rejected full step was trusted too much, whatever the ratio at rounding level
                ratio = (merit - phi(trial)) / predicted if accepted and predicted > 100 * slack else float(accepted)
                self.shift_growth = 0.5 if ratio >= 0.75 else 1.0 if ratio >= 0.25 else 4.0
            if accepted:
                self.log["alpha"] = alpha
                return trial, None
            if alpha == 1.0:
                corrected = self._correction(model, d, trial)
                if corrected is not None:
                    point, outcome = corrected
                    if phi(point) <= merit + _ARMIJO * derivative + slack:
                        self.log["alpha"], self.log["flags"] = 1.0, self.log["flags"] + "s"
                        return point, outcome
            alpha /= 2
        return None

    def _acceptable_to_filter(self, trial: _Trial) -> bool:
        return trial.theta <= self.theta_max and all(trial.theta < theta or trial.f < f for theta, f in self.filter)

    def _filter_search(self, model: _Model, d: np.ndarray):
        """Wächter–Biegler filter backtracking; returns (point, correction QP or None) or None (restoration)."""
        gamma_theta, gamma_f, delta, s_theta, s_f = 1e-5, 1e-5, 1.0, 1.1, 2.3
        theta, f = self.theta, self.f
        slope = float(self.grad @ d)
        if slope < 0:
            alpha_min = min(gamma_theta, gamma_f * theta / -slope)
            if theta <= self.theta_min:
                alpha_min = min(alpha_min, delta * theta ** s_theta / (-slope) ** s_f)
        else:
            alpha_min = gamma_theta
        alpha_min = max(0.05 * alpha_min, _MIN_STEP)

        def verdict(trial: _Trial | None, alpha: float) -> bool:
            if trial is None or not self._acceptable_to_filter(trial):
                return False
            switching = slope < 0 and alpha * (-slope) ** s_f > delta * theta ** s_theta
            if theta <= self.theta_min and switching:
                return trial.f <= f + _ARMIJO * alpha * slope + 10 * np.finfo(float).eps * max(1.0, abs(f))
            if trial.theta <= (1 - gamma_theta) * theta or trial.f <= f - gamma_f * theta:
                self.filter.append(((1 - gamma_theta) * theta, f - gamma_f * theta))
                return True
            return False

        alpha = 1.0
        while alpha >= alpha_min:
            trial = self._trial(self._clip(self.x + alpha * d))
            if verdict(trial, alpha):
                self.log["alpha"] = alpha
                return trial, None
            if alpha == 1.0:
                corrected = self._correction(model, d, trial)
                if corrected is not None and verdict(corrected[0], 1.0):
                    self.log["alpha"], self.log["flags"] = 1.0, self.log["flags"] + "s"
                    return corrected
            alpha /= 2
        return None

    def _projection_step(self) -> bool:
        """At a stationary point that is only slightly infeasible, one Gauss–Newton step onto the constraints (the
        restoration's QP), taken whole when it reduces the violation, multipliers kept. Without it the iterates can
        slide along the flat valleys of the thesis cost, each full step leaving a violation ~1e-6 behind it (forward
        HS N = 50, step 5: iteration limit at KKT residual 9e-10, violation 1.3e-6)."""
        outcome = self._elastic_qp(sp.eye(self.n, format="csc"), np.zeros(self.n), _RESTORATION_WEIGHT)
        if not outcome.solved:
            return False
        trial = self._trial(self._clip(self.x + outcome.x))
        if trial is None or trial.theta >= 0.5 * self.theta:
            return False
        self.log = {"alpha": 1.0, "regularization": 0.0, "qp_time": 0.0, "flags": "p"}
        self._accept(trial)
        return True

    # --- feasibility restoration -------------------------------------------------------------------------------

    def _start_restoration(self, reason: str) -> SolverResult | None:
        if self.theta <= self.o.tolerance:
            return self._failure(f"{reason} at a feasible point")
        self.filter.append((self.theta, self.f))
        self.restoration = (reason, self.theta)
        return self._restoration_step()

    def _restoration_step(self) -> SolverResult | None:
        """One Gauss–Newton step on θ (the elastic QP with P = I and no objective, so the least-norm step that
        reduces the linearised violation most) and an Armijo backtracking on θ; INFEASIBLE when θ cannot decrease."""
        reason, theta_entry = self.restoration
        self.log["flags"] += "r"
        outcome = self._elastic_qp(sp.eye(self.n, format="csc"), np.zeros(self.n), _RESTORATION_WEIGHT)
        if not outcome.solved:
            return self._failure(f"{reason}, and so did the restoration's elastic QP "
                                 f"({self.o.qp_solver}: {outcome.status})")
        d = outcome.x
        theta_linear = self.lin.theta(self.g + self.jac @ d)
        if self.theta - theta_linear <= 1e-6 * self.theta:
            if self.lin.max_violation(self.g) <= self.o.acceptable_tolerance:  # rounding, as in _elastic_step
                return self._failure(f"{reason}, and the restoration QP predicts no decrease of the violation")
            return self._infeasible(reason, "the restoration QP predicts no decrease of the violation")
        alpha = 1.0
        while alpha >= _MIN_STEP:
            trial = self._trial(self._clip(self.x + alpha * d))
            if trial is not None and trial.theta <= self.theta - _ARMIJO * alpha * (self.theta - theta_linear):
                break
            alpha /= 2
        else:
            return self._infeasible(reason, "no step along the restoration direction reduces the violation")
        self.log["alpha"] = alpha
        self._accept(trial)
        self.warm = None
        done = trial.theta <= max(_RESTORATION_REDUCTION * theta_entry, self.o.tolerance)
        if done and self._acceptable_to_filter(trial):
            self.restoration = None
            self.lam = self._least_squares_multipliers()
        return None


def _positive_definite(matrix) -> bool:
    """Whether a symmetric matrix is positive definite: by Sylvester's law, iff its LDLᵀ factorisation without
    pivoting has a positive D. SuperLU gives that factorisation when told to pivot on the diagonal only
    (``diag_pivot_thresh=0``) in symmetric mode, U's diagonal being D; if it pivoted off the diagonal anyway the
    test says no. Sparse: 1 ms at HS N = 100 (n = 999) against 14–30 ms for a dense Cholesky. A dense matrix (the
    BFGS one) gets LAPACK's Cholesky."""
    if not sp.issparse(matrix):
        return scipy.linalg.lapack.dpotrf(matrix, lower=1, clean=0)[1] == 0
    try:
        factor = scipy.sparse.linalg.splu(sp.csc_matrix(matrix), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                                          options={"SymmetricMode": True})
    except RuntimeError:  # exactly singular
        return False
    return bool(np.array_equal(factor.perm_r, factor.perm_c) and np.all(factor.U.diagonal() > 0))


def _backend_status(solution: qpsolvers.Solution) -> str:
    """The backend's own status where ``qpsolvers`` keeps it (OSQP, ProxQP, PIQP, Clarabel), else found or not."""
    extras = solution.extras or {}
    status = extras.get("status", getattr(extras.get("info"), "status", None))
    if status is not None:
        return str(status)
    return "solved" if solution.found else "no solution found"


@hookimpl
def register_solvers():
    return [Registration("sqp", "line-search SQP (exact or BFGS Hessian, l1 merit or filter), QPs through "
                                "qpsolvers", SQP)]
