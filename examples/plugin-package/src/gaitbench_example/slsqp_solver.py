"""A solver plugin: SciPy's SLSQP (sequential least-squares quadratic programming) on gaitbench's NLPs.

What every solver plugin does: fix the parameters and get exact derivatives from :class:`NLPEvaluator`, honour the
shared options (``max_iterations``, ``time_limit_s``), translate the method's own outcome into a
:class:`SolverStatus`, and never raise from ``solve``: a failure is a status with a message. SLSQP works on dense
matrices, so it suits the small grids (N up to about 30) rather than the thesis's N = 200.
"""

from __future__ import annotations

import numpy as np

from gaitbench import Registration, hookimpl

_STATUSES = {0: "converged", 9: "iteration_limit", 4: "infeasible"}
"""SLSQP's exit modes that mean something to gaitbench (0 converged, 9 iteration limit, 4 incompatible inequality
constraints); every other mode (a singular subproblem, a failed line search) is an error."""


class _OutOfTime(Exception):
    """Raised from SLSQP's callback when the time limit has passed, with the last iterate."""

    def __init__(self, x: np.ndarray, iterations: int) -> None:
        super().__init__("time limit")
        self.x, self.iterations = x, iterations


class Slsqp:
    """``scipy.optimize.minimize(method="SLSQP")`` with exact gradients and constraint Jacobians.

    Options: ``max_iterations`` (500), ``time_limit_s`` (None: no limit; checked after each iteration),
    ``tolerance`` (1e-8: SciPy's ``ftol`` on the objective, and the largest constraint violation that counts as
    feasible).
    """

    name = "example-slsqp"

    def __init__(self, max_iterations: int = 500, time_limit_s: float | None = None,
                 tolerance: float = 1e-8) -> None:
        if max_iterations < 1 or tolerance <= 0:
            raise ValueError(f"max_iterations = {max_iterations}, tolerance = {tolerance}: both must be positive")
        self.max_iterations = int(max_iterations)
        self.time_limit_s = time_limit_s
        self.tolerance = float(tolerance)

    def solve(self, nlp, parameters: np.ndarray, initial_guess: np.ndarray):
        from scipy.optimize import Bounds, minimize

        from gaitbench.solve.evaluation import Deadline, NLPEvaluator, error_result, solver_result
        from gaitbench.solver_result import SolverStatus

        deadline = Deadline(self.time_limit_s)
        x0 = np.clip(np.asarray(initial_guess, dtype=float).ravel(), nlp.lbx, nlp.ubx)
        iterations = 0

        def after_iteration(x: np.ndarray) -> None:
            nonlocal iterations
            iterations += 1
            if deadline.expired():
                raise _OutOfTime(np.array(x, dtype=float), iterations)

        try:
            evaluator = NLPEvaluator(nlp, parameters)
            result = minimize(evaluator.objective, x0, jac=evaluator.gradient, method="SLSQP",
                              bounds=Bounds(nlp.lbx, nlp.ubx), constraints=_constraints(nlp, evaluator),
                              callback=after_iteration,
                              options={"maxiter": self.max_iterations, "ftol": self.tolerance})
        except _OutOfTime as stop:
            return solver_result(SolverStatus.TIME_LIMIT, "scipy SLSQP: time limit", stop.x, evaluator,
                                 stop.iterations, deadline)
        except Exception as error:
            return error_result(error, x0, deadline, iterations)
        status = SolverStatus(_STATUSES.get(result.status, "error"))
        if status is SolverStatus.CONVERGED and nlp.violation(result.x, parameters) > self.tolerance:
            status = SolverStatus.INFEASIBLE  # SLSQP's ftol stops on a flat objective, feasible or not
        return solver_result(status, f"scipy SLSQP: {result.message}", result.x, evaluator, result.nit, deadline)


def _constraints(nlp, evaluator) -> list[dict]:
    """lbg ≤ g(x) ≤ ubg as SciPy's dictionaries: the rows with lbg = ubg as equalities, every finite bound of the
    others as an inequality ≥ 0, all with their dense Jacobian rows."""
    lower, upper = np.asarray(nlp.lbg, dtype=float), np.asarray(nlp.ubg, dtype=float)
    equal = lower == upper
    low = ~equal & np.isfinite(lower)
    high = ~equal & np.isfinite(upper)

    def rows(mask: np.ndarray, sign: float, bound: np.ndarray):
        return {"fun": lambda x: sign * (evaluator.constraints(x)[mask] - bound[mask]),
                "jac": lambda x: sign * evaluator.jacobian(x).toarray()[mask]}

    found = []
    if equal.any():
        found.append({"type": "eq", **rows(equal, 1.0, lower)})
    if low.any():
        found.append({"type": "ineq", **rows(low, 1.0, lower)})
    if high.any():
        found.append({"type": "ineq", **rows(high, -1.0, upper)})
    return found


@hookimpl
def register_solvers():
    return [Registration("example-slsqp", "SciPy's SLSQP, dense, for small grids (example plugin package)", Slsqp)]
