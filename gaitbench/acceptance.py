"""When a solved walk counts as verified: what a step's verification measures, and every threshold in one place.

A walk is verified when each step it reports is a motion of the robot (its dynamics defect and re-simulation error
are small) that keeps its step's constraints (it ends on the foothold, within the limits), each step starts where
the step before left the robot (the join), and each step's optimizer measured what the report quotes (the
objective gap). Reports rank verified walks only; the others are listed with the reasons :func:`step_failures` and
:func:`join_failure` give.

The re-simulation error and the objective gap are discretization errors, so their limits shrink with the grid:
every built-in transcription is at least first-order accurate, so a step whose re-simulation error exceeds a limit
proportional to h = 1/N is off for another reason than the grid's coarseness; the gap's limit has a floor, the
largest consistent difference between a transcription's cost and its interpolant's. In a walk, a step's gap is
measured against the larger of its own COT and the walk's mean step COT: a nearly free step (a downhill step at COT
0.01) is held to what it can move the walk's figure by, not to a share of its own near-zero cost. The defect and the
join are the solver's and the chain's own accuracy, independent of N.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

MAX_DEFECT = 1e-6
"""Largest violation of the transcription's dynamics constraints, and of the step's others (its start state,
heel-strike pose, angle limits, clearance, lift-off and contact): the solvers' constraint tolerance."""

RESIM_ERROR_AT_N = 5.0
"""The re-simulation's end-state error (rad, rad/s) may be at most ``RESIM_ERROR_AT_N / N``: 0.5 at N = 10,
0.05 at N = 100, 0.025 at N = 200."""

MAX_JOIN_MISMATCH = 1e-6
"""Largest difference (rad, rad/s) between a step's start state and the post-impact state of the step before (for
step 1, the walk's start state): a walk's steps are solved from that state, so anything larger is a broken chain."""

ACOT_RTOL = 0.01
"""A stored ACOT that its walk's trajectories, verified again, do not reproduce within 1 % is not trusted."""

OBJECTIVE_GAP = 0.10
OBJECTIVE_GAP_AT_N = 2.0
"""|objective gap| (:func:`objective_gap`) may be at most ``max(OBJECTIVE_GAP, OBJECTIVE_GAP_AT_N / N)``: 10 % from
N = 20, 20 % at N = 10. The floor lies above the consistent difference between DMOC's discrete cost and its
interpolant's (docs/decisions/verification-thresholds.md), so that a gap beyond it is the optimizer exploiting its
quadrature, not a transcription's own offset."""

OBJECTIVE_RTOL = 0.05
OBJECTIVE_ATOL = 1e-3
"""A step's objective agrees with its verified COT (``objective_agrees``, a diagnostic, not a threshold) when they
differ by at most 5 % of the COT, or by 1e-3 in COT for steps that cost almost nothing (where relative differences
mean nothing)."""


def objective_gap(cot: float, objective_cot: float, walk_cot: float = 0.0) -> float:
    """How much more (> 0) or less the verified COT is than the objective, relative to the larger of the COT and
    ``walk_cot`` (the walk's mean step COT, when the step is judged within its walk), floored at OBJECTIVE_ATOL /
    OBJECTIVE_RTOL so that |gap| ≤ OBJECTIVE_RTOL means agreement within 5 % or 1e-3."""
    return (cot - objective_cot) / max(abs(cot), walk_cot, OBJECTIVE_ATOL / OBJECTIVE_RTOL)


@dataclass(frozen=True)
class Thresholds:
    """The limits a walk of N nodes per step is held to."""

    max_defect: float
    max_resim_error: float
    max_join_mismatch: float
    max_objective_gap: float

    @classmethod
    def for_nodes(cls, n_nodes: int) -> Thresholds:
        return cls(max_defect=MAX_DEFECT, max_resim_error=RESIM_ERROR_AT_N / n_nodes,
                   max_join_mismatch=MAX_JOIN_MISMATCH,
                   max_objective_gap=max(OBJECTIVE_GAP, OBJECTIVE_GAP_AT_N / n_nodes))

    def as_dict(self) -> dict[str, float]:
        return {"max_defect": self.max_defect, "max_resim_error": self.max_resim_error,
                "max_join_mismatch": self.max_join_mismatch, "max_objective_gap": self.max_objective_gap}


@dataclass(frozen=True)
class StepVerification:
    """What the verification of one step measured (:func:`gaitbench.solve.verify.verify_step`), which
    :func:`step_failures` holds to the thresholds."""

    max_defect: float  # largest violation of the transcription's dynamics constraints
    resim_error: float  # largest state error (angles in rad, rates in rad/s) at the step's end
    resim_max_error: float  # largest state error at any node along the step
    hip_energy: float  # J, the objective's running cost on a fine grid of the interpolant (net-power: exact |power|)
    push_off_energy: float  # J, what the push-off is charged (ProblemOptions.push_off_cost); the COT has its event cost
    cot: float
    objective_cot: float | None = None  # the NLP objective at the solution, without its torque regularization
    objective_gap: float | None = None  # objective_gap(cot, objective_cot): against the step's own COT
    objective_agrees: bool | None = None  # |objective_gap| ≤ OBJECTIVE_RTOL
    max_violation: float | None = None  # largest violation of the step's other constraints (None: not measured)
    violated: str | None = None  # the constraint block of that largest violation, where there is one

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def judged_gap(check: StepVerification, walk_cot: float | None = None) -> float | None:
    """The objective gap a step is held to: against its own COT alone, or, within a walk whose mean step COT is
    ``walk_cot``, against the larger of the two (:func:`objective_gap`)."""
    if walk_cot is None or check.objective_cot is None:
        return check.objective_gap
    return objective_gap(check.cot, check.objective_cot, walk_cot)


def step_failures(check: StepVerification, limits: Thresholds, walk_cot: float | None = None) -> list[str]:
    """Why a step's verification does not pass ``limits``, one short reason each; empty when it passes. A figure
    that is missing or not finite fails (a step with no verification is no motion). ``walk_cot``, the mean step COT
    of the walk the step belongs to, sets the basis of its objective gap (:func:`judged_gap`); without it (choosing
    between candidate motions of one step, before any walk figure exists) the gap is against the step's own COT,
    the stricter test."""
    reasons = []
    if not check.max_defect <= limits.max_defect:
        reasons.append(f"dynamics defect {check.max_defect:.1e} > {limits.max_defect:.0e}")
    if check.max_violation is not None and not check.max_violation <= limits.max_defect:
        reasons.append(f"constraint {check.violated} violated by {check.max_violation:.1e} > "
                       f"{limits.max_defect:.0e}")
    if math.isinf(check.resim_error):
        reasons.append("re-simulation failed before the step's end")
    elif not check.resim_error <= limits.max_resim_error:
        reasons.append(f"re-simulation error {check.resim_error:.2g} > {limits.max_resim_error:.2g}")
    gap = judged_gap(check, walk_cot)
    if gap is not None and not abs(gap) <= limits.max_objective_gap:
        basis = " of the walk's mean step COT" if walk_cot is not None and walk_cot > abs(check.cot) else ""
        reasons.append(f"objective gap {gap:+.1%}{basis} beyond ±{limits.max_objective_gap:.1%}")
    return reasons


def join_failure(mismatch: float, limits: Thresholds) -> str | None:
    """Why a step's start does not join the step before, or None."""
    if mismatch <= limits.max_join_mismatch:
        return None
    return f"join mismatch {mismatch:.1e} > {limits.max_join_mismatch:.0e}"

