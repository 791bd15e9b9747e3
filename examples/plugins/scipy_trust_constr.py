"""An example solver plugin: SciPy's ``trust-constr`` (a trust-region interior point method) on gaitbench NLPs.

It is the worked example of ``docs/solvers.md``: a solver that lives outside the package and is loaded with
``gaitbench --plugins-dir examples/plugins solve -s scipy-trust-constr ...``. It shows the four things every
solver plugin does: fix the parameters and get exact sparse derivatives from :class:`NLPEvaluator`, honour the
shared options, translate the method's own outcome into a :class:`SolverStatus`, and never raise from ``solve``.
The method is SciPy's; the plugin only adapts it, and its name says so.
"""

from __future__ import annotations

import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.problem.nlp import NLP
from gaitbench.solve.evaluation import Deadline, NLPEvaluator, error_result, solver_result
from gaitbench.solver_result import SolverResult, SolverStatus

_STATUSES = {0: SolverStatus.ITERATION_LIMIT, 1: SolverStatus.CONVERGED, 2: SolverStatus.CONVERGED,
             3: SolverStatus.TIME_LIMIT, 4: SolverStatus.INFEASIBLE}
"""``OptimizeResult.status`` of trust-constr: 0 iteration limit, 1 gradient tolerance met, 2 trust radius below
``xtol``, 3 stopped by the callback (here only for the time limit), 4 constraint violation above ``gtol``."""


class ScipyTrustConstr:
    """``scipy.optimize.minimize(method="trust-constr")`` with the exact Lagrangian Hessian.

    Options: ``max_iterations`` (1000), ``time_limit_s`` (None: no limit; checked by a callback after each
    iteration), ``tolerance`` (1e-8: SciPy's ``gtol`` on the Lagrangian gradient and the constraint violation, and its
    ``barrier_tol``, the final barrier parameter),
    ``print_level`` (0 silent, 1–3 SciPy's ``verbose``).
    """

    name = "scipy-trust-constr"

    def __init__(self, max_iterations: int = 1000, time_limit_s: float | None = None, tolerance: float = 1e-8,
                 print_level: int = 0) -> None:
        self.max_iterations = int(max_iterations)
        self.time_limit_s = time_limit_s
        self.tolerance = float(tolerance)
        self.print_level = int(print_level)

    def solve(self, nlp: NLP, parameters: np.ndarray, initial_guess: np.ndarray) -> SolverResult:
        from scipy.optimize import Bounds, NonlinearConstraint, minimize

        deadline = Deadline(self.time_limit_s)
        x0 = np.clip(np.asarray(initial_guess, dtype=float).ravel(), nlp.lbx, nlp.ubx)
        try:
            evaluator = NLPEvaluator(nlp, parameters)
            constraints = []
            if nlp.n_constraints:
                constraints.append(NonlinearConstraint(
                    evaluator.constraints, nlp.lbg, nlp.ubg, jac=evaluator.jacobian,
                    hess=lambda x, v: evaluator.hessian_lagrangian(x, 0.0, v)))
            result = minimize(
                evaluator.objective, x0, jac=evaluator.gradient, method="trust-constr",
                hess=lambda x: evaluator.hessian_lagrangian(x, 1.0, np.zeros(nlp.n_constraints)),
                bounds=Bounds(nlp.lbx, nlp.ubx), constraints=constraints, callback=lambda *_: deadline.expired(),
                options={"maxiter": self.max_iterations, "gtol": self.tolerance, "xtol": self.tolerance,
                         "barrier_tol": self.tolerance, "verbose": self.print_level,
                         "sparse_jacobian": True})
        except Exception as error:
            return error_result(error, x0, deadline)
        status = _STATUSES.get(result.status, SolverStatus.ERROR)
        # trust-constr stops on a tiny trust radius even at an infeasible point: that is not convergence.
        if status is SolverStatus.CONVERGED and result.constr_violation > 1e-6:
            status = SolverStatus.INFEASIBLE
        multipliers = -np.asarray(result.v[0]) if nlp.n_constraints else np.zeros(0)
        return solver_result(status, f"scipy trust-constr: {result.message}", result.x, evaluator, result.nit,
                             deadline, multipliers)


@hookimpl
def register_solvers():
    return [Registration("scipy-trust-constr", "SciPy's trust-constr interior point (example plugin)",
                         ScipyTrustConstr)]
