"""One solver-independent NLP: what every transcription produces and every solver consumes.

    minimize f(x, p)  subject to  lbg ≤ g(x, p) ≤ ubg,  lbx ≤ x ≤ ubx

``p`` carries everything that changes between solves of the same structure (initial state, step geometry,
time step, robot parameters), so a built NLP — and a solver built on it — is reused without rebuilding.
Exact sparse first and second derivatives come from CasADi, each built once, on first use.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import casadi as ca
import numpy as np


class NLPFunctions:
    """Compiled callables over (x, p); ``hessian_lagrangian`` takes (x, p, σ_f, λ_g) and is lower-triangular.

    Each is built on first use: checking a solution needs only ``constraints``, and the symbolic Hessian of a
    large step costs seconds and a hundred megabytes that a solver building its own would pay twice.
    """

    def __init__(self, x: ca.SX, p: ca.SX, f: ca.SX, g: ca.SX) -> None:
        self._x, self._p, self._f, self._g = x, p, f, g

    @cached_property
    def objective(self) -> ca.Function:
        return ca.Function("f", [self._x, self._p], [self._f])

    @cached_property
    def constraints(self) -> ca.Function:
        return ca.Function("g", [self._x, self._p], [self._g])

    @cached_property
    def gradient(self) -> ca.Function:
        return ca.Function("grad_f", [self._x, self._p], [ca.gradient(self._f, self._x)])

    @cached_property
    def jacobian(self) -> ca.Function:
        return ca.Function("jac_g", [self._x, self._p], [ca.jacobian(self._g, self._x)])

    @cached_property
    def hessian_lagrangian(self) -> ca.Function:
        sigma = ca.SX.sym("sigma")
        lam = ca.SX.sym("lam", self._g.numel())
        hessian = ca.tril(ca.hessian(sigma * self._f + ca.dot(lam, self._g), self._x)[0])
        return ca.Function("hess_l", [self._x, self._p, sigma, lam], [hessian])


@dataclass
class NLP:
    """Variables with bounds, parameters, objective and constraints, with named blocks for diagnostics."""

    x: ca.SX
    p: ca.SX
    f: ca.SX
    g: ca.SX
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    variable_blocks: dict[str, slice]
    constraint_blocks: dict[str, slice]
    solver_cache: dict = field(default_factory=dict, repr=False)
    """Solvers keep their built instances here, keyed by their options, so re-solving costs no rebuild."""

    @property
    def n_variables(self) -> int:
        return self.x.numel()

    @property
    def n_constraints(self) -> int:
        return self.g.numel()

    @cached_property
    def functions(self) -> NLPFunctions:
        return NLPFunctions(self.x, self.p, self.f, self.g)

    def casadi_problem(self) -> dict[str, ca.SX]:
        """The problem in the dictionary form of ``casadi.nlpsol``."""
        return {"x": self.x, "p": self.p, "f": self.f, "g": self.g}

    def constraint_values(self, x: np.ndarray, p: np.ndarray) -> np.ndarray:
        return np.asarray(self.functions.constraints(x, p)).ravel()

    def violation(self, x: np.ndarray, p: np.ndarray) -> float:
        """Largest violation of any constraint or variable bound (0 when feasible)."""
        g = self.constraint_values(x, p)
        worst = [np.max(self.lbg - g, initial=0.0), np.max(g - self.ubg, initial=0.0)]
        worst += [np.max(self.lbx - x, initial=0.0), np.max(x - self.ubx, initial=0.0)]
        return float(max(worst))

    def block_violations(self, x: np.ndarray, p: np.ndarray) -> dict[str, float]:
        """Largest violation per named constraint block: which physics a bad solution breaks."""
        g = self.constraint_values(x, p)
        excess = np.maximum(np.maximum(self.lbg - g, g - self.ubg), 0.0)
        return {name: float(np.max(excess[block], initial=0.0)) for name, block in self.constraint_blocks.items()}


class NLPBuilder:
    """Collects named variable and constraint blocks while a transcription assembles its NLP."""

    def __init__(self) -> None:
        self._variables: list[tuple[str, ca.SX, np.ndarray, np.ndarray]] = []
        self._constraints: list[tuple[str, ca.SX, np.ndarray, np.ndarray]] = []

    def variable(self, name: str, shape: tuple[int, int], lower=-np.inf, upper=np.inf) -> ca.SX:
        """A (rows × cols) block of decision variables, column-major, with scalar or per-row bounds."""
        symbol = ca.SX.sym(name, *shape)
        self._variables.append((name, symbol, _expand(lower, shape), _expand(upper, shape)))
        return symbol

    def variables(self, name: str) -> ca.SX:
        """A block declared earlier, by name."""
        return next(symbol for block, symbol, _, _ in self._variables if block == name)

    def constrain(self, name: str, expression, lower=0.0, upper=0.0) -> None:
        expression = ca.vec(ca.SX(expression))
        n = expression.numel()
        self._constraints.append((name, expression, np.broadcast_to(lower, n).astype(float),
                                  np.broadcast_to(upper, n).astype(float)))

    def build(self, parameters: ca.SX, objective: ca.SX) -> NLP:
        x, lbx, ubx, variable_blocks = _stack(self._variables)
        g, lbg, ubg, constraint_blocks = _stack(self._constraints)
        return NLP(x=x, p=parameters, f=objective, g=g, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg,
                   variable_blocks=variable_blocks, constraint_blocks=constraint_blocks)


def _expand(bound, shape: tuple[int, int]) -> np.ndarray:
    """Scalar, per-row (length rows) or full bounds, flattened column-major like ``ca.vec``."""
    rows, cols = shape
    bound = np.asarray(bound, dtype=float)
    if bound.ndim == 1 and bound.size == rows:
        bound = np.repeat(bound[:, None], cols, axis=1)
    return np.broadcast_to(bound, shape).flatten(order="F")


def _stack(blocks):
    if not blocks:
        return ca.SX(0, 1), np.zeros(0), np.zeros(0), {}
    expressions, lower, upper, names, start = [], [], [], {}, 0
    for name, expression, lo, hi in blocks:
        flat = ca.vec(expression)
        n = flat.numel()
        if name in names:
            raise ValueError(f"NLP block {name!r} declared twice")
        names[name] = slice(start, start + n)
        start += n
        expressions.append(flat)
        lower.append(lo)
        upper.append(hi)
    return ca.vertcat(*expressions), np.concatenate(lower), np.concatenate(upper), names
