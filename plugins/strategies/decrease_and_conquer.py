"""Decrease & Conquer (thesis §3.7; docs/model.md §7), with the verification the thesis leaves out.

Per step:

1. the First Phase (2-DOF) problem;
2. the complete Second Phase (4-DOF) problem from the step's initial state (k0 = 1), seeded by the First Phase;
3. the sectional Second Phase problems, k0 = 2 … N−2, each started from the First Phase state at node k0 and
   covering nodes k0 … N with the same time step (the thesis's k0 = N−1 would leave a two-node problem, below the
   three nodes a step needs, so it is not posed);
4. synthesis: at each node the candidate with the lowest point cost that keeps the reference's "typical value
   relation", with backtracking (:mod:`gaitbench.solve.synthesis`);
5. the sectional trajectories completed with the earlier nodes, and the final choice by the thesis's candidate COT
   among the synthesized and completed trajectories;
6. the chosen trajectory verified, and the complete problem re-solved from it (the polish);
7. the next step from the post-impact state of the step's motion (:func:`reported_motion`): of the polish and the
   complete solution, the cheaper of those that pass verification's thresholds, else the cheaper of those solved;
   never the chosen trajectory itself.

The synthesized (and completed) trajectories are node-wise patchworks of different NLP solutions, so in general
they are not motions of the robot: a patchwork's end state is not where the robot would be. The thesis chains its
steps through the patchworks; this strategy keeps each patchwork as the step's claim (its COT is the claimed COT,
reported beside the verified one, labelled "patchwork, not a motion") and walks on from the motion it reports, so
that the walk's steps join into one motion of the robot (:mod:`gaitbench.solve.walk_verification`). The complete
Second Phase solution (the same problem from the same state, solved from the First-Phase seed) stands in for the
polish where the polish fails after its remedies, fails verification while the complete solution passes, or costs
more while both pass verification or neither does (:func:`reported_motion`; ``details["polished"]["stand_in"]``).
With ``rescue`` (the default), a First Phase that still fails is solved on coarser grids from the same state, and
the N-node First Phase started from that solution (:func:`~gaitbench.solve.rescue.coarse_grid_rescue`); a walk that
completes without it is the same walk with it.
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.acceptance import MAX_DEFECT, Thresholds, step_failures
from gaitbench.contracts import WalkProblem
from gaitbench.model.energetics import candidate_cot
from gaitbench.problem.gait_problem import StepData, role_robot_vector, sectional_structure
from gaitbench.problem.objective import Objective
from gaitbench.problem.trajectory import StepTrajectory, nodal_trajectory
from gaitbench.problem.transcription import TranscribedStep
from gaitbench.solve.parallel import WorkerPool
from gaitbench.solve.rescue import coarse_grid_rescue
from gaitbench.solve.solver import prepare, section_solver
from gaitbench.solve.synthesis import complete_sections, synthesize
from gaitbench.solve.verify import push_off_charge, verify_step
from gaitbench.solve.walk import solve_with_retries, walk_step_by_step
from gaitbench.solver_result import SolverResult, SolverStatus
from gaitbench.walk_types import StepOutcome, WalkResult

FIRST_PHASE = "first phase"
"""``details["failed_in"]`` of a step whose First Phase failed: what the rescue acts on."""


class DecreaseAndConquer:
    """Options: ``polish`` (True: re-solve the complete problem from each chosen trajectory and report its COT),
    ``sectional_guess`` ("first-phase": each sectional problem starts from the First Phase trajectory's tail, as
    the thesis's initial conditions suggest; "complete": from the complete Second Phase trajectory's tail, closer
    to a 4-DOF solution), ``max_checks`` (budget of relation checks for the synthesis search), ``workers``
    (processes for the sectional solves of a step, or "auto": the run's workers on a Dask cluster, else the cores
    no other walk is using, asked for as each section ends; see :class:`SectionalSolves`), ``rescue`` (True: a
    First Phase that every rung leaves unsolved is seeded from coarser grids)."""

    name = "decrease-and-conquer"

    def __init__(self, polish: bool = True, sectional_guess: str = "first-phase", max_checks: int = 1_000_000,
                 workers: int | Literal["auto"] = "auto", rescue: bool = True):
        if sectional_guess not in ("first-phase", "complete"):
            raise ValueError(f"sectional_guess = {sectional_guess!r}: expected 'first-phase' or 'complete'")
        if workers != "auto" and (isinstance(workers, str) or int(workers) < 1):
            raise ValueError(f"workers = {workers!r}: expected 'auto' or a number of processes, at least 1")
        if workers != "auto" and int(workers) > 1 and "fork" not in multiprocessing.get_all_start_methods():
            raise ValueError("workers > 1 needs the 'fork' start method (Linux, macOS); use workers = 1 here")
        self.polish = bool(polish)
        self.sectional_guess = sectional_guess
        self.max_checks = int(max_checks)
        self.workers = workers if workers == "auto" else int(workers)
        self.rescue = bool(rescue)

    def solve(self, problem: WalkProblem, on_step: Callable[[StepOutcome], None] | None = None) -> WalkResult:
        def solve_step(problem: WalkProblem, index: int, state: np.ndarray) -> StepOutcome:
            return self._solve_step(problem, index, state, sections)

        def rescue(problem: WalkProblem, index: int, state: np.ndarray, failed: StepOutcome) -> StepOutcome:
            if failed.details.get("failed_in") != FIRST_PHASE:
                return failed
            built = problem.transcription.build(problem.structure("first"))
            first = coarse_grid_rescue(problem, index, state, failed, built)
            return self._solve_step(problem, index, state, sections, first) if first.solved else first

        with SectionalSolves(problem, self.workers) as sections:
            walk = walk_step_by_step(problem, self.name, solve_step, on_step,
                                     rescue=rescue if self.rescue else None)
        walk.strategy_details = walk_summary(walk)
        return walk

    def _solve_step(self, problem: WalkProblem, index: int, state: np.ndarray, sections: SectionalSolves,
                    first: StepOutcome | None = None) -> StepOutcome:
        """Step ``index`` from ``state``; ``first``: its First Phase, already solved (by the rescue)."""
        transcription, n = problem.transcription, problem.n_nodes
        data = problem.step_data(index, state)
        if first is None:
            first = solve_with_retries(problem, index, transcription.build(problem.structure("first")), data,
                                       phase="first")
        if not first.solved:
            first.message = f"First Phase: {first.message}"
            first.details = {**first.details, "failed_in": FIRST_PHASE}
            return first
        if problem.out_of_time:
            return _time_ran_out(index, data, "before its complete Second Phase")
        complete_built = transcription.build(problem.structure("second"))
        complete = solve_with_retries(problem, index, complete_built, data, seed=first.trajectory.seed())
        details = {"first_phase": first.summary(), "complete": complete.summary(),
                   "retries": first.details.get("retries", []) + complete.details.get("retries", [])}
        if "rescued_from" in first.details:
            details["rescued_from"] = {**first.details["rescued_from"], "failed_in": FIRST_PHASE}
        if not complete.solved:
            complete.message = f"complete Second Phase: {complete.message}"
            complete.details = details
            return complete

        if problem.out_of_time:  # each section, and the polish, may run a whole solve's limit past the deadline
            return _time_ran_out(index, data, "before its sections")
        h = data.time_step
        candidates, starts, failed = [complete.trajectory], [0], []
        section_data = {k0: StepData(data.robot, data.stance, np.r_[first.trajectory.q[k0 - 1],
                                                                    first.trajectory.dq[k0 - 1]],
                                     data.chord, data.slope, h, data.previous_slope) for k0 in sections.starts}
        seed_from = first if self.sectional_guess == "first-phase" else complete
        tasks = [(k0, section_data[k0].parameter_vector(),
                  sections.built[k0].initial_guess(section_data[k0], seed_from.trajectory.seed((k0 - 1) * h)))
                 for k0 in sections.starts]
        results = sections.solve(tasks, stop=lambda: problem.out_of_time)
        if len(results) < len(tasks):
            return _time_ran_out(index, data, f"during its sections ({len(results)} of {len(tasks)} solved)")
        for (k0, _, _), result in zip(tasks, results, strict=True):
            if result.converged:
                candidates.append(sections.built[k0].trajectory(result.x, section_data[k0]))
                starts.append(k0 - 1)  # 0-based node
            else:
                failed.append({"k0": k0, "status": result.status.value, "message": result.message})

        costs = PointCosts(problem.objective, data.stance, role_robot_vector(data.robot, data.stance))
        nodes = NodeValues.of(candidates, starts, n, h, problem.model("second"), costs, problem.options.push_off_cost)
        synthesis = synthesize(nodes.pcot, nodes.values, max_checks=self.max_checks)
        completed = nodes.completed(starts)
        options = {"synthesized": nodes.patch(synthesis.selection)}
        options |= {_label(start): completed.patch([j] * n) for j, start in enumerate(starts)}
        robot = data.robot
        cots = {label: candidate_cot(patch.pcot, robot.total_mass, data.chord, robot.g)
                for label, patch in options.items()}
        chosen_label = min(cots, key=cots.get)
        chosen = options[chosen_label]
        # the patchwork read through the transcription's own interpolant, as its NLP variables: the claim is what the
        # transcription would make of these nodes, not a reading of its own (linear rates understate the claim)
        x_patch = complete_built.variables(chosen.trajectory(data.stance, h), data)
        trajectory = complete_built.trajectory(x_patch, data)
        model = problem.model("second")
        verification = verify_step(complete_built, x_patch, data, trajectory, model)
        details |= {
            "candidates": len(candidates), "failed_sections": failed,
            "selection": [_label(starts[j]) for j in synthesis.selection],
            "backtracks": synthesis.backtracks, "relation_checks": synthesis.checks,
            "synthesis_exhausted": synthesis.exhausted, "candidate_cots": cots, "chosen": chosen_label,
            "claimed_cot": verification.cot,
            "verified": verification.max_defect <= MAX_DEFECT,  # the patchwork satisfies the dynamics
        }
        polished = None
        if self.polish and problem.out_of_time:
            return _time_ran_out(index, data, "before its polish")
        if self.polish:
            # IPOPT calls some of these feasible problems infeasible from a good start (stairs, N = 30, step 6): the
            # solver's own remedies from the same seed, never another seed, which would polish another trajectory
            polished = solve_with_retries(problem, index, complete_built, data, seed=trajectory.seed(), reseed=False)
            details["retries"] = details["retries"] + [{**retry, "remedy": f"polish:{retry['remedy']}"}
                                                       for retry in polished.details.get("retries", [])]
        motion, source = reported_motion(complete, polished, n)
        details["polished"] = motion.summary() | (
            {key: value for key, value in motion.verification.as_dict().items() if key != "cot"}) | source
        message = (f"patchwork, not a motion (claimed COT {verification.cot:.4f}, dynamics residual "
                   f"{verification.max_defect:.1e}); the walk goes on from its {source['motion']} motion")
        return StepOutcome(index, data.stance, motion.status, message, complete.solver_result, trajectory,
                           verification, next_state=motion.next_state, details=details, polished=motion)


def _time_ran_out(index: int, data: StepData, where: str) -> StepOutcome:
    """A step the walk's deadline stopped partway: not finished, so neither reported nor saved for a resume."""
    return StepOutcome(index, data.stance, SolverStatus.TIME_LIMIT.value,
                       f"time limit: the walk's time ran out during step {index}, {where}")


def reported_motion(complete: StepOutcome, polished: StepOutcome | None, n_nodes: int
                    ) -> tuple[StepOutcome, dict]:
    """The motion a step reports and the walk goes on from: the cheaper of the polish and the complete solution
    among those that pass verification's thresholds (:mod:`gaitbench.acceptance`), else the cheaper of
    those solved; and why, as ``details["polished"]`` records it (``motion``, ``why``, and the polish's own summary
    when the complete solution stands in for it)."""
    limits = Thresholds.for_nodes(n_nodes)
    solved = [(name, outcome) for name, outcome in (("polished", polished), ("complete", complete))
              if outcome is not None and outcome.solved]
    passing = [(name, outcome) for name, outcome in solved if not step_failures(outcome.verification, limits)]
    name, motion = min(passing or solved, key=lambda pair: pair[1].verification.cot)
    if polished is None:
        why = "not polished"
    elif not polished.solved:
        why = f"the polish failed ({polished.message})"
    elif len(passing) == 1:
        why = f"the {'polish' if name == 'complete' else 'complete solution'} fails verification"
    else:
        cots = f"{complete.verification.cot:.4f} against {polished.verification.cot:.4f}"
        why = f"the cheaper ({cots})" + ("" if passing else "; neither passes verification")
    source = {"motion": name, "why": why}
    if name == "complete" and polished is not None:
        source |= {"stand_in": "complete", "polish": {"message": polished.message, **polished.summary()}}
    return motion, source


class SectionalSolves:
    """The sectional problems k0 = 2 … N−2 of a walk: each NLP built once (or kept from an earlier walk, through
    the walk's :class:`~gaitbench.problem.build_cache.BuildCache`), solved for every step.

    With ``workers = "auto"`` on a run that fans out (``problem.fan_out``: a Dask cluster), the solves of a step
    are tasks on the run's workers (:mod:`gaitbench.fan_out`), each of which builds the sections it is sent once
    (:class:`SectionSolver`). Otherwise, with ``workers`` > 1 the solves of a step run in a pool of forked workers
    (:class:`~gaitbench.solve.parallel.WorkerPool`), each holding this object. Forking, rather than sending the
    problems to fresh processes, lets the workers inherit the built NLPs (CasADi functions and closures that do
    not pickle) and, for solvers that can ``prepare``, the built solvers too, so the build is paid once rather than
    once per worker. With ``workers = "auto"`` the walk borrows the cores that no other walk holds in its
    problem's ledger (:mod:`gaitbench.cores`), asked for again as each section ends: while none is free, the
    sections are solved here, one by one; then the rest run in the pool, as wide as the cores held, which go back
    to the ledger when the step's last sections no longer need them and at the step's end. Without a ledger (a
    strategy called directly), "auto" is serial. Which process solves a section does not change its result.
    """

    def __init__(self, problem: WalkProblem, workers: int | str = 1) -> None:
        structure = problem.structure("second")
        self.starts = list(range(2, problem.n_nodes - 1))
        builder = problem.builds.builder(problem.transcription, structure)
        self.built: dict[int, TranscribedStep] = {
            k0: builder.build(sectional_structure(structure, k0)) for k0 in self.starts}
        self.solver = section_solver(problem.solver)
        self._fan_out = problem.fan_out if workers == "auto" and len(self.starts) > 1 else None
        forking = "fork" in multiprocessing.get_all_start_methods()
        self._cores = problem.cores if workers == "auto" and forking else None
        size = (self._cores.cores if self._cores is not None else 1) if workers == "auto" else int(workers)
        self._pool: WorkerPool[SectionalSolves] | None = None
        if size > 1 and len(self.starts) > 1 and self._fan_out is None:
            for built in self.built.values():  # built once here and inherited, not once per worker
                prepare(self.solver, built.nlp)
            self._pool = WorkerPool(size, state=lambda: self, start="fork")  # forks on the first solve

    def solve(self, tasks: list[tuple[int, np.ndarray, np.ndarray]],
              stop: Callable[[], bool] = lambda: False) -> list[SolverResult]:
        """Solve (k0, parameters, initial guess) tasks; results in the tasks' order. ``stop()`` is asked before each
        section solved here, one by one: once true, the results so far (fewer than the tasks). Sections spread
        over workers run to their end."""
        if self._fan_out is not None:
            return self._fan_out.map(_solve_section, tasks, SectionSolver)
        if self._pool is None:
            return self._one_by_one(tasks, stop, lambda done: True)
        if self._cores is None:
            return self._pool.map(_solve_section, tasks)
        most = self._pool.workers

        with self._cores.lease() as borrowed:
            def width(unfinished: int) -> int:  # this walk's own core, and the borrowed ones the rest can use
                return 1 + borrowed.hold(min(most, unfinished) - 1)

            # solved here until a core is free, then spread with the rest
            results = self._one_by_one(tasks, stop, lambda done: width(len(tasks) - done) == 1)
            if len(results) == len(tasks) or stop():
                return results
            return results + self._pool.map(_solve_section, tasks[len(results):], width)

    def _one_by_one(self, tasks: list[tuple[int, np.ndarray, np.ndarray]], stop: Callable[[], bool],
                    go_on: Callable[[int], bool]) -> list[SolverResult]:
        """Sections solved here in order while ``go_on(solved so far)`` and not ``stop()``."""
        results: list[SolverResult] = []
        while len(results) < len(tasks) and not stop() and go_on(len(results)):
            results.append(self.solve_one(tasks[len(results)]))
        return results

    def solve_one(self, task: tuple[int, np.ndarray, np.ndarray]) -> SolverResult:
        k0, parameters, guess = task
        return self.solver.solve(self.built[k0].nlp, parameters, guess)

    def __enter__(self) -> SectionalSolves:
        return self

    def __exit__(self, *exc_info: object) -> None:
        if self._pool is not None:
            self._pool.close()


class SectionSolver:
    """A fanned-out walk's sectional problems on a worker of the run, each built when the worker is first sent one
    of its sections (a worker of a large cluster sees few of a walk's N−3), and kept for the walk's later steps."""

    def __init__(self, problem: WalkProblem) -> None:
        self.structure = problem.structure("second")
        self.builder = problem.builds.builder(problem.transcription, self.structure)
        self.solver = section_solver(problem.solver)
        self.built: dict[int, TranscribedStep] = {}

    def solve_one(self, task: tuple[int, np.ndarray, np.ndarray]) -> SolverResult:
        k0, parameters, guess = task
        if k0 not in self.built:
            self.built[k0] = self.builder.build(sectional_structure(self.structure, k0))
        return self.solver.solve(self.built[k0].nlp, parameters, guess)


def _solve_section(task: tuple[int, np.ndarray, np.ndarray], sections: SectionalSolves | SectionSolver
                   ) -> SolverResult:
    """A sectional solve in a worker (forked, holding the walk's :class:`SectionalSolves`, or one of the run's,
    holding a :class:`SectionSolver`)."""
    return sections.solve_one(task)


def _label(start: int) -> str:
    return "complete" if start == 0 else f"sectional-{start + 1}"


@dataclass
class PointCosts:
    """The walk's objective as point costs at one step's nodes (:meth:`Objective.point_costs`): what synthesis
    ranks candidates by and the candidate COT sums. Decrease and conquer thus chooses by the objective it reports,
    read at the nodes rather than integrated: every COT a step reports is recomputed from a trajectory's
    interpolant (docs/model.md §5)."""

    objective: Objective
    stance: int
    robot: np.ndarray
    """The step's robot vector in role order."""

    def __call__(self, dq: np.ndarray, tau: np.ndarray, push_off_work: float) -> np.ndarray:
        return self.objective.point_costs(dq, tau, push_off_work, self.stance, self.robot)


class NodeValues:
    """Every candidate's values at the step's N nodes (NaN before its start): states, torques, point costs."""

    def __init__(self, q: np.ndarray, dq: np.ndarray, tau: np.ndarray, push_off: np.ndarray,
                 push_off_energy: np.ndarray, costs: PointCosts, per_interval: bool = False) -> None:
        self.q, self.dq, self.tau = q, dq, tau  # (J, N, 2), leg order
        self.push_off, self.push_off_energy = push_off, push_off_energy  # (J,)
        self.costs = costs
        self.per_interval = per_interval
        """The candidates hold one torque per interval (DMOC): ``tau`` at node k is the interval k's."""

    @classmethod
    def of(cls, candidates: list[StepTrajectory], starts: list[int], n_nodes: int, h: float, model,
           costs: PointCosts, push_off_cost: str) -> NodeValues:
        """``push_off_cost``: how a push-off is charged (``ProblemOptions.push_off_cost``)."""
        shape = (len(candidates), n_nodes, 2)
        q, dq, tau = np.full(shape, np.nan), np.full(shape, np.nan), np.full(shape, np.nan)
        push_off, energy = np.zeros(len(candidates)), np.zeros(len(candidates))
        for j, (trajectory, start) in enumerate(zip(candidates, starts, strict=True)):
            q[j, start:], dq[j, start:] = trajectory.q, trajectory.dq
            tau[j, start:] = [trajectory.control(t) for t in trajectory.times]  # per interval: the one starting there
            push_off[j] = trajectory.push_off
            energy[j] = push_off_charge(model, trajectory, push_off_cost)
        per_interval = all(len(c.control_times) == len(c.times) - 1 for c in candidates)
        return cls(q, dq, tau, push_off, energy, costs, per_interval)

    @property
    def values(self) -> np.ndarray:
        """(J, N, 4): q1, q2, q̇1, q̇2 — the variables the synthesis's relation check compares."""
        return np.concatenate([self.q, self.dq], axis=2)

    @property
    def pcot(self) -> np.ndarray:
        """(J, N) point costs, the push-off's event cost of each candidate at its last node."""
        rows = []
        for j in range(self.q.shape[0]):
            defined = ~np.isnan(self.q[j, :, 0])
            row = np.full(self.q.shape[1], np.nan)
            row[defined] = self.costs(self.dq[j, defined], self.tau[j, defined], self.push_off_energy[j])
            rows.append(row)
        return np.array(rows)

    def completed(self, starts: list[int]) -> NodeValues:
        return NodeValues(complete_sections(self.q, starts), complete_sections(self.dq, starts),
                          complete_sections(self.tau, starts), self.push_off, self.push_off_energy, self.costs,
                          self.per_interval)

    def patch(self, selection: list[int]) -> Patch:
        nodes = np.arange(len(selection))
        last = selection[-1]
        return Patch(self.q[selection, nodes], self.dq[selection, nodes], self.tau[selection, nodes],
                     float(self.push_off[last]), float(self.push_off_energy[last]), self.costs, self.per_interval)


class Patch:
    """A trajectory assembled node by node from candidates: what the thesis synthesizes and completes."""

    def __init__(self, q: np.ndarray, dq: np.ndarray, tau: np.ndarray, push_off: float, push_off_energy: float,
                 costs: PointCosts, per_interval: bool = False):
        self.q, self.dq, self.tau = q, dq, tau
        self.push_off, self.push_off_energy = push_off, push_off_energy
        self.costs = costs
        self.per_interval = per_interval

    @property
    def pcot(self) -> np.ndarray:
        return self.costs(self.dq, self.tau, self.push_off_energy)

    def trajectory(self, stance: int, h: float) -> StepTrajectory:
        """The patch as a step trajectory: cubic Hermite angles through the nodal (q, q̇), linear rates and
        torques, or each node's interval torque held on its interval where the candidates have one per interval
        (:func:`~gaitbench.problem.trajectory.nodal_trajectory`), the reading a saved walk's patchwork gets back."""
        return nodal_trajectory(np.arange(len(self.q)) * h, self.q, self.dq, self.tau, self.push_off, stance,
                                per_interval=self.per_interval)


def walk_summary(walk: WalkResult) -> dict:
    """Claimed against verified: the thesis's figure (the patchworks') and that of the motions the walk reports."""
    steps = [step for step in walk.steps if step.details.get("chosen")]
    return {
        "claimed_acot": walk.claimed_acot,
        "verified_acot": walk.acot,
        "steps_satisfying_dynamics": sum(step.details["verified"] for step in steps),
        "chosen": [step.details["chosen"] for step in steps],
        "motions": [step.details["polished"]["motion"] for step in steps],
        "candidates": sum(step.details["candidates"] for step in steps),
        "failed_sections": sum(len(step.details["failed_sections"]) for step in steps),
        "backtracks": sum(step.details["backtracks"] for step in steps),
    }


@hookimpl
def register_strategies():
    return [Registration("decrease-and-conquer", "First Phase, N−2 Second Phase solves, synthesis by point cost "
                         "with verification and backtracking (the thesis's method), verified and polished",
                         DecreaseAndConquer)]
