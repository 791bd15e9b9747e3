"""IPOPT through cyipopt, called back from Python with gaitbench's own exact sparse derivatives.

The same algorithm as the ``ipopt`` plugin, reached by a second path: IPOPT's C interface (cyipopt bundles its own
IPOPT build) calls Python for every function, gradient, Jacobian and Hessian value, which :class:`NLPEvaluator`
takes from CasADi. With equal options both paths take the same iterations to the same point, so comparing them
isolates the cost of evaluating the NLP from Python instead of inside CasADi, and checks one IPOPT against the
other. The cyipopt problem (sizes, bounds, sparsity structures, options) is built once per NLP and options and
kept in ``nlp.solver_cache``; a re-solve with new parameters only points the callbacks at a new evaluator.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import cyipopt
import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.problem.nlp import NLP
from gaitbench.solve.evaluation import Deadline, NLPEvaluator, error_result, solver_result
from gaitbench.solve.ipopt import IPOPT_STATUSES, SMALL_MU_INIT, check_ipopt_options
from gaitbench.solve.silence import quiet_stdout
from gaitbench.solve.solver import options_key, set_typed_option
from gaitbench.solver_result import SolverResult, SolverStatus

_RETURN_STATUSES = {
    0: "Solve_Succeeded",
    1: "Solved_To_Acceptable_Level",
    2: "Infeasible_Problem_Detected",
    3: "Search_Direction_Becomes_Too_Small",
    4: "Diverging_Iterates",
    5: "User_Requested_Stop",
    6: "Feasible_Point_Found",
    -1: "Maximum_Iterations_Exceeded",
    -2: "Restoration_Failed",
    -3: "Error_In_Step_Computation",
    -4: "Maximum_CpuTime_Exceeded",
    -5: "Maximum_WallTime_Exceeded",
    -10: "Not_Enough_Degrees_Of_Freedom",
    -11: "Invalid_Problem_Definition",
    -12: "Invalid_Option",
    -13: "Invalid_Number_Detected",
    -100: "Unrecoverable_Exception",
    -101: "NonIpopt_Exception_Thrown",
    -102: "Insufficient_Memory",
    -199: "Internal_Error",
}
"""IPOPT's ApplicationReturnStatus (IpReturnCodes_inc.h, IPOPT 3.14) by the number cyipopt returns in
``info["status"]``; cyipopt's own table lacks -5, Maximum_WallTime_Exceeded, which IPOPT 3.14 returns for
``max_wall_time``."""

class _Callbacks:
    """The problem object cyipopt calls: the current solve's evaluator, the iteration count, the first failure.

    An exception in a callback is kept here and turned into cyipopt's evaluation error, so IPOPT never uses a
    value that was not computed, and the solve stops at the next iteration; the plugin then reports the exception.
    (cyipopt's own handling loses an exception raised in ``hessian``, and keeps any other in the problem to
    raise again on every later solve.)

    IPOPT reports iterations of its feasibility restoration phase one higher than its own final count (the
    restoration problem counts its starting point as an iteration), so those are shifted back, which makes
    :attr:`iterations` equal to the ``iter_count`` the ``ipopt`` plugin reports.
    """

    def __init__(self, evaluator: NLPEvaluator) -> None:
        self.evaluator = evaluator
        self.iterations = 0
        self.error: Exception | None = None
        self._jacobian_structure = evaluator.jacobian_pattern()
        self._hessian_structure = evaluator.hessian_pattern()

    def start(self, evaluator: NLPEvaluator) -> None:
        self.evaluator = evaluator
        self.iterations = 0
        self.error = None

    def _evaluate(self, evaluate: Callable, *args):
        try:
            return evaluate(*args)
        except Exception as error:
            self.error = self.error or error
            raise cyipopt.CyIpoptEvaluationError(str(error)) from error

    def objective(self, x: np.ndarray) -> float:
        return self._evaluate(self.evaluator.objective, x)

    def gradient(self, x: np.ndarray) -> np.ndarray:
        return self._evaluate(self.evaluator.gradient, x)

    def constraints(self, x: np.ndarray) -> np.ndarray:
        return self._evaluate(self.evaluator.constraints, x)

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return self._evaluate(self.evaluator.jacobian_values, x)

    def jacobianstructure(self) -> tuple[np.ndarray, np.ndarray]:
        return self._jacobian_structure

    def hessian(self, x: np.ndarray, multipliers: np.ndarray, objective_factor: float) -> np.ndarray:
        return self._evaluate(self.evaluator.hessian_values, x, objective_factor, multipliers)

    def hessianstructure(self) -> tuple[np.ndarray, np.ndarray]:
        return self._hessian_structure

    def intermediate(self, alg_mod: int, iter_count: int, *_progress) -> bool:
        self.iterations = iter_count - alg_mod  # alg_mod is 1 in the restoration phase, 0 otherwise
        return self.error is None


@dataclass
class _Built:
    problem: cyipopt.Problem
    callbacks: _Callbacks


class CyIpopt:
    """IPOPT through cyipopt with the exact Hessian of the Lagrangian, evaluated from Python.

    ``max_iterations`` (IPOPT's ``max_iter``), ``time_limit_s`` (``max_wall_time``; ``None`` for no limit),
    ``tolerance`` (``tol``) and ``print_level`` (0 also sets ``sb=yes``, which silences IPOPT's banner) are the
    options every gaitbench solver shares, mapped exactly as the ``ipopt`` plugin maps them, so both take the same
    iterations. Any other keyword is an IPOPT option passed unchanged (https://coin-or.github.io/Ipopt/OPTIONS.html);
    an integer given for a numeric option is converted. :meth:`check_options` asks cyipopt's IPOPT about each of them,
so one it does not know or accept is refused when a suite loads; built without that check, it makes every solve
return ERROR.

    ``multipliers`` are IPOPT's constraint multipliers (``info["mult_g"]``), which are CasADi's ``lam_g`` too:
    ∇f + Jᵀλ_g + λ_x = 0, so they equal the ``ipopt`` plugin's.
    """

    name = "cyipopt"
    own_options = ("max_iterations", "time_limit_s", "tolerance", "print_level")
    """gaitbench's options; every other keyword is IPOPT's."""

    @classmethod
    def check_options(cls, options: Mapping[str, Any]) -> None:
        """Every IPOPT option known to IPOPT and accepted by cyipopt's own IPOPT build (docs/plugins.md)."""
        check_ipopt_options(options, cls.own_options, _cyipopt_accepts)

    def __init__(self, max_iterations: int = 3000, time_limit_s: float | None = None, tolerance: float = 1e-8,
                 print_level: int = 0, **ipopt_options) -> None:
        options: dict = {"max_iter": int(max_iterations), "tol": float(tolerance), "print_level": int(print_level)}
        if time_limit_s is not None:
            options["max_wall_time"] = float(time_limit_s)
        if print_level == 0:
            options["sb"] = "yes"
        options.update(ipopt_options)
        self.options = options
        """The IPOPT options every solve is built with."""
        self._arguments = dict(max_iterations=max_iterations, time_limit_s=time_limit_s, tolerance=tolerance,
                               print_level=print_level, **ipopt_options)

    def remedies(self) -> list:
        """Adaptive μ for the retry ladder, as the ``ipopt`` plugin offers it (docs/solvers.md, "Retries")."""
        if self.options.get("mu_strategy") == "adaptive":
            return []
        return [("adaptive-mu", type(self)(**{**self._arguments, "mu_strategy": "adaptive"}))]

    def last_resorts(self) -> list:
        """A small initial barrier parameter after every other rung, as the ``ipopt`` plugin offers it."""
        if "mu_init" in self.options:
            return []
        return [("small-mu-init", type(self)(**{**self._arguments, "mu_init": SMALL_MU_INIT}))]

    def solve(self, nlp: NLP, parameters: np.ndarray, initial_guess: np.ndarray) -> SolverResult:
        """Solve from ``initial_guess``; exceptions (in cyipopt or in a callback) become an ERROR status."""
        x0 = np.asarray(initial_guess, dtype=float).ravel()
        deadline = Deadline(None)
        built = None
        try:
            evaluator = NLPEvaluator(nlp, parameters)
            built = self._built(nlp, evaluator)
            built.callbacks.start(evaluator)
            deadline = Deadline(None)  # timing the solve, not the first build, as the ipopt plugin does
            x, info = built.problem.solve(x0)
            if built.callbacks.error is not None:
                raise built.callbacks.error
        except Exception as error:
            failure = error_result(error, x0, deadline, iterations=built.callbacks.iterations if built else 0)
            return replace(failure, message=f"cyipopt: {failure.message}")
        return_status = _RETURN_STATUSES.get(info["status"], f"status {info['status']}")
        return solver_result(IPOPT_STATUSES.get(return_status, SolverStatus.ERROR), f"cyipopt: {return_status}", x,
                             evaluator, built.callbacks.iterations, deadline,
                             multipliers=np.asarray(info["mult_g"], dtype=float))

    def _built(self, nlp: NLP, evaluator: NLPEvaluator) -> _Built:
        key = options_key(self.name, self.options)
        if key not in nlp.solver_cache:
            callbacks = _Callbacks(evaluator)
            problem = cyipopt.Problem(n=nlp.n_variables, m=nlp.n_constraints, problem_obj=callbacks, lb=nlp.lbx,
                                      ub=nlp.ubx, cl=nlp.lbg, cu=nlp.ubg)
            with quiet_stdout(self.options["print_level"] == 0):  # IPOPT prints why it rejects an option
                for option, value in self.options.items():
                    set_typed_option(problem.add_option, option, value, "IPOPT")
            nlp.solver_cache[key] = _Built(problem, callbacks)
        return nlp.solver_cache[key]


class _NoProblem:
    """Callbacks of a problem that is never solved: options are only set on it."""

    def objective(self, x: np.ndarray) -> float:
        return 0.0

    def gradient(self, x: np.ndarray) -> np.ndarray:
        return np.zeros_like(x)


def _cyipopt_accepts(name: str, value: Any) -> bool:
    """Whether cyipopt's IPOPT accepts ``name = value``, set as a solve would set it on a one-variable problem."""
    problem = cyipopt.Problem(n=1, m=0, problem_obj=_NoProblem(), lb=[-1.0], ub=[1.0])
    try:
        with quiet_stdout():  # IPOPT prints why it refuses
            set_typed_option(problem.add_option, name, value, "IPOPT")
    except ValueError:
        return False
    return True


@hookimpl
def register_solvers():
    return [Registration("cyipopt", "IPOPT through cyipopt, exact Hessian evaluated from Python", CyIpopt)]
