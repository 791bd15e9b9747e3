"""Phase 1: from a start pushed inside its bounds to a point where every inequality row holds (and, for the ``qp``
subproblem, the equalities nearly so), by damped Gauss–Newton steps (see the FSQP class docstring, "Starting
point")."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import qpsolvers
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from gaitbench.solve.qp import RetryOrder
from gaitbench.solver_result import SolverStatus
from gaitbench_plugins.solvers.fsqp.form import NLPForm
from gaitbench_plugins.solvers.fsqp.outcome import Breakdown, Outcome
from gaitbench_plugins.solvers.fsqp.qp import solve_qp

if TYPE_CHECKING:
    from gaitbench_plugins.solvers.fsqp.progress import Progress

_PUSH = 1e-8
"""The start is pushed this far (relative) inside its bounds: a start exactly on several bounds at once (HS071's
x0 is on four) has dependent active gradients, which ε-halving can only remove from rows strictly inside."""

_FEASIBILITY_MARGIN = 1e-8
"""Phase 1 aims every violated or nearly violated inequality row this far inside (scaled units). It is tiny on
purpose: on a DMOC gait step, a margin of 1e-4 moved the positions enough to raise the dynamics residual to 26."""

_EQUALITY_START = 1e-6
"""Phase 1 of the ``qp`` subproblem ends when the equality rows are within this of 0 (scaled units)."""

_ELASTIC_WEIGHT = 1e6
"""ρ of :func:`elastic_projection`: the weight of the linearised rows' residual against ½‖d‖² (scaled units), a
Levenberg–Marquardt damping of 1/ρ. Much larger, it gives back the inconsistent projection's huge step, which the
line search then cuts to almost nothing; at 1e6 the steps are moderate and taken nearly whole
(docs/decisions/0007-fsqp-qp-subproblem.md)."""


def push_inside(x: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """x projected onto the bounds and pushed inside by min(p max(1, |bound|), p (upper − lower)), p = ``_PUSH``."""
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    with np.errstate(invalid="ignore"):  # inf − inf on infinite bounds, discarded by np.where
        room = np.where(np.isfinite(upper - lower), _PUSH * (upper - lower), np.inf)
        low = np.where(np.isfinite(lower), lower + np.minimum(_PUSH * np.maximum(1.0, np.abs(lower)), room), lower)
        high = np.where(np.isfinite(upper), upper - np.minimum(_PUSH * np.maximum(1.0, np.abs(upper)), room), upper)
    return np.clip(np.clip(x, low, high), lower, upper)


def feasibility(progress: Progress, form: NLPForm, x: np.ndarray, with_equalities: bool) -> Outcome:
    """Phase 1: damped Gauss–Newton on ½‖max(c_I, 0)‖² until every inequality row holds (see the FSQP class); with
    the ``qp`` subproblem on ½‖max(c_I, 0)‖² + ½‖c_E‖², until the equalities are within ``_EQUALITY_START``
    too, so that the first QP's linearisation is consistent (``with_equalities``)."""
    n_ineq = form.n_inequalities

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
        if limit := progress.limit_reached(iteration):
            return Outcome(*limit, x, iteration, None)
        violation = violation_of(c_all)
        rows = np.flatnonzero(c > -_FEASIBILITY_MARGIN)
        target = c[rows] + _FEASIBILITY_MARGIN
        residual = np.maximum(c[rows], 0.0)
        if with_equalities:
            rows = np.concatenate([rows, np.arange(n_ineq, form.m)])
            target = np.concatenate([target, c_all[n_ineq:]])
            residual = np.concatenate([residual, c_all[n_ineq:]])
        full_jacobian = form.jacobian(x)
        jacobian = full_jacobian[rows]
        if not np.all(np.isfinite(jacobian.data)):
            return Outcome(SolverStatus.ERROR, f"NaN or infinite derivatives at iteration {iteration}", x,
                            iteration, None)
        stalled = None
        if np.linalg.norm(jacobian.T @ residual) <= 1e-10 * max(1.0, np.sqrt(2 * violation)):
            stalled = "the violation is stationary"
        else:
            direction = None
            if with_equalities:
                linearised = _LinearisedRows.at(form, x, c_all, full_jacobian)
                direction = projection(form, linearised, progress.qp_order)
                if direction is None:
                    direction = elastic_projection(form, linearised, progress.qp_order)
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
            return infeasible(form, x, c, iteration, stalled)
        progress.record("feasibility", iteration, violation, float(np.linalg.norm(direction)), step, np.nan,
                     rows.size, form.max_violation(c_all), "gn", x)
        x, c_all = trial, c_trial
        iteration += 1
    if not np.all(np.isfinite(c_all)):
        return Outcome(SolverStatus.ERROR, "NaN or infinite g at the starting point", x, iteration, None)
    return Outcome(SolverStatus.CONVERGED, "feasible", x, iteration, None)


@dataclass(frozen=True)
class _LinearisedRows:
    """Phase 1's rows linearised at x, as both of its step QPs take them: the general rows J_G d ≤ h (each aimed
    ``_FEASIBILITY_MARGIN`` inside), the equalities J_E d = b, and the step's bounds (0 on fixed variables)."""

    general: sp.csc_matrix
    h: np.ndarray
    equal: sp.csc_matrix
    b: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def at(cls, form: NLPForm, x: np.ndarray, c_all: np.ndarray, jacobian: sp.csr_matrix) -> _LinearisedRows:
        general, equal = np.arange(form.n_general), form.n_inequalities + np.arange(form.n_equal_g)
        return cls(jacobian[general].tocsc(), -c_all[general] - _FEASIBILITY_MARGIN, jacobian[equal].tocsc(),
                   -c_all[equal], np.where(form.free, form.lbx - x, 0.0), np.where(form.free, form.ubx - x, 0.0))


def projection(form: NLPForm, rows: _LinearisedRows, order: RetryOrder) -> np.ndarray | None:
    """The least-norm step onto every linearised row within the bounds (a QP: Newton's method for the
    feasibility problem, where the clipped Gauss–Newton step crept along the bounds for hundreds of iterations
    on HS, N = 20); None when the linearisation is inconsistent within the bounds."""
    general, equal = rows.h.size > 0, rows.b.size > 0
    try:
        solution = solve_qp(qpsolvers.Problem(
            sp.eye(form.n, format="csc"), np.zeros(form.n),
            rows.general if general else None, rows.h if general else None,
            rows.equal if equal else None, rows.b if equal else None, rows.lower, rows.upper), order)
    except Breakdown:
        return None
    return solution.x


def elastic_projection(form: NLPForm, rows: _LinearisedRows, order: RetryOrder) -> np.ndarray | None:
    """Where :func:`projection` is inconsistent: the step that minimises ½‖d‖² + ½ρ(‖e‖² + ‖v‖²) with the
    equality rows' residual e (c_E + J_E d = e) and the general rows' excess v ≥ 0 (c_G + J_G d ≤ v − margin),
    within the bounds: a Levenberg–Marquardt step on phase 1's violation that the bounds hold, always feasible
    (d = 0 is). None when the QP fails all the same."""
    n, n_e, n_g = form.n, rows.b.size, rows.h.size
    P = sp.diags(np.concatenate([np.ones(n), np.full(n_e + n_g, _ELASTIC_WEIGHT)]), format="csc")
    A = sp.hstack([rows.equal, -sp.eye(n_e), sp.csr_matrix((n_e, n_g))], format="csc")
    G = sp.hstack([rows.general, sp.csr_matrix((n_g, n_e)), -sp.eye(n_g)], format="csc")
    lower = np.concatenate([rows.lower, np.full(n_e, -np.inf), np.zeros(n_g)])
    upper = np.concatenate([rows.upper, np.full(n_e + n_g, np.inf)])
    try:
        solution = solve_qp(qpsolvers.Problem(P, np.zeros(n + n_e + n_g), G, rows.h, A, rows.b, lower, upper),
                            order)
    except Breakdown:
        return None
    return solution.x[:n]


def infeasible(form: NLPForm, x: np.ndarray, c: np.ndarray, iteration: int, reason: str) -> Outcome:
    worst = float(np.max(np.maximum(c, 0.0) / form.row_factor[: form.n_inequalities]))
    return Outcome(SolverStatus.INFEASIBLE, f"no point satisfies the inequalities: {reason} at a largest "
                    f"violation of {worst:.3g} (iteration {iteration})", x, iteration, None)
