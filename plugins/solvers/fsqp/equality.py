"""The thesis's Steps 1–5 (``subproblem="equality"``): every subproblem an equality-constrained QP, one sparse KKT
system; the deviations from the literal thesis are listed in the FSQP class docstring."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from gaitbench.solver_result import SolverStatus
from gaitbench_plugins.solvers.fsqp.form import NLPForm
from gaitbench_plugins.solvers.fsqp.hessian import BFGS, convexified_hessian
from gaitbench_plugins.solvers.fsqp.linalg import (
    Factorization,
    full_row_rank,
    kkt,
    least_squares_multipliers,
    row_norms,
)
from gaitbench_plugins.solvers.fsqp.outcome import ROUNDING, Breakdown, Outcome

if TYPE_CHECKING:
    from gaitbench_plugins.solvers.fsqp.options import FSQPOptions
    from gaitbench_plugins.solvers.fsqp.progress import Progress


def minimize(options: FSQPOptions, progress: Progress, form: NLPForm, x: np.ndarray,
             iteration: int) -> Outcome:
    """Steps 1–5 from a point x whose inequality rows are ≤ 0, counting iterations from ``iteration``."""
    n, m, n_ineq, equalities = form.n, form.m, form.n_inequalities, form.equalities
    f, c = form.objective(x), form.constraints(x)
    if not (np.isfinite(f) and np.all(np.isfinite(c))):
        return Outcome(SolverStatus.ERROR, "NaN or infinite f or g at the starting point", x, iteration, None)
    bfgs = BFGS(n, options.h0_scaling) if options.hessian == "bfgs" else None
    penalty, shift, d0_norm, u = options.rho, 0.0, np.inf, None
    blocking = np.zeros(0, dtype=int)
    x_old = lagrangian_gradient = None  # the last iterate and ∇f + Jᵀu there, for the BFGS update

    def merit(f_value: float, c_value: np.ndarray) -> float:
        """F_c = f − c Σ_E c_j, i.e. f + c Σ_E |c_j| on oriented rows: the ℓ1 exact penalty."""
        return f_value + penalty * np.sum(np.abs(c_value[equalities]))

    def outcome(status: SolverStatus, message: str) -> Outcome:
        return Outcome(status, message, x, iteration, u)

    def record(step: float, active: int, direction: str) -> None:
        progress.record("main", iteration, merit(f, c), d0_norm, step, penalty, active, form.max_violation(c),
                     direction, x)

    try:
        while True:
            if limit := progress.limit_reached(iteration):
                return outcome(*limit)
            gradient, jacobian = form.gradient(x), form.jacobian(x)
            if not (np.all(np.isfinite(gradient)) and np.all(np.isfinite(jacobian.data))):
                return outcome(SolverStatus.ERROR, f"NaN or infinite derivatives at iteration {iteration}")
            if bfgs is not None and x_old is not None:  # Step 5 of the last iteration, now that ∇ is known
                bfgs.update(x - x_old, gradient + jacobian.T @ u - lagrangian_gradient)

            # Step 2, first half: least-squares multipliers π (11.8), which Step 1 uses too.
            pi = least_squares_multipliers(jacobian, gradient, c, n_ineq)
            # Step 1 (11.7), with deviations 1 and 7.
            near = c.copy()
            inside = -c[:n_ineq]
            leaving = (np.abs(pi[:n_ineq]) < inside) | ((pi[:n_ineq] < 0) & (inside > options.tolerance))
            near[:n_ineq][leaving] = -np.inf
            active = active_set(options, jacobian, near, n_ineq, min(options.epsilon0, d0_norm), blocking)
            # Step 2: penalty update (11.9), then ∇F_c.
            largest = np.max(np.abs(pi[equalities]), initial=0.0)
            if penalty < largest + options.rho:
                penalty = max(largest + options.rho, penalty + options.epsilon)
            merit_gradient = gradient - penalty * np.asarray(jacobian[equalities].sum(axis=0)).ravel()
            rows, c_active, is_equality = jacobian[active], c[active], active >= n_ineq
            if bfgs is not None:
                hessian, augmentation = bfgs.matrix, 0.0
            else:
                hessian, augmentation, shift = convexified_hessian(form, x, pi, rows, shift)

            # Step 3.1: d0 (11.10); near-active rows with π_j < 0 are relaxed to ∇c_jᵀd = π_j.
            a = np.where(~is_equality & (pi[active] < 0), -pi[active], c_active)
            k0 = Factorization(kkt(hessian, rows))
            solution = k0.solve(-np.concatenate([merit_gradient, a]))
            d0, u_active = solution[:n], solution[n:]
            if augmentation:  # the multipliers of ∇²L rather than of the augmented H
                u_active = u_active - augmentation * a / row_norms(rows) ** 2
            u = np.zeros(m)
            u[active] = u_active
            u[equalities] -= penalty  # the original problem's multipliers: ũ_j − c on the equalities
            d0_norm = float(np.linalg.norm(d0))
            if d0_norm <= options.tolerance and np.max(np.abs(c[equalities]), initial=0.0) <= options.tolerance:
                record(np.nan, active.size, "-")
                return outcome(SolverStatus.CONVERGED, f"‖d0‖ = {d0_norm:.2e} ≤ {options.tolerance:g} after "
                               f"{iteration} iterations")

            # Step 3.2: d1 (11.12)-(11.13), else the d2/d3 combination (11.14)-(11.17); deviations 2-4.
            d1 = k0.solve(-np.concatenate([merit_gradient, a + margins(options, d0_norm, options.nu, c_active,
                                                                             is_equality)]))[:n]
            slope1 = merit_gradient @ d1
            if slope1 < 0 and slope1 <= -options.xi * _power(float(np.linalg.norm(d1)), options.delta):
                d, direction = d1, "d1"
            else:
                k1 = Factorization(kkt(hessian, rows, c_active))
                rhs = -np.concatenate([merit_gradient, np.zeros(active.size)])
                pi_tilde = k1.solve(rhs)[n:]
                rhs[n:] = np.minimum(pi_tilde, 0.0)  # −V, V_j = −π̃_j where π̃_j ≤ 0
                d3 = k1.solve(rhs)[:n]
                slope3 = merit_gradient @ d3
                if slope3 >= 0:
                    raise Breakdown(f"no feasible descent direction (∇F_cᵀd3 = {slope3:.2e} ≥ 0) at iteration "
                                     f"{iteration} although ‖d0‖ = {d0_norm:.2e}")
                weight = 1.0 if slope1 <= options.theta * slope3 else (1 - options.theta) * slope3 / (slope3 - slope1)
                d, direction = min(-slope3, 1.0) * ((1 - weight) * d3 + weight * d1), "d3"

            # Step 3.3: second-order correction d̃ (11.18), dropped if longer than d or not computable.
            d_norm = float(np.linalg.norm(d))
            correction = np.zeros(n)
            c_ahead = form.constraints(x + d)[active]
            if np.all(np.isfinite(c_ahead)):
                target = c_ahead + (a - c_active) + margins(options, d_norm, options.tau, c_active, is_equality)
                correction = k0.solve(-np.concatenate([merit_gradient + hessian @ d, target]))[:n]
                if np.linalg.norm(correction) > d_norm:
                    correction = np.zeros(n)

            # Step 4: arc search on x + t d + t² d̃ (11.19)-(11.20): inequality rows ≤ 0, Armijo on F_c.
            current, slope, step = merit(f, c), merit_gradient @ d, 1.0
            while True:
                if progress.deadline.expired():
                    return outcome(*progress.out_of_time(" in the arc search"))
                trial = x + step * d + step ** 2 * correction
                if form.admissible(trial):
                    c_trial = form.constraints(trial)
                    # NaN compares False, so a trial where g is undefined is rejected like an infeasible one.
                    if np.all(c_trial[:n_ineq] <= 0) and np.all(np.isfinite(c_trial)):
                        f_trial = form.objective(trial)
                        if merit(f_trial, c_trial) <= current + options.alpha * step * slope:
                            break
                rejected = trial
                step *= options.beta
                if step * np.max(np.abs(d)) <= ROUNDING * (1 + np.max(np.abs(x))):
                    raise Breakdown(f"arc search found no acceptable step at iteration {iteration} "
                                     f"(‖d0‖ = {d0_norm:.2e}, ∇F_cᵀd = {slope:.2e})")
            record(step, active.size, direction)
            if np.max(np.abs(trial - x)) <= ROUNDING * (1 + np.max(np.abs(x))):
                raise Breakdown(f"no progress at iteration {iteration}: the accepted step leaves x unchanged "
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
    except Breakdown as breakdown:
        return outcome(SolverStatus.ERROR, str(breakdown))


def margins(options: FSQPOptions, norm: float, power: float, c_active: np.ndarray,
            equality: np.ndarray) -> np.ndarray:
    """The interior margin ‖·‖^power of d1 and d̃ per active row (deviation 4)."""
    margin = _power(norm, power)
    return np.where(equality, np.minimum(margin, options.equality_margin * np.abs(c_active)), margin)


def active_set(options: FSQPOptions, jacobian: sp.csr_matrix, near: np.ndarray, n_ineq: int, epsilon: float,
                blocking: np.ndarray) -> np.ndarray:
    """Step 1: J = {j ∈ I: near_j ≥ −ε} ∪ blocking ∪ E, ε halved until the gradients are independent; the
    blocking rows are dropped again if even the smallest ε leaves J dependent."""
    equalities = np.arange(n_ineq, near.size)
    for forced in (blocking, blocking[:0]):
        eps = epsilon
        for _ in range(options.max_halvings + 1):
            active = np.concatenate([np.union1d(np.flatnonzero(near[:n_ineq] >= -eps), forced), equalities])
            if full_row_rank(jacobian[active], options.rank_tolerance):
                return active
            eps /= 2
        if not forced.size:
            break
    raise Breakdown(f"the gradients of the active constraints are linearly dependent (LICQ fails) after "
                     f"{options.max_halvings} halvings of ε")


def _power(norm: float, power: float) -> float:
    """‖·‖^p as the thesis uses it for ‖·‖ ≤ 1, linear beyond (deviation 4)."""
    return min(norm ** power, norm)

