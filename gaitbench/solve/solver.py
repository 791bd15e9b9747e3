"""What every solver plugin returns (its interface is :class:`gaitbench.contracts.Solver`), and the optional solver
members the core uses when present."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from gaitbench.problem.nlp import NLP
from gaitbench.solver_result import SolverResult as SolverResult  # where solver plugins have imported them from
from gaitbench.solver_result import SolverStatus as SolverStatus

if TYPE_CHECKING:
    from gaitbench.contracts import Solver


def prepare(solver: Solver, nlp: NLP) -> None:
    """Build what ``solver`` reuses across solves of ``nlp`` (its ``nlp.solver_cache`` entry) ahead of the first solve.

    Optional for solver plugins: one that defines ``prepare(nlp)`` lets a strategy build in one process before it
    forks workers, which then inherit the built solver instead of each building its own. Without it, this does
    nothing and the first solve builds as usual.
    """
    method = getattr(solver, "prepare", None)
    if method is not None:
        method(nlp)


def section_solver(solver: Solver) -> Solver:
    """The solver for a strategy's sectional NLPs (decrease and conquer's k0 = 2 … N−2 problems).

    Optional for solver plugins: one that defines ``for_sections()`` returns the variant it solves sections with
    (other options suit those short problems, started far from feasible, than suit whole steps); without it, the
    solver itself.
    """
    method = getattr(solver, "for_sections", None)
    return solver if method is None else method()


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
