"""The method's sparse linear algebra: KKT systems and their factorization, least-squares multipliers, and the
definiteness and rank tests (a sparse LDLᵀ); a failure is a :class:`Breakdown` of the method, not a bug."""

from __future__ import annotations

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from gaitbench_plugins.solvers.fsqp.outcome import Breakdown

_DENSE_FRACTION = 0.2
"""A KKT matrix with more than this fraction of nonzeros (a dense BFGS block) is factorized by dense LU."""


class Factorization:
    """LU of a KKT matrix: SuperLU when sparse, LAPACK when mostly dense (a BFGS block makes it so)."""

    def __init__(self, matrix: sp.spmatrix) -> None:
        size = matrix.shape[0]
        self.dense = matrix.nnz > _DENSE_FRACTION * size * size
        try:
            if self.dense:
                self.factor = la.lu_factor(matrix.toarray(), check_finite=False)
            else:
                self.factor = spla.splu(sp.csc_matrix(matrix))
        except RuntimeError as error:  # SuperLU: "Factor is exactly singular"
            raise Breakdown(f"singular KKT matrix ({error})") from error

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        if self.dense:
            solution = la.lu_solve(self.factor, rhs, check_finite=False)
        else:
            solution = self.factor.solve(rhs)
        if not np.all(np.isfinite(solution)):
            raise Breakdown("singular KKT matrix (non-finite solution)")
        return solution


def kkt(hessian, rows: sp.csr_matrix, lower: np.ndarray | None = None) -> sp.csc_matrix:
    """[[H, Aᵀ], [A, diag(lower) or 0]] with A's rows the active gradients (the thesis's A is its transpose)."""
    if rows.shape[0] == 0:
        return sp.csc_matrix(hessian)
    corner = sp.diags(lower) if lower is not None else sp.csr_matrix((rows.shape[0], rows.shape[0]))
    return sp.bmat([[sp.csr_matrix(hessian), rows.T], [rows, corner]], format="csc")


def least_squares_multipliers(jacobian: sp.csr_matrix, gradient: np.ndarray, c: np.ndarray,
                               n_ineq: int) -> np.ndarray:
    """π = −(NᵀN + D)⁻¹Nᵀ∇f (11.8) over all rows, D = c_j² on the inequalities; a 1e-12 relative ridge keeps it
    defined where exactly active gradients are dependent."""
    if c.size == 0:
        return np.zeros(0)
    weights = np.zeros(c.size)
    weights[:n_ineq] = c[:n_ineq] ** 2
    normal = (jacobian @ jacobian.T + sp.diags(weights)).tocsc()
    normal += sp.eye(c.size, format="csc") * 1e-12 * max(1.0, float(normal.diagonal().max()))
    return -spla.splu(normal).solve(jacobian @ gradient)


def symmetric_pivots(matrix: sp.spmatrix) -> np.ndarray | None:
    """Pivots of LDLᵀ of a symmetric matrix (SuperLU, symmetric ordering, diagonal pivots); None if it needed
    off-diagonal pivots or is exactly singular."""
    try:
        lu = spla.splu(sp.csc_matrix(matrix), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})
    except RuntimeError:
        return None
    if not np.array_equal(lu.perm_r, lu.perm_c):
        return None
    return lu.U.diagonal()


def positive_definite(matrix: sp.spmatrix, threshold: float = 1e-12) -> bool:
    """Whether every LDLᵀ pivot exceeds ``threshold`` × the largest diagonal entry (at least 1)."""
    pivots = symmetric_pivots(matrix)
    scale = max(1.0, float(np.max(np.abs(matrix.diagonal()), initial=0.0)))
    return pivots is not None and bool(np.all(pivots > threshold * scale))


def full_row_rank(rows: sp.csr_matrix, tolerance: float) -> bool:
    """Whether the active gradients are independent: pivots of the normalized Gram matrix ≥ tolerance²."""
    count, n = rows.shape
    if count == 0:
        return True
    norms = row_norms(rows)
    if count > n or np.any(norms == 0):
        return False
    normalized = sp.diags(1 / norms) @ rows
    pivots = symmetric_pivots(normalized @ normalized.T)
    return pivots is not None and bool(np.all(pivots >= tolerance ** 2))


def row_norms(rows: sp.csr_matrix) -> np.ndarray:
    return np.sqrt(np.asarray(rows.multiply(rows).sum(axis=1)).ravel())


