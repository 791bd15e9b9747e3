"""Walks: the problem a strategy (:class:`gaitbench.contracts.Strategy`) solves, what it returns, and the
step-by-step chaining most strategies share.

Each step starts from the heel-strike map (after push-off, in the second phase) of the previous step's solution
(docs/model.md §7). A step whose geometry is infeasible or whose solve fails ends the walk with its reason; the steps
solved before it are kept.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from gaitbench.contracts import Solver, Transcription
from gaitbench.model.energetics import average_cot
from gaitbench.model.experiment import Experiment
from gaitbench.model.mechanics import BipedModel
from gaitbench.model.terrain import StepCheck
from gaitbench.problem.build_cache import BuildCache
from gaitbench.problem.gait_problem import ProblemOptions, StepData, StepStructure
from gaitbench.problem.objective import NET_POWER, Objective
from gaitbench.problem.trajectory import Seed, StepTrajectory
from gaitbench.problem.transcription import TranscribedStep
from gaitbench.solve.cores import IdleCores
from gaitbench.solve.solver import SolverResult, SolverStatus, checked
from gaitbench.solve.verify import StepVerification, verify_step

if TYPE_CHECKING:
    from gaitbench.solve.checkpoint import WalkCheckpoint
    from gaitbench.solve.walk_verification import WalkVerification


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
    """The options the experiment was built with, so that a saved walk is tracked on the same experiment; set by
    whoever built the plugins (``gaitbench solve``, the suite runner)."""
    strategy_options: dict = field(default_factory=dict)
    """The options the strategy was built with (set like :attr:`experiment_options`)."""
    objective_options: dict = field(default_factory=dict)
    """The objective's options (its dataclass fields), so that a saved walk is verified under the same objective."""
    verification: WalkVerification | None = field(default=None, repr=False)
    """The walk checked as one motion (:func:`gaitbench.solve.walk_verification.verify_walk`), set by whoever
    solved it (``gaitbench solve``, the suite runner) or re-checked it (``gaitbench verify``)."""
    thesis_reading_acot: float | None = None
    """The walk's figure as the thesis would have computed it (nodal powers, its push-off term; of each step's own
    trajectory, so decrease and conquer's claim), set with :attr:`verification`."""
    resumed: dict = field(default_factory=dict)
    """For a walk resumed from a checkpoint (:mod:`gaitbench.solve.checkpoint`): how many of its steps were
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


@dataclass(frozen=True)
class WalkProblem:
    """What a strategy is asked to do: walk ``steps`` steps of an experiment with N nodes per step, using one
    transcription and one solver, under the given problem options, for the given objective. ``builds`` keeps
    what a strategy builds beyond the walk's own steps for later walks: this walk's alone unless its runner
    passes one it keeps (a suite's worker)."""

    experiment: Experiment
    transcription: Transcription
    solver: Solver
    n_nodes: int
    steps: int | None = None
    options: ProblemOptions | None = None
    objective: Objective = NET_POWER
    builds: BuildCache = field(default_factory=BuildCache, compare=False, repr=False)
    deadline: float | None = field(default=None, compare=False)
    """``time.monotonic()`` at which the walk's time runs out (a suite case's time limit): a step that would start
    later is not started, and the walk stops there with ``time_limit``, keeping the steps it solved, instead of
    running on until its process is stopped and losing them all."""
    cores: IdleCores | None = field(default=None, compare=False, repr=False)
    """The machine's ledger of the cores walks are using, when the walk may borrow idle ones (a suite's case, a
    `gaitbench solve`): a strategy whose solves are independent may spread them over the cores it can hold."""
    checkpoint: WalkCheckpoint | None = field(default=None, compare=False, repr=False)
    """Where the walk keeps its solved steps as it goes, and the steps an earlier, stopped run of it kept:
    the walk resumes after them (:func:`walk_step_by_step`)."""

    @property
    def out_of_time(self) -> bool:
        """Whether the walk's deadline has passed."""
        return self.deadline is not None and time.monotonic() >= self.deadline

    def __post_init__(self) -> None:
        object.__setattr__(self, "solver", checked(self.solver))  # every solve of the walk: the solver boundary
        if self.steps is not None and not 1 <= self.steps <= self.experiment.n_steps:
            raise ValueError(f"steps = {self.steps}: the {self.experiment.name} experiment has "
                             f"{self.experiment.n_steps} steps")
        if self.options is None:
            object.__setattr__(self, "options", ProblemOptions(limits=self.experiment.limits))

    @property
    def n_steps(self) -> int:
        return self.experiment.n_steps if self.steps is None else self.steps

    def structure(self, phase: str, n_nodes: int | None = None, walked: bool = False) -> StepStructure:
        """The step NLP's shape; ``walked``: a First-Phase step the walk goes on from (see StepStructure). Only the
        First Phase tells the two apart, so a 4-DOF step is one structure, and one build, for every strategy."""
        return StepStructure(phase, n_nodes or self.n_nodes, self.options, self.objective,
                             walked and phase == "first")

    def step_data(self, index: int, state: np.ndarray) -> StepData:
        """Step ``index`` (1-based) from ``state`` = (q1, q2, q̇1, q̇2), leg order, with the walk's time step."""
        terrain = self.experiment.terrain
        geometry = terrain.steps[index - 1]
        return StepData(self.experiment.robot, self.experiment.stance_leg(index), np.asarray(state, dtype=float),
                        geometry.D, geometry.theta, self.experiment.time_step(self.n_nodes),
                        previous_slope=terrain.ground_behind(index))

    def start_state(self) -> np.ndarray:
        """(q1, q2, q̇1, q̇2) at the start of step 1, in the start pose the options ask for."""
        return self.experiment.start_state(self.options.start_pose)

    def feasibility(self) -> list[StepCheck]:
        """The experiment's per-step geometry checks under the options' leg-angle limits."""
        return self.experiment.feasibility(self.options.angle_bounds)

    def model(self, phase: str) -> BipedModel:
        """The model a step of ``phase`` is verified with: 4-DOF (push-off acts) or the 2-DOF First Phase."""
        return BipedModel(self.experiment.robot, 4 if phase == "second" else 2)

    def result(self, strategy: str, phase: str = "second") -> WalkResult:
        return WalkResult(experiment=self.experiment.name, transcription=self.transcription.name,
                          solver=self.solver.name, strategy=strategy, N=self.n_nodes, phase=phase,
                          requested_steps=self.n_steps, problem_options=asdict(self.options),
                          objective=self.objective.describe(), objective_options=asdict(self.objective))


StepSolver = Callable[[WalkProblem, int, np.ndarray], "StepOutcome"]
"""Solves step ``index`` from a (q1, q2, q̇1, q̇2) state; a solved outcome carries the next step's state."""

BackUp = Callable[[WalkProblem, int, np.ndarray, "StepOutcome"], "StepOutcome"]
"""Solves step ``index`` again from its state, looking further ahead, given the outcome it is to replace."""

Rescue = Callable[[WalkProblem, int, np.ndarray, "StepOutcome"], "StepOutcome"]
"""Tries once more a step ``index`` that neither the retry ladder nor the back-up solved, from the same state, given
its failed outcome; returns the step solved, or that failure with the rescue's attempts added to its details."""


def walk_step_by_step(problem: WalkProblem, strategy: str, solve_step: StepSolver,
                      on_step: Callable[[StepOutcome], None] | None = None, phase: str = "second",
                      back_up: BackUp | None = None, resumable: bool = True,
                      rescue: Rescue | None = None) -> WalkResult:
    """The thesis's walk: step after step, each from the heel-strike state of the previous one (docs/model.md §7).

    A step whose geometry is infeasible, or that ``solve_step`` cannot solve, ends the walk with its reason; the
    steps before it are kept. With ``back_up``, a step that the solver cannot solve is first taken as a dead end
    the previous step walked into: that step is solved again by ``back_up`` (which looks further ahead) from its
    own initial state, started from its own trajectory (feasible for it, and nearer one that leaves the next step
    a way on than a blended guess is), and the walk goes on from the new one. Each step is backed up at most once;
    the step that was replaced is recorded in the new one's ``details["backed_up_from"]``. With ``rescue``, a step
    that still fails (after the back-up, or where there is none) is handed to ``rescue`` before the walk stops there.
    A walk that completes without ``back_up`` and ``rescue`` is the same walk with them.

    With the problem's ``checkpoint``, each solved step is saved as the walk goes, and a walk that an earlier run
    left unfinished goes on after the steps it saved. A strategy whose steps depend on more than the state the step
    before left (a look-ahead window's seeds) passes ``resumable=False``: its walk starts from step 1.
    """
    walk = problem.result(strategy, phase)
    started = time.perf_counter()
    checks = problem.feasibility()
    states = [problem.start_state()]  # states[i - 1]: where step i starts
    backed_up: set[int] = set()
    checkpoint = problem.checkpoint if resumable else None
    earlier = 0.0
    if checkpoint is not None and checkpoint.steps:
        walk.steps, backed_up, earlier = list(checkpoint.steps), set(checkpoint.backed_up), checkpoint.elapsed_s
        states += [step.next_state for step in walk.steps]
        walk.resumed = {"steps": len(walk.steps), "elapsed_s": earlier}
    index = len(walk.steps) + 1
    while index <= problem.n_steps:
        check = checks[index - 1]
        if problem.out_of_time:
            outcome = StepOutcome(index, problem.experiment.stance_leg(index), SolverStatus.TIME_LIMIT.value,
                                  f"time limit: the walk's time ran out before step {index}")
        elif check.ok:
            outcome = solve_step(problem, index, states[index - 1])
        else:
            outcome = StepOutcome(index, problem.experiment.stance_leg(index), "infeasible_geometry",
                                  "; ".join(check.problems))
        # the walk's deadline is final: a step it stopped is no dead end to back up from
        if (not outcome.solved and check.ok and back_up is not None and index > 1 and index - 1 not in backed_up
                and not problem.out_of_time):
            backed_up.add(index - 1)
            replaced = walk.steps[-1]
            previous = back_up(problem, index - 1, states[index - 2], replaced)
            if previous.solved:
                previous.details = {**previous.details, "backed_up_from": {
                    **replaced.summary(), "dead_end": {"step": index, "message": outcome.message}}}
                walk.steps[-1] = previous
                if on_step:
                    on_step(previous)
                del states[index - 1:]
                states.append(previous.next_state)
                continue
            outcome.details = {**outcome.details, "back_up": {"step": index - 1, "message": previous.message,
                                                              **previous.summary()}}
        if (not outcome.solved and check.ok and rescue is not None and not problem.out_of_time
                and outcome.status != SolverStatus.TIME_LIMIT.value):
            outcome = rescue(problem, index, states[index - 1], outcome)
        walk.steps.append(outcome)
        if on_step:
            on_step(outcome)
        if not outcome.solved:
            break
        if checkpoint is not None:
            checkpoint.save(walk.steps, backed_up, earlier + time.perf_counter() - started, of=problem.n_steps)
        states.append(outcome.next_state)
        index += 1
    walk.wall_time_s = earlier + time.perf_counter() - started
    return walk


def solve_and_verify(problem: WalkProblem, index: int, built: TranscribedStep, data: StepData,
                     seed: Seed | None = None, phase: str = "second", solver: Solver | None = None,
                     start: np.ndarray | None = None) -> StepOutcome:
    """Step ``index``'s NLP solved from ``seed`` (the blended guess by default), decoded, verified and chained.

    ``solver`` replaces the problem's solver for this solve (a retry's variant of it); ``start``, a point of the
    NLP's own variables, replaces the guess (a continuation from where an earlier solve stopped)."""
    solver = solver or problem.solver
    guess = built.initial_guess(data, seed) if start is None else start
    result = solver.solve(built.nlp, data.parameter_vector(), guess)
    if not result.converged:
        return StepOutcome(index, data.stance, result.status.value, f"{result.status.value}: {result.message}",
                           result)
    trajectory = built.trajectory(result.x, data)
    model = problem.model(phase)
    verification = verify_step(built, result.x, data, trajectory, model)
    return StepOutcome(index, data.stance, result.status.value, result.message, result, trajectory, verification,
                       next_state=next_step_state(model, trajectory))


RETRIED_STATUSES = (SolverStatus.INFEASIBLE.value, SolverStatus.ITERATION_LIMIT.value, SolverStatus.ERROR.value,
                    SolverStatus.TIME_LIMIT.value, SolverStatus.NON_FINITE.value)
"""Failures worth another try: a local solver that calls a feasible step infeasible, runs out of iterations or of
its own time (a suite gives each solve a quarter of the case's limit, :attr:`gaitbench.run.case.Case.
solve_time_limit_s`), fails in its restoration phase or ends at non-finite values has often only started badly.
The walk's deadline is final: no rung starts after it."""


def solve_with_retries(problem: WalkProblem, index: int, built: TranscribedStep, data: StepData,
                       seed: Seed | None = None, phase: str = "second", reseed: bool = True) -> StepOutcome:
    """:func:`solve_and_verify`, and when the solve fails with a :data:`RETRIED_STATUSES` status, the retry
    ladder (docs/solvers.md, "Retries") until a rung solves the step:

    0. when the solve ran out of iterations, each of the solver's continuations (``solver.continuations()``; ``sqp``:
       itself), started from the solve's last iterate: a solve cut by its budget while converging reaches its own
       optimum, where another start may reach a worse one;
    1. each of the solver's own remedies (``solver.remedies()``; IPOPT: adaptive μ) from the same guess, and when
       that guess is a trajectory ``seed``, each of its seed remedies (``solver.seed_remedies()``) too;
    2. ``first-phase-seed`` (4-DOF steps only, and only with ``reseed``): the step's 2-DOF First-Phase problem
       solved, and the 4-DOF problem started from its trajectory, with the solver and then each of its remedies
       and seed remedies.
       A caller whose result means "the optimum near *this* seed" (decrease-and-conquer's polish) passes
       ``reseed=False``;
    3. each of the solver's last resorts (``solver.last_resorts()``; IPOPT: a small initial barrier parameter) from
       the same guess: variants that solve where the others fail but often reach a worse optimum, so they come
       after every other rung.

    A rung is not started once the walk's deadline has passed: the step then ends with ``time_limit``, which the
    walk does not back up from (a suite case keeps the steps it solved instead of being stopped from outside).

    Every rung tried is recorded in the outcome's ``details["retries"]`` (remedy, status, iterations, time), and
    the first attempt's status in ``details["first_attempt"]``; a step that still fails keeps the first failure's
    message, with the rungs that were tried.
    """
    outcome = solve_and_verify(problem, index, built, data, seed, phase)
    if outcome.solved or outcome.status not in RETRIED_STATUSES:
        return outcome
    first_attempt, retries = outcome, []
    for remedy, attempt in _ladder(problem, index, built, data, seed, phase, reseed, first_attempt):
        if problem.out_of_time:  # a rung started after the deadline could run a whole solve's limit past it
            outcome = replace(first_attempt, status=SolverStatus.TIME_LIMIT.value,
                              message=f"time limit: the walk's time ran out during step {index}'s retries")
            break
        retry = attempt()
        retries.append({"remedy": remedy, **retry.summary(), **_failed_in(retry)})
        if retry.solved:
            outcome = retry
            break
    outcome.details = {**outcome.details, "first_attempt": first_attempt.summary(), "retries": retries}
    if not outcome.solved:
        tried = ", ".join(entry["remedy"] + (f" (its {entry['failed_in']}: {entry['status']})"
                                             if "failed_in" in entry else "") for entry in retries) or "none"
        outcome.message = f"{outcome.message} (retried: {tried})"
    return outcome


def _ladder(problem: WalkProblem, index: int, built: TranscribedStep, data: StepData, seed: Seed | None,
            phase: str, reseed: bool, failed: StepOutcome):
    """The rungs of the retry ladder as (remedy, attempt) pairs; attempts run lazily, the First Phase once."""
    stopped = stopped_at(failed)
    if stopped is not None:
        for name, variant in solver_variants(problem.solver, "continuations"):
            yield name, lambda variant=variant: solve_and_verify(problem, index, built, data, phase=phase,
                                                                 solver=variant, start=stopped)
    for name, variant in solver_remedies(problem.solver, seeded=seed is not None):
        yield name, lambda variant=variant: solve_and_verify(problem, index, built, data, seed, phase, variant)
    if phase == "second" and reseed:
        yield from _first_phase_rungs(problem, index, built, data)
    for name, variant in solver_variants(problem.solver, "last_resorts"):
        yield name, lambda variant=variant: solve_and_verify(problem, index, built, data, seed, phase, variant)


def _first_phase_rungs(problem: WalkProblem, index: int, built: TranscribedStep, data: StepData):
    """Rung 2: the 4-DOF step started from its First Phase's trajectory, with the solver and each remedy, seed
    remedies included."""
    first_phase: list[StepOutcome] = []

    def seeded(variant: Solver | None) -> StepOutcome:
        if not first_phase:
            first = problem.transcription.build(problem.structure("first"))
            first_phase.append(solve_and_verify(problem, index, first, data, phase="first"))
        coarse = first_phase[0]
        if not coarse.solved:
            return replace(coarse, message=f"its 2-DOF First Phase: {coarse.message}",
                           details={**coarse.details, "failed_in": "first phase"})
        return solve_and_verify(problem, index, built, data, coarse.trajectory.seed(), "second", variant)

    yield "first-phase-seed", lambda: seeded(None)
    if not first_phase[0].solved:
        return  # no seed: the remedies below would only repeat the First Phase's failure
    for name, variant in solver_remedies(problem.solver, seeded=True):
        yield f"first-phase-seed+{name}", lambda variant=variant: seeded(variant)


def _failed_in(outcome: StepOutcome) -> dict:
    """Where a rung failed when it was not the 4-DOF solve itself (the First Phase that seeds it)."""
    return {"failed_in": outcome.details["failed_in"]} if "failed_in" in outcome.details else {}


def stopped_at(failed: StepOutcome) -> np.ndarray | None:
    """The last iterate of a solve cut by its iteration limit, where the solver's continuations start; None after
    any other failure (an error's or an infeasible solve's last point is no way on)."""
    x = failed.solver_result.x if failed.solver_result is not None else None
    if failed.status != SolverStatus.ITERATION_LIMIT.value or x is None or not np.all(np.isfinite(x)):
        return None
    return x


def solver_remedies(solver: Solver, seeded: bool) -> list[tuple[str, Solver]]:
    """The solver's variants worth a retry after a failed solve (its optional ``remedies()``), named; ``seeded``:
    the retry starts from a trajectory, not the blended guess, so its ``seed_remedies()`` follow."""
    return solver_variants(solver, "remedies") + (solver_variants(solver, "seed_remedies") if seeded else [])


def solver_variants(solver: Solver, kind: str) -> list[tuple[str, Solver]]:
    """The solver's named variants of one kind, ``continuations``, ``remedies``, ``seed_remedies`` or
    ``last_resorts``: empty where it has none."""
    method = getattr(solver, kind, None)
    return list(method()) if method is not None else []


def next_step_state(model: BipedModel, trajectory: StepTrajectory) -> np.ndarray:
    """(q1, q2, q̇1, q̇2) at the start of the next step: push-off (4 DOF), then heel strike and the role swap."""
    q, dq = trajectory.q[-1], trajectory.dq[-1]
    if model.dof == 4:
        q, dq = np.r_[q, 0.0, 0.0], np.r_[dq, 0.0, 0.0]
        dq, _ = model.push_off(q, dq, trajectory.push_off, trajectory.stance)
    strike = model.heel_strike(q, dq, trajectory.stance)
    return np.r_[strike.q[:2], strike.dq[:2]]
