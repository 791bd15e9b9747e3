"""What every solver plugin returns, and the protocol it implements."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from enum import Enum
from typing import Protocol

import numpy as np

from gaitbench.nlp import NLP


class SolverStatus(str, Enum):
    CONVERGED = "converged"
    INFEASIBLE = "infeasible"
    ITERATION_LIMIT = "iteration_limit"
    TIME_LIMIT = "time_limit"
    ERROR = "error"


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


class Solver(Protocol):
    """Solves an :class:`NLP` for given parameter values from an initial guess."""

    name: str

    def solve(self, nlp: NLP, parameters: np.ndarray, initial_guess: np.ndarray) -> SolverResult: ...
