"""Gait QPs saved from solves (``tests/data``), for tests of how the QP backends are called on the QPs that made
each setting necessary."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import qpsolvers
import scipy.sparse as sp

DATA = Path(__file__).parent / "data"


def saved_qp(name: str) -> qpsolvers.Problem:
    """The QP ``tests/data/<name>.npz``, saved by ``np.savez`` as its vectors and the CSC parts of P, G and A."""
    saved = np.load(DATA / f"{name}.npz")
    matrices = {part: sp.csc_matrix((saved[f"{part}_data"], saved[f"{part}_indices"], saved[f"{part}_indptr"]),
                                    shape=tuple(saved[f"{part}_shape"])) for part in ("P", "G", "A")}
    return qpsolvers.Problem(matrices["P"], saved["q"], matrices["G"], saved["h"], matrices["A"], saved["b"],
                             saved["lb"], saved["ub"])


def clarabel_objective(problem: qpsolvers.Problem) -> float:
    """The QP's optimal value as Clarabel finds it at the tolerance the solvers ask of their backends (1e-10)."""
    x = qpsolvers.solve_problem(problem, solver="clarabel", tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10).x
    return float(0.5 * x @ problem.P @ x + problem.q @ x)
