"""The NLP in the thesis's form c_j(x) ≤ 0 (general rows, then bounds), c_j(x) = 0 (equalities), with IPOPT's
gradient-based scaling of its rows."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from gaitbench.solve.evaluation import NLPEvaluator

_MAX_GRADIENT = 100.0
"""Gradient-based scaling target (IPOPT's ``nlp_scaling_max_gradient``): rows whose gradient at the start exceeds
it in the max-norm are scaled down to it, so ε0 and the margins ‖d0‖^ν mean the same on every row."""


class NLPForm:
    """A gaitbench NLP in the thesis's form: rows c_j(x) ≤ 0 first (general, then bounds), equalities c_j(x) = 0 last.

    c(x) = r ⊙ (S_g g(x) + S_x x + o) with sparse selection matrices S_g, S_x holding each row's sign, offsets o
    from the bounds, and row factors r: the gradient-based scaling times the orientation sign of the equalities.
    The objective is scaled by ``objective_scale``.
    """

    def __init__(self, evaluator: NLPEvaluator, x: np.ndarray, scaling: str) -> None:
        nlp = evaluator.nlp
        self.evaluator = evaluator
        self.n = nlp.n_variables
        lbg, ubg, lbx, ubx = (np.asarray(v, dtype=float).ravel() for v in (nlp.lbg, nlp.ubg, nlp.lbx, nlp.ubx))
        equal, fixed = lbg == ubg, lbx == ubx
        g_blocks = [(np.flatnonzero(~equal & np.isfinite(ubg)), 1.0, ubg),
                    (np.flatnonzero(~equal & np.isfinite(lbg)), -1.0, lbg)]
        x_blocks = [(np.flatnonzero(~fixed & np.isfinite(ubx)), 1.0, ubx),
                    (np.flatnonzero(~fixed & np.isfinite(lbx)), -1.0, lbx)]
        blocks = [("g", *block) for block in g_blocks] + [("x", *block) for block in x_blocks]
        blocks += [("g", np.flatnonzero(equal), 1.0, lbg), ("x", np.flatnonzero(fixed), 1.0, lbx)]
        self.n_general = sum(index.size for index, _, _ in g_blocks)
        self.n_equal_g = int(np.count_nonzero(equal))
        self.n_inequalities = self.n_general + sum(index.size for index, _, _ in x_blocks)
        self.m = sum(index.size for _, index, _, _ in blocks)
        rows, start = {"g": ([], [], []), "x": ([], [], [])}, 0
        offset = np.zeros(self.m)
        for source, index, sign, bound in blocks:
            row = np.arange(start, start + index.size)
            rows[source][0].append(row)
            rows[source][1].append(index)
            rows[source][2].append(np.full(index.size, sign))
            offset[row] = -sign * bound[index]
            start += index.size
        self.select_g, self.select_x = (
            sp.csr_matrix((np.concatenate(v), (np.concatenate(r), np.concatenate(c))), shape=(self.m, size))
            for (r, c, v), size in ((rows["g"], nlp.n_constraints), (rows["x"], self.n)))
        self.offset = offset
        self.lbx, self.ubx, self.free = lbx, ubx, ~fixed
        self.row_factor = np.ones(self.m)
        self.objective_scale = 1.0
        if scaling == "gradient":
            gradient = evaluator.gradient(x)
            jacobian = self.select_g @ evaluator.jacobian(x) + self.select_x
            self.objective_scale = _gradient_scale(np.max(np.abs(gradient), initial=0.0))
            self.row_factor = _gradient_scale(abs(jacobian).max(axis=1).toarray().ravel())

    @property
    def equalities(self) -> slice:
        return slice(self.n_inequalities, self.m)

    def orient(self, x: np.ndarray) -> None:
        """Flip each equality row that is positive at x, so that c_j(x) ≤ 0 holds for every row there."""
        self.flip(self.n_inequalities + np.flatnonzero(self.constraints(x)[self.equalities] > 0))

    def flip(self, rows: np.ndarray) -> None:
        self.row_factor[rows] *= -1

    def admissible(self, x: np.ndarray) -> bool:
        """Within the variable bounds: the cheap, linear rows, checked before the NLP is evaluated."""
        free = self.free
        return bool(np.all(x[free] <= self.ubx[free]) and np.all(x[free] >= self.lbx[free]))

    def objective(self, x: np.ndarray) -> float:
        return self.objective_scale * self.evaluator.objective(x)

    def gradient(self, x: np.ndarray) -> np.ndarray:
        return self.objective_scale * self.evaluator.gradient(x)

    def constraints(self, x: np.ndarray) -> np.ndarray:
        g = self.evaluator.constraints(x) if self.evaluator.m else np.zeros(0)
        return self.row_factor * (self.select_g @ g + self.select_x @ x + self.offset)

    def jacobian(self, x: np.ndarray) -> sp.csr_matrix:
        jacobian = self.select_g @ self.evaluator.jacobian(x) if self.evaluator.m else sp.csr_matrix((self.m, self.n))
        return sp.diags(self.row_factor) @ (jacobian + self.select_x).tocsr()

    def hessian(self, x: np.ndarray, u: np.ndarray, sigma: float = 1.0) -> sp.csc_matrix:
        """∇²(σ f̂ + Σ u_j c_j): only the rows on g are curved."""
        multipliers = self.select_g.T @ (self.row_factor * u)
        return self.evaluator.hessian_lagrangian(x, sigma * self.objective_scale, multipliers)

    def nlp_multipliers(self, u: np.ndarray) -> np.ndarray:
        """λ_g in CasADi's convention (∇f + Jᵀλ_g + λ_x = 0) from the thesis-form multipliers u."""
        return self.select_g.T @ (self.row_factor * u) / self.objective_scale

    def max_violation(self, c: np.ndarray) -> float:
        """The NLP's largest violation in its own units, from the row values c."""
        inequalities = slice(0, self.n_inequalities)
        excess = np.abs(c) / np.abs(self.row_factor)
        excess[inequalities] = np.maximum(c[inequalities], 0.0) / self.row_factor[inequalities]
        return float(np.max(excess, initial=0.0))


def _gradient_scale(gradient_max: np.ndarray | float):
    """Factors that bring gradient max-norms above the target down to it; 1 elsewhere (also for NaN)."""
    gradient_max = np.asarray(gradient_max, dtype=float)
    large = np.isfinite(gradient_max) & (gradient_max > _MAX_GRADIENT)
    return np.where(large, _MAX_GRADIENT / np.where(large, gradient_max, 1.0), 1.0)
