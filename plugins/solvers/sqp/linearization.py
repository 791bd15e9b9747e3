"""The NLP's rows as ``qpsolvers`` sees them: sorted once into QP equalities and the finite sides of the other rows,
with the violation measures the globalisations use."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import qpsolvers
import scipy.sparse as sp

from gaitbench.problem.nlp import NLP
from gaitbench_plugins.solvers.sqp.backends import QPOutcome

DEGENERATE_GRADIENT = 1e-2
"""A row whose gradient norm is below this is degenerate: the gait rows are O(1), and the one that gets there is the
clearance where the legs cross (docs/decisions/0006-sqp-clearance-saddle.md)."""


def row_norms(jacobian: sp.csr_matrix) -> np.ndarray:
    """‖∇g_i‖₂ of every row."""
    return np.sqrt(np.asarray(jacobian.multiply(jacobian).sum(axis=1)).ravel())


class Linearization:
    """The NLP's rows sorted once into QP equalities and the finite sides of the other rows."""

    def __init__(self, nlp: NLP) -> None:
        self.lbg, self.ubg, self.lbx, self.ubx = nlp.lbg, nlp.ubg, nlp.lbx, nlp.ubx
        equal = (nlp.lbg == nlp.ubg) & np.isfinite(nlp.lbg)
        self.equality = np.flatnonzero(equal)
        self.upper = np.flatnonzero(~equal & np.isfinite(nlp.ubg))
        self.lower = np.flatnonzero(~equal & np.isfinite(nlp.lbg))
        self.m = nlp.n_constraints
        self.upper_only = np.setdiff1d(self.upper, self.lower)
        self.lower_only = np.setdiff1d(self.lower, self.upper)
        eq, up, lo = self.equality, self.upper, self.lower
        self.select_equality = sp.csr_matrix((np.ones(eq.size), (np.arange(eq.size), eq)), shape=(eq.size, self.m))
        self.select_inequality = sp.csr_matrix((np.concatenate([np.ones(up.size), -np.ones(lo.size)]),
                                                (np.arange(up.size + lo.size), np.concatenate([up, lo]))),
                                               shape=(up.size + lo.size, self.m))
        """Row selections: the QP's A and G as products with the Jacobian, far cheaper than fancy indexing."""
        self.bounded = bool(np.isfinite(nlp.lbx).any() or np.isfinite(nlp.ubx).any())

    @property

    def unconstrained(self) -> bool:
        return not (self.bounded or self.equality.size or self.upper.size or self.lower.size)

    def violations(self, g: np.ndarray) -> np.ndarray:
        """How far each row is outside lbg ≤ g ≤ ubg."""
        return np.maximum(self.lbg - g, 0.0) + np.maximum(g - self.ubg, 0.0)

    def theta(self, g: np.ndarray) -> float:
        """ℓ1 violation of lbg ≤ g ≤ ubg."""
        return float(np.sum(self.violations(g)))

    def max_violation(self, g: np.ndarray) -> float:
        return float(max(np.max(self.lbg - g, initial=0.0), np.max(g - self.ubg, initial=0.0)))

    @staticmethod
    def row_scale(jacobian: sp.csr_matrix) -> np.ndarray | None:
        """1/‖∇g_i‖ (at most 1e6) for the degenerate rows (gradient norm below :data:`DEGENERATE_GRADIENT`), 1 for the
        others; None when no row is degenerate.

        Why: the multiplier of an active row whose gradient vanishes grows as 1/‖∇g_i‖ while its force stays
        bounded. Posed at unit norm, the row's QP dual is that force: with the crossing's clearance at ~1e-4, PIQP
        and its retry failed nearly every QP of the stairs N = 140 step 3's slide (~400 ms an iteration, Clarabel's
        fallback solving them), and scaled they solve (~50 ms) along the same path
        (docs/decisions/0003-sqp-late-step-crawl.md). ``sqp`` scales once the late-step crawl shows
        (``Subproblems._qp``)."""
        norms = row_norms(jacobian)
        degenerate = (norms < DEGENERATE_GRADIENT) & (norms > 0)
        if not degenerate.any():
            return None
        return np.where(degenerate, 1.0 / np.maximum(norms, 1e-6), 1.0)

    def problem(self, P, q: np.ndarray, jacobian: sp.csr_matrix, g: np.ndarray, lb: np.ndarray | None,
                ub: np.ndarray | None, dense: bool, scale: np.ndarray | None = None) -> qpsolvers.Problem:
        """min ½dᵀPd + qᵀd s.t. lbg ≤ g + jacobian·d ≤ ubg, lb ≤ d ≤ ub, in ``qpsolvers`` form, each row multiplied by
        its ``scale`` (:meth:`row_scale`; the outcome's :meth:`multipliers` undo it)."""
        eq, up, lo = self.equality, self.upper, self.lower
        if scale is not None:
            jacobian = (sp.diags(scale) @ jacobian).tocsr()
        A = (self.select_equality @ jacobian).tocsc() if eq.size else None
        b = self.lbg[eq] - g[eq] if eq.size else None
        G = (self.select_inequality @ jacobian).tocsc() if up.size + lo.size else None
        h = np.concatenate([self.ubg[up] - g[up], g[lo] - self.lbg[lo]]) if G is not None else None
        if scale is not None:  # the right-hand sides too; no work on the QPs without a degenerate row
            equality_scale, inequality_scale = self._by_qp_rows(scale)
            b = None if b is None else b * equality_scale
            h = None if h is None else h * inequality_scale
        if dense:
            P = P.toarray() if sp.issparse(P) else P
            A = None if A is None else A.toarray()
            G = None if G is None else G.toarray()
        else:
            P = sp.csc_matrix(P)
        return qpsolvers.Problem(P, q, G, h, A, b, lb, ub)

    def bounds(self, x: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Bounds on the step d keeping lbx ≤ x + d ≤ ubx (None when no variable is bounded)."""
        if not self.bounded:
            return None, None
        return self.lbx - x, self.ubx - x

    def multipliers(self, outcome: QPOutcome) -> np.ndarray:
        """λ_g from the QP duals: y for equalities, +z on upper sides, −z on lower sides, times the rows' scale of
        the QP (``outcome.scale``)."""
        lam = np.zeros(self.m)
        if self.equality.size:
            lam[self.equality] = outcome.y
        if self.upper.size or self.lower.size:
            lam[self.upper] += outcome.z[:self.upper.size]
            lam[self.lower] -= outcome.z[self.upper.size:]
        return lam if outcome.scale is None else lam * outcome.scale

    def rescaled(self, warm: QPOutcome, scale: np.ndarray | None) -> QPOutcome:
        """``warm`` with its duals in the rows' ``scale`` (None: unscaled), for a backend that starts from them: the
        QP it came from may have been posed at another scale (:meth:`row_scale`), and its duals are that QP's."""
        if warm.scale is None and scale is None:
            return warm
        factor = (np.ones(self.m) if warm.scale is None else warm.scale) / (1.0 if scale is None else scale)
        equality_factor, inequality_factor = self._by_qp_rows(factor)
        y = warm.y if warm.y is None or not warm.y.size else warm.y * equality_factor
        z = warm.z if warm.z is None or not warm.z.size else warm.z * inequality_factor
        return replace(warm, y=y, z=z, scale=scale)

    def _by_qp_rows(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A value per row of g laid out as the QP's rows: (its equalities A, its one-sided rows G: upper sides,
        then lower sides)."""
        return values[self.equality], np.concatenate([values[self.upper], values[self.lower]])
