"""What the phases of the method share: the outcome of a phase, the record of an iteration, the breakdown that ends a
phase at its iterate, and when a step is lost in rounding."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gaitbench.solver_result import SolverStatus

ROUNDING = 1e-15
"""The arc search gives up when t‖d‖∞ ≤ this × (1 + ‖x‖∞): the trial no longer differs from x but for rounding."""


class Breakdown(Exception):
    """A failure of the method at the current iterate (not a bug): it becomes an ERROR with that iterate."""


@dataclass
class IterationRecord:
    """One iterate x_k and what iteration k computed there (the rows of the ``print_level ≥ 1`` log)."""

    phase: str
    """"feasibility" (phase 1, Gauss–Newton on the inequality violation) or "main"."""
    iteration: int
    merit: float
    """Main phase: F_c(x_k) = f + c Σ_E |c_j| (scaled units); phase 1: ½‖max(c_I, 0)‖²."""
    d0_norm: float
    """‖d0‖ (phase 1: the length of the Gauss–Newton step)."""
    step: float
    """The accepted arc-search step t_k (NaN for the last iterate)."""
    penalty: float
    """c_k (NaN in phase 1)."""
    active: int
    """|J_k|: near-active inequalities plus equalities (phase 1: the rows of the Gauss–Newton step)."""
    max_violation: float
    """The NLP's largest constraint or bound violation at x_k, in its own units."""
    direction: str
    """"d1" (the feasible direction passed the descent test), "d3" (the Panier–Tits combination), "gn" (phase 1)."""
    x: np.ndarray
    """The NLP's variables at x_k."""


@dataclass
class Outcome:
    """How a phase ended: its status and message, at the point ``x`` after ``iterations`` iterations in all."""

    status: SolverStatus
    message: str
    x: np.ndarray
    iterations: int
    multipliers: np.ndarray | None
    """Multipliers u of the thesis-form rows (∇f + Σ u_j ∇c_j = 0, scaled units), when d0 was computed."""

