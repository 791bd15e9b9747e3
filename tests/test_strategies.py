"""Strategies: the synthesis and backtracking logic on hand-made candidates, and end-to-end walks."""

from __future__ import annotations

import dataclasses
import json
import pickle
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner

from gaitbench.acceptance import MAX_DEFECT
from gaitbench.cli.main import main
from gaitbench.contracts import WalkProblem
from gaitbench.cores import IdleCores
from gaitbench.fan_out import WorkerStates
from gaitbench.plugins import load_registry
from gaitbench.problem.build_cache import BuildCache
from gaitbench.problem.gait_problem import ProblemOptions, role_robot_vector
from gaitbench.solve.parallel import WorkerPool
from gaitbench.solve.synthesis import complete_sections, relation_holds, synthesize
from gaitbench.solve.verify import verify_step
from gaitbench.solve.walk import next_step_state
from gaitbench.solver_result import SolverResult, SolverStatus
from gaitbench_plugins.strategies.decrease_and_conquer import (
    DecreaseAndConquer,
    NodeValues,
    PointCosts,
    SectionalSolves,
)

NAN = np.nan
REGISTRY = load_registry()


def _values(*rows):
    """Candidates with one variable: (J, N, 1)."""
    return np.array(rows, dtype=float)[:, :, None]


def test_relation_compares_directions_of_change():
    assert relation_holds(np.array([2.0, 1.0]), np.array([1.0, 3.0]), np.array([5.0, 0.0]), np.array([4.0, 1.0]))
    assert not relation_holds(np.array([2.0]), np.array([1.0]), np.array([3.0]), np.array([4.0]))
    assert relation_holds(np.array([1.0]), np.array([1.0]), np.array([7.0]), np.array([7.0]))  # equal, equal


def test_cheapest_candidate_wins_where_the_relation_holds():
    # Reference rises 0, 1, 2, 3; candidates 1 (from node 1) and 2 (from node 2) rise too.
    values = _values([0, 1, 2, 3], [NAN, 1.5, 2.5, 3.5], [NAN, NAN, 2.2, 3.2])
    costs = np.array([[1, 5, 5, 5], [NAN, 1, 4, 6], [NAN, NAN, 2, 1]], dtype=float)
    result = synthesize(costs, values)
    assert result.selection == [0, 1, 2, 2]
    assert (result.backtracks, result.exhausted) == (0, False)


def test_a_cheaper_candidate_breaking_the_relation_is_skipped():
    # At node 2 candidate 2 is cheapest but would make the variable fall from candidate 1's node-1 value.
    values = _values([0, 1, 2, 3], [NAN, 1.5, 2.5, 3.5], [NAN, NAN, 1.0, 3.2])
    costs = np.array([[1, 5, 5, 5], [NAN, 1, 4, 6], [NAN, NAN, 2, 1]], dtype=float)
    result = synthesize(costs, values)
    assert result.selection == [0, 1, 1, 2]
    assert result.backtracks == 0


def test_a_dead_end_steps_back_and_takes_the_next_cheapest_earlier():
    # After candidate 1 at node 1 (value 5), nothing at node 2 rises above 5: back to node 1, take the
    # reference (next cheapest there); from it candidate 1 falls and candidate 2 rises.
    values = _values([0, 1, 2, 3], [NAN, 5.0, 0.5, 4.5], [NAN, NAN, 1.5, 3.5])
    costs = np.array([[1, 3, 5, 5], [NAN, 1, 1, 1], [NAN, NAN, 2, 2]], dtype=float)
    result = synthesize(costs, values)
    assert result.selection == [0, 0, 2, 1]
    assert result.backtracks == 1
    assert not result.exhausted


def test_the_search_budget_falls_back_to_the_reference():
    """The all-reference path always satisfies the relation, so only the budget can end the search early."""
    values = _values([0, 1, 2], [NAN, 5.0, 4.0])
    costs = np.array([[1, 9, 9], [NAN, 1, 1]], dtype=float)
    found = synthesize(costs, values)  # candidate 1 at node 1 leaves no rising value at node 2: back off
    assert (found.selection, found.backtracks) == ([0, 0, 1], 1)
    budget = synthesize(np.array([[1, 9, 9], [NAN, 1, 1]], dtype=float), _values([0, 1, 2], [NAN, 0.5, 0.7]),
                        max_checks=1)
    assert budget.exhausted and budget.selection == [0, 0, 0]


def test_a_candidate_dearest_at_every_node_is_still_chosen_where_it_alone_keeps_the_relation():
    """Why no bound on a section's cost can rule it out of the synthesis (docs/decisions/0014-section-pruning.md):
    candidate 2 costs most at every node, yet it is the only way on after the cheapest choice at node 1."""
    values = _values([0, 1, 2, 3], [NAN, 5.0, 0.5, 4.5], [NAN, NAN, 6.0, 7.0])
    costs = np.array([[1, 3, 5, 5], [NAN, 1, 1, 1], [NAN, NAN, 9, 9]], dtype=float)
    assert synthesize(costs, values).selection == [0, 1, 2, 2]
    assert synthesize(costs[:2], values[:2]).selection == [0, 0, 0, 1]  # without it: another path altogether


def test_the_synthesis_is_unchanged_by_leaving_out_a_candidate_it_did_not_select():
    """The search returns the first path in rank order that keeps the relation, so a candidate off that path changes
    nothing when left out, within the check budget: what decision 0014's replay of the choice relies on."""
    rng = np.random.default_rng(11)
    compared = 0
    for trial in range(200):
        n_candidates, n_nodes = rng.integers(3, 8), rng.integers(3, 12)
        starts = np.r_[0, np.sort(rng.integers(1, n_nodes - 1, n_candidates - 1))]
        values = np.cumsum(rng.normal(size=(n_candidates, n_nodes, 2)), axis=1)
        costs = rng.random((n_candidates, n_nodes))
        for j, start in enumerate(starts):
            values[j, :start], costs[j, :start] = NAN, NAN
        found = synthesize(costs, values)
        for left_out in set(range(1, n_candidates)) - set(found.selection):
            keep = [j for j in range(n_candidates) if j != left_out]
            again = synthesize(costs[keep], values[keep])
            assert [keep[j] for j in again.selection] == found.selection, trial
            compared += 1
    assert compared > 200


def _search_one_check_at_a_time(costs, values, max_checks):
    """The synthesis as the thesis describes it, one relation check at a time: what the batched search must equal."""
    n_nodes = costs.shape[1]
    ranked = [[int(j) for j in np.flatnonzero(~np.isnan(costs[:, k]))[np.argsort(
        costs[~np.isnan(costs[:, k]), k], kind="stable")]] for k in range(n_nodes)]
    selection, tried, backtracks, checks, k = [0] * n_nodes, [0] * n_nodes, 0, 0, 1
    while k < n_nodes:
        found = False
        while tried[k] < len(ranked[k]):
            j = ranked[k][tried[k]]
            checks += 1
            if relation_holds(values[j, k], values[selection[k - 1], k - 1], values[0, k], values[0, k - 1]):
                selection[k], found = j, True
                break
            tried[k] += 1
        if checks > max_checks:
            return [0] * n_nodes, backtracks, checks, True
        if found:
            k += 1
            if k < n_nodes:
                tried[k] = 0
            continue
        tried[k], k, backtracks = 0, k - 1, backtracks + 1
        tried[k] += 1
    return selection, backtracks, checks, False


def test_the_batched_search_makes_the_same_choices_and_counts_as_checking_one_at_a_time():
    rng = np.random.default_rng(7)
    seen_backtracks = seen_exhausted = 0
    for trial in range(300):
        n_candidates, n_nodes = rng.integers(2, 9), rng.integers(3, 14)
        starts = np.r_[0, np.sort(rng.integers(1, n_nodes - 1, n_candidates - 1))]
        values = np.cumsum(rng.normal(size=(n_candidates, n_nodes, 2)), axis=1)
        values[:, :, 1] = np.round(values[:, :, 1])  # equal neighbours too: direction 0
        costs = rng.random((n_candidates, n_nodes))
        for j, start in enumerate(starts):
            values[j, :start], costs[j, :start] = NAN, NAN
        max_checks = int(rng.choice([5, 20, 1_000_000]))
        found = synthesize(costs, values, max_checks=max_checks)
        expected = _search_one_check_at_a_time(costs, values, max_checks)
        assert (found.selection, found.backtracks, found.checks, found.exhausted) == expected, trial
        seen_backtracks += found.backtracks > 0
        seen_exhausted += found.exhausted
    assert seen_backtracks > 20 and seen_exhausted > 20  # both branches of the search were exercised


def test_sections_are_completed_from_the_candidates_starting_earlier():
    values = _values([0, 1, 2, 3], [NAN, 11, 12, 13], [NAN, NAN, 22, 23])
    completed = complete_sections(values, [0, 1, 2])
    np.testing.assert_array_equal(completed[:, :, 0], [[0, 1, 2, 3], [0, 11, 12, 13], [0, 11, 22, 23]])


@pytest.fixture(scope="module")
def forward():
    return REGISTRY.create("experiment", "forward")


class PolishCalledInfeasibleOnce:
    """IPOPT, except that the second solve of one NLP, on a one-step walk decrease-and-conquer's polish of the
    complete problem, is called infeasible once, as IPOPT called stairs N = 30 step 6's; its remedy is IPOPT."""

    name = "polish-called-infeasible-once"

    def __init__(self) -> None:
        self.ipopt = REGISTRY.create("solver", "ipopt")
        self.solves: dict[int, int] = {}
        self.failed = False

    def solve(self, nlp, parameters, initial_guess):
        self.solves[id(nlp)] = self.solves.get(id(nlp), 0) + 1
        if self.solves[id(nlp)] == 2 and not self.failed:
            self.failed = True
            return SolverResult(SolverStatus.INFEASIBLE, "infeasible (scripted)", np.asarray(initial_guess), np.nan,
                                np.nan, 3, 0.0, 0.0)
        return self.ipopt.solve(nlp, parameters, initial_guess)

    def remedies(self):
        return [("use-ipopt", self.ipopt)]


def test_a_polish_called_infeasible_climbs_the_solver_s_remedies_from_its_own_seed(forward):
    solver = PolishCalledInfeasibleOnce()
    problem = WalkProblem(forward, REGISTRY.create("transcription", "hermite-simpson"), solver, 8, steps=1)
    walk = DecreaseAndConquer().solve(problem)
    details = walk.steps[0].details
    assert solver.failed and details["polished"]["status"] == "converged"
    assert [retry["remedy"] for retry in details["retries"]] == ["polish:use-ipopt"]  # no first-phase reseed
    assert walk.strategy_details["verified_acot"] == pytest.approx(details["polished"]["cot"])


class FirstNlpCalledInfeasible:
    """IPOPT, except that the first NLP it is given (decrease-and-conquer's N-node First Phase) is called infeasible
    on its first two solves (the first attempt and the remedy), as IPOPT called stairs HS N = 130 step 5's."""

    name = "first-nlp-called-infeasible"

    def __init__(self) -> None:
        self.ipopt = REGISTRY.create("solver", "ipopt")
        self.first_nlp = None
        self.refused = 0

    def solve(self, nlp, parameters, initial_guess):
        self.first_nlp = self.first_nlp or nlp
        if nlp is self.first_nlp and self.refused < 2:
            self.refused += 1
            return SolverResult(SolverStatus.INFEASIBLE, "infeasible (scripted)", np.asarray(initial_guess), np.nan,
                                np.nan, 3, 0.0, 0.0)
        return self.ipopt.solve(nlp, parameters, initial_guess)

    def remedies(self):
        return [("use-ipopt", self)]


@pytest.mark.parametrize("rescue", [True, False])
def test_a_first_phase_that_every_rung_leaves_unsolved_is_rescued_from_a_coarser_grid(forward, rescue):
    problem = WalkProblem(forward, REGISTRY.create("transcription", "hermite-simpson"), FirstNlpCalledInfeasible(), 8,
                          steps=1)
    step = DecreaseAndConquer(rescue=rescue).solve(problem).steps[0]
    if not rescue:
        assert not step.solved and step.details["failed_in"] == "first phase"
        assert step.message.startswith("First Phase: infeasible")
        return
    assert step.solved and step.polished.solved, step.message
    assert step.details["rescued_from"]["failed_in"] == "first phase"
    assert step.details["rescued_from"]["status"] == "infeasible"
    # the N-node First Phase's remedy, then the 6-node grid that seeded it (6 = ¾ · 8; ½ · 8 = 4 is below the least)
    assert [retry["remedy"] for retry in step.details["retries"]] == ["use-ipopt", "coarse-seed-6"]
    assert step.details["first_phase"]["status"] == "converged"


class PolishNeverSolves(PolishCalledInfeasibleOnce):
    """IPOPT, except that every solve of an NLP after its first (a one-step walk's polish and its remedy) is called
    infeasible, as stairs HS N = 120 step 5's polish ended at IPOPT's iteration limit with every remedy."""

    def solve(self, nlp, parameters, initial_guess):
        self.solves[id(nlp)] = self.solves.get(id(nlp), 0) + 1
        if self.solves[id(nlp)] > 1:
            return SolverResult(SolverStatus.INFEASIBLE, "infeasible (scripted)", np.asarray(initial_guess), np.nan,
                                np.nan, 3, 0.0, 0.0)
        return self.ipopt.solve(nlp, parameters, initial_guess)

    def remedies(self):
        return [("retry", self)]


def test_a_polish_that_fails_leaves_the_complete_second_phase_as_the_verified_step(forward):
    problem = WalkProblem(forward, REGISTRY.create("transcription", "hermite-simpson"), PolishNeverSolves(), 8,
                          steps=1)
    walk = DecreaseAndConquer().solve(problem)
    step = walk.steps[0]
    details = step.details
    assert details["polished"]["stand_in"] == "complete"
    assert details["polished"]["polish"]["status"] == "infeasible"
    assert step.verified is step.polished and step.polished.solved
    assert details["polished"]["cot"] == details["complete"]["cot"] == step.polished.verification.cot
    assert walk.strategy_details["verified_acot"] == pytest.approx(details["complete"]["cot"])


@pytest.mark.parametrize("transcription", ["hermite-simpson", "dmoc"])
def test_decrease_and_conquer_walks_and_records_everything(forward, transcription, tmp_path):
    n = 8
    problem = WalkProblem(forward, REGISTRY.create("transcription", transcription), REGISTRY.create("solver", "ipopt"),
                          n, steps=2)
    walk = DecreaseAndConquer().solve(problem)
    assert walk.complete, walk.failure
    for step in walk.steps:
        details = step.details
        assert details["candidates"] + len(details["failed_sections"]) == n - 2  # complete + k0 = 2 … N−2
        assert len(details["selection"]) == n and details["selection"][0] == "complete"
        assert set(details["candidate_cots"]) >= {"synthesized", "complete"}
        assert details["chosen"] == min(details["candidate_cots"], key=details["candidate_cots"].get)
        assert details["verified"] == (step.verification.max_defect <= MAX_DEFECT)
        assert details["claimed_cot"] == step.verification.cot
        assert details["polished"]["status"] == "converged"
        assert details["first_phase"]["status"] == "converged"
    summary = walk.strategy_details
    assert summary["claimed_acot"] == pytest.approx(np.mean([s.verification.cot for s in walk.steps]))
    assert summary["claimed_acot"] == walk.claimed_acot
    assert summary["verified_acot"] == walk.acot == pytest.approx(np.mean([s.details["polished"]["cot"]
                                                                            for s in walk.steps]))
    assert walk.acot == pytest.approx(np.mean([s.verified.verification.cot for s in walk.steps]))
    assert summary["candidates"] == sum(s.details["candidates"] for s in walk.steps)
    assert all(s.message.startswith("patchwork, not a motion") for s in walk.steps)
    _the_polished_trajectory_is_kept_and_stored(walk, tmp_path)
    _the_walk_goes_on_from_each_steps_motion(problem, walk)


def _the_walk_goes_on_from_each_steps_motion(problem, walk):
    """Step 2 starts from the post-impact state of step 1's reported motion (its polish or complete solution),
    never from the patchwork's: the walk's motions join, and the whole-walk verification finds the join exact."""
    from gaitbench.solve.walk_verification import verify_walk

    first, second = walk.steps
    expected = next_step_state(problem.model("second"), first.verified.trajectory)
    np.testing.assert_allclose(first.next_state, expected)
    start = np.r_[second.verified.trajectory.q[0], second.verified.trajectory.dq[0]]
    np.testing.assert_allclose(start, expected, atol=1e-8)
    check = verify_walk(walk, problem.start_state(), problem.experiment.robot)
    assert check.max_join_mismatch < 1e-6 and abs(check.join_energy) < 1e-6


@pytest.mark.slow
def test_decrease_and_conquer_walks_on_from_motions_past_the_patchwork_dead_end():
    """Upward slope, HS, N = 60 (a thesis-all case): from step 3's chosen patchwork, step 4's First Phase reaches
    IPOPT's iteration limit with both μ strategies; walking on from each step's motion, the walk completes."""
    upward = REGISTRY.create("experiment", "upward-slope")
    problem = WalkProblem(upward, REGISTRY.create("transcription", "hermite-simpson"),
                          REGISTRY.create("solver", "ipopt"), 60, steps=4)
    walk = DecreaseAndConquer().solve(problem)
    assert walk.complete, walk.failure


def _the_polished_trajectory_is_kept_and_stored(walk, tmp_path):
    """The verified trajectory, each step re-solved from the chosen patchwork, is in the outcome and in the walk's
    NPZ beside the patchwork, and comes back from it (what the report draws and tracking follows)."""
    from gaitbench.solve.walk_file import load_walk, write_walk

    for step in walk.steps:
        assert step.polished is not None and step.polished.solved and step.verified is step.polished
        assert step.polished.verification.cot == step.details["polished"]["cot"]
        assert step.polished.verification.max_defect <= MAX_DEFECT
        assert step.details["polished"]["max_defect"] == step.polished.verification.max_defect
    path = write_walk(walk, tmp_path / "walk.json")
    with np.load(path.with_suffix(".npz")) as arrays:
        for step in walk.steps:
            prefix = f"step{step.index:02d}"
            np.testing.assert_array_equal(arrays[f"{prefix}_polished_q"], step.polished.trajectory.q)
            np.testing.assert_array_equal(arrays[f"{prefix}_polished_tau"], step.polished.trajectory.tau)
            np.testing.assert_array_equal(arrays[f"{prefix}_q"], step.trajectory.q)  # the patchwork stays
    loaded, _ = load_walk(path, REGISTRY)
    for original, copy in zip(walk.steps, loaded.steps, strict=True):
        assert copy.polished is not None and copy.verified is copy.polished
        np.testing.assert_array_equal(copy.polished.trajectory.dq, original.polished.trajectory.dq)
        assert copy.polished.verification.cot == pytest.approx(original.polished.verification.cot)


def test_parallel_sectional_solves_give_the_sequential_walk(forward):
    """Forked workers solve the same sectional NLPs from the same guesses: the walk must not change."""
    def walk(workers):
        problem = WalkProblem(forward, REGISTRY.create("transcription", "hermite-simpson"),
                              REGISTRY.create("solver", "ipopt"), 8, steps=1)
        return DecreaseAndConquer(polish=False, workers=workers).solve(problem)

    sequential, parallel = walk(1), walk(2)
    assert parallel.complete
    _assert_same_step(parallel, sequential)
    for workers in (0, "all"):
        with pytest.raises(ValueError, match=f"workers = {workers!r}"):
            DecreaseAndConquer(workers=workers)


def _assert_same_step(walk, reference):
    for key in ("candidates", "failed_sections", "selection", "candidate_cots", "chosen", "claimed_cot"):
        assert walk.steps[0].details[key] == reference.steps[0].details[key], key
    np.testing.assert_array_equal(walk.steps[0].trajectory.q, reference.steps[0].trajectory.q)


def test_auto_workers_borrow_only_the_idle_cores_and_give_the_sequential_walk(forward, tmp_path, monkeypatch):
    """workers = "auto" spreads a step's sections over the cores no other walk holds, and solves them here when
    none is free; either way the walk is the one solved serially."""
    widths = []
    pool_map = WorkerPool.map

    def counted_map(self, task, items, width=None):
        if items:
            widths.append(width(len(items)))
        return pool_map(self, task, items, width)

    monkeypatch.setattr(WorkerPool, "map", counted_map)
    cores = IdleCores(tmp_path / "cores", 2)

    def walk(workers, cores=None):
        problem = WalkProblem(forward, REGISTRY.create("transcription", "hermite-simpson"),
                              REGISTRY.create("solver", "ipopt"), 8, steps=1, cores=cores)
        return DecreaseAndConquer(polish=False, workers=workers).solve(problem)

    sequential = walk(1)
    with cores.occupy():
        borrowing = walk("auto", cores)
        assert widths == [2]  # its own core and the idle one, from the first section on
        other_walk = cores.lease()
        assert other_walk.hold(1) == 1
        busy = walk("auto", cores)
        assert widths == [2]  # no core to borrow: solved here
        assert walk("auto").complete and widths == [2]  # without a ledger, serial

        solve_one, solved_here = SectionalSolves.solve_one, []

        def freed_after_two(self, task):  # the other walk ends while this step's third section is due
            solved_here.append(task[0])
            if len(solved_here) == 2:
                other_walk.release()
            return solve_one(self, task)

        monkeypatch.setattr(SectionalSolves, "solve_one", freed_after_two)
        assert other_walk.hold(1) == 1
        freed = walk("auto", cores)
    assert solved_here[:2] == [2, 3] and widths == [2, 2]  # the rest of the step spread over both cores
    for walked in (borrowing, busy, freed):
        _assert_same_step(walked, sequential)


class PickledFanOut:
    """A run's fan-out without a cluster: each item and the task and state factory pickled as a Dask worker gets
    them, and the state made from the walk's problem built afresh, as a worker rebuilds it
    (:mod:`gaitbench.fan_out`)."""

    def __init__(self, problem: Callable[[], WalkProblem]) -> None:
        self.states, self.problem, self.items = WorkerStates(), problem, []

    def map(self, task, items, state):
        task, state = pickle.loads(pickle.dumps((task, state)))
        self.items += [pickle.loads(pickle.dumps(item)) for item in items]
        return [task(item, self.states.get("walk", state, self.problem)) for item in self.items[-len(items):]]


def test_a_fanned_out_walk_s_sections_go_to_the_run_s_workers_and_give_the_walk_solved_here(forward, monkeypatch):
    """With a run's fan-out, workers = "auto" sends every section of a step to it, a worker builds each section it
    is sent once for the whole walk, and the walk is the one solved serially; a set number of workers keeps the
    walk's own processes."""
    from gaitbench.problem.transcription import Transcription

    def problem(fan_out=None, builds=None):
        return WalkProblem(forward, REGISTRY.create("transcription", "hermite-simpson"),
                           REGISTRY.create("solver", "ipopt"), 8, steps=2, fan_out=fan_out,
                           builds=builds or BuildCache())

    built, build = [], Transcription._build
    sequential = DecreaseAndConquer(polish=False, workers=1).solve(problem())
    worker_builds = BuildCache()
    fan_out = PickledFanOut(lambda: problem(builds=worker_builds))
    monkeypatch.setattr(Transcription, "_build",
                        lambda self, structure: built.append(structure) or build(self, structure))
    fanned = DecreaseAndConquer(polish=False).solve(problem(fan_out))
    assert [k0 for k0, _, _ in fan_out.items] == [2, 3, 4, 5, 6] * 2  # every section of both steps
    worker_sections = [structure for structure in built if structure.n_nodes < 8][5:]
    assert len(worker_sections) == 5  # the walk's own five, then the worker's five, once for both steps
    assert fanned.complete and fanned.strategy_details == sequential.strategy_details
    for one, other in zip(fanned.steps, sequential.steps, strict=True):
        assert one.details["candidate_cots"] == other.details["candidate_cots"]
        np.testing.assert_array_equal(one.trajectory.q, other.trajectory.q)
    fan_out.items.clear()
    DecreaseAndConquer(polish=False, workers=1).solve(problem(fan_out))
    assert fan_out.items == []


def test_walks_sharing_a_build_cache_build_only_the_sections_not_built_yet(forward, monkeypatch):
    from gaitbench.problem.transcription import Transcription

    built, build = [], Transcription._build
    monkeypatch.setattr(Transcription, "_build",
                        lambda self, structure: built.append(structure) or build(self, structure))
    builds = BuildCache()  # a suite worker's

    def walk(n, cache=builds, **options):
        problem = WalkProblem(forward, REGISTRY.create("transcription", "dmoc"), REGISTRY.create("solver", "ipopt"),
                              n, steps=1, options=dataclasses.replace(ProblemOptions(limits=forward.limits), **options),
                              builds=cache)
        built.clear()
        result = DecreaseAndConquer(polish=False).solve(problem)
        return result, sorted(structure.n_nodes for structure in built if structure.phase == "second")

    _, sizes = walk(8)
    assert sizes == [3, 4, 5, 6, 7, 8]  # the sections k0 = 2 … 6, and the complete step
    shared, sizes = walk(10)
    assert sizes == [9, 10]  # the 3 … 8-node sections: built by the walk at N = 8 (8 nodes: its complete step)
    alone, sizes = walk(10, cache=BuildCache())
    assert sizes == [3, 4, 5, 6, 7, 8, 9, 10]  # a walk of its own builds everything
    for key in ("candidates", "failed_sections", "selection", "candidate_cots", "chosen", "claimed_cot"):
        assert shared.steps[0].details[key] == alone.steps[0].details[key], key
    walk(8, torque_regularization=1e-3)  # other problem options: other structures, and the kept ones are dropped
    _, sizes = walk(8)
    assert sizes == [3, 4, 5, 6, 7, 8]


def test_verification_tells_a_solution_from_a_patchwork(forward):
    """The complete trajectory re-assembled node by node satisfies the dynamics; a patch mixing it with a
    sectional solution does not — the check that decrease-and-conquer's claims rely on."""
    problem = WalkProblem(forward, REGISTRY.create("transcription", "hermite-simpson"),
                          REGISTRY.create("solver", "ipopt"), 8, steps=1)
    walk = DecreaseAndConquer(polish=False).solve(problem)
    step = walk.steps[0]
    assert step.details["chosen"] != "complete"  # measured: a patch wins the thesis's COT comparison here
    assert not step.details["verified"] and step.verification.max_defect > 1e-3

    built = problem.transcription.build(problem.structure("second"))
    data = problem.step_data(1, np.asarray(forward.initial_state)[[0, 1, 4, 5]])
    complete = problem.solver.solve(built.nlp, data.parameter_vector(), built.initial_guess(data))
    trajectory = built.trajectory(complete.x, data)
    costs = PointCosts(problem.objective, data.stance, role_robot_vector(data.robot, data.stance))
    nodes = NodeValues.of([trajectory], [0], 8, data.time_step, problem.model("second"), costs, "impulse")
    patch = nodes.patch([0] * 8).trajectory(data.stance, data.time_step)
    x = built.initial_guess(data, patch.seed())
    check = verify_step(built, x, data, patch, problem.model("second"))
    assert check.max_defect < 1e-7
    # not polished: the step reports its complete Second Phase solution, the motion the walk goes on from
    assert step.details["polished"]["motion"] == "complete" and step.details["polished"]["why"] == "not polished"
    assert step.verified is step.polished and step.polished.verification.max_defect < 1e-7


@pytest.mark.parametrize("transcription", ["hermite-simpson", "dmoc", "trapezoidal"])
def test_a_patch_of_one_candidate_is_that_candidate(transcription):
    """The complete solution re-assembled node by node and read back through its transcription is the same motion
    at the same cost, for every transcription: DMOC's torques are one per interval, and a patch that averaged two
    intervals' at each midpoint priced every DMOC claim on other torques (upward slope, N = 10: COT 0.307 against
    the solution's 0.451, defect 54)."""
    experiment = REGISTRY.create("experiment", "upward-slope")
    problem = WalkProblem(experiment, REGISTRY.create("transcription", transcription),
                          REGISTRY.create("solver", "ipopt"), 10, steps=1)
    built = problem.transcription.build(problem.structure("second"))
    data = problem.step_data(1, problem.start_state())
    solved = problem.solver.solve(built.nlp, data.parameter_vector(), built.initial_guess(data))
    trajectory = built.trajectory(solved.x, data)
    model = problem.model("second")
    own = verify_step(built, solved.x, data, trajectory, model)
    costs = PointCosts(problem.objective, data.stance, role_robot_vector(data.robot, data.stance))
    nodes = NodeValues.of([trajectory], [0], 10, data.time_step, model, costs, "impulse")
    patch = nodes.patch([0] * 10).trajectory(data.stance, data.time_step)
    x = built.variables(patch, data)
    again = verify_step(built, x, data, built.trajectory(x, data), model)
    assert again.max_defect < 1e-6 and again.cot == pytest.approx(own.cot, rel=1e-6)


def test_warm_start_records_the_first_phase(forward):
    problem = WalkProblem(forward, REGISTRY.create("transcription", "dmoc"), REGISTRY.create("solver", "ipopt"), 10,
                          steps=2)
    walk = REGISTRY.create("strategy", "warm-start").solve(problem)
    assert walk.complete, walk.failure
    assert walk.strategy == "warm-start"
    assert all(step.details["first_phase"]["status"] == "converged" for step in walk.steps)


def test_solve_command_with_a_strategy_writes_strategy_details(tmp_path):
    out = tmp_path / "dc.json"
    result = CliRunner().invoke(main, ["solve", "-e", "forward", "-t", "dmoc", "--N", "8", "--steps", "1",
                                       "-S", "decrease-and-conquer", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "claimed ACOT" in result.output and "verified ACOT" in result.output
    data = json.loads(out.read_text())
    assert data["strategy"] == "decrease-and-conquer"
    assert {"claimed_acot", "verified_acot", "candidates", "backtracks"} <= set(data["strategy_details"])
    assert data["steps"][0]["details"]["chosen"]


def test_unknown_strategy_option_is_a_clear_error():
    result = CliRunner().invoke(main, ["solve", "-e", "forward", "-S", "decrease-and-conquer",
                                       "-x", "sectional_guess=random"])
    assert result.exit_code == 2
    assert "sectional_guess = 'random'" in result.output


def test_whole_walk_chains_its_steps_and_improves_on_one_phase(forward):
    """Started from the One Phase walk (a feasible point of the whole-walk NLP), the whole-walk optimum costs no
    more, and each step starts exactly where the event map of the previous one ends."""
    problem = WalkProblem(forward, REGISTRY.create("transcription", "dmoc"), REGISTRY.create("solver", "ipopt"), 10,
                          steps=3)
    baseline = REGISTRY.create("strategy", "one-phase").solve(problem)
    walk = REGISTRY.create("strategy", "whole-walk", guess="one-phase").solve(problem)
    assert walk.complete, walk.failure
    assert walk.strategy_details["solver"]["status"] == "converged"
    optimum = walk.strategy_details["solver"]["objective"]
    assert optimum <= np.mean([step.solver_result.objective for step in baseline.steps]) + 1e-7
    for before, after in zip(walk.steps, walk.steps[1:], strict=False):
        start = np.r_[after.trajectory.q[0], after.trajectory.dq[0]]
        np.testing.assert_allclose(start, before.next_state, atol=1e-7)
    assert all(step.verification.max_defect < 1e-6 for step in walk.steps)


def _short_slope(n_steps: int):
    from gaitbench.model.experiment import Experiment
    from gaitbench.model.robot import RobotParameters
    from gaitbench.model.terrain import Terrain

    return Experiment(name="short-slope", description=f"{n_steps} 0.5 m steps up a 0.1 rad slope",
                      robot=RobotParameters(m1=20.0, m2=20.0, M=40.0, l=1.0, a=0.5),
                      terrain=Terrain.slope([0.5] * n_steps, 0.1),
                      initial_state=[0.2187, -0.2187, 0.0, 0.0, -1.0924, -0.3774, 0.0, 0.0], step_duration=0.7343)


def test_whole_walk_without_a_step_count_solves_the_full_walk():
    """steps = None is the experiment's full walk (it once crashed asking for step n + 1)."""
    experiment = _short_slope(3)
    problem = WalkProblem(experiment, REGISTRY.create("transcription", "dmoc"), REGISTRY.create("solver", "ipopt"), 8)
    reported = []
    walk = REGISTRY.create("strategy", "whole-walk").solve(problem, on_step=lambda step: reported.append(step.index))
    assert walk.complete, walk.failure
    assert walk.requested_steps == experiment.n_steps == len(walk.steps) == 3
    assert reported == [1, 2, 3] and [step.index for step in walk.steps] == [1, 2, 3]
    assert [step.stance for step in walk.steps] == [1, 2, 1]
    assert walk.acot is not None and all(step.verification.max_defect < 1e-6 for step in walk.steps)


def test_whole_walk_command_without_steps_walks_every_step(tmp_path):
    out = tmp_path / "whole.json"
    plugins = Path(__file__).resolve().parent.parent / "examples" / "plugins"
    result = CliRunner().invoke(main, ["--plugins-dir", str(plugins), "solve", "-e", "gentle-slope", "-t", "dmoc",
                                       "-S", "whole-walk", "--N", "8", "--out", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["complete"] and data["requested_steps"] == len(data["steps"]) == 5


@pytest.mark.slow
def test_whole_walk_solves_the_full_forward_walk(forward):
    """All 11 forward steps in one NLP (HS, N = 20): measured 43 s wall, ACOT 0.287, 334 IPOPT iterations."""
    problem = WalkProblem(forward, REGISTRY.create("transcription", "hermite-simpson"),
                          REGISTRY.create("solver", "ipopt"), 20)
    walk = REGISTRY.create("strategy", "whole-walk").solve(problem)
    assert walk.complete, walk.failure
    assert len(walk.steps) == forward.n_steps == 11
    assert 0 < walk.acot < 1 and all(step.verification.max_defect < 1e-6 for step in walk.steps)


def test_a_chain_starts_each_step_where_the_event_map_of_the_previous_one_ends():
    """The symbolic push-off and heel-strike map inside a chain is the numeric one the per-step walk uses, also for
    a Leg-2 stance step of a robot with unequal legs (whose role-ordered robot vector the chain turns back)."""
    from gaitbench.model.robot import RobotParameters
    from gaitbench.solve.walk import next_step_state
    from gaitbench.solve.walk_chain import WalkChain

    experiment = dataclasses.replace(_short_slope(3), robot=RobotParameters(m1=15.0, m2=25.0, M=40.0, l=1.0, a=0.5))
    problem = WalkProblem(experiment, REGISTRY.create("transcription", "hermite-simpson"),
                          REGISTRY.create("solver", "ipopt"), 8)
    built = problem.transcription.build(problem.structure("second"))
    chain = WalkChain(built, first_stance=2, count=2)
    state = np.array([0.25, -0.2, -1.1, -0.4])
    p = chain.parameters(problem, 2, state)
    noise = 0.01 * np.random.default_rng(0).standard_normal(chain.nlp.n_variables)
    x = chain.guess(problem, 2, [(state, None)]) + noise
    (x1, data1), (_, data2) = chain.steps(problem, 2, x, p)
    assert (data1.stance, data2.stance) == (2, 1)
    np.testing.assert_allclose(data1.initial_state, state)
    expected = next_step_state(problem.model("second"), built.trajectory(x1, data1))
    np.testing.assert_allclose(data2.initial_state, expected, atol=1e-10)


def test_look_ahead_and_back_up_walk_past_the_greedy_dead_end():
    """Stairs, DMOC, N = 20: the greedy walk (H = 1, no back-up) stops at step 8, infeasible after every rung of the
    retry ladder but the last resort. Backing up (the default) solves step 7 again with step 8 and walks on; a fixed
    look-ahead of two steps walks all 11 without a dead end. IPOPT's μ₀ is fixed at its default, which removes the
    last resort (``small-mu-init`` solves step 8 of the greedy walk) so the dead end stays one."""
    stairs = REGISTRY.create("experiment", "stairs")
    ipopt = REGISTRY.create("solver", "ipopt", mu_init=0.1)
    problem = WalkProblem(stairs, REGISTRY.create("transcription", "dmoc"), ipopt, 20)
    greedy = REGISTRY.create("strategy", "one-phase", back_up=False, rescue=False).solve(problem)
    assert not greedy.complete and greedy.steps[-1].index == 8 and greedy.steps[-1].status == "infeasible"

    walk = REGISTRY.create("strategy", "one-phase").solve(problem)
    assert walk.complete, walk.failure
    backed_up = [step for step in walk.steps if "backed_up_from" in step.details]
    assert [step.index for step in backed_up] == [7]
    assert backed_up[0].details["backed_up_from"]["dead_end"]["step"] == 8
    assert backed_up[0].details["backed_up_from"]["cot"] == pytest.approx(greedy.steps[6].verification.cot)
    assert [step.verification.cot for step in walk.steps[:6]] == [step.verification.cot for step in greedy.steps[:6]]

    ahead = REGISTRY.create("strategy", "one-phase", look_ahead=2).solve(problem)
    assert ahead.complete, ahead.failure
    assert all(step.verification.max_defect < 1e-6 for step in ahead.steps)
    windows = [step.details["look_ahead"] for step in ahead.steps[:-1]]
    assert all(window["horizon"] == 2 and "fallback" not in window for window in windows)
    assert "look_ahead" not in ahead.steps[-1].details  # the last step has nothing to look ahead to


@pytest.mark.slow
def test_a_back_up_started_from_the_step_it_replaces_walks_past_an_upward_slope_dead_end():
    """Upward slope, HS, N = 90 (a thesis-all case): greedy step 4 leaves too little momentum for step 5, which no
    rung solves (IPOPT calls it infeasible; with clearance off it converges in 133 iterations). Steps 4 and 5 as one
    window from the blended guess reached IPOPT's 3000 iterations with both μ strategies (the stored case); started
    from step 4's own trajectory the window converges (526 iterations, measured) and step 5 follows."""
    upward = REGISTRY.create("experiment", "upward-slope")
    problem = WalkProblem(upward, REGISTRY.create("transcription", "hermite-simpson"),
                          REGISTRY.create("solver", "ipopt"), 90, steps=5)
    walk = REGISTRY.create("strategy", "one-phase").solve(problem)
    assert walk.complete, walk.failure
    backed_up = [step for step in walk.steps if "backed_up_from" in step.details]
    assert [step.index for step in backed_up] == [4]
    assert backed_up[0].details["backed_up_from"]["dead_end"]["step"] == 5
    assert all(step.verification.max_defect < 1e-6 for step in walk.steps)


def test_a_walk_backs_up_once_per_step_and_records_what_it_replaced():
    """walk_step_by_step's back-up on made-up steps: step 3 is a dead end from the greedy step 2 only; step 5 from
    every step 4, so its back-up fails and the walk stops there, naming the back-up. Each back-up starts from the
    trajectory of the step it replaces."""
    from gaitbench.solve.walk import walk_step_by_step
    from gaitbench.walk_types import StepOutcome

    experiment = _short_slope(6)
    problem = WalkProblem(experiment, REGISTRY.create("transcription", "dmoc"), REGISTRY.create("solver", "ipopt"), 8)
    seeds = []

    def outcome(index, state, solved):
        return StepOutcome(index, experiment.stance_leg(index), "converged" if solved else "infeasible", "",
                           trajectory=SimpleNamespace(seed=lambda: f"seed of step {index}") if solved else None,
                           verification=SimpleNamespace(cot=0.1, resim_error=0.0) if solved else None,
                           next_state=state + np.array([1.0, 0, 0, 0]) if solved else None)

    def greedy(problem, index, state):
        if index == 3:
            return outcome(index, state, solved=state[1] > 0.5)  # only from the backed-up step 2
        return outcome(index, state, solved=index != 5)

    def back_up(problem, index, state, replaced):
        seeds.append(replaced.verified.trajectory.seed())
        result = outcome(index, state, solved=index == 2)
        if result.solved:
            result.next_state = state + np.array([1.0, 1.0, 0, 0])
        return result

    walk = walk_step_by_step(problem, "test", greedy, back_up=back_up)
    assert [step.index for step in walk.steps] == [1, 2, 3, 4, 5]
    assert walk.steps[1].details["backed_up_from"]["dead_end"]["step"] == 3
    assert not walk.steps[-1].solved and walk.steps[-1].details["back_up"]["step"] == 4
    assert seeds == ["seed of step 2", "seed of step 4"]
    assert walk_step_by_step(problem, "test", greedy).steps[-1].index == 3  # without back-up: the first dead end


def test_a_step_that_no_rung_and_no_back_up_solves_is_rescued_from_the_same_state():
    """walk_step_by_step's rescue on made-up steps: it gets the failed step after its back-up has failed, from the
    state the step started at, and a rescued step walks on; a time limit is never rescued."""
    from gaitbench.solve.walk import walk_step_by_step
    from gaitbench.walk_types import StepOutcome

    experiment = _short_slope(4)
    problem = WalkProblem(experiment, REGISTRY.create("transcription", "dmoc"), REGISTRY.create("solver", "ipopt"), 8)
    calls = []

    def outcome(index, state, solved, status="infeasible"):
        return StepOutcome(index, experiment.stance_leg(index), "converged" if solved else status, "no",
                           trajectory=SimpleNamespace(seed=lambda: None) if solved else None,
                           verification=SimpleNamespace(cot=0.1, resim_error=0.0) if solved else None,
                           next_state=state + np.array([1.0, 0, 0, 0]) if solved else None)

    def greedy(problem, index, state):
        return outcome(index, state, solved=index != 3)

    def back_up(problem, index, state, replaced):
        calls.append(("back-up", index))
        return outcome(index, state, solved=False)

    def rescue(problem, index, state, failed):
        calls.append(("rescue", index, float(state[0]), failed.details["back_up"]["step"]))
        return outcome(index, state, solved=True)

    walk = walk_step_by_step(problem, "test", greedy, back_up=back_up, rescue=rescue)
    assert walk.complete and [step.index for step in walk.steps] == [1, 2, 3, 4]
    started = problem.start_state()[0] + 2.0  # step 3 starts where steps 1 and 2 left it
    assert calls == [("back-up", 2), ("rescue", 3, pytest.approx(started), 2)]
    assert walk_step_by_step(problem, "test", greedy, back_up=back_up).steps[-1].index == 3  # without: it stops

    def out_of_time(problem, index, state):
        return outcome(index, state, solved=index != 3, status="time_limit")

    calls.clear()
    assert not walk_step_by_step(problem, "test", out_of_time, rescue=rescue).complete and calls == []


def test_the_coarse_grid_rescue_walks_past_the_greedy_dead_end():
    """Stairs, DMOC, N = 20, the greedy walk of ``test_look_ahead_and_back_up_walk_past_the_greedy_dead_end``
    without a back-up: step 8, which no rung solves, is solved on a coarser grid from the same state, and the 20-node
    step started from that solution converges; the walk goes on to step 11."""
    stairs = REGISTRY.create("experiment", "stairs")
    ipopt = REGISTRY.create("solver", "ipopt", mu_init=0.1)
    problem = WalkProblem(stairs, REGISTRY.create("transcription", "dmoc"), ipopt, 20)
    walk = REGISTRY.create("strategy", "one-phase", back_up=False).solve(problem)
    assert walk.complete, walk.failure
    rescued = [step for step in walk.steps if "rescued_from" in step.details]
    assert [step.index for step in rescued] == [8]
    assert rescued[0].details["rescued_from"]["status"] == "infeasible"
    assert rescued[0].details["retries"][-1]["remedy"].startswith("coarse-seed-")
    assert all(step.verification.max_defect < 1e-6 for step in walk.steps)


def test_decrease_and_conquer_stops_solving_sections_once_the_deadline_has_passed(monkeypatch):
    """Sections solved one by one are not started past the walk's deadline: a step's sections at large N run for
    minutes, each up to a solve's share of the time limit."""
    late, solved = {"now": False}, []
    monkeypatch.setattr(WalkProblem, "out_of_time", property(lambda self: late["now"]))
    solve_one = SectionalSolves.solve_one

    def deadline_passes_in_the_second(self, task):
        solved.append(task[0])
        late["now"] = len(solved) == 2
        return solve_one(self, task)

    monkeypatch.setattr(SectionalSolves, "solve_one", deadline_passes_in_the_second)
    problem = WalkProblem(REGISTRY.create("experiment", "forward"), REGISTRY.create("transcription", "hermite-simpson"),
                          REGISTRY.create("solver", "ipopt"), 8, steps=2)
    walk = DecreaseAndConquer(workers=1).solve(problem)
    (step,) = walk.steps
    assert step.status == SolverStatus.TIME_LIMIT.value and not walk.complete
    assert "during its sections (2 of 5 solved)" in step.message and solved == [2, 3]


def test_look_ahead_must_be_a_positive_whole_number_of_second_phase_steps():
    with pytest.raises(ValueError, match="look_ahead = 0"):
        REGISTRY.create("strategy", "one-phase", look_ahead=0)
    with pytest.raises(ValueError, match="needs phase = 'second'"):
        REGISTRY.create("strategy", "one-phase", phase="first", look_ahead=2)


@pytest.mark.parametrize(("late_after", "where"), [("first", "before its complete Second Phase"),
                                                    ("second", "before its sections")])
def test_decrease_and_conquer_stops_a_step_the_deadline_passes_in(monkeypatch, late_after, where):
    """Each of a step's sections and its polish may run a whole solve's share of the time limit: once the walk's
    deadline has passed, the step ends with ``time_limit`` instead of starting them."""
    import gaitbench_plugins.strategies.decrease_and_conquer as dc

    late = {"now": False}
    monkeypatch.setattr(WalkProblem, "out_of_time", property(lambda self: late["now"]))
    solve = dc.solve_with_retries

    def deadline_passes_during(problem, index, built, data, phase="second", **kwargs):
        outcome = solve(problem, index, built, data, phase=phase, **kwargs)
        late["now"] = late["now"] or phase == late_after
        return outcome

    monkeypatch.setattr(dc, "solve_with_retries", deadline_passes_during)
    problem = WalkProblem(REGISTRY.create("experiment", "forward"), REGISTRY.create("transcription", "hermite-simpson"),
                          REGISTRY.create("solver", "ipopt"), 8, steps=2)
    walk = DecreaseAndConquer().solve(problem)
    (step,) = walk.steps
    assert step.status == SolverStatus.TIME_LIMIT.value and where in step.message and not walk.complete
