"""Tests that would catch a wrong figure (issue 61, item 9): each checks a reported number against the same number
computed independently here, in a case built so that the mistake it guards against changes that number.

``benchmarks/mutation.py`` applies plausible mistakes to the code one by one and records which of them these and the
other fast tests catch.
"""

from __future__ import annotations

import dataclasses
from functools import cache

import casadi as ca
import numpy as np
import pytest

from gaitbench.acceptance import OBJECTIVE_RTOL, StepVerification
from gaitbench.model.mechanics import BipedModel, biped_functions
from gaitbench.model.robot import RobotParameters
from gaitbench.plugins import load_registry
from gaitbench.problem.gait_problem import ProblemOptions, StepData, StepStructure, role_robot_vector
from gaitbench.problem.nlp import NLPBuilder
from gaitbench.problem.objective import NET_POWER
from gaitbench.problem.step_cost import QUADRATURE_RULES, charged
from gaitbench.problem.trajectory import Interpolant, StepTrajectory
from gaitbench.solve.verify import fine_grid_running_cost, verify_step
from gaitbench.solve.walk import next_step_state
from gaitbench.walk_types import StepOutcome, WalkResult
from gaitbench_plugins.objectives.energy_costs import ActuatorWork, TorqueSquared
from gaitbench_plugins.solvers.ipopt import Ipopt
from gaitbench_plugins.transcriptions.dmoc import interval_motion

REGISTRY = load_registry()
N_NODES = 12
TIE_BREAK = 1e-3
"""A small ∫τ² tie-break makes each step's optimum unique (the net-power cost alone has a flat set of optima)."""
OBJECTIVES = {"net-power": NET_POWER, "actuator-work": ActuatorWork()}
LOPSIDED = RobotParameters(m1=14.0, m2=26.0, M=40.0, l=1.0, a=0.45, I1=0.9, I2=2.6)
"""Unequal legs with inertias unlike a rod's: a step posed with the wrong leg's mass or inertia is another motion."""


@cache
def solved_step(experiment_name: str = "stairs", transcription: str = "hermite-simpson", phase: str = "second",
                objective: str = "net-power", step: int = 1, lopsided: bool = False):
    """Step ``step`` of an experiment (``lopsided``: with :data:`LOPSIDED` legs) solved by IPOPT from the standard
    guess at N = :data:`N_NODES`, and verified: (built, x, data, trajectory, model, verification)."""
    experiment = REGISTRY.create("experiment", experiment_name)
    robot = LOPSIDED if lopsided else experiment.robot
    geometry = experiment.terrain.steps[step - 1]
    stance = experiment.stance_leg(step)
    state = np.asarray(experiment.initial_state, dtype=float)[[0, 1, 4, 5]]
    if stance == 2:  # the printed start state with the legs' labels swapped: Leg 2 stands where Leg 1 stood
        state = state[[1, 0, 3, 2]]
    data = StepData(robot, stance, state, geometry.D, geometry.theta, experiment.time_step(N_NODES))
    options = ProblemOptions(limits=experiment.limits, torque_regularization=TIE_BREAK)
    structure = StepStructure(phase, N_NODES, options, objective=OBJECTIVES[objective])
    built = REGISTRY.create("transcription", transcription).build(structure)
    result = Ipopt().solve(built.nlp, data.parameter_vector(), built.initial_guess(data))
    assert result.converged, f"{experiment_name} step {step}, {transcription}, {phase}: {result.message}"
    trajectory = built.trajectory(result.x, data)
    model = BipedModel(robot, 4 if phase == "second" else 2)
    return built, result.x, data, trajectory, model, verify_step(built, result.x, data, trajectory, model)


def dense_hip_energy(trajectory: StepTrajectory, samples_per_interval: int = 400) -> float:
    """∫ |τ·q̇| dt by the trapezoid rule on a dense grid of each interval (read just inside its ends)."""
    energy = 0.0
    for start, end in zip(trajectory.times[:-1], trajectory.times[1:], strict=True):
        t = np.linspace(start, end, samples_per_interval + 1)
        inside = np.clip(t, start + 1e-12, end - 1e-12)
        power = [trajectory.control(s) @ trajectory.state(s)[1] for s in inside]
        energy += np.trapezoid(np.abs(power), t)
    return float(energy)


def test_the_verified_cot_charges_the_push_off_energy():
    """COT = (hip energy + E_PO) / (M g D), E_PO the kinetic energy the push-off impulse adds, both computed here:
    on a solved stairs step (whose optimum pushes off) and on the same step with a harder push."""
    built, x, data, trajectory, model, _ = solved_step()
    robot = data.robot
    hip = dense_hip_energy(trajectory)
    q = np.r_[trajectory.q[-1], 0.0, 0.0]
    dq = np.r_[trajectory.dq[-1], 0.0, 0.0]
    for impulse in (trajectory.push_off, 3 * trajectory.push_off + 20.0):
        pushed = dataclasses.replace(trajectory, push_off=impulse)
        check = verify_step(built, x, data, pushed, model)
        dq_plus, _ = model.push_off(q, dq, impulse, data.stance)
        push_off_energy = model.kinetic_energy(q, dq_plus, data.stance) - model.kinetic_energy(q, dq, data.stance)
        assert push_off_energy > 0.01 * hip  # ten times the tolerance below: leaving it out shows
        assert check.push_off_energy == pytest.approx(push_off_energy, rel=1e-9)
        assert check.hip_energy == pytest.approx(hip, rel=1e-3)  # |P|'s kinks: the two quadratures differ by 2e-4
        expected = (hip + push_off_energy) / (robot.total_mass * robot.g * data.chord)
        assert check.cot == pytest.approx(expected, rel=1e-3)


def test_the_resimulation_error_is_read_at_the_step_end():
    """A step whose last node is moved by δ is no longer a motion: the re-simulation misses it by δ (up to the step's
    own error). A step moved at a middle node misses there, not at its end."""
    built, x, data, trajectory, model, check = solved_step()
    tolerance = check.resim_max_error
    assert tolerance < 0.01
    delta = 0.05
    for node, end_error in ((-1, delta), (N_NODES // 2, 0.0)):
        q = trajectory.q.copy()
        q[node] += delta
        edited = verify_step(built, x, data, dataclasses.replace(trajectory, q=q), model)
        assert abs(edited.resim_max_error - delta) <= tolerance
        assert abs(edited.resim_error - end_error) <= tolerance


def test_the_resimulation_error_grows_with_a_control_the_trajectory_did_not_use():
    """The step re-simulated under torques offset by 2 N·m ends far from its nodes: the error is reported, at the
    size of the offset's effect (a constant torque δτ over the step moves the legs by ~δτ T² / (2 m l²))."""
    built, x, data, trajectory, model, check = solved_step()
    interpolant = trajectory._interpolant
    offset = Interpolant(state=interpolant.state, control=lambda t: interpolant.control(t) + 2.0)
    edited = verify_step(built, x, data, dataclasses.replace(trajectory, _interpolant=offset), model)
    duration, robot = trajectory.duration, data.robot
    scale = 2.0 * duration**2 / (2 * min(robot.m1, robot.m2) * robot.l**2)
    assert edited.resim_error > 10 * check.resim_error
    assert scale / 10 < edited.resim_error < 100 * scale


def test_a_step_that_costs_less_than_its_objective_says_disagrees_with_it():
    """The objective check is two-sided: a trajectory that spends half the hip energy its NLP objective charges (its
    torques halved on the same motion) has a negative gap beyond the tolerance."""
    built, x, data, trajectory, model, check = solved_step()
    assert check.objective_agrees
    interpolant = trajectory._interpolant
    halved = Interpolant(state=interpolant.state, control=lambda t: 0.5 * interpolant.control(t))
    edited = verify_step(built, x, data, dataclasses.replace(trajectory, _interpolant=halved), model)
    assert edited.objective_cot == check.objective_cot
    assert edited.objective_gap < -OBJECTIVE_RTOL and not edited.objective_agrees


def _outcome(index: int, cot: float | None) -> StepOutcome:
    """A step outcome built by hand: solved with the given COT, or failed (``cot`` None)."""
    if cot is None:
        return StepOutcome(index, 2 - index % 2, "infeasible", "infeasible: made up")
    verification = StepVerification(max_defect=0.0, resim_error=0.0, resim_max_error=0.0, hip_energy=cot,
                                    push_off_energy=0.0, cot=cot)
    return StepOutcome(index, 2 - index % 2, "converged", "", verification=verification, next_state=np.zeros(4))


def test_acot_is_the_mean_of_a_complete_walk_and_none_for_a_partial_one():
    def walk(cots, requested):
        return WalkResult("stairs", "hermite-simpson", "ipopt", "one-phase", N_NODES, "second", requested,
                          steps=[_outcome(i + 1, cot) for i, cot in enumerate(cots)])

    complete = walk([0.2, 0.3, 1.0], 3)
    assert complete.complete and complete.acot == pytest.approx(0.5)  # the mean (the median would be 0.3)
    for partial in (walk([0.2, 0.5, None], 3), walk([0.2, None], 3), walk([0.2, 0.5], 3)):
        assert not partial.complete and partial.acot is None
        assert partial.as_dict()["acot"] is None
    assert walk([0.2, 0.5, None], 3).failure == "step 3: infeasible: made up"


def test_a_polished_step_reports_its_polished_outcome_when_that_solved():
    """Decrease and conquer's patchwork need not be a motion: the step's verified outcome (the trajectory tracked and
    reported) is its polished re-solve, unless that failed."""
    patchwork, polished = _outcome(1, 0.3), _outcome(1, 0.4)
    patchwork.polished = polished
    assert patchwork.verified is polished
    patchwork.polished = _outcome(1, None)
    assert patchwork.verified is patchwork
    assert _outcome(1, 0.3).verified.verification.cot == 0.3


EXACT_DEGREE = {"trapezoid": 1, "simpson": 3, "boole": 5}
"""The degree of the polynomials each closed Newton–Cotes rule integrates exactly (n points: n − 1 for even n, n for
odd n)."""


@pytest.mark.parametrize("name", list(QUADRATURE_RULES))
def test_each_quadrature_rule_is_exact_up_to_its_degree_and_no_further(name):
    rule = QUADRATURE_RULES[name]
    assert name in EXACT_DEGREE, f"{name}: state its degree of exactness here"
    points = np.array([0.0, *rule.points, 1.0])
    weights = np.array([rule.end_weight, *rule.weights, rule.end_weight])
    assert len(points) - 1 + len(points) % 2 == EXACT_DEGREE[name]  # Newton–Cotes on n equispaced points
    np.testing.assert_allclose(np.diff(points), 1 / (len(points) - 1), rtol=1e-12)
    degree = EXACT_DEGREE[name]
    a, b = -0.3, 0.8  # an interval of its own, as the rule is used: fractions of [a, b]
    for power in range(degree + 2):
        exact = (b ** (power + 1) - a ** (power + 1)) / (power + 1)
        rule_value = (b - a) * weights @ (a + (b - a) * points) ** power
        if power <= degree:
            assert rule_value == pytest.approx(exact, rel=1e-13, abs=1e-15), f"{name}, degree {power}"
        else:
            assert abs(rule_value - exact) > 1e-6 * abs(exact), f"{name} is exact at degree {power} too"


def _sign_changing_step(stance: int, a: float = 30.0, b: float = 20.0, periods: int = 2) -> StepTrajectory:
    """Constant role rates (1, 2) rad/s under role torques (a sin ωt, b cos ωt) over whole periods: every power
    changes sign, its signed integral is 0, and ∫|R sin(ωt + φ)| dt = 2 R T / π over whole periods."""
    duration, n = 0.6, 13
    omega = 2 * np.pi * periods / duration
    order = [0, 1] if stance == 1 else [1, 0]

    def state(t):
        return np.array([t, 2 * t]), np.array([1.0, 2.0])

    def control(t):
        return np.array([a * np.sin(omega * t), b * np.cos(omega * t)])

    times = np.linspace(0.0, duration, n)
    q = np.array([state(t)[0] for t in times])[:, order]
    dq = np.array([state(t)[1] for t in times])[:, order]
    tau = np.array([control(t) for t in times])[:, order]
    return StepTrajectory(times=times, q=q, dq=dq, tau=tau, control_times=times, push_off=0.0, stance=stance,
                          _interpolant=Interpolant(state, control))


@pytest.mark.parametrize("objective", list(OBJECTIVES))
@pytest.mark.parametrize("stance", [1, 2])
def test_the_charged_power_is_its_magnitude_where_it_changes_sign(objective, stance):
    """Net power a sin + 2 b cos; actuator work |b cos| + |(a sin + b cos)|: their ∫|·| in closed form, where the
    signed integrals vanish."""
    a, b = 30.0, 20.0
    trajectory = _sign_changing_step(stance, a, b)
    whole = 2 * trajectory.duration / np.pi  # ∫|sin| over whole periods, per unit amplitude
    amplitude = {"net-power": np.hypot(a, 2 * b), "actuator-work": b + np.hypot(a, b)}[objective]
    energy = fine_grid_running_cost(trajectory, OBJECTIVES[objective], np.zeros(8))
    assert energy == pytest.approx(whole * amplitude, rel=1e-3)


@pytest.mark.parametrize("objective", list(OBJECTIVES))
def test_dmoc_prices_each_interval_on_the_velocities_of_its_interpolant(objective):
    """The cost reads each interval's power at Boole's points from the interval's forced discrete Legendre transforms:
    at a solution these are the node velocities, and inside the interval the cubic Hermite velocities that
    verification integrates. So the NLP's objective is Boole's rule on the interpolant's power, computed here."""
    built, x, data, trajectory, model, _ = solved_step(transcription="dmoc", objective=objective)
    assert data.stance == 1  # role order is leg order
    rule = QUADRATURE_RULES["boole"]
    points = (0.0, *rule.points, 1.0)
    weights = np.array([rule.end_weight, *rule.weights, rule.end_weight])
    motion = interval_motion(biped_functions(2, 1), points)
    p = data.parameter_vector()
    h = data.time_step
    robot = role_robot_vector(data.robot, data.stance)
    q, tau = trajectory.q, trajectory.tau
    energy = 0.0
    for k in range(N_NODES - 1):
        read = np.asarray(motion(np.r_[q[k], q[k + 1], tau[k]], p)).reshape(len(points), 4)
        times = trajectory.times[k] + h * np.clip(np.array(points), 1e-9, 1 - 1e-9)
        velocities = np.array([trajectory.state(t)[1] for t in times])
        np.testing.assert_allclose(read[:, :2], velocities, atol=1e-6 * (1 + np.abs(velocities).max()))
        np.testing.assert_allclose(read[[0, -1], :2], trajectory.dq[[k, k + 1]], atol=1e-5)
        rates = OBJECTIVES[objective].rate(velocities, np.tile(tau[k], (len(points), 1)), data.stance, robot)
        energy += h * weights @ rates
    _, push_off_energy = model.push_off(np.r_[q[-1], 0.0, 0.0], np.r_[trajectory.dq[-1], 0.0, 0.0],
                                        trajectory.push_off, data.stance)
    event = OBJECTIVES[objective].event_cost(push_off_energy)
    expected = (energy + event) / (data.robot.total_mass * data.robot.g * data.chord)
    assert built.objective_cot(x, data) == pytest.approx(expected, rel=1e-5, abs=1e-7)


@pytest.mark.parametrize(("transcription", "phase"), [("hermite-simpson", "first"), ("hermite-simpson", "second"),
                                                      ("dmoc", "second")])
def test_a_leg_2_stance_step_of_unequal_legs_is_a_motion_of_that_robot(transcription, phase):
    """The NLP poses a Leg-2 stance step in role order, with the stance leg's mass and inertia in Leg 1's place;
    the core simulator runs it in leg order. With either swapped wrongly, the solved step would be another robot's
    motion and its re-simulation would miss it; and the step must end on its heel-strike map in leg order."""
    _, _, data, trajectory, model, check = solved_step("forward", transcription, phase, step=2, lopsided=True)
    assert data.stance == 2
    reference, reference_check = solved_step("forward", transcription, phase, step=2)[3::2]
    assert check.max_defect < 1e-6
    assert check.resim_max_error < max(2 * reference_check.resim_max_error, 0.02)
    # unequal legs walk another step: the lopsided robot's optimum is not the symmetric one's
    assert np.abs(trajectory.q - reference.q).max() > 1e-3


@pytest.mark.parametrize("absolute_value", ["slack", "smooth"])
def test_the_nlp_charges_positive_and_negative_work_by_their_own_weights(absolute_value):
    """Margaria's actuator work as the NLP charges one power: 4 J per joule of positive work and 1/1.2 J per joule of
    negative work, exactly with the slack split (at its optimum) and within ε·(w⁺ + w⁻)/2 with the thesis's
    smoothed |P|."""
    objective = ActuatorWork(margaria=True)
    options = ProblemOptions(absolute_value=absolute_value)
    structure = StepStructure("second", 5, options, objective=objective)
    builder = NLPBuilder()
    power = builder.variable("power", (1, 1), -np.inf, np.inf)
    cost = charged(builder, structure, "charge", power)
    nlp = builder.build(ca.SX.sym("p", 0), cost)
    tolerance = options.smoothing_eps * (objective.positive_weight + objective.negative_weight) / 2
    for value, expected in ((10.0, 4 * 10.0), (-12.0, 12.0 / 1.2)):
        x = np.zeros(nlp.n_variables)
        x[nlp.variable_blocks["power"]] = value
        if absolute_value == "slack":  # the split at its optimum: the power's positive and negative parts
            x[nlp.variable_blocks["charge_positive"]] = max(value, 0.0)
            x[nlp.variable_blocks["charge_negative"]] = max(-value, 0.0)
            assert nlp.violation(x, np.zeros(0)) == 0.0
        assert float(nlp.functions.objective(x, np.zeros(0))) == pytest.approx(expected, abs=tolerance + 1e-12)


def test_torque_squared_scales_by_the_robot_s_own_units_on_a_leg_that_is_not_1_m():
    """c = 1 / (M g l √(l/g)): torques in units of M g l over times in units of √(l/g). On a 1 m leg, √(g/l) and
    √(g l) coincide; on 0.8 m they do not."""
    robot = dataclasses.replace(LOPSIDED, l=0.8, a=0.35)
    vector = role_robot_vector(robot, 1)
    rate = TorqueSquared().rate(np.zeros((1, 2)), np.array([[3.0, 4.0]]), 1, vector)
    unit_torque, unit_time = robot.total_mass * robot.g * robot.l, np.sqrt(robot.l / robot.g)
    assert rate == pytest.approx(25.0 / (unit_torque * unit_time), rel=1e-12)


def test_the_next_step_starts_after_the_push_off_and_the_heel_strike():
    """The heel strike's only impulse acts at the landing foot, so the robot's angular momentum about that foot just
    after the push-off is the one the next step starts with (the old stance foot lifting off); the push-off, whose
    impulse acts along the stance leg, changes it first."""
    _, _, data, trajectory, model, _ = solved_step()
    stance = data.stance
    q, dq = np.r_[trajectory.q[-1], 0.0, 0.0], np.r_[trajectory.dq[-1], 0.0, 0.0]
    pushed, _ = model.push_off(q, dq, trajectory.push_off, stance)
    momentum = model.angular_momentum_about_swing_foot(q, pushed, stance)
    assert abs(momentum - model.angular_momentum_about_swing_foot(q, dq, stance)) > 0.01 * abs(momentum)
    start = next_step_state(model, trajectory)
    lifting_foot = model.heel_strike(q, pushed, stance).lifting_foot_velocity
    after = model.angular_momentum_about_swing_foot(q, np.r_[start[2:], lifting_foot], stance)
    assert after == pytest.approx(momentum, rel=1e-9)
    np.testing.assert_allclose(start[:2], trajectory.q[-1], atol=1e-12)  # angles unchanged, legs' labels kept
