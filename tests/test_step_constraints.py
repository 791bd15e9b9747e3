"""The step constraints docs/model.md §3–§4 ask for: lift-off at push-off, clearance above the terrain, physical leg
angles; and the retry ladder that a failed step solve climbs before a walk stops."""

from dataclasses import replace

import numpy as np
import pytest

from gaitbench.contracts import WalkProblem
from gaitbench.model.mechanics import BipedModel
from gaitbench.model.terrain import terrain_clearance
from gaitbench.plugins import load_registry
from gaitbench.problem.gait_problem import ProblemOptions, StepData, StepStructure
from gaitbench.problem.transcription import TranscribedStep
from gaitbench.solve.one_phase import OnePhase
from gaitbench.solve.walk import solve_with_retries
from gaitbench.solver_result import SolverResult, SolverStatus
from gaitbench_plugins.solvers.ipopt import Ipopt
from gaitbench_plugins.transcriptions.dmoc import DiscreteMechanics
from gaitbench_plugins.transcriptions.hermite_simpson import HermiteSimpson

REGISTRY = load_registry()


def stairs_problem(n_nodes=12, **options):
    experiment = REGISTRY.create("experiment", "stairs")
    problem_options = ProblemOptions(limits=experiment.limits, **options)
    return WalkProblem(experiment, HermiteSimpson(), Ipopt(), n_nodes, options=problem_options)


def lift_off_rate(problem, data, x, built):
    """The old stance foot's post-impact normal velocity, from the numeric model (not the NLP's expression)."""
    trajectory = built.trajectory(x, data)
    model = BipedModel(problem.experiment.robot, 4)
    q, dq = np.r_[trajectory.q[-1], 0.0, 0.0], np.r_[trajectory.dq[-1], 0.0, 0.0]
    dq_push, _ = model.push_off(q, dq, trajectory.push_off, data.stance)
    strike = model.heel_strike(q, dq_push, data.stance)
    velocity = strike.lifting_foot_velocity
    return -np.sin(data.slope) * velocity[0] + np.cos(data.slope) * velocity[1]


@pytest.mark.parametrize("transcription", [HermiteSimpson(), DiscreteMechanics()], ids=["hs", "dmoc"])
def test_lift_off_row_is_the_old_stance_feet_normal_velocity_after_heel_strike(transcription):
    problem = stairs_problem()
    problem = replace(problem, transcription=transcription)
    built = transcription.build(problem.structure("second"))
    data = problem.step_data(6, problem.start_state())
    rng = np.random.default_rng(0)
    for _ in range(3):
        x = built.initial_guess(data) + 0.05 * rng.standard_normal(built.nlp.n_variables)
        x[built.nlp.variable_blocks["push_off"]] = rng.uniform(0, 50)
        g = np.asarray(built.nlp.functions.constraints(x, data.parameter_vector())).ravel()
        row = g[built.nlp.constraint_blocks["lift_off"]]
        assert row == pytest.approx(lift_off_rate(problem, data, x, built) / problem.experiment.robot.l, rel=1e-9)


@pytest.mark.parametrize("transcription", [HermiteSimpson(), DiscreteMechanics()], ids=["hs", "dmoc"])
def test_first_phase_lift_off_row_is_the_old_stance_feet_normal_velocity_after_the_2dof_impact(transcription):
    """The 2-DOF step has no push-off: its impact map alone must send the old stance foot up (a First-Phase walk at
    N = 100 on flat ground otherwise reaches step 6 with that foot moving into the ground at 2.0 m/s)."""
    problem = replace(stairs_problem(), transcription=transcription)
    assert "lift_off" not in transcription.build(problem.structure("first")).nlp.constraint_blocks  # seeds only
    built = transcription.build(problem.structure("first", walked=True))
    data = problem.step_data(6, problem.start_state())
    model = BipedModel(problem.experiment.robot, 2)
    rng = np.random.default_rng(1)
    for _ in range(3):
        x = built.initial_guess(data) + 0.05 * rng.standard_normal(built.nlp.n_variables)
        g = np.asarray(built.nlp.functions.constraints(x, data.parameter_vector())).ravel()
        trajectory = built.trajectory(x, data)
        strike = model.heel_strike(trajectory.q[-1], trajectory.dq[-1], data.stance)
        new_stance = 3 - data.stance  # the old stance foot is the next step's swing foot, relative to its stance foot
        jacobian = (np.array([model.swing_foot_position(strike.q + 1e-7 * e, new_stance) for e in np.eye(2)])
                    - model.swing_foot_position(strike.q, new_stance)) / 1e-7
        velocity = jacobian.T @ strike.dq
        expected = -np.sin(data.slope) * velocity[0] + np.cos(data.slope) * velocity[1]
        row = g[built.nlp.constraint_blocks["lift_off"]]
        assert row == pytest.approx(expected / problem.experiment.robot.l, rel=1e-5, abs=1e-7)


def test_a_solved_step_lifts_the_old_stance_foot_and_without_the_constraint_the_row_is_gone():
    problem = stairs_problem()
    built = problem.transcription.build(problem.structure("second"))
    data = problem.step_data(1, problem.start_state())
    result = problem.solver.solve(built.nlp, data.parameter_vector(), built.initial_guess(data))
    assert result.converged
    assert lift_off_rate(problem, data, result.x, built) >= -1e-7
    literal = problem.transcription.build(StepStructure("second", 12, replace(problem.options, lift_off=False)))
    assert "lift_off" not in literal.nlp.constraint_blocks


def test_clearance_rows_follow_the_terrain_the_chord_or_nothing():
    problem = stairs_problem()
    data = problem.step_data(6, problem.start_state())
    built = problem.transcription.build(problem.structure("second"))
    x = built.initial_guess(data)
    q = np.reshape(x[built.nlp.variable_blocks["states"]], (4, -1), order="F")[:2, 1:-1]
    g = np.asarray(built.nlp.functions.constraints(x, data.parameter_vector())).ravel()
    expected = terrain_clearance(q[0], q[1], data.slope, data.previous_slope)
    np.testing.assert_allclose(g[built.nlp.constraint_blocks["clearance"]], expected, atol=1e-12)
    assert data.previous_slope == problem.experiment.terrain.steps[4].theta != data.slope
    off = problem.transcription.build(StepStructure("second", 12, replace(problem.options, clearance="off")))
    assert "clearance" not in off.nlp.constraint_blocks
    rounded = problem.transcription.build(StepStructure("second", 12, replace(problem.options,
                                                                              clearance_rounding=0.1)))
    g = np.asarray(rounded.nlp.functions.constraints(x, data.parameter_vector())).ravel()
    expected = terrain_clearance(q[0], q[1], data.slope, data.previous_slope, 0.1)
    np.testing.assert_allclose(g[rounded.nlp.constraint_blocks["clearance"]], expected, atol=1e-12)


@pytest.mark.parametrize("name", ["forward", "downward-slope", "upward-slope", "stairs"])
def test_physical_leg_angle_rows_hold_at_the_first_steps_heel_strike_and_start(name):
    experiment = REGISTRY.create("experiment", name)
    problem = WalkProblem(experiment, HermiteSimpson(), Ipopt(), 10)
    built = problem.transcription.build(problem.structure("second"))
    for index in range(1, experiment.n_steps + 1):
        # The blended guess runs from the heel-strike pose of the step before to this step's: both ends checked.
        start = problem.start_state() if index == 1 else np.r_[experiment.heel_strike_configuration(index - 1), 0, 0]
        data = problem.step_data(index, start)
        x = built.initial_guess(data)
        g = np.asarray(built.nlp.functions.constraints(x, data.parameter_vector())).ravel()
        assert g[built.nlp.constraint_blocks["leg_angles"]].min() >= -1e-12, (name, index)


class FailingFirst:
    """A solver that calls every step infeasible, with IPOPT as its remedy (as a solver's ``remedies`` offers)."""

    name = "failing-first"

    def __init__(self, remedies=True):
        self.has_remedies = remedies
        self.calls = 0

    def solve(self, nlp, parameters, initial_guess):
        self.calls += 1
        return SolverResult(SolverStatus.INFEASIBLE, "infeasible (scripted)", np.asarray(initial_guess), np.nan,
                            np.nan, 3, 0.0, 0.0)

    def remedies(self):
        return [("use-ipopt", Ipopt())] if self.has_remedies else []


def test_a_failed_solve_climbs_the_ladder_and_records_every_rung():
    experiment = REGISTRY.create("experiment", "forward")
    solver = FailingFirst()
    problem = WalkProblem(experiment, HermiteSimpson(), solver, 10, steps=1)
    built = problem.transcription.build(problem.structure("second"))
    outcome = solve_with_retries(problem, 1, built, problem.step_data(1, problem.start_state()))
    assert outcome.solved and solver.calls == 1
    assert [entry["remedy"] for entry in outcome.details["retries"]] == ["use-ipopt"]
    assert outcome.details["first_attempt"]["status"] == "infeasible"


class RunsOutOfTime(FailingFirst):
    """A solve that ends at its own time limit (as IPOPT's did, seconds per iteration, while MUMPS reallocated)."""

    def solve(self, nlp, parameters, initial_guess):
        self.calls += 1
        return SolverResult(SolverStatus.TIME_LIMIT, "IPOPT: Maximum_WallTime_Exceeded (scripted)",
                            np.asarray(initial_guess), np.nan, np.nan, 2776, 900.0, 0.0)


def test_a_solve_that_runs_out_of_its_own_time_climbs_the_ladder_while_the_walk_has_time():
    """Downward slope, OP-DM, N = 180, step 1: a solve that spends its time limit is retried like one that spends its
    iterations; only the walk's deadline is final."""
    import time

    experiment = REGISTRY.create("experiment", "forward")
    solver = RunsOutOfTime()
    problem = WalkProblem(experiment, HermiteSimpson(), solver, 10, steps=1, deadline=time.monotonic() + 3600)
    built = problem.transcription.build(problem.structure("second"))
    outcome = solve_with_retries(problem, 1, built, problem.step_data(1, problem.start_state()))
    assert outcome.solved and solver.calls == 1
    assert outcome.details["first_attempt"]["status"] == "time_limit"
    assert [entry["remedy"] for entry in outcome.details["retries"]] == ["use-ipopt"]


def test_a_step_that_fails_every_rung_names_them_and_the_walk_stops_there():
    experiment = REGISTRY.create("experiment", "forward")
    walk = OnePhase().solve(WalkProblem(experiment, HermiteSimpson(), FailingFirst(remedies=False), 10, steps=2))
    assert len(walk.steps) == 1 and not walk.complete
    step = walk.steps[0]
    # The First Phase fails with the same solver, so the first-phase seed cannot be tried further; then the
    # coarse-grid rescue solves the step at 8 and 5 nodes, and fails there too.
    assert [entry["remedy"] for entry in step.details["retries"]] == ["first-phase-seed", "coarse-seed-8",
                                                                      "coarse-seed-5"]
    assert [entry["failed_in"] for entry in step.details["retries"]] == ["first phase", "8-node step", "5-node step"]
    assert step.message == ("infeasible: infeasible (scripted) "
                            "(retried: first-phase-seed (its first phase: infeasible)) "
                            "(coarse grids: coarse-seed-8 infeasible, coarse-seed-5 infeasible)")


def test_a_first_phase_that_fails_ends_the_ladder_instead_of_being_recorded_once_per_remedy():
    experiment = REGISTRY.create("experiment", "forward")
    solver = FailingFirst(remedies=False)
    solver.remedies = lambda: [("scripted-remedy", FailingFirst(remedies=False))]
    problem = WalkProblem(experiment, HermiteSimpson(), solver, 10, steps=1)
    built = problem.transcription.build(problem.structure("second"))
    outcome = solve_with_retries(problem, 1, built, problem.step_data(1, problem.start_state()))
    assert not outcome.solved
    rungs = outcome.details["retries"]
    assert [entry["remedy"] for entry in rungs] == ["scripted-remedy", "first-phase-seed"]
    assert "failed_in" not in rungs[0] and rungs[1]["failed_in"] == "first phase"


def _forward_step_1(solver) -> tuple[WalkProblem, TranscribedStep, StepData]:
    """Forward step 1 at N = 10 for ``solver``: the problem, its built 4-DOF step and the step's data."""
    problem = WalkProblem(REGISTRY.create("experiment", "forward"), HermiteSimpson(), solver, 10, steps=1)
    return problem, problem.transcription.build(problem.structure("second")), problem.step_data(
        1, problem.start_state())


def test_a_last_resort_comes_after_every_other_rung_from_the_same_guess():
    solver = FailingFirst(remedies=False)
    solver.remedies = lambda: [("scripted-remedy", FailingFirst(remedies=False))]
    solver.last_resorts = lambda: [("use-ipopt", Ipopt())]
    problem, built, data = _forward_step_1(solver)
    outcome = solve_with_retries(problem, 1, built, data)
    assert outcome.solved
    assert [entry["remedy"] for entry in outcome.details["retries"]] == [
        "scripted-remedy", "first-phase-seed", "use-ipopt"]


class FailsTheSecondPhase(FailingFirst):
    """Fails every 4-DOF solve and solves the 2-DOF First Phase (with IPOPT), so the First-Phase seed exists."""

    def solve(self, nlp, parameters, initial_guess):
        if nlp.n_variables < self.second_phase_size:
            return Ipopt().solve(nlp, parameters, initial_guess)
        return super().solve(nlp, parameters, initial_guess)


def test_seed_remedies_are_tried_only_from_a_trajectory_never_from_the_blended_guess():
    """``sqp``'s filter solved none of the reference column's 63 steps it was tried on from the blended guess, and
    every step it was tried on from the First-Phase seed."""
    solver = FailsTheSecondPhase(remedies=False)
    solver.remedies = lambda: [("scripted-remedy", FailingFirst(remedies=False))]
    solver.seed_remedies = lambda: [("use-ipopt", Ipopt())]
    problem, built, data = _forward_step_1(solver)
    solver.second_phase_size = built.nlp.n_variables
    outcome = solve_with_retries(problem, 1, built, data)
    assert outcome.solved
    assert [entry["remedy"] for entry in outcome.details["retries"]] == [
        "scripted-remedy", "first-phase-seed", "first-phase-seed+scripted-remedy", "first-phase-seed+use-ipopt"]
    seed = outcome.trajectory.seed()
    from_seed = solve_with_retries(problem, 1, built, data, seed=seed)
    assert [entry["remedy"] for entry in from_seed.details["retries"]] == ["scripted-remedy", "use-ipopt"]


class StopsAtItsLimit(FailingFirst):
    """Ends every solve at its iteration limit, at a point of its own (the guess shifted), and remembers its starts."""

    status = SolverStatus.ITERATION_LIMIT

    def __init__(self):
        super().__init__(remedies=False)
        self.starts = []

    def solve(self, nlp, parameters, initial_guess):
        self.starts.append(np.asarray(initial_guess, dtype=float).copy())
        return SolverResult(self.status, "scripted", np.asarray(initial_guess) + 1e-3, np.nan, np.nan, 3000, 0.0, 0.0)


class Continues:
    """A continuation that records where it started and solves with IPOPT from there."""

    name = "continues"

    def __init__(self):
        self.starts = []

    def solve(self, nlp, parameters, initial_guess):
        self.starts.append(np.asarray(initial_guess, dtype=float).copy())
        return Ipopt().solve(nlp, parameters, initial_guess)


@pytest.mark.parametrize("status", [SolverStatus.ITERATION_LIMIT, SolverStatus.ERROR])
def test_a_solve_that_ran_out_of_iterations_is_continued_from_its_last_iterate_before_any_other_rung(status):
    """Forward N = 120, step 6 in the reference column: the first attempt reached its limit 752 iterations before
    an optimum at COT 0.688, and the First-Phase seed gave 1.488. A solve that failed otherwise is not continued."""
    solver = StopsAtItsLimit()
    solver.status = status
    continuation = Continues()
    solver.continuations = lambda: [("continue", continuation)]
    solver.remedies = lambda: [("use-ipopt", Ipopt())]
    problem, built, data = _forward_step_1(solver)
    outcome = solve_with_retries(problem, 1, built, data)
    assert outcome.solved
    if status is SolverStatus.ITERATION_LIMIT:
        assert [entry["remedy"] for entry in outcome.details["retries"]] == ["continue"]
        assert np.array_equal(continuation.starts[0], solver.starts[0] + 1e-3)  # where the first attempt stopped
    else:
        assert [entry["remedy"] for entry in outcome.details["retries"]] == ["use-ipopt"]
        assert continuation.starts == []


def test_ipopt_s_last_resort_is_a_small_initial_barrier_parameter_unless_one_is_set():
    (name, variant), = Ipopt().last_resorts()
    assert name == "small-mu-init" and variant.options["ipopt"]["mu_init"] == 1e-3
    assert Ipopt(mu_init=0.01).last_resorts() == []


@pytest.mark.slow
def test_small_mu_init_solves_the_stairs_first_step_that_diverges_at_n_140():
    """Stairs, HS, N = 140, step 1 (a thesis-all case): IPOPT diverges from the blended guess with both μ
    strategies, and the First Phase reaches its iteration limit, so only the last resort solves it."""
    stairs = REGISTRY.create("experiment", "stairs")
    problem = WalkProblem(stairs, HermiteSimpson(), Ipopt(), 140, steps=1)
    built = problem.transcription.build(problem.structure("second"))
    outcome = solve_with_retries(problem, 1, built, problem.step_data(1, problem.start_state()))
    assert outcome.solved and outcome.verification.max_defect < 1e-6
    assert [entry["remedy"] for entry in outcome.details["retries"]] == [
        "adaptive-mu", "first-phase-seed", "small-mu-init"]


def test_a_look_ahead_walks_last_step_starts_from_the_last_windows_solution_of_it(monkeypatch):
    """With H = 2 the window of steps 1–2 commits step 1 and keeps its step 2; the walk's last step, solved alone,
    starts from that, as a window would, not from the blended guess."""
    import gaitbench.solve.walk_chain as walk_chain

    seeds = []
    solve = walk_chain.solve_with_retries

    def recorded(problem, index, built, data, seed=None, **kwargs):
        seeds.append((index, seed))
        return solve(problem, index, built, data, seed=seed, **kwargs)

    monkeypatch.setattr(walk_chain, "solve_with_retries", recorded)
    problem = WalkProblem(REGISTRY.create("experiment", "forward"), HermiteSimpson(), Ipopt(), 10, steps=2)
    walk = OnePhase(look_ahead=2).solve(problem)
    assert walk.complete and [index for index, _ in seeds] == [2] and seeds[0][1] is not None


def test_a_look_ahead_window_tries_the_solver_s_last_resorts_after_its_remedies():
    from gaitbench.solve.walk_chain import LookAhead

    experiment = REGISTRY.create("experiment", "forward")
    solver = FailingFirst(remedies=False)
    solver.remedies = lambda: [("scripted-remedy", FailingFirst(remedies=False))]
    solver.last_resorts = lambda: [("use-ipopt", Ipopt())]
    problem = WalkProblem(experiment, HermiteSimpson(), solver, 10, steps=2)
    built = problem.transcription.build(problem.structure("second", walked=True))
    outcome = LookAhead(built, 2, fallback=False).solve_step(problem, 1, problem.start_state())
    assert outcome.solved
    assert [attempt["remedy"] for attempt in outcome.details["look_ahead"]["attempts"]] == [
        "none", "scripted-remedy", "use-ipopt"]


@pytest.mark.parametrize("status", [SolverStatus.ITERATION_LIMIT, SolverStatus.ERROR])
def test_a_look_ahead_window_that_ran_out_of_iterations_is_continued_from_its_last_iterate_first(status):
    """The reference column's back-up windows: stairs N = 100, step 2, reached the limit with the first attempt
    and the filter, Clarabel's rung ended in an error, and 3,631 iterations from the start solved it. A window,
    like a step alone, is continued where its first attempt stopped; one that failed otherwise is not."""
    from gaitbench.solve.walk_chain import LookAhead

    experiment = REGISTRY.create("experiment", "forward")
    solver = StopsAtItsLimit()
    solver.status = status
    continuation = Continues()
    solver.continuations = lambda: [("continue", continuation)]
    solver.last_resorts = lambda: [("use-ipopt", Ipopt())]
    problem = WalkProblem(experiment, HermiteSimpson(), solver, 10, steps=2)
    built = problem.transcription.build(problem.structure("second", walked=True))
    outcome = LookAhead(built, 2, fallback=False).solve_step(problem, 1, problem.start_state())
    assert outcome.solved
    remedies = [attempt["remedy"] for attempt in outcome.details["look_ahead"]["attempts"]]
    if status is SolverStatus.ITERATION_LIMIT:
        assert remedies == ["none", "continue"]
        assert np.array_equal(continuation.starts[0], solver.starts[0] + 1e-3)  # where the first attempt stopped
    else:
        assert remedies == ["none", "use-ipopt"]
        assert continuation.starts == []


def test_no_rung_starts_after_the_walk_s_deadline_and_the_step_ends_with_its_time_limit():
    import time

    experiment = REGISTRY.create("experiment", "forward")
    solver = FailingFirst()
    problem = WalkProblem(experiment, HermiteSimpson(), solver, 10, steps=1, deadline=time.monotonic() - 1.0)
    built = problem.transcription.build(problem.structure("second"))
    outcome = solve_with_retries(problem, 1, built, problem.step_data(1, problem.start_state()))
    assert solver.calls == 1 and outcome.status == "time_limit" and outcome.details["retries"] == []
    assert outcome.message == "time limit: the walk's time ran out during step 1's retries (retried: none)"
