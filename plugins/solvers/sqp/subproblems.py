"""The QP subproblems of an iteration: the SQP QP itself, its elastic version, and the multipliers read off them."""

from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg

from gaitbench_plugins.solvers.sqp.backends import QPOutcome
from gaitbench_plugins.solvers.sqp.hessian import (
    LINEAR_STEP,
    SHIFT_FLOOR,
    Model,
    convexify,
    hessian_multipliers,
    hessian_scale,
    release_linear_variables,
    working_set,
)
from gaitbench_plugins.solvers.sqp.iterate import Iterate

_FLOOR_ITERATIONS = 20
"""Consecutive iterations with the shift at its floor after which the linear variables are released: how the
late-step crawl shows (docs/decisions/0003-sqp-late-step-crawl.md)."""
_INSIDE_STEPS = 5
"""Consecutive QP steps that leave a row strictly inside its bounds after which nearness alone no longer puts it in
the convexification's working set (:func:`.hessian.working_set`). Measured on the solver benchmark's 18 ``sqp``
rows: after one step, 14 converged against 15 (the first steps' paths move with any change of their QPs); after
five, the same 15, in 10 % fewer iterations (docs/decisions/0003-sqp-late-step-crawl.md)."""


def _row_tolerance(value: np.ndarray) -> np.ndarray:
    """How close to a bound a QP's row value counts as on it."""
    return 1e-7 * (1.0 + np.abs(value))


class Subproblems(Iterate):
    """The iterate, with the QPs it poses."""

    def _model(self) -> Model:
        """This iteration's QP matrix; see the package docstring for the convexification."""
        if self.bfgs is not None:
            return Model(self.bfgs, self.bfgs, np.zeros(0, dtype=int), np.zeros(0), 0.0)
        lam = hessian_multipliers(self.lam, self.jac)  # H's multipliers, and so its convexification's working set
        if lam is not self.lam:
            self.log["flags"] += "c"
        H = sp.csc_matrix(self.evaluator.hessian_lagrangian(self.x, 1.0, lam))
        if not np.all(np.isfinite(H.data)):
            raise FloatingPointError("the Hessian of the Lagrangian is not finite")
        model, self.shift = convexify(H, self.shift, self.shift_growth, self.jac,
                                      lambda: working_set(self.lin, self.x, self.g, lam,
                                                          -(self.grad + self.jac.T @ lam),
                                                          self.inside >= _INSIDE_STEPS),
                                      self.o.crawl_shift_floor if self._crawling() else SHIFT_FLOOR)
        # at the floor by the usual one, so that the lower floor does not end the crawl it is for
        self.at_floor = self.at_floor + 1 if self.shift <= SHIFT_FLOOR * hessian_scale(H) else 0
        # only where the crawl shows (the first steps' paths are sensitive to any change of their QPs), and not for
        # the dense backends (quadprog, DAQP), which need P strictly definite
        if not self._crawling() or self.dense:
            return model
        return release_linear_variables(model, H)

    def _crawling(self) -> bool:
        """Whether the shift has sat at its floor for :data:`_FLOOR_ITERATIONS`: how the late-step crawl shows."""
        return self.at_floor >= _FLOOR_ITERATIONS

    def _qp(self, model: Model, g: np.ndarray, warm: QPOutcome | None) -> QPOutcome:
        """The SQP subproblem with the constraints' constant term ``g`` (g(x), or g(x+d) − J d for a correction)."""
        if self.lin.unconstrained:  # the Newton system itself: no backend needed
            P = model.P
            step = (scipy.sparse.linalg.spsolve(sp.csc_matrix(P), -self.grad) if sp.issparse(P)
                    else scipy.linalg.cho_solve(scipy.linalg.cho_factor(P), -self.grad))
            return QPOutcome(True, "unconstrained", step, np.zeros(0), np.zeros(0), None)
        lb, ub = self._step_bounds(model)
        # the rows' scale and the backends' swap once the crawl shows, as the release: the first steps' paths move
        # with any change of their QPs (forward step 2, HS N = 100, scaled from the first QP: stuck at iteration 16,
        # where it converged in 363; DMOC N = 50 with the swap from the first QP: an error at 134, where 385)
        crawling = self._crawling()
        scale = self.lin.row_scale(self.jac) if crawling else None
        self.backends.swap = crawling
        problem = self.lin.problem(model.P, self.grad, self.jac, g, lb, ub, self.dense, scale)
        outcome = self.backends.solve(problem, None if warm is None else self.lin.rescaled(warm, scale), self.log)
        outcome.scale = scale
        return outcome

    def _step_bounds(self, model: Model | None) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Bounds on d: lbx ≤ x + d ≤ ubx, and |d_i| ≤ LINEAR_STEP·(1 + |x_i|) on the variables ``model``
        released (:func:`.hessian.release_linear_variables`)."""
        lb, ub = self.lin.bounds(self.x)
        if model is None or model.linear is None:
            return lb, ub
        linear = model.linear
        lb = np.full(self.n, -np.inf) if lb is None else lb.copy()
        ub = np.full(self.n, np.inf) if ub is None else ub.copy()
        radius = LINEAR_STEP * (1.0 + np.abs(self.x[linear]))
        lb[linear] = np.maximum(lb[linear], -radius)
        ub[linear] = np.minimum(ub[linear], radius)
        return lb, ub

    def _elastic_qp(self, P, q: np.ndarray, weight: float, model: Model | None = None) -> QPOutcome:
        """min ½dᵀPd + qᵀd + W·Σ(p + n) s.t. lbg ≤ g + J d − p + n ≤ ubg, bounds on x + d, p, n ≥ 0: always
        feasible, with multipliers bounded by W; the result's ``x`` is d alone. With the iteration's ``model``, the
        bounds on the variables it released too."""
        n, m = self.n, self.m
        jacobian = sp.hstack([self.jac, -sp.eye(m), sp.eye(m)], format="csr")
        lb, ub = self._step_bounds(model)
        lb = np.concatenate([np.full(n, -np.inf) if lb is None else lb, np.zeros(2 * m)])
        ub = np.concatenate([np.full(n, np.inf) if ub is None else ub, np.full(2 * m, np.inf)])
        q = np.concatenate([q, np.full(2 * m, weight)])
        P = sp.csc_matrix(P)
        elastic_curvature = 1e-6 * max(1.0, weight, float(np.max(P.diagonal())))  # strictly convex (quadprog)
        P = sp.block_diag([P, elastic_curvature * sp.eye(2 * m)], format="csc")
        outcome = self.backends.solve(self.lin.problem(P, q, jacobian, self.g, lb, ub, self.dense), None, self.log)
        if outcome.solved:
            outcome.x = outcome.x[:n]
            outcome.z_box = None if outcome.z_box is None else outcome.z_box[:n]
        return outcome

    def _count_inside(self, d: np.ndarray) -> None:
        """Count, per row, the consecutive QP steps ``d`` that leave it strictly inside its bounds."""
        value = self.g + self.jac @ d
        tolerance = _row_tolerance(value)
        inside = (value > self.lin.lbg + tolerance) & (value < self.lin.ubg - tolerance)
        self.inside = np.where(inside, self.inside + 1, 0)

    def _multipliers(self, outcome: QPOutcome, model: Model) -> np.ndarray:
        """λ_g from the QP duals, with the augmented rows corrected (package docstring)."""
        if self.lin.unconstrained:
            return np.zeros(self.m)
        lam = self.lin.multipliers(outcome)
        if model.rows.size:  # only rows active in this QP: the others keep their (zero) QP multiplier
            lin, rows = self.lin, model.rows
            value = self.g[rows] + self.jac[rows] @ outcome.x
            tolerance = _row_tolerance(value)
            active = (np.abs(value - lin.ubg[rows]) <= tolerance) | (np.abs(value - lin.lbg[rows]) <= tolerance)
            lam[rows[active]] += model.weights[active] * (value - self.g[rows])[active]
            # A one-sided row the augmented QP holds active where H's own QP would not comes back with a multiplier
            # of the wrong sign (on the gait steps, clearance rows at 1e-2): it is not active for H, so zero.
            lam[lin.upper_only] = np.maximum(lam[lin.upper_only], 0.0)
            lam[lin.lower_only] = np.minimum(lam[lin.lower_only], 0.0)
        return lam
