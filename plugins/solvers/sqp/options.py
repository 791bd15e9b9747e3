"""The options of an ``sqp`` solve, checked when they are built: what the layers of a solve read, apart from the
solver that runs them. Each option is described in the :class:`~plugins.solvers.sqp.solver.SQP` docstring."""

from __future__ import annotations

from dataclasses import dataclass

import qpsolvers

from gaitbench.options import SolverOptions
from gaitbench_plugins.solvers.sqp.hessian import SHIFT_FLOOR

_HESSIANS = ("exact", "bfgs")
_MERITS = ("l1", "filter")


@dataclass(frozen=True, eq=False)
class SQPOptions(SolverOptions):
    """The ``sqp`` solver's options, after the four every solver shares (a bad value raises ValueError)."""

    qp_solver: str = "piqp"
    qp_tolerance: float = 1e-10
    hessian: str = "exact"
    merit: str = "l1"
    second_order_correction: bool = True
    acceptable_tolerance: float = 1e-6
    fallback_qp_solver: str | None = "clarabel"
    crawl_shift_floor: float = SHIFT_FLOOR

    def __post_init__(self) -> None:
        if self.qp_solver not in qpsolvers.available_solvers:
            raise ValueError(f"unknown QP solver {self.qp_solver!r}; available: "
                             f"{', '.join(sorted(qpsolvers.available_solvers))}")
        fallback = None if self.fallback_qp_solver in (None, "none") else self.fallback_qp_solver
        if fallback is not None and fallback not in qpsolvers.available_solvers:
            raise ValueError(f"unknown fallback QP solver {fallback!r}; available: "
                             f"{', '.join(sorted(qpsolvers.available_solvers))}")
        if self.hessian not in _HESSIANS:
            raise ValueError(f"unknown hessian {self.hessian!r}; choose one of {', '.join(_HESSIANS)}")
        if self.merit not in _MERITS:
            raise ValueError(f"unknown merit {self.merit!r}; choose one of {', '.join(_MERITS)}")
        if self.max_iterations < 0 or min(self.tolerance, self.qp_tolerance, self.acceptable_tolerance) <= 0:
            raise ValueError("max_iterations must be ≥ 0, the tolerances > 0")
        if not 0 < self.crawl_shift_floor <= SHIFT_FLOOR:
            raise ValueError(f"crawl_shift_floor must be in (0, {SHIFT_FLOOR:g}]: the crawl floor is the usual one "
                             f"or lower")
        super().__post_init__()
        normalized = {"fallback_qp_solver": fallback, "qp_tolerance": float(self.qp_tolerance),
                      "second_order_correction": bool(self.second_order_correction),
                      "acceptable_tolerance": max(float(self.acceptable_tolerance), self.tolerance),
                      "crawl_shift_floor": float(self.crawl_shift_floor)}
        for field_name, value in normalized.items():
            object.__setattr__(self, field_name, value)
