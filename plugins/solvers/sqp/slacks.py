"""Magical steps on slack pairs: after a step, the two slacks of a split row are set to their cheapest values given
the rest of x (Conn, Gould and Toint's "magical steps"; their closed form needs no QP and no derivatives).

A slack pair is two variables that enter the NLP linearly (an empty Hessian column), each in one equality row only,
the same row, with coefficients of opposite sign, and a lower bound but no upper one, whose joint increase along the
row raises the objective: the split P = s⁺ − s⁻ of a charged power is one (the gait steps' power rows). Given the
rest of x, the row fixes a⁺s⁺ + a⁻s⁻, and the cheapest such pair has one slack at its bound.

Why: along the thesis cost's flat valleys the QP's steps move the powers' factors (torques, rates) far enough that
the bilinear powers leave their split rows violated by ~1e-3, while the rows' multipliers, and so their ℓ1 weights,
are ~1e-6: the merit hardly sees that violation, so it stays, and the solve can never be at the acceptable level
(docs/decisions/0003-sqp-late-step-crawl.md). The reset removes it exactly, at the cost of one evaluation of f and g.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from gaitbench.solve.evaluation import NLPEvaluator
from gaitbench_plugins.solvers.sqp.linearization import Linearization


@dataclass(frozen=True)
class SlackPairs:
    """The slack pairs of an NLP: for each, its row, its two variables and their coefficients in that row."""

    rows: np.ndarray
    up: np.ndarray
    """The slack with the positive coefficient in its row (s⁻ in P − s⁺ + s⁻ = 0): raising it raises the row."""
    down: np.ndarray
    """The slack with the negative coefficient (s⁺ there)."""
    up_coefficient: np.ndarray
    down_coefficient: np.ndarray

    @classmethod
    def find(cls, evaluator: NLPEvaluator, lin: Linearization, grad: np.ndarray,
             jacobian: sp.csr_matrix) -> SlackPairs | None:
        """The NLP's slack pairs (module docstring), from the structural patterns of its Hessian of the Lagrangian
        and its Jacobian, with the coefficients read off ``jacobian`` and the costs off ``grad`` (both constant in
        such variables); None when it has none."""
        n = evaluator.n
        curved = np.zeros(n, dtype=bool)
        hessian_rows, hessian_columns = evaluator.hessian_pattern()
        curved[hessian_rows] = curved[hessian_columns] = True
        columns = sp.csc_matrix(jacobian)
        single_row = np.diff(columns.indptr) == 1
        lower_only = np.isfinite(lin.lbx) & ~np.isfinite(lin.ubx)
        candidates = np.flatnonzero(~curved & single_row & lower_only)
        rows = columns.indices[columns.indptr[candidates]]
        coefficients = columns.data[columns.indptr[candidates]]
        keep = np.isin(rows, lin.equality) & (coefficients != 0)
        candidates, rows, coefficients = candidates[keep], rows[keep], coefficients[keep]
        order = np.argsort(rows, kind="stable")
        candidates, rows, coefficients = candidates[order], rows[order], coefficients[order]
        _, first, count = np.unique(rows, return_index=True, return_counts=True)
        pairs = first[count == 2]
        first_up = coefficients[pairs] > 0
        opposite = first_up != (coefficients[pairs + 1] > 0)
        pairs, first_up = pairs[opposite], first_up[opposite]
        up = np.where(first_up, pairs, pairs + 1)
        down = np.where(first_up, pairs + 1, pairs)
        a_up, a_down = coefficients[up], coefficients[down]
        # raising both slacks along their row (by 1/a_up and −1/a_down) must cost, or the cheapest pair is unbounded
        costly = grad[candidates[up]] / a_up - grad[candidates[down]] / a_down > 0
        if not costly.any():
            return None
        return cls(rows[up][costly], candidates[up][costly], candidates[down][costly], a_up[costly], a_down[costly])

    def reset(self, x: np.ndarray, g: np.ndarray, lin: Linearization) -> np.ndarray:
        """x with every pair at the cheapest values that satisfy its row exactly given the other variables, which
        stay as they are (``g`` is g(x))."""
        rows, up, down, a_up, a_down = self.rows, self.up, self.down, self.up_coefficient, self.down_coefficient
        lower_up, lower_down = lin.lbx[up], lin.lbx[down]
        # what the pair must add to the rest of the row beyond its value with both slacks at their bounds: the up
        # slack adds it when positive, the down slack when negative, the other stays at its bound
        rest = g[rows] - a_up * x[up] - a_down * x[down]
        needed = lin.lbg[rows] - rest - a_up * lower_up - a_down * lower_down
        reset = x.copy()
        reset[up] = np.where(needed >= 0, lower_up + needed / a_up, lower_up)
        reset[down] = np.where(needed >= 0, lower_down, lower_down + needed / a_down)
        return reset
