"""What every solver plugin returns (a status, a point and the solve's figures), and the boundary that holds a
solver to it. It sits beside the contracts (:class:`gaitbench.contracts.Solver` returns it); the optional solver
members the core uses are in :mod:`gaitbench.solve.solver`."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from enum import Enum
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from gaitbench.contracts import Solver
    from gaitbench.problem.nlp import NLP


class SolverStatus(str, Enum):
    CONVERGED = "converged"
    INFEASIBLE = "infeasible"
    ITERATION_LIMIT = "iteration_limit"
    TIME_LIMIT = "time_limit"
    ERROR = "error"
    NON_FINITE = "non_finite"
    """The solver claimed convergence at a point or objective that is not finite
    (:class:`gaitbench.solver_result.CheckedSolver`)."""


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


VARIANT_KINDS = ("continuations", "remedies", "seed_remedies", "last_resorts")
"""The optional solver members that return named variants of the solver for the retry ladder."""


class CheckedSolver:
    """A solver plugin behind the boundary every solve of a walk passes (:class:`gaitbench.walk_types.WalkProblem`
    holds its solver so): a result that claims convergence at a non-finite ``x`` or objective becomes
    :attr:`SolverStatus.NON_FINITE`, with a message that says so, instead of a point the verification would fail
    on for another reason. The solver's variants are checked alike; everything else is the plugin's own."""

    def __init__(self, solver: Solver) -> None:
        self.plugin = solver

    def solve(self, nlp: NLP, parameters: np.ndarray, initial_guess: np.ndarray) -> SolverResult:
        return finite_or_flagged(self.plugin.solve(nlp, parameters, initial_guess), self.plugin.name)

    def __getattr__(self, name: str) -> Any:
        if name == "plugin":  # not set yet (an object being unpickled): no recursion through it
            raise AttributeError(name)
        member = getattr(self.plugin, name)
        if name in VARIANT_KINDS:
            return lambda: [(label, checked(variant)) for label, variant in member()]
        return member


def checked(solver: Solver) -> Solver:
    """``solver`` behind :class:`CheckedSolver` (once)."""
    return solver if isinstance(solver, CheckedSolver) else CheckedSolver(solver)  # type: ignore[return-value]


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
