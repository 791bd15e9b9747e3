"""What every solver plugin returns (its interface is :class:`gaitbench.contracts.Solver`), and the optional solver
members the core uses when present."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from gaitbench.problem.nlp import NLP
from gaitbench.solver_result import SolverResult, SolverStatus

if TYPE_CHECKING:
    from gaitbench.contracts import Solver


VARIANT_KINDS = ("continuations", "remedies", "seed_remedies", "last_resorts")
"""The optional solver members that return named variants of the solver for the retry ladder."""


class CheckedSolver:
    """A solver plugin behind the boundary every solve of a walk passes (:class:`gaitbench.solve.walk.WalkProblem`
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


def prepare(solver: Solver, nlp: NLP) -> None:
    """Build what ``solver`` reuses across solves of ``nlp`` (its ``nlp.solver_cache`` entry) ahead of the first solve.

    Optional for solver plugins: one that defines ``prepare(nlp)`` lets a strategy build in one process before it
    forks workers, which then inherit the built solver instead of each building its own. Without it, this does
    nothing and the first solve builds as usual.
    """
    method = getattr(solver, "prepare", None)
    if method is not None:
        method(nlp)


def options_key(name: str, options: dict) -> tuple:
    """A hashable, order-independent key for ``nlp.solver_cache``: a solver built with these options is reusable."""
    return (name, _freeze(options))


def set_typed_option(setter: Callable[[str, Any], None], option: str, value: Any, library: str) -> None:
    """``setter(option, value)`` for a library binding (cyipopt, unopy) that picks the option's type from the
    Python value's: an int given for a real option is set again as a float. A ValueError names the option the
    library rejects."""
    try:
        setter(option, value)
    except TypeError:
        if type(value) is not int:
            raise ValueError(f"{library} rejects option {option}={value!r}") from None
        try:
            setter(option, float(value))
        except TypeError:
            raise ValueError(f"{library} rejects option {option}={value!r}") from None


def _freeze(options):
    if isinstance(options, dict):
        return tuple(sorted((key, _freeze(value)) for key, value in options.items()))
    if isinstance(options, list | tuple):
        return tuple(_freeze(value) for value in options)
    return options
