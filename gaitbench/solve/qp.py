"""Reading a ``qpsolvers`` solution the same way in every solver that builds on QP subproblems (``sqp``, ``fsqp``).

Why here: which backend statuses still carry a usable step is a fact about the QP backends, not about one method,
and two solver plugins must agree on it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import qpsolvers

INACCURATE_STATUSES = frozenset({"AlmostSolved", "solved inaccurate"})
"""Statuses ``qpsolvers`` reports as not found whose solutions are still used (Clarabel's and OSQP's reduced-accuracy
optimum): the line search judges the step, and rejecting them would end a solve that is nearly done."""


def backend_status(solution: qpsolvers.Solution) -> str:
    """The backend's own status where ``qpsolvers`` keeps it (OSQP, ProxQP, PIQP, Clarabel), else found or not."""
    extras = solution.extras or {}
    status = extras.get("status", getattr(extras.get("info"), "status", None))
    if status is not None:
        return str(status)
    return "solved" if solution.found else "no solution found"
