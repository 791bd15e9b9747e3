"""The options of an ``fsqp`` solve, checked when they are built: what the phases of a solve read, apart from the
solver that runs them. Each option is described in the :class:`~plugins.solvers.fsqp.solver.FSQP` docstring."""

from __future__ import annotations

from dataclasses import dataclass

from gaitbench.options import SolverOptions


@dataclass(frozen=True, eq=False)
class FSQPOptions(SolverOptions):
    """The ``fsqp`` solver's options, after the four every solver shares (a bad value raises ValueError)."""

    hessian: str = "exact"
    alpha: float = 0.1
    beta: float = 0.5
    nu: float = 2.5
    delta: float = 2.2
    tau: float = 2.5
    theta: float = 0.8
    xi: float = 1e-3
    epsilon0: float = 1.0
    epsilon: float = 1.0
    rho: float = 1.0
    max_halvings: int = 50
    rank_tolerance: float = 1e-6
    equality_margin: float = 0.1
    h0_scaling: str | float = "auto"
    scaling: str = "gradient"
    subproblem: str = "qp"

    def __post_init__(self) -> None:
        if self.subproblem not in ("qp", "equality"):
            raise ValueError(f"subproblem must be 'qp' or 'equality', not {self.subproblem!r}")
        if self.hessian not in ("bfgs", "exact"):
            raise ValueError(f"hessian must be 'bfgs' or 'exact', not {self.hessian!r}")
        if self.subproblem == "qp" and self.hessian != "exact":
            raise ValueError("the 'qp' subproblem takes the exact Hessian; BFGS needs subproblem='equality'")
        if self.scaling not in ("gradient", "none"):
            raise ValueError(f"scaling must be 'gradient' or 'none', not {self.scaling!r}")
        h0 = self.h0_scaling
        if h0 != "auto" and not (isinstance(h0, int | float) and h0 > 0):
            raise ValueError(f"h0_scaling must be 'auto' or a positive number, not {h0!r}")
        if not (0 < self.alpha < 0.5 and 0 < self.beta < 1 and self.nu > 2 and 2 < self.delta < self.nu
                and 2 < self.tau < 3 and 0 < self.theta < 1 and self.xi > 0 and self.epsilon0 > 0
                and self.epsilon > 0 and self.rho > 0 and self.equality_margin > 0):
            raise ValueError("FSQP needs α ∈ (0, ½), β, θ ∈ (0, 1), ν > 2, δ ∈ (2, ν), τ ∈ (2, 3) and positive ξ, "
                             "ε0, ε, ρ and equality_margin")
        super().__post_init__()
        normalized = {"max_halvings": int(self.max_halvings), "rank_tolerance": float(self.rank_tolerance),
                      "equality_margin": float(self.equality_margin)}
        for name, value in normalized.items():
            object.__setattr__(self, name, value)
