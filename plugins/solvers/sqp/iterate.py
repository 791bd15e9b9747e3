"""The iterate of one solve and what is read off it: f, g and their derivatives, the multipliers, the KKT test, and the
result it becomes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import qpsolvers
import scipy.sparse as sp
import scipy.sparse.linalg

from gaitbench.solve.evaluation import Deadline, NLPEvaluator, solver_result
from gaitbench.solver_result import SolverResult, SolverStatus
from gaitbench_plugins.solvers.sqp.backends import QPBackends, QPOutcome
from gaitbench_plugins.solvers.sqp.hessian import damped_bfgs_update
from gaitbench_plugins.solvers.sqp.linearization import Linearization
from gaitbench_plugins.solvers.sqp.slacks import SlackPairs

if TYPE_CHECKING:
    from gaitbench_plugins.solvers.sqp.options import SQPOptions


@dataclass
class Trial:
    """A point of the line search with its objective, constraints and ℓ1 violation θ of g."""

    x: np.ndarray
    f: float
    g: np.ndarray
    theta: float


def _complementarity(multipliers: np.ndarray, values: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> float:
    """max_i |μ_i|·min(1, d_i), d_i the distance to the bound μ_i's sign says is active: zero iff signs and
    complementarity hold. Near a bound it is IPOPT's complementarity product; a multiplier with no bound to hold it
    (d_i = ∞) counts in full, as stationarity. The product, not min(|μ_i|, d_i): on the gait steps (gradients
    ~1e-5) the latter is ~1e-5 at IPOPT's own converged points, and would demand far more than IPOPT does."""
    distance = np.where(multipliers > 0, np.abs(upper - values), np.abs(values - lower))
    return float(np.max(np.abs(multipliers) * np.minimum(distance, 1.0), initial=0.0))


def least_squares_multipliers(jacobian: sp.csr_matrix, grad: np.ndarray) -> np.ndarray:
    """λ minimising ‖∇f + Jᵀλ‖, from the sparse augmented system [[I, Jᵀ], [J, 0]] (r, −λ) = (∇f, 0), r the
    residual: the dense least squares took 0.36 s at HS N = 100 (799 equalities), more than IPOPT's whole step 1.
    A rank-deficient J, whose null space the sparse solve does not avoid, gets the dense minimum-norm solution: it
    shows as a pivot at rounding level (gait steps, N = 20: smallest/largest pivot 1e-4 to 2e-8 at full rank, with
    cond(J) up to 3e9; 3e-27 or an exactly singular factor with a row repeated)."""
    rows, n = jacobian.shape
    system = sp.bmat([[sp.eye(n), jacobian.T], [jacobian, None]], format="csc")
    rhs = np.concatenate([grad, np.zeros(rows)])
    try:
        factor = scipy.sparse.linalg.splu(system)
    except RuntimeError:  # exactly singular
        factor = None
    if factor is not None:
        pivots = np.abs(factor.U.diagonal())
        solution = factor.solve(rhs)
        if np.min(pivots) > 1e-14 * np.max(pivots) and np.all(np.isfinite(solution)):
            return -solution[n:]
    return -np.linalg.lstsq(jacobian.toarray().T, grad, rcond=None)[0]


class Iterate:
    """The state of one solve: the point with its derivatives and multipliers, and what the later layers keep."""

    def __init__(self, options: SQPOptions, evaluator: NLPEvaluator, x0: np.ndarray, deadline: Deadline) -> None:
        self.o = options
        self.evaluator = evaluator
        self.deadline = deadline
        nlp = evaluator.nlp
        if x0.size != nlp.n_variables:
            raise ValueError(f"the initial guess has {x0.size} values, the NLP {nlp.n_variables} variables")
        self.lin = Linearization(nlp)
        self.n, self.m = nlp.n_variables, nlp.n_constraints
        self.dense = options.qp_solver not in qpsolvers.sparse_solvers
        self.backends = QPBackends(options.qp_solver, options.fallback_qp_solver, options.qp_tolerance, deadline,
                                   evaluator)
        self.iteration = 0
        self.lam = np.zeros(self.m)
        self.weights = np.zeros(self.m)
        """The ℓ1 merit's weight per row of g."""
        self.filter: list[tuple[float, float]] = []
        self.shift = 0.0
        self.shift_growth = 0.5
        """Factor from the last shift to the first one tried next (``LineSearch._l1_search``; the filter always
        halves)."""
        self.at_floor = 0
        """Consecutive iterations whose shift sat at its floor (``Subproblems._model``)."""
        self.bfgs: np.ndarray | None = np.eye(self.n) if options.hessian == "bfgs" else None
        self.bfgs_scaled = False
        self.warm: QPOutcome | None = None
        self.inside = np.zeros(self.m, dtype=int)
        """Per row of g, the consecutive QP steps that left it strictly inside its bounds
        (``Subproblems._count_inside``)."""
        self.restoration: tuple[str, float] | None = None
        """(why restoration started, θ on entry) while restoring."""
        self.log = {"alpha": float("nan"), "regularization": 0.0, "qp_time": 0.0, "flags": ""}
        self.stalled = 0
        """Consecutive accepted steps that changed φ by no more than its rounding slack."""
        self.acceptable = 0
        """Consecutive iterates at the acceptable level, with their own multipliers or the QP's."""
        self.streak = 0
        """``acceptable`` before this iteration's test."""
        self.x: np.ndarray | None = None
        self.step: np.ndarray | None = None
        """The last accepted step (None before the first)."""
        trial = self._trial(np.clip(x0, nlp.lbx, nlp.ubx))
        if trial is None:
            raise FloatingPointError("the objective or constraints are not finite at the initial point")
        self._accept(trial)
        self.lam = self._least_squares_multipliers()
        self.slack_pairs = SlackPairs.find(evaluator, self.lin, self.grad, self.jac)
        """The NLP's slack pairs, reset at accepted points once the crawl shows (``LineSearch._reset_slacks``)."""
        theta0 = max(1.0, trial.theta)
        self.theta_max, self.theta_min = 1e4 * theta0, 1e-4 * theta0

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
        message = f"SQP: {detail} ({self.o.qp_solver}: {qps} QPs in {self.backends.time:.3f} s)"
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
        if self.o.print_level >= 2:
            print(f"      {self._where()}")

    def _where(self) -> str:
        """Where the violation is and what the last step moved, by the NLP's named blocks: the two constraint blocks
        with the most ℓ1 violation (with their part of the ℓ1 merit, Σ μ_i·viol_i) and the two variable blocks the
        step moved most (‖d‖₂). This is how the late-step crawl was read: violation the merit does not weigh, on
        rows with tiny multipliers, and steps along variables without curvature
        (docs/decisions/0003-sqp-late-step-crawl.md)."""
        nlp = self.evaluator.nlp
        violations = self.lin.violations(self.g)
        rows = sorted(((float(np.sum(violations[block])), name, float(self.weights[block] @ violations[block]))
                       for name, block in nlp.constraint_blocks.items()), reverse=True)
        merit = self.o.merit == "l1"
        where = ", ".join(f"{name} {total:.1e}" + (f" (merit {weighted:.1e})" if merit else "")
                          for total, name, weighted in rows[:2] if total > 0) or "none"
        moved = "none"
        if self.step is not None:
            blocks = sorted(((float(np.linalg.norm(self.step[block])), name)
                             for name, block in nlp.variable_blocks.items()), reverse=True)
            moved = ", ".join(f"{name} {size:.1e}" for size, name in blocks[:2] if size > 0) or "none"
        return f"violation: {where}; step: {moved}"

    def _infeasible(self, reason: str, why: str) -> SolverResult:
        return self._result(SolverStatus.INFEASIBLE, f"{reason}; {why}: a local minimiser of the constraint "
                                                     f"violation {self.theta:.3g} (ℓ1)")

    def _trial(self, x: np.ndarray) -> Trial | None:
        """f and g at x, or None where they are not finite (the line search then backtracks)."""
        f = self.evaluator.objective(x)
        g = self.evaluator.constraints(x)
        if not (np.isfinite(f) and np.all(np.isfinite(g))):
            return None
        return Trial(x, f, g, self.lin.theta(g))

    def _accept(self, trial: Trial) -> None:
        """Move to ``trial``: derivatives there, and the BFGS update from the previous point with the current λ."""
        grad = self.evaluator.gradient(trial.x)
        jac = sp.csr_matrix(self.evaluator.jacobian(trial.x))
        if not (np.all(np.isfinite(grad)) and np.all(np.isfinite(jac.data))):
            raise FloatingPointError("the derivatives are not finite at an accepted point")
        self.step = None if self.x is None else trial.x - self.x
        if self.bfgs is not None and self.step is not None:
            self._update_bfgs(self.step, grad + jac.T @ self.lam - self.grad - self.jac.T @ self.lam)
        self.x, self.f, self.g, self.theta, self.grad, self.jac = trial.x, trial.f, trial.g, trial.theta, grad, jac

    def _least_squares_multipliers(self) -> np.ndarray:
        """IPOPT's initial estimate: the equality multipliers minimising ‖∇f + J_Eᵀλ_E‖ (others zero), dropped when
        larger than 1e3. Without it a linear objective would give the first QP no curvature at all."""
        lam = np.zeros(self.m)
        equality = self.lin.equality
        if equality.size:
            estimate = least_squares_multipliers(self.jac[equality], self.grad)
            if np.max(np.abs(estimate)) <= 1e3:
                lam[equality] = estimate
        return lam

    def _update_bfgs(self, s: np.ndarray, y: np.ndarray) -> None:
        """Powell's damped BFGS update: keeps the approximation positive definite whatever the curvature."""
        if not self.bfgs_scaled and y @ s > 0:
            self.bfgs = (y @ y) / (y @ s) * np.eye(self.n)
            self.bfgs_scaled = True
        self.bfgs = damped_bfgs_update(self.bfgs, s, y)
