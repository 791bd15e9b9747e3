"""Diagonal variable and constraint scaling of an NLP, for solvers that do not scale both themselves.

    x = d ⊙ x̃,   g̃(x̃) = g(d ⊙ x̃) / c

IPOPT's own scaling only scales constraint rows *down* (a gradient above 100) and never the variables; a gait
step mixes angles of 0.1 rad, torques of tens of N·m and power slacks in W. ``nominal_factors`` gives each
variable block the magnitude of its initial guess and each constraint row a unit gradient in the scaled
variables at that guess (Betts, *Practical Methods for Optimal Control*, §4.8).

The factors are parameters of the scaled problem (p̃ = [p; d; c]), so one solver built on it serves every
scaling: a walk's steps and a D&C step's sections each start from another guess. The objective is not scaled
here; IPOPT's ``nlp_scaling_obj_target_gradient`` does that (docs/performance.md, "Objective scaling").
A solver's tolerances then hold in the scaled units: a row scaled down by c is met to c × tol in its own.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import casadi as ca
import numpy as np
from scipy.sparse import diags

from gaitbench.problem.nlp import NLP

SCALINGS = ("none", "nominal")
"""The ``scaling`` option of the solver plugins that offer it: ``none``, the solver's own scaling only; ``nominal``,
variables and constraint rows scaled first by :func:`nominal_factors`, from each solve's initial guess."""

FACTOR_RANGE = (1e-6, 1e6)
"""Every factor is clipped to this range; a variable block guessed at 0, or a row without gradient, gets 1."""


@dataclass(frozen=True)
class ScaleFactors:
    """Per-variable ``d`` and per-constraint-row ``c``, both positive."""

    variables: np.ndarray
    constraints: np.ndarray

    def parameters(self, p: np.ndarray) -> np.ndarray:
        """The scaled problem's parameter vector p̃ = [p; d; c]."""
        return np.concatenate([np.asarray(p, dtype=float).ravel(), self.variables, self.constraints])


def nominal_factors(nlp: NLP, x0: np.ndarray, p: np.ndarray) -> ScaleFactors:
    """Variables: each block's largest |x0| (1 where the guess is 0). Rows: the max-norm of the row's gradient
    with respect to the scaled variables at x0 (1 where it is 0), so every scaled row starts with unit gradient."""
    x0 = np.asarray(x0, dtype=float).ravel()
    d = np.ones(nlp.n_variables)
    for block in nlp.variable_blocks.values():
        magnitude = float(np.max(np.abs(x0[block]), initial=0.0))
        d[block] = magnitude if magnitude > 0.0 else 1.0
    d = np.clip(d, *FACTOR_RANGE)
    jacobian = abs(nlp.functions.jacobian(x0, p).sparse() @ diags(d))
    rows = jacobian.max(axis=1).toarray().ravel()
    c = np.clip(np.where(rows > 0.0, rows, 1.0), *FACTOR_RANGE)
    return ScaleFactors(d, c)


class ScaledProblem:
    """The scaled problem's functions in the forms ``casadi.nlpsol`` takes, over (x̃, p̃).

    Built from the NLP's own functions, so interval blocks keep their compiled derivatives: the scaled Jacobian is
    diag(1/c) J diag(d), the scaled Hessian diag(d) ∇²L(x; σ, λ̃/c) diag(d), both with J's and ∇²L's sparsity.
    """

    def __init__(self, nlp: NLP) -> None:
        self._nlp = nlp
        n, m, n_p = nlp.n_variables, nlp.n_constraints, nlp.p.numel()
        self._x = ca.MX.sym("x_scaled", n)
        self._parameters = ca.MX.sym("p_scaled", n_p + n + m)
        self._p = self._parameters[:n_p]
        self._d = self._parameters[n_p:n_p + n]
        self._c = self._parameters[n_p + n:]
        self._unscaled_x = self._d * self._x

    @cached_property
    def oracle(self) -> dict[str, ca.MX]:
        functions = self._nlp.functions
        return {"x": self._x, "p": self._parameters, "f": functions.objective(self._unscaled_x, self._p),
                "g": functions.constraints(self._unscaled_x, self._p) / self._c}

    @cached_property
    def constraints_and_jacobian(self) -> ca.Function:
        """(g̃, ∂g̃/∂x̃): the form of ``nlpsol``'s ``jac_g`` option."""
        g, jacobian = self._nlp.functions.constraints_and_jacobian(self._unscaled_x, self._p)
        return ca.Function("jac_g", [self._x, self._parameters],
                           [g / self._c, _scale_entries(jacobian, 1.0 / self._c, self._d)])

    @cached_property
    def hessian_lagrangian_upper(self) -> ca.Function:
        """The upper triangle of ∇²_x̃ (σ f + λ̃·g̃): the form of ``nlpsol``'s ``hess_lag`` option."""
        sigma, lam = ca.MX.sym("sigma"), ca.MX.sym("lam", self._nlp.n_constraints)
        hessian = self._nlp.functions.hessian_lagrangian_upper(self._unscaled_x, self._p, sigma, lam / self._c)
        return ca.Function("hess_l", [self._x, self._parameters, sigma, lam],
                           [_scale_entries(hessian, self._d, self._d)])


def _scale_entries(matrix: ca.MX, row_factors: ca.MX, column_factors: ca.MX) -> ca.MX:
    """diag(row_factors) · matrix · diag(column_factors), entry by entry on matrix's own sparsity."""
    rows, cols = matrix.sparsity().get_triplet()
    entries = ca.vec(matrix.nz[:]) * ca.vec(row_factors[rows]) * ca.vec(column_factors[cols])
    return ca.MX(matrix.sparsity(), entries)
