"""The thesis's reading of a step's cost (gaitbench.solve.thesis_reading), and the options that pose its cost terms
in the NLP: push_off_cost, first_phase_cost and Hermite–Simpson's nodal-Simpson quadrature."""

from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

from gaitbench.model.mechanics import BipedModel
from gaitbench.model.robot import RobotParameters
from gaitbench.plugins import load_registry
from gaitbench.problem.gait_problem import ProblemOptions, StepData, StepStructure
from gaitbench.problem.trajectory import nodal_trajectory
from gaitbench.solve.thesis_reading import thesis_push_off_energy, thesis_reading, thesis_reading_acot

ROBOT = RobotParameters(m1=20.0, m2=20.0, M=40.0, l=1.0, a=0.5)
UNEQUAL = RobotParameters(m1=10.0, m2=30.0, M=40.0, l=1.0, a=0.5)


def _step(n: int, duration: float, tau: np.ndarray, dq: np.ndarray, push_off: float = 0.0, stance: int = 1,
          robot: RobotParameters = ROBOT, chord: float = 0.8):
    times = np.linspace(0.0, duration, n)
    q = np.column_stack([0.3 - 0.5 * times, -0.3 + 0.5 * times])
    trajectory = nodal_trajectory(times, q, dq, tau, push_off, stance)
    data = StepData(robot, stance, np.r_[q[0], dq[0]], chord, 0.0, times[1] - times[0])
    return trajectory, data


@pytest.mark.parametrize("n", [11, 10])
def test_constant_power_reads_power_times_duration_over_weight_and_distance(n):
    tau = np.tile([10.0, 4.0], (n, 1))
    dq = np.tile([-1.0, 0.5], (n, 1))  # P = −10 + 2 = −8 W: the thesis charges |P|
    trajectory, data = _step(n, 1.8, tau, dq)
    reading = thesis_reading(trajectory, data)
    assert reading.hip_energy == pytest.approx(8.0 * 1.8, rel=1e-12)
    assert reading.push_off_energy == 0.0
    assert reading.cot == pytest.approx(8.0 * 1.8 / (80.0 * 9.81 * 0.8), rel=1e-12)


@pytest.mark.parametrize("n", [9, 12, 21, 20])
def test_nodal_simpson_integrates_a_cubic_power_exactly_for_odd_and_even_n(n):
    duration = 1.5
    times = np.linspace(0.0, duration, n)
    power = 3.0 + times - times**2 + 0.5 * times**3  # positive on [0, 1.5]
    tau = np.column_stack([power, np.full(n, 7.0)])
    dq = np.column_stack([np.ones(n), np.zeros(n)])  # P = τ1 · 1 + τ2 · 0
    trajectory, data = _step(n, duration, tau, dq)
    exact = 3.0 * duration + duration**2 / 2 - duration**3 / 3 + duration**4 / 8
    assert thesis_reading(trajectory, data).hip_energy == pytest.approx(exact, rel=1e-12)


def test_the_reading_sees_only_the_nodes():
    n = 11
    # Torques that vanish at every node but not between them: the nodes read nothing (the thesis's blind spot).
    tau = np.zeros((n, 2))
    dq = np.tile([1.0, 1.0], (n, 1))
    trajectory, data = _step(n, 1.0, tau, dq)
    assert thesis_reading(trajectory, data).hip_energy == 0.0


@pytest.mark.parametrize("stance", [1, 2])
def test_push_off_is_half_the_stance_leg_mass_times_the_foot_speed_after_the_impulse(stance):
    n, impulse = 11, 25.0
    dq = np.tile([-1.2, 0.8], (n, 1))
    trajectory, data = _step(n, 1.0, np.zeros((n, 2)), dq, impulse, stance, UNEQUAL)
    model = BipedModel(UNEQUAL, 4)
    q4, dq4 = np.r_[trajectory.q[-1], 0.0, 0.0], np.r_[trajectory.dq[-1], 0.0, 0.0]
    stance_angle = q4[stance - 1]
    generalized = impulse * np.array([0.0, 0.0, -np.sin(stance_angle), np.cos(stance_angle)])
    foot_velocity = (dq4 + np.linalg.solve(np.asarray(model.mass_matrix(q4, stance)), generalized))[2:4]
    stance_mass = UNEQUAL.m1 if stance == 1 else UNEQUAL.m2
    expected = 0.5 * stance_mass * float(foot_velocity @ foot_velocity)
    assert expected > 0.0
    assert thesis_push_off_energy(trajectory, UNEQUAL) == pytest.approx(expected, rel=1e-10)
    reading = thesis_reading(trajectory, data)
    assert reading.cot == pytest.approx(expected / (80.0 * 9.81 * 0.8), rel=1e-10)
    # The thesis's term is a share of the kinetic energy the impulse gives the robot, never more.
    _, kinetic_gain = model.push_off(q4, dq4, impulse, stance)
    assert 0.0 < expected < kinetic_gain


def test_walk_reading_is_the_mean_of_its_steps():
    n = 11
    first = _step(n, 1.0, np.tile([10.0, 0.0], (n, 1)), np.tile([1.0, 0.0], (n, 1)))
    second = _step(n, 1.0, np.tile([30.0, 0.0], (n, 1)), np.tile([1.0, 0.0], (n, 1)), stance=2)
    expected = (thesis_reading(*first).cot + thesis_reading(*second).cot) / 2
    assert thesis_reading(*second).cot == pytest.approx(3 * thesis_reading(*first).cot)
    assert thesis_reading_acot([first, second]) == pytest.approx(expected, rel=1e-12)


def _forward_step(n_nodes: int, phase: str, **options):
    registry = load_registry()
    experiment = registry.create("experiment", "forward")
    geometry = experiment.terrain.steps[0]
    data = StepData(experiment.robot, experiment.stance_leg(1), experiment.initial_state[[0, 1, 4, 5]], geometry.D,
                    geometry.theta, experiment.time_step(n_nodes))
    structure = StepStructure(phase, n_nodes, ProblemOptions(limits=experiment.limits, **options))
    return registry, experiment, data, structure


def test_thesis_push_off_cost_charges_half_the_stance_mass_foot_speed_in_the_nlp_objective():
    registry, experiment, data, structure = _forward_step(9, "second")
    transcription = registry.create("transcription", "hermite-simpson")
    impulse_built = transcription.build(structure)
    thesis_built = transcription.build(replace(structure, options=replace(structure.options, push_off_cost="thesis")))
    x = impulse_built.initial_guess(data)
    x[impulse_built.nlp.variable_blocks["push_off"]] = 30.0
    trajectory = impulse_built.trajectory(x, data)
    model = BipedModel(experiment.robot, 4)
    foot = np.zeros(2)
    _, kinetic_gain = model.push_off(np.r_[trajectory.q[-1], foot], np.r_[trajectory.dq[-1], foot], 30.0, 1)
    thesis_term = thesis_push_off_energy(trajectory, experiment.robot, model)
    weight = experiment.robot.total_mass * experiment.robot.g * data.chord
    difference = thesis_built.objective_cot(x, data) - impulse_built.objective_cot(x, data)
    assert difference == pytest.approx((thesis_term - kinetic_gain) / weight, rel=1e-8)
    assert thesis_term < kinetic_gain


def test_effort_first_phase_minimises_torque_squared_and_reports_no_objective_cot():
    registry, _, data, structure = _forward_step(9, "first")
    transcription = registry.create("transcription", "hermite-simpson")
    objective_built = transcription.build(structure)
    effort_built = transcription.build(replace(structure, options=replace(structure.options,
                                                                          first_phase_cost="effort")))
    assert effort_built.cost_of_transport is None
    assert effort_built.structure.objective == objective_built.structure.objective  # verification's objective
    nlp, p = effort_built.nlp, data.parameter_vector()
    objective = ca.Function("f", [nlp.x, nlp.p], [nlp.f])
    x = effort_built.initial_guess(data)
    x[nlp.variable_blocks["torques"]] = np.tile([3.0, -4.0], 9)  # |τ|² = 25 N²m² throughout the step
    robot = data.robot
    scale = robot.total_mass * robot.l * (robot.g * robot.l) ** 0.5
    expected = 25.0 * 8 * data.time_step / scale / (robot.total_mass * robot.g * data.chord)
    assert float(objective(x, p)) == pytest.approx(expected, rel=1e-10)
    assert objective_built.nlp.n_variables > nlp.n_variables  # no |P| slack pairs: no power is charged


def test_nodal_simpson_charges_only_the_nodes_with_simpson_weights():
    registry, _, data, structure = _forward_step(9, "first")
    nodal = registry.create("transcription", "hermite-simpson", quadrature="nodal-simpson").build(structure)
    x = nodal.initial_guess(data)
    x[nodal.nlp.variable_blocks["torques"]] = np.linspace(-20.0, 30.0, 18)
    trajectory = nodal.trajectory(x, data)
    expected = thesis_reading(trajectory, data).cot
    assert nodal.objective_cot(x, data) == pytest.approx(expected, rel=1e-10)
