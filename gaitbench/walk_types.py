"""What a strategy returns for a walk (the values :class:`gaitbench.contracts.Strategy` names): each step's outcome
and the walk's result, with the checks a solved step and a solved walk carry. They sit below the contracts, which
also hold the walk a strategy is asked to solve (:class:`gaitbench.contracts.WalkProblem`); solving is in
:mod:`gaitbench.solve.walk`, verifying in :mod:`gaitbench.solve.verify` and :mod:`gaitbench.solve.walk_verification`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gaitbench.acceptance import StepVerification, Thresholds
from gaitbench.model.energetics import average_cot
from gaitbench.problem.objective import NET_POWER
from gaitbench.problem.trajectory import StepTrajectory
from gaitbench.solver_result import SolverResult


@dataclass(frozen=True)
class StepCheck:
    """One reported step of a walk, as the walk's verification saw it."""

    index: int
    cot: float
    max_defect: float
    resim_error: float
    objective_gap: float | None
    """The gap the step was held to: against the larger of its COT and the walk's mean step COT."""
    join_mismatch: float
    """Largest |start state − post-impact state of the step before| (rad, rad/s)."""
    join_energy: float
    """Mechanical energy (J) at the step's start minus that of the post-impact state it should start from: > 0 is
    energy that appeared from nowhere."""
    failures: tuple[str, ...] = ()


@dataclass(frozen=True)
class WalkVerification:
    verified: bool
    reasons: tuple[str, ...]
    """Why the walk is not verified (empty when it is), each naming its step."""
    acot: float | None
    """The ACOT of the steps the walk reports; None unless the walk is complete."""
    thresholds: Thresholds
    steps: tuple[StepCheck, ...] = field(default=())

    @property
    def reason(self) -> str | None:
        return "; ".join(self.reasons) if self.reasons else None

    @property
    def max_join_mismatch(self) -> float | None:
        return max((step.join_mismatch for step in self.steps), default=None)

    @property
    def max_resim_error(self) -> float | None:
        return max((step.resim_error for step in self.steps), default=None)

    @property
    def max_defect(self) -> float | None:
        return max((step.max_defect for step in self.steps), default=None)

    @property
    def join_energy(self) -> float:
        """Energy (J) that appeared at the walk's joins, summed where it is positive."""
        return float(sum(max(step.join_energy, 0.0) for step in self.steps))

    def as_dict(self) -> dict[str, Any]:
        return {"verified": self.verified, "reason": self.reason, "acot": self.acot,
                "max_join_mismatch": self.max_join_mismatch, "join_energy": self.join_energy,
                "max_resim_error": self.max_resim_error, "max_defect": self.max_defect,
                "thresholds": self.thresholds.as_dict(),
                "steps": [{"index": step.index, "cot": step.cot, "max_defect": step.max_defect,
                           "resim_error": step.resim_error, "objective_gap": step.objective_gap,
                           "join_mismatch": step.join_mismatch, "join_energy": step.join_energy,
                           "failures": list(step.failures)} for step in self.steps]}


@dataclass
class StepOutcome:
    index: int
    stance: int
    status: str  # a SolverStatus value, or "infeasible_geometry"
    message: str
    solver_result: SolverResult | None = None
    trajectory: StepTrajectory | None = None
    verification: StepVerification | None = None
    next_state: np.ndarray | None = field(default=None, repr=False)
    """(q1, q2, q̇1, q̇2) after this step's push-off and heel strike: where the next step starts."""
    details: dict = field(default_factory=dict)
    """What the strategy did to produce this step (candidates, choices, polish), JSON-ready."""
    polished: StepOutcome | None = field(default=None, repr=False)
    """The step's problem re-solved from this outcome's trajectory and verified, when the strategy polishes (decrease
    and conquer, whose own trajectory is a patchwork that need not satisfy the dynamics): the verified trajectory.
    Saved beside the step's own (``stepNN_polished_*`` arrays)."""

    @property
    def solved(self) -> bool:
        return self.verification is not None and self.next_state is not None

    @property
    def verified(self) -> StepOutcome:
        """The outcome whose trajectory is the verified one: the polished step when there is one that solved, else
        this step."""
        return self.polished if self.polished is not None and self.polished.solved else self

    def summary(self) -> dict:
        """Status, verified COT, iterations and time: how a strategy records a sub-solve in its details."""
        result, check = self.solver_result, self.verification
        return {"status": self.status, "cot": check.cot if check else None,
                "iterations": result.iterations if result else None,
                "solve_time_s": result.wall_time_s if result else None,
                "resim_error": check.resim_error if check else None}

    def as_dict(self) -> dict:
        result, check = self.solver_result, self.verification
        return {
            "index": self.index,
            "stance": self.stance,
            "status": self.status,
            "message": self.message,
            "cot": check.cot if check else None,
            "objective": result.objective if result else None,
            "solve_time_s": result.wall_time_s if result else None,
            "function_time_s": result.function_time_s if result else None,
            "iterations": result.iterations if result else None,
            "constraint_violation": result.constraint_violation if result else None,
            "max_defect": check.max_defect if check else None,
            "max_violation": check.max_violation if check else None,
            "violated": check.violated if check else None,
            "resim_error": check.resim_error if check else None,
            "resim_max_error": check.resim_max_error if check else None,
            "hip_energy": check.hip_energy if check else None,
            "push_off_energy": check.push_off_energy if check else None,
            "objective_cot": check.objective_cot if check else None,
            "objective_gap": check.objective_gap if check else None,
            "objective_agrees": check.objective_agrees if check else None,
            "push_off_impulse": self.trajectory.push_off if self.trajectory else None,
            **({"details": self.details} if self.details else {}),
        }


@dataclass
class WalkResult:
    experiment: str
    transcription: str
    solver: str
    strategy: str
    N: int
    phase: str
    requested_steps: int
    steps: list[StepOutcome] = field(default_factory=list)
    wall_time_s: float = 0.0
    strategy_details: dict = field(default_factory=dict)
    """Walk-level figures of the strategy (for decrease-and-conquer: claimed and verified ACOT, candidates)."""
    problem_options: dict = field(default_factory=dict)
    """The :class:`ProblemOptions` the walk was solved under, every field (limits included)."""
    objective: str = NET_POWER.name
    """The objective every COT of the walk is measured in (:meth:`gaitbench.problem.objective.Objective.describe`)."""
    experiment_options: dict = field(default_factory=dict)
    """The options the experiment was built with, so that a saved walk is tracked on the same experiment; set from
    the problem's by :func:`gaitbench.solve.walk_verification.solve_verified`."""
    strategy_options: dict = field(default_factory=dict)
    """The options the strategy was built with (set like :attr:`experiment_options`)."""
    transcription_options: dict = field(default_factory=dict)
    """The options the transcription was built with (its quadrature, say: set like :attr:`experiment_options`), so
    that a saved walk is verified by the NLP it was solved with."""
    objective_options: dict = field(default_factory=dict)
    """The objective's options (its dataclass fields), so that a saved walk is verified under the same objective."""
    verification: WalkVerification | None = field(default=None, repr=False)
    """The walk checked as one motion (:func:`gaitbench.solve.walk_verification.verify_walk`), set by whoever
    solved it (``gaitbench solve``, the suite runner) or re-checked it (``gaitbench verify``)."""
    thesis_reading_acot: float | None = None
    """The walk's figure as the thesis would have computed it (nodal powers, its push-off term; of each step's own
    trajectory, so decrease and conquer's claim), set with :attr:`verification`."""
    resumed: dict = field(default_factory=dict)
    """For a walk resumed from a checkpoint (:mod:`gaitbench.checkpoint`): how many of its steps were
    restored (``steps``) and the time it had run before it was stopped (``elapsed_s``); empty otherwise."""

    @property
    def failure(self) -> str | None:
        failed = [step for step in self.steps if not step.solved]
        return f"step {failed[0].index}: {failed[0].message}" if failed else None

    @property
    def complete(self) -> bool:
        return len(self.steps) == self.requested_steps and all(step.solved for step in self.steps)

    @property
    def acot(self) -> float | None:
        """Average verified COT over the motions the walk reports (:attr:`StepOutcome.verified`: decrease and
        conquer's polished or complete step, never its patchwork); ``None`` unless every requested step was solved."""
        return average_cot([step.verified.verification.cot for step in self.steps]) if self.complete else None

    @property
    def claimed_acot(self) -> float | None:
        """Average COT of the steps' own trajectories where a strategy reports another motion for them (decrease and
        conquer's patchworks, a claim and not a motion); ``None`` for walks without such steps or incomplete ones."""
        if not self.complete or all(step.verified is step for step in self.steps):
            return None
        return average_cot([step.verification.cot for step in self.steps])

    @property
    def verified(self) -> bool:
        """Whether the walk passed its whole-walk verification (:mod:`gaitbench.solve.walk_verification`)."""
        return self.verification is not None and self.verification.verified

    def as_dict(self) -> dict:
        return {
            "experiment": self.experiment,
            "experiment_options": self.experiment_options,
            "transcription": self.transcription,
            "transcription_options": self.transcription_options,
            "solver": self.solver,
            "strategy": self.strategy,
            "strategy_options": self.strategy_options,
            "objective": self.objective,
            "objective_options": self.objective_options,
            "N": self.N,
            "phase": self.phase,
            "requested_steps": self.requested_steps,
            "complete": self.complete,
            "acot": self.acot,
            "claimed_acot": self.claimed_acot,
            "thesis_reading_acot": self.thesis_reading_acot,
            "verified": self.verified,
            **({"verification": self.verification.as_dict()} if self.verification is not None else {}),
            "failure": self.failure,
            "wall_time_s": self.wall_time_s,
            **({"resumed": self.resumed} if self.resumed else {}),
            "strategy_details": self.strategy_details,
            "problem_options": self.problem_options,
            "steps": [step.as_dict() for step in self.steps],
        }
