"""Per-step gait problems solved and verified, multi-step chaining, and the solve command."""

import json
import time

import numpy as np
import pytest
from click.testing import CliRunner

from gaitbench.cli.main import main
from gaitbench.contracts import WalkProblem
from gaitbench.model.mechanics import BipedModel
from gaitbench.plugins import load_registry
from gaitbench.problem.gait_problem import ProblemOptions, StepData, StepStructure, sectional_structure
from gaitbench.solve.one_phase import OnePhase
from gaitbench.solve.verify import verify_step
from gaitbench.solve.walk import next_step_state
from gaitbench_plugins.solvers.ipopt import Ipopt
from gaitbench_plugins.transcriptions.hermite_simpson import HermiteSimpson

REGISTRY = load_registry()


def forward_step_data(n_nodes, step=1, state=None):
    experiment = REGISTRY.create("experiment", "forward")
    geometry = experiment.terrain.steps[step - 1]
    state = np.asarray(experiment.initial_state)[[0, 1, 4, 5]] if state is None else state
    return experiment, StepData(experiment.robot, experiment.stance_leg(step), state, geometry.D, geometry.theta,
                                experiment.time_step(n_nodes))


def solve_step(transcription, phase, n_nodes, options=None, **data_kwargs):
    experiment, data = forward_step_data(n_nodes, **data_kwargs)
    structure = StepStructure(phase, n_nodes, options or ProblemOptions(limits=experiment.limits))
    built = transcription.build(structure)
    result = Ipopt().solve(built.nlp, data.parameter_vector(), built.initial_guess(data))
    return experiment, data, built, result


def test_resimulation_error_falls_as_the_grid_is_refined():
    """The same smooth step (a torque tie-break makes the optimum unique) at growing N re-simulates ever better."""
    options = ProblemOptions(torque_regularization=1e-3)
    errors = []
    for n_nodes in (11, 21, 41):
        experiment, data, built, result = solve_step(HermiteSimpson(), "first", n_nodes, options)
        assert result.converged, result.message
        trajectory = built.trajectory(result.x, data)
        errors.append(verify_step(built, result.x, data, trajectory, BipedModel(experiment.robot, 2)).resim_max_error)
    assert errors[0] > errors[1] > errors[2], errors
    assert errors[2] < 1e-4


def test_four_dof_step_tracks_the_two_dof_optimum_up_to_the_push_off():
    """Ground reactions unconstrained: the second phase differs only by the push-off, which costs energy."""
    transcription = HermiteSimpson()
    options = ProblemOptions(torque_regularization=1e-3)
    _, _, built1, first = solve_step(transcription, "first", 21, options)
    experiment, data, built2, second = solve_step(transcription, "second", 21, options)
    assert first.converged and second.converged
    # Nothing within one step rewards a push-off, so its energy (quadratic in the impulse from a foot at rest)
    # vanishes; the impulse itself only sits at the interior-point barrier's distance from its bound.
    trajectory = built2.trajectory(second.x, data)
    energy = verify_step(built2, second.x, data, trajectory, BipedModel(experiment.robot, 4)).push_off_energy
    assert 0 <= energy < 1e-5
    assert second.objective == pytest.approx(first.objective, rel=1e-4)
    states1 = first.x[built1.nlp.variable_blocks["states"]]
    states2 = second.x[built2.nlp.variable_blocks["states"]]
    np.testing.assert_allclose(states2, states1, atol=1e-4)


def test_enforced_ground_reaction_constraints_hold_at_the_solution():
    options = ProblemOptions(torque_regularization=1e-3, unilateral_contact=True, friction_coefficient=0.6)
    _, data, built, result = solve_step(HermiteSimpson(), "second", 21, options)
    assert result.converged, result.message
    violations = built.nlp.block_violations(result.x, data.parameter_vector())
    assert violations["unilateral_contact"] < 1e-7 and violations["friction_cone"] < 1e-7
    assert violations["impact_contact"] < 1e-7 and violations["impact_friction_cone"] < 1e-7



@pytest.mark.parametrize(("mu", "holds"), [(0.25, False), (0.6, True)])
def test_the_push_off_is_held_to_the_friction_cone(mu, holds):
    """The push-off acts along the stance leg, at α = asin(D / 2l) to the ground's normal (tan α = 0.31 on this
    step): a push-off of 10 N·s needs μ ≥ tan α (it was unconstrained, and a verified walk pushed off at
    |f_t| / f_n = 1.6)."""
    options = ProblemOptions(torque_regularization=1e-3, unilateral_contact=True, friction_coefficient=mu)
    experiment, data, built, result = solve_step(HermiteSimpson(), "second", 21, options)
    assert result.converged, result.message
    assert 0.25 < np.tan(np.arcsin(data.chord / (2 * experiment.robot.l))) < 0.6
    pushed = result.x.copy()
    pushed[built.nlp.variable_blocks["push_off"]] = 10.0
    violations = built.nlp.block_violations(pushed, data.parameter_vector())
    assert (violations["impact_friction_cone"] == 0.0) == holds and violations["impact_contact"] == 0.0


def test_the_friction_cone_stands_on_the_ground_not_on_the_horizontal():
    """On the upward slope (θ = 0.698 rad) a foot stays put only with a friction coefficient near tan θ = 0.84 or
    more: with μ = 0.5 the step has no solution, with μ = 1.5 it does (a cone taken in world axes let μ = 0.5 walk
    the slope)."""
    from dataclasses import replace

    experiment = REGISTRY.create("experiment", "upward-slope")
    problem = WalkProblem(experiment, HermiteSimpson(), Ipopt(), 10, steps=1)
    data = problem.step_data(1, problem.start_state())
    outcomes = {}
    for mu in (0.5, 1.5):
        options = replace(ProblemOptions(limits=experiment.limits), unilateral_contact=True, friction_coefficient=mu)
        built = HermiteSimpson().build(StepStructure("second", 10, options))
        outcomes[mu] = Ipopt().solve(built.nlp, data.parameter_vector(), built.initial_guess(data)).converged
    assert outcomes == {0.5: False, 1.5: True}


@pytest.mark.parametrize("n_nodes", [20, 50, 100])
def test_a_flat_step_converges_and_lands_on_its_heel_strike_configuration(n_nodes):
    experiment, data, built, result = solve_step(HermiteSimpson(), "second", n_nodes)
    assert result.converged, result.message
    trajectory = built.trajectory(result.x, data)
    alpha = np.arcsin(data.chord / (2 * experiment.robot.l))
    np.testing.assert_allclose(trajectory.q[-1], [-alpha, alpha], atol=1e-8)  # Leg 1 stance on step 1


def test_even_steps_are_solved_in_mirrored_role_coordinates():
    """Step 2 (Leg 2 stance) lands with Leg 2 behind and Leg 1 in front, in leg-labelled output."""
    experiment = REGISTRY.create("experiment", "forward")
    walk = OnePhase().solve(WalkProblem(experiment, HermiteSimpson(), Ipopt(), 21, steps=2))
    assert walk.complete, walk.failure
    step2 = walk.steps[1].trajectory
    alpha = np.arcsin(experiment.terrain.steps[1].D / (2 * experiment.robot.l))
    np.testing.assert_allclose(step2.q[-1], [alpha, -alpha], atol=1e-8)
    # Step 2 starts from step 1's heel-strike map.
    model = BipedModel(experiment.robot, 4)
    np.testing.assert_allclose(np.r_[step2.q[0], step2.dq[0]], next_step_state(model, walk.steps[0].trajectory),
                               atol=1e-8)
    for step in walk.steps:
        assert step.verification.max_defect < 1e-8
        assert step.verification.resim_error < 1e-2


def test_a_failed_step_ends_the_walk_keeping_the_solved_steps():
    experiment = REGISTRY.create("experiment", "forward")
    walk = OnePhase().solve(WalkProblem(experiment, HermiteSimpson(), Ipopt(max_iterations=5), 21, steps=2))
    assert not walk.complete and walk.acot is None
    assert walk.failure.startswith("step 1: iteration_limit")


def test_a_walk_whose_time_runs_out_stops_at_the_next_step_and_keeps_the_steps_it_solved():
    """A case past its time limit used to run on until its process was stopped, losing every solved step."""
    experiment = REGISTRY.create("experiment", "forward")
    solved = []

    def on_step(outcome):  # the time runs out as step 1 is solved
        solved.append(outcome)
        object.__setattr__(problem, "deadline", time.monotonic())

    problem = WalkProblem(experiment, HermiteSimpson(), Ipopt(), 10, steps=3, deadline=time.monotonic() + 3600)
    walk = OnePhase().solve(problem, on_step=on_step)
    assert [step.status for step in walk.steps] == ["converged", "time_limit"]
    assert walk.failure == "step 2: time limit: the walk's time ran out before step 2"
    assert "back_up" not in walk.steps[1].details  # a time limit is final: no dead-end back-up


def test_infeasible_geometry_is_reported_before_solving():
    experiment = REGISTRY.create("experiment", "downward-slope")
    options = ProblemOptions(limits=experiment.limits, angle_bounds="thesis")
    walk = OnePhase().solve(WalkProblem(experiment, HermiteSimpson(), Ipopt(), 21, steps=2, options=options))
    assert walk.steps[0].status == "infeasible_geometry"
    assert "below the lower angle bound" in walk.failure and walk.steps[0].solver_result is None
    assert walk.failure.startswith("step 1: stance angle at heel strike") and walk.failure.count("step 1:") == 1


def test_solve_command_writes_the_documented_json(tmp_path):
    out = tmp_path / "result.json"
    result = CliRunner().invoke(main, ["solve", "--experiment", "forward", "--N", "15", "--steps", "2",
                                       "--out", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    for key in ("experiment", "transcription", "solver", "strategy", "N", "acot", "steps"):
        assert key in data
    assert data["N"] == 15 and len(data["steps"]) == 2
    for step in data["steps"]:
        for key in ("index", "status", "cot", "solve_time_s", "iterations", "max_defect", "resim_error"):
            assert step[key] is not None
    assert data["acot"] == pytest.approx(np.mean([step["cot"] for step in data["steps"]]))
    trajectories = np.load(tmp_path / data["trajectories"])
    assert trajectories["step02_q"].shape == (15, 2)


def test_solve_command_names_the_available_plugins_for_a_typo():
    result = CliRunner().invoke(main, ["solve", "--experiment", "forward", "--solver", "ipopd"])
    assert result.exit_code == 2
    assert "ipopt" in result.output + result.stderr


def test_sectional_problem_from_a_node_of_the_complete_optimum_is_no_worse_than_its_tail():
    """Bellman: the tail of the complete optimum from node k0 is feasible for the sectional problem."""
    options = ProblemOptions(torque_regularization=1e-3)
    transcription = HermiteSimpson()
    _, data, built, complete = solve_step(transcription, "first", 21, options)
    assert complete.converged
    trajectory = built.trajectory(complete.x, data)
    k0 = 8
    sectional = transcription.build(sectional_structure(built.structure, k0))
    assert sectional.structure.n_nodes == 14
    start = np.r_[trajectory.q[k0 - 1], trajectory.dq[k0 - 1]]
    section_data = StepData(data.robot, data.stance, start, data.chord, data.slope, data.time_step)
    p = section_data.parameter_vector()
    result = Ipopt().solve(sectional.nlp, p, sectional.initial_guess(section_data))
    assert result.converged, result.message
    np.testing.assert_allclose(sectional.trajectory(result.x, section_data).q[-1], trajectory.q[-1], atol=1e-8)

    tail = tail_point(sectional, trajectory.q[k0 - 1:], trajectory.dq[k0 - 1:], trajectory.tau[k0 - 1:], p)
    assert sectional.nlp.violation(tail, p) < 1e-7  # the tail is feasible for the sectional problem
    assert result.objective <= float(sectional.nlp.functions.objective(tail, p)) + 1e-8
    with pytest.raises(ValueError, match="start node"):
        sectional_structure(built.structure, 20)


def tail_point(built, q, dq, tau, p):
    """A Hermite–Simpson NLP point from nodal q, q̇, τ (leg order = role order on step 1), |power| slacks exact."""
    states, torques = np.vstack([q.T, dq.T]), tau.T
    x = np.zeros(built.nlp.n_variables)
    x[built.nlp.variable_blocks["states"]] = states.flatten(order="F")
    x[built.nlp.variable_blocks["torques"]] = torques.flatten(order="F")
    return built.settle_slacks(x, p)


class NaNClaimsConvergence:
    """A solver plugin that reports convergence at NaN, as a broken binding might; its remedy does the same."""

    name = "nan-claims-convergence"

    def __init__(self, objective: float = 0.5) -> None:
        self.objective = objective

    def solve(self, nlp, parameters, initial_guess):
        from gaitbench.solver_result import SolverResult, SolverStatus

        x = np.asarray(initial_guess, dtype=float).copy()
        x[::7] = np.nan
        return SolverResult(SolverStatus.CONVERGED, "Optimal Solution Found", x, self.objective, 0.0, 3, 0.1, 0.0)

    def remedies(self):
        return [("inf-objective", NaNClaimsConvergence(objective=float("inf")))]

    def for_sections(self):
        return NaNClaimsConvergence(objective=1.0)


def test_the_sectional_variant_of_a_solver_is_behind_the_same_boundary():
    from gaitbench.contracts import checked
    from gaitbench.solve.solver import section_solver
    from gaitbench.solver_result import SolverStatus

    sections = section_solver(checked(NaNClaimsConvergence()))  # what decrease and conquer solves its sections with
    assert sections.solve(None, np.zeros(3), np.zeros(14)).status == SolverStatus.NON_FINITE


def test_non_finite_output_claiming_convergence_is_its_own_status_at_the_solver_boundary():
    """Not SciPy's "y0 must be finite" from the verification after it: the step ends ``non_finite``, naming the
    solver and what was not finite, and the retry ladder's rungs are checked alike."""
    from gaitbench.run.runner import walk_stop
    from gaitbench.solver_result import SolverStatus

    experiment = REGISTRY.create("experiment", "forward")
    problem = WalkProblem(experiment, HermiteSimpson(), NaNClaimsConvergence(), 8, steps=1)
    walk = OnePhase().solve(problem)
    step, = walk.steps
    assert step.status == SolverStatus.NON_FINITE.value == "non_finite" and not walk.complete
    assert step.message.startswith("non_finite: solver nan-claims-convergence returned non-finite values while "
                                   "claiming convergence: ")
    x = step.solver_result.x
    assert f"{int(np.isnan(x).sum())} of the {x.size} values of x are NaN or infinite (Optimal Solution Found)" \
        in step.message and "y0" not in step.message
    retries = {entry["remedy"]: entry for entry in step.details["retries"]}
    assert retries["inf-objective"]["status"] == "non_finite"
    variant, = problem.solver.remedies()
    flagged = variant[1].solve(None, None, np.zeros(7))  # x[0] is the one NaN
    assert flagged.message.endswith("1 of the 7 values of x and the objective (inf) are NaN or infinite "
                                    "(Optimal Solution Found)")
    assert walk_stop(walk) | {"retries": None, "back_ups": None} == {
        "stop_cause": "solver", "stop_step": 1, "stop_status": "non_finite", "retries": None, "back_ups": None}
