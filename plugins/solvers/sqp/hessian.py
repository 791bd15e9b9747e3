"""The QP matrix P of an iteration: the Hessian of the Lagrangian made positive definite, or damped BFGS (see the
package docstring for the convexification and the Levenberg–Marquardt control of its shift)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg.lapack
import scipy.sparse as sp
import scipy.sparse.linalg

from gaitbench_plugins.solvers.sqp.linearization import DEGENERATE_GRADIENT, Linearization, row_norms


@dataclass
class Model:
    """The QP matrix P of one iteration and how it was made positive definite."""

    P: np.ndarray | sp.csc_matrix
    """Sparse for the exact Hessian, dense for BFGS."""
    curvature: np.ndarray | sp.csc_matrix
    """P without the augmentation: the curvature the ℓ1 weight update may rely on."""
    rows: np.ndarray
    """The rows of g in the augmentation (empty when there is none)."""
    weights: np.ndarray
    """ρ/‖∇g_i‖² for those rows, to correct their multipliers."""
    shift: float
    linear: np.ndarray | None = None
    """The variables the shift was taken off (:func:`release_linear_variables`), whose steps the QP bounds."""


SHIFT_FLOOR = 1e-10
"""The shift's floor relative to max|H|: H + δI with δ at the floor lifts only directions without curvature."""
CRAWL_SHIFT_FLOOR = 1e-12
"""The floor of the ``crawl-floor`` last resort once the late-step crawl shows (``Subproblems._model``). max|H| is
set by H's largest entries (~2e4 on the stairs step 3 at N = 80; ~7e6 where multipliers reach ~5e5), so 1e-10 of
it can be the only curvature along the cost's valleys, and the steps along them their reduced gradient over it:
that step slid to the iteration limit, f falling ~2e-4 an iteration; with 1e-12 it converges in 477
(docs/decisions/0003-sqp-late-step-crawl.md). Not lower: at 1e-13 PIQP fails the QPs and the iteration cycles through
elastic steps."""


DEGENERATE_MULTIPLIER_CAP = 1e3
"""The largest multiplier a degenerate row brings into the Hessian (:func:`hessian_multipliers`)."""


def hessian_multipliers(lam: np.ndarray, jacobian: sp.csr_matrix) -> np.ndarray:
    """The multipliers the Hessian of the Lagrangian is built with: ``lam``, with those of rows whose gradient nearly
    vanishes (norm below :data:`DEGENERATE_GRADIENT`) capped at :data:`DEGENERATE_MULTIPLIER_CAP` in magnitude.

    Why: where a row's gradient vanishes at an active point, the constraint qualification fails there, its
    multiplier grows as 1/‖∇c_i‖ while its force λ_i·∇c_i stays bounded, and its curvature λ_i·∇²c_i comes to
    dominate H and pins the iterate. On the gait steps that row is the clearance at the node where the legs cross
    (a product of two factors that both change sign in the stride, zero whatever the stance angle there): stairs
    N = 140, step 5, spent ~800 of its 3,000 iterations, at 10x their cost, with that multiplier climbing from 1e4
    to 1e6 (docs/decisions/0006-sqp-clearance-saddle.md). The QP's rows, the merit's weights
    and the KKT test keep the multipliers as they are."""
    over = np.abs(lam) > DEGENERATE_MULTIPLIER_CAP
    if not over.any():
        return lam
    rows = np.flatnonzero(over)
    degenerate = rows[row_norms(jacobian[rows]) < DEGENERATE_GRADIENT]
    if not degenerate.size:
        return lam
    capped = lam.copy()
    capped[degenerate] = np.sign(lam[degenerate]) * DEGENERATE_MULTIPLIER_CAP
    return capped


def hessian_scale(H: sp.csc_matrix) -> float:
    """max(1, max|H|): what the shift's floor and every rounding-level diagonal are relative to."""
    return max(1.0, float(np.max(np.abs(H.data), initial=0.0)))


def convexify(H: sp.csc_matrix, shift: float, shift_growth: float, jacobian: sp.csr_matrix,
              working_set: Callable[[], tuple[np.ndarray, np.ndarray]],
              relative_floor: float = SHIFT_FLOOR) -> tuple[Model, float]:
    """H made positive definite (package docstring), and the shift to remember for the next iteration's damping.

    ``shift`` is the last iteration's, ``shift_growth`` the factor the line search chose for it; ``working_set``
    gives the (rows, variables) to augment, asked only when the shift alone does not suffice; ``relative_floor``
    is the shift's floor relative to max|H|, below which the remembered shift is 0."""
    scale = hessian_scale(H)
    floor = relative_floor * scale
    damping = shift * shift_growth  # the Levenberg–Marquardt part (``LineSearch._l1_search``)
    if shift_growth > 1:  # at most max|H|: beyond, a gradient step that only gets shorter
        damping = min(max(damping, 1e-8 * scale), scale)
    floor = max(floor, damping)
    kept_shift = damping if damping > relative_floor * scale else 0.0
    identity = sp.eye(H.shape[0], format="csc")
    regularised = (H + floor * identity).tocsc()
    if positive_definite(regularised):
        return Model(regularised, regularised, np.zeros(0, dtype=int), np.zeros(0), floor), kept_shift
    rows, bounds = working_set()
    normals = jacobian[rows]
    inverse_norms = 1.0 / np.maximum(np.asarray(normals.multiply(normals).sum(axis=1)).ravel(), 1e-300)
    at_bound = np.zeros(H.shape[0])
    at_bound[bounds] = 1.0
    gram = (normals.T @ sp.diags(inverse_norms) @ normals + sp.diags(at_bound)).tocsc()
    for rho in (1.0, 1e1, 1e2, 1e3, 1e4):  # the least that works: a large ρ makes the QP ill-conditioned
        P = (regularised + rho * scale * gram).tocsc()
        if positive_definite(P):
            return Model(P, regularised, rows, rho * scale * inverse_norms, floor), kept_shift
    augmentation = 1e2 * scale * gram
    shift = max(floor, 1e-8 * scale)
    while shift <= 1e10 * scale:
        curvature = (H + shift * identity).tocsc()
        P = (curvature + augmentation).tocsc()
        if positive_definite(P):
            return Model(P, curvature, rows, 1e2 * scale * inverse_norms, shift), shift
        shift *= 4
    raise FloatingPointError("no shift up to 1e10·max|H| makes the Hessian of the Lagrangian positive definite")


LINEAR_STEP = 1.0
"""The step bound on a released variable, relative to 1 + |x_i|: once released, only its bounds and the rows it
enters limit it, and on the gait steps those leave directions along which the cost is flat."""


def release_linear_variables(model: Model, H: sp.csc_matrix) -> Model:
    """``model`` with the shift taken off the variables H has no curvature in (an empty column; on the gait steps the
    power slacks s± of the charged powers, which enter the cost and their split rows linearly), their steps bounded
    by :data:`LINEAR_STEP` instead; ``model`` itself when that leaves P not positive definite on the rest.

    Why: the shift was those variables' only curvature, so the QP's step along them was the reduced gradient over
    the shift. Along the cost's flat valleys (reduced gradients ~1e-8) that made the QP nearly unbounded, PIQP
    failed it, and the steps, of the same direction at every iteration, moved f by ~2e-8 each while keeping the
    split rows violated: the late-step crawl (docs/decisions/0003-sqp-late-step-crawl.md). Released and bounded, the
    step on them is the linear programme's, to a bound or to where the rows stop it; a bound alone, with the shift kept,
    did not end the crawl on DMOC (forward DMOC N = 100, step 2: iteration limit on every rung). Released from the first
    iteration it moved the first steps' paths (forward HS N = 50, 3-step walk: ACOT 0.0557 against 0.0504), so
    ``Subproblems._model`` releases only once the shift has sat at its floor."""
    linear = np.asarray(abs(H).sum(axis=0)).ravel() == 0
    if model.shift == 0 or not linear.any():
        return model
    release = sp.diags(model.shift * linear.astype(float), format="csc")
    P = (model.P - release).tocsc()
    scale = hessian_scale(H)
    # P is now singular along the released variables the rows do not tie down: test the rest with a rounding-level
    # diagonal on them (in the augmented forms the shift on them may have been what made P definite)
    if model.rows.size and not positive_definite(P + sp.diags(1e-12 * scale * linear.astype(float), format="csc")):
        return model
    curvature = (sp.csc_matrix(model.curvature) - release).tocsc()
    return Model(P, curvature, model.rows, model.weights, model.shift, linear)


def working_set(lin: Linearization, x: np.ndarray, g: np.ndarray, lam: np.ndarray, bound_multipliers: np.ndarray,
                kept_inside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rows, bounds) to augment: the equalities, the inequality rows that are violated, carry a multiplier, or
    are within 1e-6 of a bound unless ``kept_inside`` says the last QPs kept them strictly inside, and the
    variables within 1e-8 of a bound whose multiplier does not push them off it.

    Augmented, such a variable could not leave its bound: forward HS N = 50, step 6, a torque 5e-6 from its lower
    bound with a multiplier of the upper sign held the KKT residual at 3.7e-6 for 1,300 iterations. A row near its
    bound that the QP leaves inactive is held the same way: its term ρ·(aᵀd)²/‖a‖² is constant only where the row
    is active, so off its bound it damps every step towards it, and the iterate crept there (forward DMOC N = 100,
    step 1: a clearance row 2e-7 above its bound came down 6e-10 an iteration for 42 iterations, which held the
    KKT residual at 5.5e-4, until it reached its bound with a multiplier of 0.1;
    docs/decisions/0003-sqp-late-step-crawl.md)."""
    significant = 1e-6 * max(1.0, float(np.max(np.abs(lam), initial=0.0)))  # interior-point duals never
    near = 1e-6 * (1.0 + np.abs(np.where(np.isfinite(lin.ubg), lin.ubg, 0.0)))  # vanish on inactive rows
    upper = lin.upper[((g[lin.upper] >= lin.ubg[lin.upper] - near[lin.upper]) & ~kept_inside[lin.upper])
                      | (g[lin.upper] > lin.ubg[lin.upper]) | (lam[lin.upper] > significant)]
    near = 1e-6 * (1.0 + np.abs(np.where(np.isfinite(lin.lbg), lin.lbg, 0.0)))
    lower = lin.lower[((g[lin.lower] <= lin.lbg[lin.lower] + near[lin.lower]) & ~kept_inside[lin.lower])
                      | (g[lin.lower] < lin.lbg[lin.lower]) | (lam[lin.lower] < -significant)]
    rows = np.unique(np.concatenate([lin.equality, upper, lower]))
    at_bound = (((x - lin.lbx <= 1e-8 * (1.0 + np.abs(x))) & (bound_multipliers <= 0))
                | ((lin.ubx - x <= 1e-8 * (1.0 + np.abs(x))) & (bound_multipliers >= 0)))
    return rows, np.flatnonzero(at_bound)


def damped_bfgs_update(B: np.ndarray, s: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Powell's damped BFGS update: keeps the approximation positive definite whatever the curvature (B itself when
    the step s is below rounding)."""
    Bs = B @ s
    sBs = s @ Bs
    if sBs <= 1e-16 * max(1.0, s @ s):
        return B
    sy = s @ y
    theta = 1.0 if sy >= 0.2 * sBs else 0.8 * sBs / (sBs - sy)
    r = theta * y + (1 - theta) * Bs
    return B - np.outer(Bs, Bs) / sBs + np.outer(r, r) / (s @ r)


def positive_definite(matrix: np.ndarray | sp.spmatrix) -> bool:
    """Whether a symmetric matrix is positive definite: by Sylvester's law, iff its LDLᵀ factorisation without
    pivoting has a positive D. SuperLU gives that factorisation when told to pivot on the diagonal only
    (``diag_pivot_thresh=0``) in symmetric mode, U's diagonal being D; if it pivoted off the diagonal anyway the
    test says no. Sparse: 1 ms at HS N = 100 (n = 999) against 14–30 ms for a dense Cholesky. A dense matrix (the
    BFGS one) gets LAPACK's Cholesky."""
    if not sp.issparse(matrix):
        return scipy.linalg.lapack.dpotrf(matrix, lower=1, clean=0)[1] == 0
    try:
        factor = scipy.sparse.linalg.splu(sp.csc_matrix(matrix), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                                          options={"SymmetricMode": True})
    except RuntimeError:  # exactly singular
        return False
    return bool(np.array_equal(factor.perm_r, factor.perm_c) and np.all(factor.U.diagonal() > 0))
