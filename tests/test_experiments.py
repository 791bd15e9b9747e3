import math

import numpy as np
import pytest
from rich.console import Console

from gaitbench import Registration
from gaitbench.model.experiment import (
    Experiment,
    FrictionParameters,
    Limits,
    feasibility_summary,
    render_experiment,
)
from gaitbench.model.robot import InvalidParameterError, RobotParameters
from gaitbench.model.terrain import Terrain
from gaitbench_plugins.experiments import thesis_experiments

THESIS_NAMES = ("forward", "downward-slope", "upward-slope", "stairs")


def build(name: str) -> Experiment:
    registrations = {r.name: r for r in thesis_experiments.register_experiments()}
    return registrations[name].factory()


def test_plugin_registers_the_four_thesis_experiments_with_one_line_descriptions():
    registrations = thesis_experiments.register_experiments()
    assert [r.name for r in registrations] == list(THESIS_NAMES)
    for registration in registrations:
        assert isinstance(registration, Registration)
        assert registration.description and "\n" not in registration.description


@pytest.mark.parametrize("name", THESIS_NAMES)
def test_every_thesis_experiment_builds_with_the_common_parameters(name):
    experiment = build(name)
    assert experiment.name == name
    assert experiment.n_steps == 11
    assert experiment.step_duration == 0.7343
    assert experiment.robot.a == experiment.robot.b == experiment.robot.l / 2
    assert experiment.robot.m1 == experiment.robot.m2 == experiment.robot.M / 2
    assert experiment.robot.inertia1 == pytest.approx(experiment.robot.m1 * experiment.robot.l**2 / 12)
    np.testing.assert_array_equal(experiment.initial_state[[2, 3, 6, 7]], 0.0)
    assert experiment.friction is not None and experiment.friction.n == 2
    assert experiment.limits == Limits.sized_for(experiment.robot)
    assert experiment.source.startswith("thesis §5.")  # the thesis section its parameters come from


def test_forward_parameters():
    e = build("forward")
    assert (e.robot.M, e.robot.m1, e.robot.l) == (40.0, 20.0, 1.0)
    assert [s.D for s in e.terrain.steps] == [0.6, 0.8, 1.0, 1.4, 1.7, 1.9, 1.6, 1.3, 1.1, 0.8, 0.6]
    assert all(s.theta == 0.0 for s in e.terrain.steps)
    np.testing.assert_array_equal(e.initial_state, [0.2187, -0.2187, 0, 0, -1.0924, -0.3774, 0, 0])
    f = e.friction
    assert (f.Fc, f.Fs, f.fv, f.vs) == (6.0, 10.0, 8.0, 0.19)
    assert (f.Fc_lin, f.Fs_lin, f.fv_lin, f.vs_lin) == (5.0, 5.0, 6.0, 0.03)
    assert all(check.ok for check in e.feasibility())


def test_downward_slope_parameters():
    e = build("downward-slope")
    assert (e.robot.M, e.robot.m2, e.robot.l, e.robot.a) == (60.0, 30.0, 1.5, 0.75)
    assert {s.theta for s in e.terrain.steps} == {-0.677}
    assert e.terrain.steps[0].D == 2.8 and e.terrain.steps[-1].D == 0.6
    assert e.initial_state[4] == -2.162
    assert (e.friction.Fs, e.friction.fv_lin, e.friction.vs_lin) == (11.0, 7.0, 0.07)


def test_upward_slope_parameters():
    e = build("upward-slope")
    assert (e.robot.M, e.robot.m1, e.robot.l) == (55.0, 27.5, 1.2)
    assert {s.theta for s in e.terrain.steps} == {0.698}
    assert e.terrain.steps[-1].D == 2.25
    assert e.initial_state[1] == -0.2296
    assert (e.friction.Fs, e.friction.vs, e.friction.fv_lin) == (12.0, 0.25, 7.5)


def test_stairs_parameters_come_from_run_and_rise():
    e = build("stairs")
    assert (e.robot.M, e.robot.m1, e.robot.l) == (70.0, 35.0, 1.0)
    third = e.terrain.steps[2]
    assert third.D == pytest.approx(1.7)
    assert third.theta == pytest.approx(math.atan2(0.8, 1.5))
    assert e.terrain.steps[0].theta == pytest.approx(math.radians(30.96), abs=1e-4)  # not the printed 52.96°
    assert e.terrain.steps[1].D == pytest.approx(1.5232, abs=1e-4)  # not the printed 1.56
    np.testing.assert_allclose(e.terrain.footholds()[5], [6.2, 2.9])  # top of the five stairs up
    assert e.initial_state[0] == 0.2843 and e.initial_state[1] == -0.2893  # q2 kept as printed
    assert (e.friction.Fc_lin, e.friction.Fs_lin) == (6.5, 6.0)


@pytest.mark.parametrize("name", THESIS_NAMES)
def test_leg_labelled_heel_strike_angles_alternate_roles(name):
    e = build(name)
    for step in range(1, e.n_steps + 1):
        geometry = e.terrain.steps[step - 1]
        q1, q2 = e.heel_strike_configuration(step)
        stance, swing = (q1, q2) if step % 2 == 1 else (q2, q1)
        assert e.stance_leg(step) == (1 if step % 2 == 1 else 2)
        assert stance < geometry.theta < swing  # the stance leg trails, whichever label it has
        assert stance + swing == pytest.approx(2 * geometry.theta)


def test_stance_leg_and_time_step():
    e = build("forward")
    assert [e.stance_leg(i) for i in (1, 2, 3, 11)] == [1, 2, 1, 1]
    assert e.time_step(101) == pytest.approx(0.007343)
    with pytest.raises(ValueError):
        e.stance_leg(12)
    with pytest.raises(ValueError):
        e.time_step(1)


def _experiment(**changes):
    values = dict(
        name="x", description="test", robot=RobotParameters(m1=1.0, m2=1.0, M=2.0, l=1.0, a=0.5),
        terrain=Terrain.flat([0.5]), initial_state=np.zeros(8), step_duration=0.5,
    )
    values.update(changes)
    return Experiment(**values)


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"step_duration": -0.7}, "step_duration"),
        ({"step_duration": float("nan")}, "step_duration"),
        ({"initial_state": [0.1, float("nan"), 0, 0, 0, 0, 0, 0]}, "q2"),
        ({"initial_state": np.zeros(7)}, "initial_state"),
    ],
)
def test_invalid_experiment_values_name_the_field(changes, field):
    with pytest.raises(InvalidParameterError, match=field):
        _experiment(**changes)


def test_initial_state_is_a_read_only_copy():
    state = np.zeros(8)
    e = _experiment(initial_state=state)
    state[0] = 1.0
    assert e.initial_state[0] == 0.0
    with pytest.raises(ValueError):
        e.initial_state[0] = 1.0


def test_invalid_limits_and_friction_name_the_field():
    with pytest.raises(InvalidParameterError, match="tau_max"):
        Limits(tau_max=0.0)
    with pytest.raises(InvalidParameterError, match="angle_bounds"):
        Limits(angle_bounds=(1.0, -1.0))
    with pytest.raises(InvalidParameterError, match="vs_lin"):
        FrictionParameters(Fc=1, Fs=1, fv=1, vs=1, Fc_lin=1, Fs_lin=1, fv_lin=1, vs_lin=0)


def test_friction_scales_the_linear_joints_by_the_time_step():
    f = build("forward").friction
    coefficients = f.joint_coefficients(0.01)
    np.testing.assert_allclose(coefficients["Fc"], [6.0, 6.0, 0.05, 0.05])
    np.testing.assert_allclose(coefficients["fv"], [8.0, 8.0, 0.06, 0.06])
    np.testing.assert_allclose(coefficients["vs"], [0.19, 0.19, 0.03, 0.03])


def render(name: str) -> str:
    console = Console(record=True, width=240)
    render_experiment(build(name), console)
    return console.export_text()


def test_render_shows_parameters_step_rows_and_the_thesis_bounds_refusals():
    text = render("downward-slope")
    assert "0.7343 s" in text and "60 kg" in text
    assert text.count("gaitbench choice, not thesis") == 4  # tau_max, dq_max, push_off_max, Stribeck n
    assert "6750 Nm" in text  # 3000 Nm scaled by m g l to the 120 kg, 1.5 m robot
    rows = [line.split() for line in text.splitlines() if "Leg 1" in line or "Leg 2" in line]
    assert [row[0] for row in rows] == [str(i) for i in range(1, 12)]
    step_1 = ["Leg", "1", "2.8000", "-0.6770", "-38.79", "2.182", "-1.754", "-1.8806", "0.5266", "✓"]
    assert rows[0][1:] == step_1
    assert "11 steps, 11 feasible, 0 infeasible" in text
    assert 'angle_bounds = "thesis"): 11 steps, 9 feasible, 2 infeasible: steps 1, 2' in text
    assert "step 1: stance angle at heel strike -1.881 rad is below the lower angle bound -1.571" in text


def test_render_of_a_feasible_experiment():
    text = render("forward")
    assert "11 steps, 11 feasible, 0 infeasible" in text
    assert "✗" not in text


def test_feasibility_summary_for_stairs_names_step_7_under_the_thesis_bounds_only():
    stairs = build("stairs")
    assert feasibility_summary(stairs.feasibility("thesis")) == "11 steps, 10 feasible, 1 infeasible: step 7"
    assert feasibility_summary(stairs.feasibility()) == "11 steps, 11 feasible, 0 infeasible"


@pytest.mark.parametrize("name", ["forward", "downward-slope", "upward-slope", "stairs"])
def test_the_walk_starts_with_both_feet_on_the_ground_and_the_printed_inter_leg_angle(name):
    experiment = build(name)
    state = experiment.start_state()
    printed = experiment.initial_state[[0, 1, 4, 5]]
    q1, q2 = state[:2]
    ground = experiment.terrain.ground_behind(1)
    trailing = np.array([math.sin(q2) - math.sin(q1), math.cos(q1) - math.cos(q2)])  # from the stance foot, in l
    assert trailing[1] == pytest.approx(math.tan(ground) * trailing[0], abs=1e-12)
    assert trailing[0] < 0
    assert q1 - q2 == pytest.approx(printed[0] - printed[1])
    np.testing.assert_array_equal(state[2:], printed[2:])
    np.testing.assert_array_equal(experiment.start_state("printed"), printed)


def test_the_printed_downward_pose_puts_the_trailing_foot_inside_the_slope():
    experiment = build("downward-slope")
    q1, q2 = experiment.initial_state[:2]
    l, theta = experiment.robot.l, experiment.terrain.steps[0].theta  # noqa: E741
    x, y = l * (math.sin(q2) - math.sin(q1)), l * (math.cos(q1) - math.cos(q2))
    depth = (math.tan(theta) * x - y) * math.cos(theta)  # distance below the slope line
    assert depth == pytest.approx(0.79, abs=0.01)


def test_limits_are_sized_to_the_robot():
    forward, downward = build("forward"), build("downward-slope")
    assert forward.limits == Limits()
    assert downward.limits.tau_max == pytest.approx(3000 * 120 * 1.5 / 80)
    assert downward.limits.dq_max == pytest.approx(50 / math.sqrt(1.5))
    assert downward.limits.push_off_max == pytest.approx(500 * 120 / 80 * math.sqrt(1.5))
