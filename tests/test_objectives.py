"""Objectives (issue 26): the optimised and the reported figure come from one definition, and actuator-work is
the work of the real actuators."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from gaitbench.acceptance import OBJECTIVE_RTOL
from gaitbench.cli.main import main
from gaitbench.contracts import WalkProblem
from gaitbench.plugins import load_registry
from gaitbench.problem.gait_problem import ProblemOptions, role_robot_vector
from gaitbench.problem.objective import NET_POWER
from gaitbench.problem.trajectory import nodal_trajectory
from gaitbench.solve.one_phase import OnePhase
from gaitbench.solve.verify import fine_grid_running_cost
from gaitbench_plugins.objectives.energy_costs import ActuatorWork, TorqueSquared

REGISTRY = load_registry()
OBJECTIVES = {"net-power": NET_POWER, "actuator-work": ActuatorWork(), "actuator-work-margaria": ActuatorWork(True),
              "torque-squared": TorqueSquared()}


@pytest.fixture(scope="module")
def forward():
    return REGISTRY.create("experiment", "forward")


@pytest.fixture
def invoke():
    def run(*args: str):
        return CliRunner().invoke(main, list(args))

    return run


def test_the_objective_kind_lists_the_three_built_in_objectives():
    assert {"net-power", "actuator-work", "torque-squared"} <= set(REGISTRY.names("objective"))
    assert REGISTRY.create("objective", "net-power") == NET_POWER
    assert REGISTRY.create("objective", "actuator-work", margaria=True).describe() == "actuator-work(margaria=True)"


@pytest.mark.parametrize("transcription", ["hermite-simpson", "dmoc"])
@pytest.mark.parametrize("name", list(OBJECTIVES))
def test_the_verified_cot_is_the_nlp_objective_at_the_optimum(transcription, name):
    """Each step's COT recomputed on the fine grid agrees with the NLP's objective within its quadrature error
    (the 5 % / 1e-3 of verification's objective check). Both transcriptions integrate the interpolant's running
    cost by Boole's rule here, exact wherever the charged powers keep their sign; Hermite–Simpson's default Simpson
    rule lets net power hide between its points (15 % on this walk's step 1, docs/convergence.md)."""
    experiment = REGISTRY.create("experiment", "forward")
    options = {"quadrature": "boole"}
    problem = WalkProblem(experiment, REGISTRY.create("transcription", transcription, **options),
                          REGISTRY.create("solver", "ipopt"), 20, steps=2, objective=OBJECTIVES[name])
    walk = OnePhase().solve(problem)
    assert walk.complete and walk.objective == OBJECTIVES[name].describe()
    for step in walk.steps:
        check = step.verification
        assert check.objective_agrees, (step.index, check.cot, check.objective_cot)
        assert abs(check.objective_gap) <= OBJECTIVE_RTOL


def _motion(dq_stance: np.ndarray, dq_swing: np.ndarray, stance: int, seed: int):
    """Nodes of a step on a uniform grid with the given role rates and random torques, in leg order."""
    rng = np.random.default_rng(seed)
    n = len(dq_stance)
    times = np.linspace(0.0, 0.7, n)
    roles = np.column_stack([dq_stance, dq_swing])
    q = np.cumsum(roles, axis=0) * (times[1] - times[0])
    tau = 50 * rng.standard_normal((n, 2))
    order = [0, 1] if stance == 1 else [1, 0]
    return nodal_trajectory(times, q[:, order], roles[:, order], tau, 0.0, stance)


@pytest.mark.parametrize("stance", [1, 2])
def test_actuator_work_is_net_power_when_a_single_joint_moves(forward, stance):
    """Stance leg at rest: only the hip moves. Legs locked together: only the ankle moves. Either way the one
    actuator's |power| is the net |power|; with both joints moving against each other actuator-work exceeds it."""
    robot = role_robot_vector(forward.robot, stance)
    t = np.linspace(0.0, 0.7, 15)
    hip_only = _motion(np.zeros_like(t), np.sin(5 * t) - 0.3, stance, 0)
    ankle_only = _motion(np.cos(4 * t) - 0.5, np.cos(4 * t) - 0.5, stance, 1)
    both = _motion(np.cos(4 * t) - 0.5, np.sin(5 * t) + 0.2, stance, 2)
    for trajectory in (hip_only, ankle_only):
        net = fine_grid_running_cost(trajectory, NET_POWER, robot)
        assert net > 1.0
        assert fine_grid_running_cost(trajectory, ActuatorWork(), robot) == pytest.approx(net, rel=1e-12)
    assert fine_grid_running_cost(both, ActuatorWork(), robot) > 1.05 * fine_grid_running_cost(both, NET_POWER, robot)


def test_margaria_weighs_positive_work_by_4_and_negative_work_by_1_over_1_2():
    objective = ActuatorWork(margaria=True)
    assert objective.charge(np.array([2.0, -2.4])) == pytest.approx([8.0, 2.0])
    assert objective.event_cost(3.0) == pytest.approx(12.0)
    assert NET_POWER.event_cost(-1.0) == -1.0  # the thesis's E_PO, charged as it is


def test_torque_squared_is_scaled_by_the_robot_or_a_motor_constant(forward):
    robot = role_robot_vector(forward.robot, 1)
    mass, leg, g = forward.robot.total_mass, forward.robot.l, forward.robot.g
    rate = TorqueSquared().rate(np.zeros((1, 2)), np.array([[3.0, 4.0]]), 1, robot)
    assert rate == pytest.approx(25.0 / (mass * g * leg * np.sqrt(leg / g)))
    assert TorqueSquared(motor_constant=0.5).rate(np.zeros((1, 2)), np.array([[3.0, 4.0]]), 1, robot) == 12.5
    with pytest.raises(ValueError):
        TorqueSquared(motor_constant=0.0)


def test_actuator_work_finds_the_passive_compass_gait(invoke, tmp_path):
    """The passive walker uses no actuator, so under actuator-work (which sees torque) the optimum with scuffing
    allowed is the passive gait: zero work and, unlike net power, no opposing torques either."""
    out = tmp_path / "compass.json"
    result = invoke("solve", "-e", "compass-gait", "-t", "dmoc", "--N", "40", "--steps", "2",
                    "--objective", "actuator-work", "-p", "clearance=off", "--out", str(out))
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["objective"] == "actuator-work" and data["complete"]
    assert data["acot"] < 1e-3
    assert all(step["push_off_impulse"] < 0.01 for step in data["steps"])


def test_problem_options_and_objective_build_apart():
    """The objective is part of the built structure: the same options under another objective build another NLP."""
    transcription = REGISTRY.create("transcription", "dmoc")
    experiment = REGISTRY.create("experiment", "forward")
    options = ProblemOptions(limits=experiment.limits)
    built = {name: transcription.build(WalkProblem(experiment, transcription, REGISTRY.create("solver", "ipopt"), 8,
                                                   options=options, objective=objective).structure("second"))
             for name, objective in OBJECTIVES.items()}
    assert len({id(step) for step in built.values()}) == len(OBJECTIVES)
    assert "power_intervals_positive" in built["actuator-work"].nlp.variable_blocks
    assert "push_off_work_positive" in built["torque-squared"].nlp.variable_blocks
    assert "push_off_work_positive" not in built["net-power"].nlp.variable_blocks
