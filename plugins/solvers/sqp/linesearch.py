"""The globalisations: Armijo backtracking on the ℓ1 merit with Powell's per-row weights, or the Wächter–Biegler filter,
each with one second-order correction (package docstring, "Globalisation")."""

from __future__ import annotations

import numpy as np

from gaitbench_plugins.solvers.sqp.backends import QPOutcome
from gaitbench_plugins.solvers.sqp.hessian import Model
from gaitbench_plugins.solvers.sqp.iterate import Trial
from gaitbench_plugins.solvers.sqp.subproblems import Subproblems

ARMIJO = 1e-4
MIN_STEP = 1e-10


class LineSearch(Subproblems):
    """The iterate and its QPs, with the searches along a QP step."""

    def _update_weights(self, model: Model, d: np.ndarray, lam: np.ndarray) -> None:
        """Powell's per-row update μ_i = max(|λ_i|, (μ_i + |λ_i|)/2), as in SLSQP: weights follow the multipliers
        of each row, so neither a badly scaled row nor a past spike dominates the merit for good. When that leaves
        the step without a descent of ½ max(dᵀHd, 0), every weight is raised by the same amount (as the
        Nocedal–Wright rule (18.36) raises a single penalty)."""
        self.weights = np.maximum(np.abs(lam), 0.5 * (self.weights + np.abs(lam)))
        decrease = self.lin.violations(self.g) - self.lin.violations(self.g + self.jac @ d)
        excess = self.grad @ d - self.weights @ decrease + 0.5 * max(d @ model.curvature @ d, 0.0)
        if excess > 0 and decrease.sum() > 0:
            self.weights = self.weights + 1.1 * excess / decrease.sum()

    def _move(self, accepted: tuple[Trial, QPOutcome | None], lam: np.ndarray, model: Model) -> None:
        trial, correction = accepted
        if correction is not None:
            self.warm = correction
            lam = self._multipliers(correction, model)
        self.lam = lam
        self._accept(self._reset_slacks(trial))

    def _reset_slacks(self, trial: Trial) -> Trial:
        """``trial`` with its slack pairs at their cheapest values (:mod:`.slacks`), once the crawl shows and when
        that does not raise the ℓ1 merit; ``trial`` itself otherwise."""
        if self.slack_pairs is None or self.o.merit != "l1" or not self._crawling():
            return trial
        reset = self._trial(self.slack_pairs.reset(trial.x, trial.g, self.lin))
        if reset is None or self._phi(reset) > self._phi(trial):
            return trial
        self.log["flags"] += "m"
        return reset

    def _phi(self, point: Trial | LineSearch) -> float:
        """The ℓ1 merit φ = f + Σ μ_i·viol_i(g) at ``point``, with the current weights."""
        return point.f + self.weights @ self.lin.violations(point.g)

    def _correction(self, model: Model, d: np.ndarray, trial: Trial | None) -> tuple[Trial, QPOutcome] | None:
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

    def _merit_slope(self, d: np.ndarray) -> float:
        """φ's directional derivative along d, with the violation's change taken from the linearisation."""
        return float(self.grad @ d - self.weights @ (self.lin.violations(self.g)
                                                     - self.lin.violations(self.g + self.jac @ d)))

    def _l1_search(self, model: Model, d: np.ndarray):
        """Armijo backtracking on φ = f + Σ μ_i·viol_i(g); returns (point, correction QP or None) or None."""
        phi = self._phi

        def count_stall(point: Trial) -> None:
            self.stalled = self.stalled + 1 if merit - phi(point) <= slack else 0

        merit = phi(self)
        derivative = self._merit_slope(d)
        # rounding in φ itself: in f, and in each g_i (relative to its magnitude) times its weight
        slack = 10 * np.finfo(float).eps * (max(1.0, abs(self.f)) + self.weights @ (1.0 + np.abs(self.g)))
        # Levenberg–Marquardt control of the shift: the ratio of φ's actual to its model's decrease for the full
        # step says whether the shifted model was trusted too much (a ratio below ¼ doubles the next shift) or not
        predicted = -derivative - 0.5 * (d @ (model.curvature @ d))
        alpha = 1.0
        while alpha >= MIN_STEP:
            trial = self._trial(self._clip(self.x + alpha * d))
            accepted = trial is not None and phi(trial) <= merit + ARMIJO * alpha * derivative + slack
            if alpha == 1.0:  # a rejected full step was trusted too much, whatever the ratio at rounding level
                ratio = (merit - phi(trial)) / predicted if accepted and predicted > 100 * slack else float(accepted)
                self.shift_growth = 0.5 if ratio >= 0.75 else 1.0 if ratio >= 0.25 else 4.0
            if accepted:
                self.log["alpha"] = alpha
                count_stall(trial)
                return trial, None
            if alpha == 1.0:
                corrected = self._correction(model, d, trial)
                if corrected is not None:
                    point, outcome = corrected
                    if phi(point) <= merit + ARMIJO * derivative + slack:
                        self.log["alpha"], self.log["flags"] = 1.0, self.log["flags"] + "s"
                        count_stall(point)
                        return point, outcome
            alpha /= 2
        return None

    def _acceptable_to_filter(self, trial: Trial) -> bool:
        return trial.theta <= self.theta_max and all(trial.theta < theta or trial.f < f for theta, f in self.filter)

    def _filter_search(self, model: Model, d: np.ndarray):
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
        alpha_min = max(0.05 * alpha_min, MIN_STEP)

        def verdict(trial: Trial | None, alpha: float) -> bool:
            if trial is None or not self._acceptable_to_filter(trial):
                return False
            switching = slope < 0 and alpha * (-slope) ** s_f > delta * theta ** s_theta
            if theta <= self.theta_min and switching:
                return trial.f <= f + ARMIJO * alpha * slope + 10 * np.finfo(float).eps * max(1.0, abs(f))
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
