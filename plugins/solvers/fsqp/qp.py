"""The QPs of the ``qp`` subproblem, through ``qpsolvers``: each backend in turn until one solves it, and the
second-order correction."""

from __future__ import annotations

import warnings

import numpy as np
import qpsolvers

from gaitbench.solve.qp import BACKEND_SETTINGS, INACCURATE_STATUSES, RetryOrder, backend_status
from gaitbench.solve.silence import quiet_stdout
from gaitbench_plugins.solvers.fsqp.form import NLPForm
from gaitbench_plugins.solvers.fsqp.outcome import Breakdown

_QP_SOLVERS = ("piqp", "clarabel")
"""Backends of the ``qp`` subproblem, in turn: PIQP, the fastest on the gait QPs (docs/decisions/0002-qp-backends.md),
then Clarabel, which solves the convexified QPs PIQP stops on. Each tries a QP with its own settings and its
``RETRY_SETTINGS`` before the next, in the solve's ``RetryOrder``: from the first QP on, unlike ``sqp``, which
swaps only once its crawl shows (docs/decisions/0002-qp-backends.md)."""


_QP_SETTINGS: dict[str, dict] = {
    "piqp": {"eps_abs": 1e-10, "eps_rel": 1e-10, "max_iter": 100},
    "clarabel": {"tol_gap_abs": 1e-10, "tol_gap_rel": 1e-10, "tol_feas": 1e-10},
}
"""Each backend's accuracy, ``sqp``'s default ``qp_tolerance`` (and its PIQP iteration limit): the convergence test
reads stationarity off the QP's own optimality conditions, so a QP solved only to the NLP's tolerance (the backends'
defaults, ~1e-8) leaves that much KKT error where there is none."""


def solve_qp(problem: qpsolvers.Problem, order: RetryOrder) -> qpsolvers.Solution:
    """The QP by each backend under each of its settings in ``order``'s turn, until one solves it (or returns a
    reduced-accuracy optimum)."""
    statuses = []
    for solver in _QP_SOLVERS:
        for turn, extra in enumerate(order.settings(solver)):
            label = f"{solver} retried" if extra else solver
            try:
                with warnings.catch_warnings(), quiet_stdout():
                    warnings.simplefilter("ignore")
                    solution = qpsolvers.solve_problem(problem, solver=solver, **{
                        **BACKEND_SETTINGS.get(solver, {}), **_QP_SETTINGS.get(solver, {}), **extra})
            except Exception as error:  # a backend that rejects the problem counts as a failed QP
                statuses.append(f"{label}: {type(error).__name__}")
                continue
            status = backend_status(solution)
            usable = solution.found or status in INACCURATE_STATUSES
            if usable and solution.x is not None and np.all(np.isfinite(solution.x)):
                if solution.z_box is None:
                    solution.z_box = np.zeros(problem.P.shape[0])
                if turn:
                    order.solved_second(solver, extra)
                return solution
            statuses.append(f"{label}: {status}")
    raise Breakdown(f"the QP subproblem failed ({'; '.join(statuses)})")


def bend(form: NLPForm, x: np.ndarray, d: np.ndarray, qp: qpsolvers.Problem, general: np.ndarray,
          equal: np.ndarray, d_norm: float, order: RetryOrder) -> np.ndarray:
    """The second-order correction d̃ = s − d, s the QP again with every row linearised at x + d
    (c(x + d) − ∇c d + ∇c s), so that the arc x + t d + t² d̃ is x + s at t = 1; zero when that QP fails or d̃
    is longer than d. (Holding the inequalities ‖d‖^τ inside, as the thesis's d̃ does, made this QP jump.)"""
    ahead = form.constraints(x + d)
    if not np.all(np.isfinite(ahead)):
        return np.zeros(form.n)
    h = None if qp.G is None else -(ahead[general] - qp.G @ d)
    b = None if qp.A is None else -(ahead[equal] - qp.A @ d)
    try:
        s = solve_qp(qpsolvers.Problem(qp.P, qp.q, qp.G, h, qp.A, b, qp.lb, qp.ub), order).x
    except Breakdown:
        return np.zeros(form.n)
    correction = np.clip(x + s, form.lbx, form.ubx) - x - d
    if np.linalg.norm(correction) > d_norm:
        return np.zeros(form.n)
    return correction
