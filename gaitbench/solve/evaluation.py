"""Numeric access to an NLP for solvers written in Python: counted, timed callbacks and the shared result.

CasADi-backed solvers (``ipopt``, ``fatrop``) evaluate the NLP inside CasADi. Solvers that iterate in
Python (``fsqp``, ``sqp``, ``cyipopt``) call the same exact derivatives through :class:`NLPEvaluator`, which fixes
the parameters, returns NumPy arrays and SciPy sparse matrices, and counts calls and time per callback, so every
solver reports evaluations and function time the same way.
"""

from __future__ import annotations

import time
from collections import Counter

import casadi as ca
import numpy as np
import scipy.sparse as sp

from gaitbench.problem.nlp import NLP
from gaitbench.solver_result import SolverResult, SolverStatus


class NLPEvaluator:
    """The objective, constraints and their exact derivatives at fixed parameters ``p``.

    ``evaluations`` counts calls under the callback names IPOPT uses (``f``, ``g``, ``grad_f``, ``jac_g``,
    ``hess_l``) and ``function_time_s`` sums their wall time.
    """

    def __init__(self, nlp: NLP, parameters: np.ndarray) -> None:
        self.nlp = nlp
        self.p = np.asarray(parameters, dtype=float).ravel()
        if self.p.size != nlp.p.numel():
            raise ValueError(f"the NLP has {nlp.p.numel()} parameters, {self.p.size} values were given")
        self.evaluations: Counter[str] = Counter()
        self.function_time_s = 0.0
        functions = nlp.functions
        self._jacobian_pattern = functions.jacobian.sparsity_out(0)
        self._hessian_pattern = functions.hessian_lagrangian.sparsity_out(0)

    @property
    def n(self) -> int:
        return self.nlp.n_variables

    @property
    def m(self) -> int:
        return self.nlp.n_constraints

    def objective(self, x: np.ndarray) -> float:
        return float(self._call("f", self.nlp.functions.objective, x))

    def gradient(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(self._call("grad_f", self.nlp.functions.gradient, x), dtype=float).ravel()

    def constraints(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(self._call("g", self.nlp.functions.constraints, x), dtype=float).ravel()

    def jacobian(self, x: np.ndarray) -> sp.csc_matrix:
        """∂g/∂x, m × n, in CasADi's sparsity pattern (structural zeros are kept out)."""
        return _to_csc(self._call("jac_g", self.nlp.functions.jacobian, x), self._jacobian_pattern)

    def hessian_lagrangian(self, x: np.ndarray, sigma: float, multipliers: np.ndarray) -> sp.csc_matrix:
        """∇²(σ f + λᵀg), full symmetric n × n (CasADi builds the lower triangle; it is mirrored here)."""
        lower = _to_csc(self._call("hess_l", self.nlp.functions.hessian_lagrangian, x, sigma, multipliers),
                        self._hessian_pattern)
        return (lower + sp.tril(lower, k=-1).T).tocsc()

    def jacobian_pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the Jacobian's structural nonzeros, in the order :meth:`jacobian_values` returns them."""
        return _coordinates(self._jacobian_pattern)

    def jacobian_values(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(self._call("jac_g", self.nlp.functions.jacobian, x).nonzeros())

    def hessian_pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the lower triangle of the Lagrangian Hessian, in :meth:`hessian_values` order."""
        return _coordinates(self._hessian_pattern)

    def hessian_values(self, x: np.ndarray, sigma: float, multipliers: np.ndarray) -> np.ndarray:
        return np.asarray(self._call("hess_l", self.nlp.functions.hessian_lagrangian, x, sigma,
                                     multipliers).nonzeros())

    def _call(self, name: str, function: ca.Function, x: np.ndarray, *extra):
        start = time.perf_counter()
        try:
            return function(x, self.p, *extra)
        finally:
            self.function_time_s += time.perf_counter() - start
            self.evaluations[name] += 1


def _to_csc(matrix: ca.DM, pattern: ca.Sparsity) -> sp.csc_matrix:
    values = np.asarray(matrix.nonzeros(), dtype=float)
    return sp.csc_matrix((values, np.asarray(pattern.row()), np.asarray(pattern.colind())), shape=pattern.shape)


def _coordinates(pattern: ca.Sparsity) -> tuple[np.ndarray, np.ndarray]:
    rows, cols = pattern.get_triplet()
    return np.asarray(rows, dtype=int), np.asarray(cols, dtype=int)


class Deadline:
    """A wall-clock budget started at construction; ``None`` never expires."""

    def __init__(self, time_limit_s: float | None) -> None:
        self.start = time.perf_counter()
        self.time_limit_s = time_limit_s

    @property
    def elapsed_s(self) -> float:
        return time.perf_counter() - self.start

    def expired(self) -> bool:
        return self.time_limit_s is not None and self.elapsed_s >= self.time_limit_s


def solver_result(status: SolverStatus, message: str, x: np.ndarray, evaluator: NLPEvaluator, iterations: int,
                  deadline: Deadline, multipliers: np.ndarray | None = None) -> SolverResult:
    """The shared result, with objective and violation evaluated at ``x`` (NaN where they cannot be)."""
    x = np.asarray(x, dtype=float).ravel()
    nlp, p = evaluator.nlp, evaluator.p
    try:
        objective = float(nlp.functions.objective(x, p))
        violation = nlp.violation(x, p)
    except Exception:  # a result must still be returned when x is unusable
        objective = violation = float("nan")
    return SolverResult(status=status, message=message, x=x, objective=objective, constraint_violation=violation,
                        iterations=iterations, wall_time_s=deadline.elapsed_s,
                        function_time_s=evaluator.function_time_s, evaluations=dict(evaluator.evaluations),
                        multipliers=multipliers)


def error_result(error: BaseException, x0: np.ndarray, deadline: Deadline, iterations: int = 0) -> SolverResult:
    """An exception turned into an ERROR status: the Solver protocol reports failures, it never raises them."""
    return SolverResult(status=SolverStatus.ERROR, message=f"{type(error).__name__}: {error}",
                        x=np.asarray(x0, dtype=float).ravel(), objective=float("nan"),
                        constraint_violation=float("nan"), iterations=iterations, wall_time_s=deadline.elapsed_s,
                        function_time_s=0.0)
