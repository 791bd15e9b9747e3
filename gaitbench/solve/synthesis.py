"""Decrease & Conquer's trajectory synthesis with on-line verification (thesis §3.7), in the core so
that any strategy can build on it.

Pure logic on node arrays, independent of how the candidates were computed: candidate ``j`` is defined from its
start node on; at every node the candidate with the lowest point cost is taken, provided the "typical value
relation" with the previous node holds (each of q1, q2, q̇1, q̇2 rises, falls or stays as it does along the
reference, the complete trajectory); otherwise the next-cheapest candidate is tried, and when none fits the search
steps back one node and tries that node's next candidate (depth-first with backtracking).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

REFERENCE = 0
"""Candidate 0 is the complete trajectory (k0 = 1), defined at every node: the verification's reference."""


@dataclass(frozen=True)
class Synthesis:
    selection: list[int]
    """The candidate each node's values come from."""
    backtracks: int
    """How many times the search stepped back to an earlier node."""
    checks: int
    """Relation checks made."""
    exhausted: bool
    """The search went over its check budget and fell back to the reference."""


def relation_holds(candidate: np.ndarray, previous: np.ndarray, reference: np.ndarray, reference_previous: np.ndarray,
                   tolerance: float = 1e-9) -> bool:
    """Whether every variable changes from ``previous`` to ``candidate`` in the direction the reference changes.

    The thesis's "typical value relation" (§3.7) is not defined further; here it holds when the signs of the
    increments agree, with changes within ``tolerance`` counting as "equal"
    (docs/deviations.md, "D&C verification (relation check)").
    """
    return bool(relations_hold(candidate[None], previous, _direction(reference - reference_previous, tolerance),
                               tolerance)[0])


def relations_hold(candidates: np.ndarray, previous: np.ndarray, reference_direction: np.ndarray,
                   tolerance: float) -> np.ndarray:
    """:func:`relation_holds` for each row of ``candidates`` (C, V) at once, given the reference's direction."""
    return np.all(_direction(candidates - previous, tolerance) == reference_direction, axis=1)


def _direction(change: np.ndarray, tolerance: float) -> np.ndarray:
    return np.where(np.abs(change) <= tolerance, 0, np.sign(change))


def synthesize(point_costs: np.ndarray, values: np.ndarray, *, tolerance: float = 1e-9,
               max_checks: int = 1_000_000) -> Synthesis:
    """Select a candidate per node.

    ``point_costs`` is (J, N) and ``values`` (J, N, V), NaN where a candidate is not defined (before its start
    node); candidate 0 is the reference and must be defined everywhere. The all-reference path satisfies the
    relation with itself, so the search always ends with a path; it is exponential in the worst case, and after
    ``max_checks`` relation checks every node takes the reference. Each (node, previous candidate) pair's relations
    are computed once, for all of the node's candidates together: backtracking revisits them.
    """
    point_costs = np.asarray(point_costs, dtype=float)
    values = np.asarray(values, dtype=float)
    n_nodes = point_costs.shape[1]
    if np.isnan(point_costs[REFERENCE]).any() or np.isnan(values[REFERENCE]).any():
        raise ValueError("the reference candidate (row 0) must be defined at every node")
    ranked = [_ranked(point_costs[:, k]) for k in range(n_nodes)]
    reference_direction = _direction(np.diff(values[REFERENCE], axis=0), tolerance)  # row k − 1: node k − 1 → k
    fits: dict[tuple[int, int], np.ndarray] = {}  # (node, previous node's candidate) → relation for ranked[node]

    def fitting(k: int, previous: int) -> np.ndarray:
        """Whether each of node k's ranked candidates keeps the relation after ``previous`` at node k − 1."""
        if (k, previous) not in fits:
            fits[k, previous] = relations_hold(values[ranked[k], k], values[previous, k - 1],
                                               reference_direction[k - 1], tolerance)
        return fits[k, previous]

    selection = [REFERENCE] * n_nodes
    tried = [0] * n_nodes
    backtracks = checks = 0
    k = 1
    while k < n_nodes:
        holding = np.flatnonzero(fitting(k, selection[k - 1])[tried[k]:])
        found = holding.size > 0
        examined = holding[0] + 1 if found else len(ranked[k]) - tried[k]  # the first that fits, or all left
        checks += int(examined)
        if checks > max_checks:
            return Synthesis([REFERENCE] * n_nodes, backtracks, checks, exhausted=True)
        if found:
            tried[k] += int(holding[0])
            selection[k] = ranked[k][tried[k]]
            k += 1
            if k < n_nodes:
                tried[k] = 0
            continue
        tried[k] = 0
        k -= 1  # never reaches node 0: the reference at node k always fits the reference at k − 1
        backtracks += 1
        tried[k] += 1
    return Synthesis(selection, backtracks, checks, exhausted=False)


def _ranked(costs: np.ndarray) -> list[int]:
    """Candidates defined at a node, cheapest first (ties by candidate index, so the result is deterministic)."""
    defined = np.flatnonzero(~np.isnan(costs))
    return [int(j) for j in defined[np.argsort(costs[defined], kind="stable")]]


def complete_sections(values: np.ndarray, starts: list[int]) -> np.ndarray:
    """Each candidate's missing nodes filled in (thesis §3.7): node m < start comes from the candidate starting at m
    (whose state there is the First Phase's, with its own torque), or from the reference where no candidate starts
    at m (the start of a section that did not converge).

    ``values`` is (J, N, ...) with NaN before each start; returns the completed copy.
    """
    completed = np.array(values, dtype=float, copy=True)
    owner = {start: j for j, start in enumerate(starts)}
    for j, start in enumerate(starts):
        for m in range(start):
            completed[j, m] = values[owner.get(m, REFERENCE), m]
    return completed
