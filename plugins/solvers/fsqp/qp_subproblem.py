"""FSQP with the ``qp`` subproblem (the default): a QP over every linearised row for d0, the convexified exact Hessian,
Powell's weights on the equalities and an arc search that keeps the inequalities (FSQP class docstring)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import qpsolvers
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from gaitbench.solver_result import SolverStatus
from gaitbench_plugins.solvers.fsqp.form import NLPForm
from gaitbench_plugins.solvers.fsqp.hessian import SHIFT_RANGE, qp_hessian
from gaitbench_plugins.solvers.fsqp.linalg import row_norms
from gaitbench_plugins.solvers.fsqp.outcome import ROUNDING, Breakdown, Outcome
from gaitbench_plugins.solvers.fsqp.qp import bend, solve_qp

if TYPE_CHECKING:
    from gaitbench_plugins.solvers.fsqp.options import FSQPOptions
    from gaitbench_plugins.solvers.fsqp.progress import Progress

_ACTIVE = 1e-6
"""A row is held by a QP step when c_j + ∇c_jᵀd ≥ −this (scaled units), and a bound row is near when c_j ≥ −this:
the rows whose augmentation is constant on the QP's feasible set, and the working set's bounds."""


_ACCEPTABLE_TOLERANCE = 1e-6
_ACCEPTABLE_ITERATIONS = 15
"""IPOPT's acceptable level: a KKT error below ``_ACCEPTABLE_TOLERANCE`` for this many iterations in a row is
converged; on the flat valleys of the thesis cost the last digits of the tolerance cost hundreds of iterations."""


def minimize_qp(options: FSQPOptions, progress: Progress, form: NLPForm, x: np.ndarray,
                iteration: int) -> Outcome:
    """FSQP with the ``qp`` subproblem (see the class docstring), from x with every inequality row ≤ 0."""
    n, m, n_ineq = form.n, form.m, form.n_inequalities
    general, equal = np.arange(form.n_general), n_ineq + np.arange(form.n_equal_g)
    f, c = form.objective(x), form.constraints(x)
    if not (np.isfinite(f) and np.all(np.isfinite(c))):
        return Outcome(SolverStatus.ERROR, "NaN or infinite f or g at the starting point", x, iteration, None)
    weights, damping, d_norm, u, streak = np.zeros(equal.size), 0.0, np.nan, np.zeros(m), 0
    scored = None  # the multipliers the KKT error was last scored with, when the refined test gave it
    working = equal  # the rows whose normals may convexify H: the equalities and the last QP's active rows

    def merit(f_value: float, c_value: np.ndarray) -> float:
        """f + Σ_E w_j |c_j|: the ℓ1 exact penalty, Mayne–Polak's F_c with a weight per row."""
        return f_value + weights @ np.abs(c_value[equal])

    def outcome(status: SolverStatus, message: str) -> Outcome:
        return Outcome(status, message, x, iteration, u if scored is None else scored)

    def record(step: float, direction: str) -> None:
        progress.record("main", iteration, merit(f, c), d_norm, step, np.max(weights, initial=0.0), working.size,
                     form.max_violation(c), direction, x)

    try:
        while True:
            if limit := progress.limit_reached(iteration):
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
            passes = 0
            while passes < 2:  # once more, convexified over the rows the QP holds, if rows it left were in W
                hessian, augmentation, base = qp_hessian(form, x, multipliers, jacobian[working], damping)
                qp = qpsolvers.Problem(hessian, gradient, rows_g.tocsc() if general.size else None,
                                       -c[general] if general.size else None,
                                       rows_e.tocsc() if equal.size else None, -c[equal] if equal.size else None,
                                       lower, upper)
                try:
                    solution = solve_qp(qp, progress.qp_order)
                except Breakdown:
                    # A QP the backends cannot solve is ill-conditioned (augmentation/shift up to ~1e12 on the
                    # flat valleys): solve it again with H shifted 100× more, up to 1e-2·max|∇²L|.
                    size = max(1.0, float(np.max(np.abs(base.diagonal()), initial=0.0)))
                    if damping >= 1e-2 * size:
                        raise
                    damping = max(100 * damping, SHIFT_RANGE[0] * size)
                    continue
                d = np.clip(x + solution.x, form.lbx, form.ubx) - x  # the QP's bounds hold to its tolerance
                linear = c + jacobian @ d
                held = np.intersect1d(working, np.flatnonzero(linear >= -_ACTIVE))  # kept at their bound
                held = np.union1d(held, np.intersect1d(working, equal))
                loose = np.setdiff1d(working, held)
                if not (augmentation and loose.size):
                    break
                working, passes = held, passes + 1
            u = np.zeros(m)
            u[general] = solution.z if general.size else 0.0
            u[equal] = solution.y if equal.size else 0.0
            bound_multipliers = solution.z_box
            if augmentation:  # the multipliers of ∇²L rather than of the augmented H (rows held in the QP)
                rows_held = jacobian[held]
                u[held] += augmentation * (rows_held @ d) / row_norms(rows_held) ** 2
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
            normals = sp.diags(1 / row_norms(jacobian[loose])) @ jacobian[loose] if loose.size else None
            curvature = base @ d + (augmentation * (normals.T @ (normals @ d)) if normals is not None else 0.0)
            stationarity = np.max(np.abs(curvature), initial=0.0)
            # The QP's bound multipliers hold the bounds at x + d: one at a bound x is far from leaves ∇f + Jᵀu
            # unbalanced at x, which the QP's identity above does not show (a flat direction stepped to its bound).
            complementarity = max(np.max(np.abs(u[general]) * np.minimum(1.0, -c[general]), initial=0.0),
                                  _bound_complementarity(form, x, bound_multipliers))
            scale = max(1.0, (np.sum(np.abs(u)) + np.sum(np.abs(bound_multipliers))) / (100 * (m + n)))
            violation = max(np.max(c[general], initial=0.0), np.max(np.abs(c[equal]), initial=0.0))
            error, scored = max(stationarity / scale, complementarity / scale, violation), None
            if error > options.tolerance:  # the same test with least-squares multipliers at x (see _refined_error)
                refined, corrected = _refined_error(form, x, c, jacobian, linear, u, bound_multipliers, -curvature)
                if max(refined / scale, violation) < error:  # returned if it converges; the iteration keeps the QP's
                    error, scored = max(refined / scale, violation), corrected
            streak = streak + 1 if error <= _ACCEPTABLE_TOLERANCE else 0
            if options.print_level >= 2:
                print(f"      KKT {error:.2e}: stationarity {stationarity / scale:.2e}, complementarity "
                      f"{complementarity / scale:.2e}, violation {violation:.2e}; H: augmentation {augmentation:.2e}, "
                      f"shift {_shift(form, x, multipliers, base):.2e}, "
                      f"{loose.size} working rows left")
            if error <= options.tolerance or (d_norm <= options.tolerance and violation <= options.tolerance):
                record(np.nan, "-")
                return outcome(SolverStatus.CONVERGED, f"KKT error {error:.2e} ≤ {options.tolerance:g} after "
                               f"{iteration} iterations")
            if streak >= _ACCEPTABLE_ITERATIONS:
                record(np.nan, "-")
                return outcome(SolverStatus.CONVERGED, f"acceptable level: KKT error {error:.2e} for "
                               f"{streak} iterations")

            # Second-order correction against the Maratos effect (the equalities' curvature).
            correction = bend(form, x, d, qp, general, equal, d_norm, progress.qp_order)

            # Arc search on x + t d + t² d̃: inequality rows stay ≤ tolerance, Armijo on the ℓ1 merit.
            current = merit(f, c)
            slope = gradient @ d - weights @ np.abs(c[equal])
            step = 1.0
            while True:
                if progress.deadline.expired():
                    return outcome(*progress.out_of_time(" in the arc search"))
                trial = np.clip(x + step * d + step ** 2 * correction, form.lbx, form.ubx)
                c_trial = form.constraints(trial)
                if np.all(np.isfinite(c_trial)) and np.all(c_trial[:n_ineq] <= options.tolerance):
                    f_trial = form.objective(trial)
                    if merit(f_trial, c_trial) <= current + options.alpha * step * min(slope, 0.0):
                        break
                step *= options.beta
                if step * np.max(np.abs(d)) <= ROUNDING * (1 + np.max(np.abs(x))):
                    if error <= _ACCEPTABLE_TOLERANCE:
                        return outcome(SolverStatus.CONVERGED, f"acceptable level: KKT error {error:.2e}, no "
                                       "further progress")
                    raise Breakdown(f"arc search found no acceptable step at iteration {iteration} "
                                     f"(‖d‖ = {d_norm:.2e}, slope {slope:.2e}, KKT error {error:.2e})")
            record(step, "qp" if not correction.any() else "qp+soc")
            # Levenberg–Marquardt damping, as ``sqp``'s: set by the merit's actual against predicted decrease;
            # a cut step or a poor ratio says the model reaches too far.
            size = max(1.0, float(np.max(np.abs(base.diagonal()), initial=0.0)))
            predicted = -slope - 0.5 * d @ (base @ d)
            ratio = (current - merit(f_trial, c_trial)) / predicted if predicted > 0 else 1.0
            if step < 1 or ratio < 0.25:
                damping = min(max(4 * damping, SHIFT_RANGE[0] * size), size)
            elif ratio >= 0.75:
                damping /= 2
            x, f, c = trial, f_trial, c_trial
            bounds_near = np.arange(form.n_general, n_ineq)[c[form.n_general:n_ineq] >= -_ACTIVE]
            working = np.concatenate([general[u[general] > 0], bounds_near, equal])
            iteration += 1
    except Breakdown as breakdown:
        return outcome(SolverStatus.ERROR, str(breakdown))


def _shift(form: NLPForm, x: np.ndarray, multipliers: np.ndarray, base: sp.csc_matrix) -> float:
    """The shift δ of H = ∇²L + δI (+ augmentation), for the print-level-2 log (one more Hessian evaluation)."""
    clipped = multipliers.copy()
    clipped[: form.n_inequalities] = np.maximum(clipped[: form.n_inequalities], 0.0)
    return float(np.max((base - form.hessian(x, clipped)).diagonal(), initial=0.0))


def _bound_complementarity(form: NLPForm, x: np.ndarray, z: np.ndarray) -> float:
    """max |z_i|·min(1, distance from x to the bound z_i holds) over the free variables: zero when every bound the
    QP's multipliers hold is active at x (``qpsolvers``: z_i > 0 holds the upper bound, z_i < 0 the lower)."""
    distance = np.where(z > 0, form.ubx - x, x - form.lbx)
    return float(np.max(np.where(form.free, np.abs(z) * np.minimum(1.0, np.abs(distance)), 0.0), initial=0.0))


def _refined_error(form: NLPForm, x: np.ndarray, c: np.ndarray, jacobian: sp.csr_matrix, linear: np.ndarray,
                   u: np.ndarray, z: np.ndarray, residual: np.ndarray) -> tuple[float, np.ndarray]:
    """Stationarity, sign and complementarity error (unscaled by IPOPT's s_d) with the QP's multipliers corrected by
    least squares over the rows the step holds (the thesis's π of (11.8), on the QP's active set), and those
    corrected multipliers.

    The QP's multipliers belong to x + d: ∇f + Jᵀu + z = −Hd at x. On the thesis cost's flat valleys d stays ~0.03
    long while f moves by 1e-9, and ∇²L d (~1e-5) keeps that test from ever passing (forward step 2, DMOC, N = 50).
    Most of ∇²L d lies in the span of the active gradients, where other multipliers absorb it; what they cannot
    absorb, or absorb only with the wrong sign, is the KKT error at x. The QP's bound multipliers ``z`` are taken
    out of ``residual`` (∇f + Jᵀu + z): at x only the bounds active there may take up what remains."""
    general, equal = np.arange(form.n_general), np.arange(form.n_inequalities, form.m)
    residual = residual - z
    rows = np.concatenate([general[(linear[general] >= -_ACTIVE) | (u[general] > 0)], equal])
    lower = form.free & (x - form.lbx <= _ACTIVE)
    upper = form.free & (form.ubx - x <= _ACTIVE)
    interior = form.free & ~lower & ~upper
    active = jacobian[rows]
    inner = active[:, interior]
    normal = (inner @ inner.T).tocsc()
    normal += sp.eye(rows.size, format="csc") * 1e-12 * max(1.0, float(normal.diagonal().max(initial=0.0)))
    try:
        factor = spla.splu(normal)
    except RuntimeError:
        return np.inf, u
    correction = np.zeros(rows.size)
    for _ in range(3):  # iterative refinement of the normal equations
        remaining = residual - active.T @ correction
        correction += factor.solve(inner @ remaining[interior])
    remaining = residual - active.T @ correction
    multipliers = u[rows] - correction  # ∇f + Jᵀ(u − Δ) = the remaining residual
    is_general = rows < form.n_general
    bound = -remaining  # the bound multipliers that take up the rest on variables at a bound
    sign = max(np.max(-multipliers[is_general], initial=0.0), np.max(bound[lower & ~upper], initial=0.0),
               np.max(-bound[upper & ~lower], initial=0.0))
    complementarity = np.max(np.abs(multipliers[is_general]) * np.minimum(1.0, -c[rows[is_general]]), initial=0.0)
    corrected = u.copy()
    corrected[rows] = multipliers
    return max(float(np.max(np.abs(remaining[interior]), initial=0.0)), sign, complementarity), corrected
