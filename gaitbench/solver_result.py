"""What every solver plugin returns: a status, a point and the solve's figures. It sits beside the contracts
(:class:`gaitbench.contracts.Solver` returns it); :mod:`gaitbench.solve.solver` holds what the core does with it."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
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
    (:class:`gaitbench.solve.solver.CheckedSolver`)."""


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
