"""Calling and reading ``qpsolvers`` backends the same way in every solver that builds on QP subproblems (``sqp``,
``fsqp``).

Why here: which backend settings the gait QPs need, and which backend statuses still carry a usable step, are facts
about the QP backends, not about one method, and two solver plugins must agree on them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import qpsolvers

BACKEND_SETTINGS: dict[str, dict] = {"piqp": {"reg_finetune_lower_limit": 1e-10}}
"""Backend settings every QP of a gait NLP gets. PIQP: near its solution it lowers its proximal regularisation from
``reg_lower_limit`` (1e-10) to ``reg_finetune_lower_limit`` (1e-13 by default) to reach its tolerance; on the
convexified gait QPs, whose Hessian shift is as small as 1e-10·max|H|, its iterates then diverge from a point where
the QP was solved to a duality gap of 1e-8 (the dual residual climbs from 2e-9 to 1e-1), and it ends at its
iteration limit. With the floor kept at 1e-10 it solves half of the QPs it failed that way, in the same iterations
as the others (docs/decisions/0002-qp-backends.md)."""

RETRY_SETTINGS: dict[str, dict] = {"piqp": {"preconditioner_iter": 0}}
"""Settings under which a backend solves again, before another backend, a gait QP it failed. PIQP without its Ruiz
equilibration: on the late gait steps PIQP fails up to half the QPs (forward step 2, HS N = 100: 266 of 587), and
Clarabel, solving them cold, ends most at its reduced accuracy (``AlmostSolved``, 124 of 255) in 85-110 ms each.
Unequilibrated, PIQP solves 38 of 40 of those QPs in a median of 33 iterations, to objectives at or below
Clarabel's; as the first try it fails others that the equilibrated PIQP solves, so it is the second
(docs/decisions/0002-qp-backends.md), but where :class:`RetryOrder` lets the two
take turns going first: for ``fsqp`` from a solve's first QP, for ``sqp`` once its late-step crawl shows ("PIQP's
failures in runs")."""


class RetryOrder:
    """Which of its two settings each backend tries a QP with first, over one solve: its own, or its
    ``RETRY_SETTINGS`` once those solved the last QP its own failed, until the reverse.

    Why: PIQP fails the late gait steps' QPs in runs (a QP after a failed one failed 229 times in 266 on forward
    step 2, HS N = 100), and each failure costs its iteration limit before the retry solves the QP; trying the
    settings that solved the last failed QP first saves those calls (docs/decisions/0002-qp-backends.md,
    and for ``fsqp`` "The retry settings first")."""

    def __init__(self) -> None:
        self._retry_first: set[str] = set()

    def settings(self, solver: str, swap: bool = True) -> list[dict]:
        """The extra settings to try ``solver`` with, in order: its own ({}) and its ``RETRY_SETTINGS`` if it has
        any, those first where they solved the last QP the other failed and ``swap`` is on."""
        if solver not in RETRY_SETTINGS:
            return [{}]
        order = [{}, RETRY_SETTINGS[solver]]
        return order[::-1] if swap and solver in self._retry_first else order

    def solved_second(self, solver: str, settings: dict) -> None:
        """``settings`` solved a QP that the other settings of ``solver`` failed: they go first from now on."""
        if settings:
            self._retry_first.add(solver)
        else:
            self._retry_first.discard(solver)

    def retry_first(self, solver: str) -> bool:
        """Whether ``solver``'s retry settings go first (where swapping is on)."""
        return solver in self._retry_first


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
