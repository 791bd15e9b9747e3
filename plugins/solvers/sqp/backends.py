"""The QP backends of one solve: the chosen one, the fallback that solves again what it fails, and what each is
given (accuracy, time left, warm starts; see the package docstring, "QP failures" and "Warm starts")."""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import numpy as np
import qpsolvers
import scipy.sparse as sp

from gaitbench.solve.evaluation import Deadline, NLPEvaluator
from gaitbench.solve.qp import BACKEND_SETTINGS, INACCURATE_STATUSES, RetryOrder, backend_status
from gaitbench.solve.silence import quiet_stdout

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

_BACKEND_OPTIONS: dict[str, dict] = {"osqp": {"polishing": True, "max_iter": 20000}, "piqp": {"max_iter": 100}}
"""Fixed extra options, besides the settings every gait QP gets (``BACKEND_SETTINGS``). OSQP's ADMM alone reaches
tight tolerances slowly; its polishing step solves the identified active set's equality QP exactly. PIQP solves the
gait QPs it solves at all in at most 95 iterations; on the others it ends at its limit whatever the limit, so 100
iterations instead of 250 bound what such a failure costs before the fallback solves the QP
(docs/decisions/0002-qp-backends.md)."""

_TIME_LIMITED = frozenset({"clarabel", "daqp", "highs", "osqp"})
"""Backends with a ``time_limit`` option (seconds): they get the time left, so one slow QP cannot overrun the
solve's limit (PIQP, ProxQP and quadprog have none, and are only stopped between iterations)."""

_PRIMAL_WARM_START = frozenset({"osqp", "proxqp", "daqp"})
"""Backends whose ``qpsolvers`` interface passes ``initvals`` on to the solver."""

_DUAL_WARM_START = frozenset({"proxqp"})
"""Backends that also take dual start values through ``qpsolvers`` (ProxQP's ``y`` and ``z``)."""


@dataclass
class QPOutcome:
    """One backend call: the step and duals when ``solved``, the backend's own status either way."""

    solved: bool
    status: str
    x: np.ndarray | None = None
    y: np.ndarray | None = None
    z: np.ndarray | None = None
    z_box: np.ndarray | None = None
    scale: np.ndarray | None = None
    """The rows' scale of the QP it solved (:meth:`.linearization.Linearization.row_scale`), None for none."""


class QPBackends:
    """Calls the backends, counting every call in the evaluator's ``evaluations["qp"]`` and its time in ``time``."""

    def __init__(self, solver: str, fallback: str | None, tolerance: float, deadline: Deadline,
                 evaluator: NLPEvaluator) -> None:
        self.solver = solver
        self.fallback = fallback
        self.tolerance = tolerance
        self.deadline = deadline
        self.evaluator = evaluator
        self.time = 0.0
        """Seconds spent in backend calls so far."""
        self.order = RetryOrder()
        """Which settings each backend tries first (``_call_with_retry``)."""
        self.swap = False
        """Whether ``order`` may put a backend's ``RETRY_SETTINGS`` first."""

    def solve(self, problem: qpsolvers.Problem, warm: QPOutcome | None, log: dict) -> QPOutcome:
        """The QP by the chosen backend, and by the fallback backend (cold) when the first one fails (flag "f" in the
        iteration's ``log``, which also gets the time); each tries a QP it failed once more under its
        ``RETRY_SETTINGS`` (flag "u")."""
        outcome = self._call_with_retry(self.solver, problem, warm, log)
        fallback = self.fallback
        if outcome.solved or fallback is None or fallback == self.solver:
            return outcome
        if fallback not in qpsolvers.sparse_solvers and sp.issparse(problem.P):
            problem = qpsolvers.Problem(*(part.toarray() if sp.issparse(part) else part for part in problem.unpack()))
        second = self._call_with_retry(fallback, problem, None, log)
        if second.solved:
            log["flags"] += "f"
            return second
        return QPOutcome(False, f"{outcome.status}; {fallback}: {second.status}")

    def _call_with_retry(self, solver: str, problem: qpsolvers.Problem, warm: QPOutcome | None,
                         log: dict) -> QPOutcome:
        """One backend's answer: its call, and where that fails, its call under ``RETRY_SETTINGS`` (cold; flag "u"
        when those solve it). While ``swap`` is on (``sqp`` turns it on once the late-step crawl shows), the two go
        in the other order after the retry settings have solved a QP the backend's own failed, until the reverse:
        PIQP fails the late gait steps' QPs in runs, each failure costing its 100-iteration limit
        (docs/decisions/0002-qp-backends.md)."""
        first, *rest = self.order.settings(solver, self.swap)
        outcome = self._call(solver, problem, None if first else warm, log, first)
        if outcome.solved or not rest:
            log["flags"] += "u" if outcome.solved and first else ""
            return outcome
        second = rest[0]
        retried = self._call(solver, problem, None if second else warm, log, second)
        if not retried.solved:
            return QPOutcome(False, f"{outcome.status}; retried: {retried.status}")
        log["flags"] += "u" if second else ""
        self.order.solved_second(solver, second)
        return retried

    def _call(self, solver: str, problem: qpsolvers.Problem, warm: QPOutcome | None, log: dict,
              extra: dict | None = None) -> QPOutcome:
        """One backend call, with ``extra`` options, counted in ``evaluations["qp"]`` and timed; backend warnings
        and exceptions are turned into an unsolved outcome with the backend's status."""
        options = {**BACKEND_SETTINGS.get(solver, {}), **_BACKEND_OPTIONS.get(solver, {}), **(extra or {})}
        options.update({key: self.tolerance for key in _TOLERANCE_KEYWORDS.get(solver, ())})
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
            return QPOutcome(False, f"{type(error).__name__}: {error}")
        finally:
            elapsed = time.perf_counter() - start
            self.time += elapsed
            log["qp_time"] += elapsed
            self.evaluator.evaluations["qp"] += 1
        status = backend_status(solution)
        usable = solution.found or status in INACCURATE_STATUSES
        if not usable or solution.x is None or not np.all(np.isfinite(solution.x)):
            return QPOutcome(False, status)
        empty = np.zeros(0)
        return QPOutcome(True, status, np.asarray(solution.x, dtype=float),
                          empty if solution.y is None else np.asarray(solution.y, dtype=float),
                          empty if solution.z is None else np.asarray(solution.z, dtype=float),
                          None if solution.z_box is None else np.asarray(solution.z_box, dtype=float))
