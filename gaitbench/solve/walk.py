"""Walks: the problem a strategy (:class:`gaitbench.contracts.Strategy`) solves, what it returns, and the
step-by-step chaining most strategies share.

Each step starts from the heel-strike map (after push-off, in the second phase) of the previous step's solution
(docs/model.md §7). A step whose geometry is infeasible or whose solve fails ends the walk with its reason; the steps
solved before it are kept.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from gaitbench.contracts import Solver, WalkProblem
from gaitbench.model.mechanics import BipedModel
from gaitbench.problem.gait_problem import StepData
from gaitbench.problem.trajectory import Seed, StepTrajectory
from gaitbench.problem.transcription import TranscribedStep
from gaitbench.solve.verify import verify_step
from gaitbench.solver_result import SolverStatus
from gaitbench.walk_types import StepOutcome, WalkResult

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
        if checkpoint is not None and not problem.out_of_time:
            # A step that ends after the deadline may have been cut short (starts, retries or a polish skipped for
            # time): a resumed walk, given more time, solves it again in full rather than walk on from it.
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
