"""The ``sqp`` solver plugin's face: the solve under its options (:mod:`.options`), which reports every failure as a
status, and the variants it offers the walk's retry ladder."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from gaitbench.problem.nlp import NLP
from gaitbench.solve.evaluation import Deadline, NLPEvaluator, error_result, solver_result
from gaitbench.solver_result import SolverResult, SolverStatus
from gaitbench_plugins.solvers.sqp.hessian import CRAWL_SHIFT_FLOOR
from gaitbench_plugins.solvers.sqp.options import SQPOptions
from gaitbench_plugins.solvers.sqp.run import Run

LONG_BUDGET = 10_000
"""The iteration budget of the ``more-iterations`` last resort (:meth:`SQP.last_resorts`)."""


@dataclass(frozen=True, eq=False)
class SQP(SQPOptions):
    """Line-search SQP with QP subproblems solved through ``qpsolvers``; see the package docstring for the method.

    Shared options: ``max_iterations`` (QP-based steps, restoration steps included; 3000, IPOPT's default: forward
    HS N = 50, step 6 of an ``sqp`` walk takes 965, IPOPT 1,852 from the same start), ``time_limit_s`` (checked
    once per iteration and passed on to the backends that take one; ``None`` for none), ``tolerance`` (on the
    constraint violation, max-norm, and on the stationarity/complementarity residual scaled as IPOPT does),
    ``print_level`` (≥ 1: one log line per iteration; ≥ 2: below each, the constraint blocks holding the most
    violation, with their part of the ℓ1 merit, and the variable blocks the last step moved most).

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
    - ``crawl_shift_floor=1e-10``: the shift's floor relative to max|H| once the late-step crawl shows (the shift at
      its floor, 1e-10·max|H|, for 20 iterations); the ``crawl-floor`` last resort lowers it to 1e-12.

    A bad option value raises ValueError at construction (the CLI reports it).
    """

    name: ClassVar[str] = "sqp"

    def continuations(self) -> list[tuple[str, SQP]]:
        """After a solve that ran out of iterations, the same solver again from its last iterate, with the crawl
        floor (:data:`.hessian.CRAWL_SHIFT_FLOOR` once the crawl shows): on the gait steps such a solve is often
        still converging along the cost's valleys, and the lower floor lengthens its steps there; where the solve
        was not sliding, the floor never drops and the continuation is the same solve on
        (docs/decisions/0008-retry-ladder.md)."""
        if self.crawl_shift_floor <= CRAWL_SHIFT_FLOOR:
            return [("continue", self)]
        return [("continue-crawl-floor", replace(self, crawl_shift_floor=CRAWL_SHIFT_FLOOR))]

    def remedies(self) -> list[tuple[str, SQP]]:
        """Variants for the walk's retry ladder from any start: Clarabel's QPs instead of PIQP's. From the first
        attempt's guess it is the variant that solves most often (docs/decisions/0008-retry-ladder.md)."""
        if self.qp_solver == "clarabel":
            return []
        return [("clarabel", replace(self, qp_solver="clarabel", fallback_qp_solver=self.qp_solver))]

    def seed_remedies(self) -> list[tuple[str, SQP]]:
        """Variants for retries started from a trajectory (the First-Phase seed, a coarse grid's solution, a back-up
        window), never from the blended guess: the filter instead of the ℓ1 merit. From the blended guess the first
        QP step is huge and the filter goes into restoration at once and stays there; from a trajectory it solves
        steps the ℓ1 merit does not (docs/decisions/0008-retry-ladder.md)."""
        if self.merit == "filter":
            return []
        return [("filter", replace(self, merit="filter"))]

    def last_resorts(self) -> list[tuple[str, SQP]]:
        """After the walk's other rungs, the crawl's two remedies, cheaper first. ``crawl-floor``: the shift's floor
        lowered to :data:`.hessian.CRAWL_SHIFT_FLOOR` once the crawl shows, whose steps along the cost's valleys
        are then 100 times longer (docs/decisions/0003-sqp-late-step-crawl.md). ``more-iterations``:
        :data:`LONG_BUDGET` iterations, on which a slide itself converges. Last resorts because either moves where a
        solve ends on the valley, which the first attempt and the other rungs leave as it was."""
        resorts = []
        if self.crawl_shift_floor > CRAWL_SHIFT_FLOOR:
            resorts.append(("crawl-floor", replace(self, crawl_shift_floor=CRAWL_SHIFT_FLOOR)))
        if self.max_iterations < LONG_BUDGET:
            resorts.append(("more-iterations", replace(self, max_iterations=LONG_BUDGET)))
        return resorts

    def solve(self, nlp: NLP, parameters: np.ndarray, initial_guess: np.ndarray) -> SolverResult:
        """Solve from ``initial_guess``; every failure, including exceptions, becomes a status."""
        deadline = Deadline(self.time_limit_s)
        x0 = np.asarray(initial_guess, dtype=float).ravel()
        run = None
        try:
            run = Run(self, NLPEvaluator(nlp, parameters), x0, deadline)
            return run.solve()
        except Exception as error:  # the Solver protocol reports failures, it never raises them
            if run is None:
                return error_result(error, x0, deadline)
            return solver_result(SolverStatus.ERROR, f"SQP: {type(error).__name__}: {error}", run.x,
                                 run.evaluator, run.iteration, deadline, run.lam.copy())
