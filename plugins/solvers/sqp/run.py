"""One solve's outer loop: the convergence tests, then an optimality step (the QP, or its elastic version when it
fails) or a restoration step (package docstring, "Convergence")."""

from __future__ import annotations

import itertools

import numpy as np

from gaitbench.solver_result import SolverResult, SolverStatus
from gaitbench_plugins.solvers.sqp.hessian import Model
from gaitbench_plugins.solvers.sqp.restoration import Restoration

_ACCEPTABLE_ITERATIONS = 15
"""Consecutive iterates at the acceptable level that end a solve as converged (IPOPT's acceptable_iter)."""
_STALLED_ITERATIONS = 15
"""Consecutive accepted steps within φ's rounding that end a solve as making no progress."""
_TRUSTED_MULTIPLIER = 1e6
"""A QP whose multipliers exceed this is treated like a failed one: its linearisation is nearly inconsistent."""


class Run(Restoration):
    """One solve, built from its layers: :class:`Restoration` on the line searches, on the subproblems, on the
    iterate."""

    def solve(self) -> SolverResult:
        """Iterate until a convergence test or a limit ends the solve, which every way out reports as a result."""
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
            # at iteration 0 the least-squares multipliers make x look stationary by construction
            if (self.restoration is None and self.iteration > 0 and dual <= self.o.tolerance * scale
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

    def _optimality_step(self) -> SolverResult | None:
        model = self._model()
        self.log["regularization"] = model.shift
        if model.rows.size:
            self.log["flags"] += "a"
        outcome = self._qp(model, self.g, self.warm)
        lam = self._multipliers(outcome, model) if outcome.solved else None
        # at the QP's own scale: a degenerate row's multiplier, which grows as 1/‖∇g_i‖, counts at its force
        force = lam if lam is None or outcome.scale is None else lam / outcome.scale
        if lam is None or np.max(np.abs(force), initial=0.0) > _TRUSTED_MULTIPLIER:
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
        self._count_inside(d)
        if self.o.merit == "l1":
            self._update_weights(model, d, lam)
            if self.acceptable > 0 and self._merit_slope(d) >= 0:
                # the weights make every exact QP step a descent direction of φ; one that is not comes from a QP
                # solved less accurately than the point is stationary, and backtracking along it only moves x by
                # rounding while the QP's noisy multipliers break the acceptable streak (forward DMOC N = 100, step
                # 1: 270 such iterations at f = 1.366059e-4)
                return self._failure("the QP step is no descent direction of the merit (the QP's accuracy is spent)")
            accepted = self._l1_search(model, d)
        else:
            accepted = self._filter_search(model, d)
        if accepted is None:
            if self.o.merit == "filter" and self.theta > self.o.tolerance:
                return self._start_restoration("the filter line search found no acceptable step")
            return self._failure("the line search found no acceptable step")
        self._move(accepted, lam, model)
        return self._stall()

    def _elastic_step(self, model: Model, reason: str) -> SolverResult | None:
        """The ℓ1 merit's answer to an unusable QP: the elastic QP's step, or the restoration when it cannot reduce θ.
        Its multipliers (up to W on relaxed rows) set the merit weights, not the next Hessian."""
        self.log["flags"] += "e"
        weight = max(1e2, 10 * float(np.max(np.abs(self.lam), initial=0.0)))
        outcome = self._elastic_qp(model.P, self.grad, weight, model)
        if not outcome.solved:  # the restoration's QP, with P = I, is far better conditioned
            return self._start_restoration(f"{reason}, and so did its elastic version ({outcome.status})")
        d = outcome.x
        # Only a clear violation can be a local infeasibility: below the acceptable level a degenerate QP's failure
        # to predict a decrease is rounding (forward HS N = 50, step 2: "infeasible" at θ = 2e-7)
        infeasible = self.lin.max_violation(self.g) > self.o.acceptable_tolerance
        # The elastic QP still weighs the objective (against W): that it predicts no decrease of the violation does
        # not show the violation cannot decrease; the restoration, on the violation alone, decides infeasibility
        if infeasible and self.theta - self.lin.theta(self.g + self.jac @ d) <= 1e-6 * self.theta:
            return self._start_restoration(f"{reason}, and its elastic version predicts no decrease of the violation")
        self._update_weights(model, d, self._multipliers(outcome, model))
        accepted = self._l1_search(model, d)
        if accepted is None and infeasible:
            return self._start_restoration(f"{reason}, and no step along its elastic version's direction reduces "
                                           "the merit")
        if accepted is None:
            return self._failure(f"{reason}, and no step along its elastic version's direction reduces the merit")
        # The multipliers restart from least squares, as after restoration: kept, the ones that made the QP fail
        # would shape every next Hessian (forward HS N = 50, step 2: 500 elastic steps at multipliers ~1e5)
        self._move(accepted, self.lam, model)
        self.lam = self._least_squares_multipliers()
        return self._stall()

    def _stall(self) -> SolverResult | None:
        """The end of a solve whose accepted steps, optimality or elastic, have not lowered φ beyond its rounding for
        :data:`_STALLED_ITERATIONS` iterations. Elastic steps count too: at a point where every QP fails, they go on
        at α ~ 1e-8 to the iteration limit (upward slope, HS N = 100, step 11 on Clarabel's QPs: from iteration 250
        at f = 1.0988, violation 1e-8, one second a step)."""
        if self.stalled >= _STALLED_ITERATIONS:
            return self._failure(f"φ has not fallen beyond rounding for {self.stalled} iterations")
        return None
