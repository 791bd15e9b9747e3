"""The matrix H of the subproblems: the exact Hessian of the Lagrangian made positive definite (for the equality
subproblem as in the class docstring, for the ``qp`` subproblem as ``sqp`` does), or damped BFGS."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from gaitbench_plugins.solvers.fsqp.form import NLPForm
from gaitbench_plugins.solvers.fsqp.linalg import positive_definite, row_norms
from gaitbench_plugins.solvers.fsqp.outcome import Breakdown

_AUGMENTATION = 1e2
"""ρ̄ of the exact-Hessian convexification H + ρ̄ ÂᵀÂ + δI, relative to the Hessian's largest diagonal entry."""

SHIFT_RANGE = (1e-8, 1e10)
"""Smallest and largest shift δ of the exact-Hessian convexification, relative to its largest diagonal entry."""

_QP_SHIFT_FLOOR = 1e-14
"""The ``qp`` subproblem's least shift, relative to max|∇²L| (see :func:`qp_hessian`)."""

_QP_PIVOT = 1e-15
"""Least LDLᵀ pivot of the ``qp`` subproblem's H, relative to its largest diagonal entry: the augmentation makes
that entry ~100·max|∇²L|, so the default 1e-12 refused any shift below ~1e-10·max|∇²L|."""


class BFGS:
    """Dense damped BFGS (Powell): yᵀs ≥ 0.2 sᵀHs is enforced by mixing y with Hs, so H stays positive definite."""

    def __init__(self, n: int, h0_scaling: str | float) -> None:
        self.matrix = np.eye(n) * (1.0 if h0_scaling == "auto" else float(h0_scaling))
        self.rescale = h0_scaling == "auto"

    def update(self, s: np.ndarray, y: np.ndarray) -> None:
        """The damped update; skipped when sᵀHs vanishes (s below rounding)."""
        if self.rescale and y @ s > 0:
            self.matrix *= (y @ y) / (y @ s)
        self.rescale = False
        hs = self.matrix @ s
        shs, ys = s @ hs, y @ s
        if not shs > 0:
            return
        if ys < 0.2 * shs:
            mix = 0.8 * shs / (shs - ys)
            y = mix * y + (1 - mix) * hs
            ys = y @ s
        self.matrix += np.outer(y, y) / ys - np.outer(hs, hs) / shs


def qp_hessian(form: NLPForm, x: np.ndarray, u: np.ndarray, rows: sp.csr_matrix,
                damping: float) -> tuple[sp.csc_matrix, float, sp.csc_matrix]:
    """∇²L(x, u⁺) + δI made positive definite as ``sqp`` does: δ = max(damping, 1e-14 max|H|), then the least
    ρ max|H| Σ â âᵀ (ρ = 1, 10, …, 10⁴; â the working rows, normalized) that factorizes, then ρ = 10⁴ with δ
    growing ×4 from there, so that it stays within 4× of the least shift that works. Returns H, the augmentation's
    factor (for the multiplier correction) and H without the augmentation (for the KKT test).

    Along the thesis cost's flat valleys ∇²L has no curvature, so δ sets the QP's step length there (d = −g/δ),
    and the merit falls by twice the model's decrease. A shift that jumped to 1e-8·max|H| (``sqp``'s), or that the
    pivot test held near 1e-10·max|H|, made forward step 2 (HS, N = 50) crawl by ~1e-6 of merit per iteration to
    the iteration limit; the Levenberg–Marquardt damping still raises δ where the model reaches too far. The last
    rung keeps the largest ρ tried: with ρ = 100 there, forward step 2 (DMOC, N = 50) needed δ ≈ 1.7e-7·max|H| in
    the second convexification (over the rows the QP held), and crawled by ~1.5e-7 of merit per iteration to the
    iteration limit; with ρ = 10⁴ the shifts of that stretch were 2e-10–9e-9·max|H|."""
    multipliers = u.copy()
    multipliers[: form.n_inequalities] = np.maximum(multipliers[: form.n_inequalities], 0.0)
    lagrangian = form.hessian(x, multipliers)
    if not np.all(np.isfinite(lagrangian.data)):
        raise Breakdown("NaN or infinite Hessian of the Lagrangian")
    size = max(1.0, float(np.max(np.abs(lagrangian.data), initial=0.0)))
    shift = max(damping, _QP_SHIFT_FLOOR * size)
    shifted = (lagrangian + shift * sp.eye(form.n)).tocsc()
    if positive_definite(shifted, _QP_PIVOT):
        return shifted, 0.0, shifted
    normals = sp.diags(1 / row_norms(rows)) @ rows
    gram = (normals.T @ normals).tocsc()
    for rho in (1.0, 10.0, 100.0, 1e3, 1e4):
        augmented = (shifted + rho * size * gram).tocsc()
        if positive_definite(augmented, _QP_PIVOT):
            return augmented, rho * size, shifted
    augmentation = 1e4 * size
    while shift <= SHIFT_RANGE[1] * size:
        shift *= 4
        base = (lagrangian + shift * sp.eye(form.n)).tocsc()
        candidate = (base + augmentation * gram).tocsc()
        if positive_definite(candidate, _QP_PIVOT):
            return candidate, augmentation, base
    raise Breakdown("the Hessian of the Lagrangian cannot be made positive definite")


def convexified_hessian(form: NLPForm, x: np.ndarray, pi: np.ndarray, rows: sp.csr_matrix,
                         shift: float) -> tuple[sp.csc_matrix, float, float]:
    """∇²L(x, π⁺) made positive definite: (H, ρ, δ) of H = ∇²L + ρ ÂᵀÂ + δI (see the class docstring)."""
    multipliers = pi.copy()
    multipliers[: form.n_inequalities] = np.maximum(multipliers[: form.n_inequalities], 0.0)
    lagrangian = form.hessian(x, multipliers)
    if not np.all(np.isfinite(lagrangian.data)):
        raise Breakdown("NaN or infinite Hessian of the Lagrangian")
    if positive_definite(lagrangian):
        return lagrangian, 0.0, 0.0
    scale = max(1.0, float(np.max(np.abs(lagrangian.diagonal()), initial=0.0)))
    normalized = sp.diags(1 / row_norms(rows)) @ rows
    augmentation = _AUGMENTATION * scale
    augmented = (lagrangian + augmentation * (normalized.T @ normalized)).tocsc()
    if positive_definite(augmented):
        return augmented, augmentation, 0.0
    low, high = SHIFT_RANGE
    shift = max(low * scale, shift / 4)
    while shift <= high * scale:
        shifted = (augmented + shift * sp.eye(form.n)).tocsc()
        if positive_definite(shifted):
            return shifted, augmentation, shift
        shift *= 8
    raise Breakdown("the Hessian of the Lagrangian cannot be made positive definite")

