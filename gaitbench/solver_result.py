"""What every solver plugin returns (a status, a point and the solve's figures), and how a result that claims
convergence at non-finite values is flagged. It sits below the contracts (:class:`gaitbench.contracts.Solver` returns
it, and :class:`gaitbench.contracts.CheckedSolver` holds every solve of a walk to it); the optional solver members the
core uses are in :mod:`gaitbench.solve.solver`."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from enum import Enum

import numpy as np


class SolverStatus(str, Enum):
    CONVERGED = "converged"
    INFEASIBLE = "infeasible"
    ITERATION_LIMIT = "iteration_limit"
    TIME_LIMIT = "time_limit"
    ERROR = "error"
    NON_FINITE = "non_finite"
    """The solver claimed convergence at a point or objective that is not finite
    (:class:`gaitbench.contracts.CheckedSolver`)."""


@dataclass
class SolverResult:
    """The shared result of one NLP solve. A failure is a status with a message, never an exception."""

    status: SolverStatus
    message: str
    x: np.ndarray
    objective: float
    constraint_violation: float
    iterations: int
    wall_time_s: float
    function_time_s: float
    evaluations: dict[str, int] = field(default_factory=dict)
    multipliers: np.ndarray | None = None

    @property
    def converged(self) -> bool:
        return self.status is SolverStatus.CONVERGED

    def summary(self) -> dict:
        """JSON-ready fields (no arrays)."""
        data = asdict(self)
        for key in ("x", "multipliers"):
            data.pop(key)
        data["status"] = self.status.value
        return data


def finite_or_flagged(result: SolverResult, solver: str) -> SolverResult:
    """``result``, or, when it claims convergence at non-finite values, the same result with status
    :attr:`SolverStatus.NON_FINITE` and a message naming what is not finite."""
    if not result.converged:
        return result
    try:
        x = np.asarray(result.x, dtype=float).ravel()
    except (TypeError, ValueError):
        x = np.array([math.nan])
    bad_x = int(x.size - np.count_nonzero(np.isfinite(x)))
    objective_finite = _finite(result.objective)
    if bad_x == 0 and objective_finite:
        return result
    problems = ([f"{bad_x} of the {x.size} values of x"] if bad_x else []) + \
        ([f"the objective ({result.objective})"] if not objective_finite else [])
    return replace(result, status=SolverStatus.NON_FINITE,
                   message=f"solver {solver} returned non-finite values while claiming convergence: "
                           f"{' and '.join(problems)} are NaN or infinite ({result.message or 'no message'})")


def _finite(value: object) -> bool:
    try:
        return math.isfinite(float(value))  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False
