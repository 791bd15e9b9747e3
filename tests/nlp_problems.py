"""Small NLPs with published optima, for testing any solver plugin against known answers.

The Hock–Schittkowski problems follow W. Hock and K. Schittkowski, *Test Examples for Nonlinear Programming
Codes*, Lecture Notes in Economics and Mathematical Systems 187, Springer, 1981: the same objective, constraints,
bounds, starting point and reported optimum. Each builder returns a fresh :class:`NLP`, so a test that inspects
``nlp.solver_cache`` sees only its own solves.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from gaitbench.problem.nlp import NLP, NLPBuilder


@dataclass(frozen=True)
class ReferenceProblem:
    """An NLP with parameter values, a starting point and its known optimum (``f_star`` None: there is none)."""

    name: str
    nlp: NLP
    parameters: np.ndarray
    x0: np.ndarray
    f_star: float | None
    x_star: np.ndarray | None


_NO_PARAMETERS = ca.SX.sym("p", 0)


def _problem(name, nlp, x0, f_star, x_star=None, values=()):
    return ReferenceProblem(name, nlp, np.asarray(values, dtype=float), np.asarray(x0, dtype=float), f_star,
                            None if x_star is None else np.asarray(x_star, dtype=float))


def _bound_constrained(x: ca.SX, objective: ca.SX, lower: float = -np.inf, upper: float = np.inf) -> NLP:
    """An NLP without constraints g, assembled directly because ``NLPBuilder.build`` needs a constraint block."""
    n = x.numel()
    return NLP(x=x, p=_NO_PARAMETERS, f=objective, g=ca.SX(0, 1), lbx=np.full(n, lower), ubx=np.full(n, upper),
               lbg=np.zeros(0), ubg=np.zeros(0), variable_blocks={"x": slice(0, n)}, constraint_blocks={})


def hs071() -> ReferenceProblem:
    """HS071: a product objective with a product inequality and a sphere equality (IPOPT's own example)."""
    b = NLPBuilder()
    x = b.variable("x", (4, 1), 1.0, 5.0)
    b.constrain("product", x[0] * x[1] * x[2] * x[3] - 25, 0.0, np.inf)
    b.constrain("sphere", ca.sumsqr(x) - 40)
    nlp = b.build(_NO_PARAMETERS, x[0] * x[3] * (x[0] + x[1] + x[2]) + x[2])
    return _problem("hs071", nlp, [1, 5, 5, 1], 17.0140173, [1.0, 4.7429994, 3.8211503, 1.3794082])


def hs035() -> ReferenceProblem:
    """HS035 (Beale): a convex quadratic over a simplex-like region, the optimum on one linear constraint."""
    b = NLPBuilder()
    x = b.variable("x", (3, 1), 0.0)
    b.constrain("linear", 3 - x[0] - x[1] - 2 * x[2], 0.0, np.inf)
    f = (9 - 8 * x[0] - 6 * x[1] - 4 * x[2] + 2 * x[0] ** 2 + 2 * x[1] ** 2 + x[2] ** 2
         + 2 * x[0] * x[1] + 2 * x[0] * x[2])
    return _problem("hs035", b.build(_NO_PARAMETERS, f), [0.5, 0.5, 0.5], 1 / 9, [4 / 3, 7 / 9, 4 / 9])


def hs038() -> ReferenceProblem:
    """HS038 (Colville's Wood function): two coupled Rosenbrock valleys inside a box."""
    x = ca.SX.sym("x", 4)
    f = (100 * (x[1] - x[0] ** 2) ** 2 + (1 - x[0]) ** 2 + 90 * (x[3] - x[2] ** 2) ** 2 + (1 - x[2]) ** 2
         + 10.1 * ((x[1] - 1) ** 2 + (x[3] - 1) ** 2) + 19.8 * (x[1] - 1) * (x[3] - 1))
    return _problem("hs038", _bound_constrained(x, f, -10.0, 10.0), [-3, -1, -3, -1], 0.0, [1, 1, 1, 1])


def hs039() -> ReferenceProblem:
    """HS039: a linear objective on two nonlinear equalities, degenerate (x3 = x4 = 0) at the optimum."""
    b = NLPBuilder()
    x = b.variable("x", (4, 1))
    b.constrain("cubic", x[1] - x[0] ** 3 - x[2] ** 2)
    b.constrain("quadratic", x[0] ** 2 - x[1] - x[3] ** 2)
    return _problem("hs039", b.build(_NO_PARAMETERS, -x[0]), [2, 2, 2, 2], -1.0, [1, 1, 0, 0])


def hs040() -> ReferenceProblem:
    """HS040: a product objective on three nonlinear equalities; x* = 2^(-1/3, -1/2, -11/12, -1/4)."""
    b = NLPBuilder()
    x = b.variable("x", (4, 1))
    b.constrain("cubic", x[0] ** 3 + x[1] ** 2 - 1)
    b.constrain("product", x[0] ** 2 * x[3] - x[2])
    b.constrain("square", x[3] ** 2 - x[1])
    nlp = b.build(_NO_PARAMETERS, -x[0] * x[1] * x[2] * x[3])
    return _problem("hs040", nlp, [0.8] * 4, -0.25, 2.0 ** -np.array([1 / 3, 1 / 2, 11 / 12, 1 / 4]))


def hs076() -> ReferenceProblem:
    """HS076: a convex quadratic with three linear inequalities; x* = (3, 23, 0, 6)/11, f* = -103/22."""
    b = NLPBuilder()
    x = b.variable("x", (4, 1), 0.0)
    b.constrain("first", 5 - x[0] - 2 * x[1] - x[2] - x[3], 0.0, np.inf)
    b.constrain("second", 4 - 3 * x[0] - x[1] - 2 * x[2] + x[3], 0.0, np.inf)
    b.constrain("third", x[1] + 4 * x[2] - 1.5, 0.0, np.inf)
    f = (x[0] ** 2 + 0.5 * x[1] ** 2 + x[2] ** 2 + 0.5 * x[3] ** 2 - x[0] * x[2] + x[2] * x[3]
         - x[0] - 3 * x[1] + x[2] - x[3])
    return _problem("hs076", b.build(_NO_PARAMETERS, f), [0.5] * 4, -4.681818181, np.array([3, 23, 0, 6]) / 11)


def rosenbrock() -> ReferenceProblem:
    """Rosenbrock's banana valley, unconstrained, from the classic start (-1.2, 1)."""
    return extended_rosenbrock(2)


def extended_rosenbrock(n: int) -> ReferenceProblem:
    """``n / 2`` independent Rosenbrock valleys: a larger unconstrained problem with the same optimum, x* = 1."""
    x = ca.SX.sym("x", n)
    odd, even = x[0::2], x[1::2]
    f = ca.sumsqr(10 * (even - odd ** 2)) + ca.sumsqr(1 - odd)
    name = "rosenbrock" if n == 2 else f"extended-rosenbrock-{n}"
    return _problem(name, _bound_constrained(x, f), np.tile([-1.2, 1.0], n // 2), 0.0, np.ones(n))


def nonnegative_projection(target: float) -> ReferenceProblem:
    """min (x - p)² s.t. x ≥ 0 at p = ``target``: re-solve ``.nlp`` with another p to test parameter reuse."""
    b = NLPBuilder()
    x = b.variable("x", (1, 1))
    p = ca.SX.sym("p")
    b.constrain("nonnegative", x, 0.0, np.inf)
    f_star, x_star = projection_optimum(target)
    return _problem("nonnegative-projection", b.build(p, (x - p) ** 2), [1.0], f_star, x_star, values=[target])


def projection_optimum(target: float) -> tuple[float, np.ndarray]:
    """(f*, x*) of :func:`nonnegative_projection`: x* = max(p, 0), f* = min(p, 0)²."""
    return min(target, 0.0) ** 2, np.array([max(target, 0.0)])


def infeasible() -> ReferenceProblem:
    """x ≥ 1 and x ≤ 0 as two constraints (not bounds, which a solver could reject before iterating)."""
    b = NLPBuilder()
    x = b.variable("x", (1, 1))
    b.constrain("at_least_one", x, 1.0, np.inf)
    b.constrain("at_most_zero", x, -np.inf, 0.0)
    return _problem("infeasible", b.build(_NO_PARAMETERS, x ** 2), [0.5], None)


def undefined_at_start() -> ReferenceProblem:
    """min √x from x = -1, where the objective is NaN: a solver must report an error, not crash or converge."""
    x = ca.SX.sym("x")
    return _problem("undefined-at-start", _bound_constrained(x, ca.sqrt(x)), [-1.0], None)


STANDARD_PROBLEMS: list[ReferenceProblem] = [
    hs071(), hs035(), hs038(), hs039(), hs040(), hs076(), rosenbrock(), nonnegative_projection(-1.0),
]
"""Every feasible problem with a known optimum, from its standard starting point."""
