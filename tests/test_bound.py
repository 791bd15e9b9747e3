"""The physical lower bound on a walk's ACOT (gaitbench/solve/bound.py, `gaitbench bound`, the report's flag columns):
a two-step walk up a constant slope worked by hand, the thesis's push-off ratio, the answers that are no bound, the
command's JSON and the report's flags."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from gaitbench.cli.main import main
from gaitbench.model.mechanics import BipedModel
from gaitbench.model.terrain import Terrain
from gaitbench.plugins import load_registry
from gaitbench.reports import tables
from gaitbench.reports.bounds import ExperimentBounds, experiment_bounds
from gaitbench.reports.thesis_values import MINIMUM_ACOT
from gaitbench.solve.bound import NoBound, push_off_ratios, walk_bound


@pytest.fixture(scope="module")
def registry():
    return load_registry()


@pytest.fixture(scope="module")
def two_steps_up(registry):
    """The upward slope's robot and start state on two 1 m steps of its slope."""
    upward = registry.create("experiment", "upward-slope")
    theta = upward.terrain.steps[0].theta
    return replace(upward, terrain=Terrain.slope((1.0, 1.0), theta))


def _potential(robot, q_st: float, q_sw: float) -> float:
    """V with the stance foot at the origin, from the geometry: hip = l(−sin q_st, cos q_st), swing foot below it."""
    hip = robot.l * math.cos(q_st)
    return robot.g * (robot.m1 * robot.a * math.cos(q_st) + robot.M * hip
                      + robot.m2 * (hip - (robot.l - robot.a) * math.cos(q_sw)))


def _kinetic(robot, q_st: float, q_sw: float, dq_st: float, dq_sw: float) -> float:
    """Kinetic energy of the legs pivoting on the stance foot (Leg 1 stance, equal legs)."""
    hip_velocity = robot.l * dq_st * np.array([-math.cos(q_st), -math.sin(q_st)])
    swing_velocity = hip_velocity + (robot.l - robot.a) * dq_sw * np.array([math.cos(q_sw), math.sin(q_sw)])
    return 0.5 * (robot.inertia1 * dq_st ** 2 + robot.inertia2 * dq_sw ** 2 + robot.m1 * (robot.a * dq_st) ** 2
                  + robot.M * (robot.l * dq_st) ** 2 + robot.m2 * swing_velocity @ swing_velocity)


def test_two_steps_up_a_slope_cost_the_potential_energy_gained_less_the_starting_kinetic_energy(two_steps_up):
    robot, theta = two_steps_up.robot, two_steps_up.terrain.steps[0].theta
    q1, q2, dq1, dq2 = two_steps_up.start_state()  # Leg 1 is the stance leg of step 1
    alpha = math.asin(1.0 / (2 * robot.l))
    gain_1 = _potential(robot, theta - alpha, theta + alpha) - _potential(robot, q1, q2)
    gain_2 = _potential(robot, theta - alpha, theta + alpha) - _potential(robot, theta + alpha, theta - alpha)
    assert gain_2 == pytest.approx(robot.total_mass * robot.g * math.sin(theta))  # the robot moved 1 m up the slope
    start_energy = _kinetic(robot, q1, q2, dq1, dq2)
    assert 0 < start_energy < gain_1  # the start's kinetic energy is spent in step 1 or carried to step 2: same price
    weight = robot.total_mass * robot.g * 1.0

    bound = walk_bound(two_steps_up)

    assert bound.useful and bound.message is None
    assert bound.start_kinetic_energy == pytest.approx(start_energy)
    assert [step.potential_gain for step in bound.steps] == pytest.approx([gain_1, gain_2])
    assert bound.acot == pytest.approx((gain_1 + gain_2 - start_energy) / weight / 2)
    assert bound.steps[0].prefix_acot == pytest.approx((gain_1 - start_energy) / weight)
    assert np.mean([step.cot for step in bound.steps]) == pytest.approx(bound.acot)

    # The thesis's push-off term charges a fraction r of the push-off's energy: step 2's gain comes cheapest through
    # step 1's push-off, while step 1's cannot come from a push-off (none precedes it).
    ratio = push_off_ratios(two_steps_up)[0]
    thesis = walk_bound(two_steps_up, push_off_cost="thesis")
    assert thesis.acot == pytest.approx((gain_1 - start_energy + ratio * gain_2) / weight / 2)
    assert thesis.steps[0].push_off_ratio == pytest.approx(ratio)


def test_the_thesis_push_off_term_is_one_fraction_of_the_impulse_energy_for_every_impulse_and_rate(registry):
    upward = registry.create("experiment", "upward-slope")
    ratios = push_off_ratios(upward)
    assert np.all((ratios > 0.2) & (ratios < 0.4))
    model, rng = BipedModel(upward.robot, 4), np.random.default_rng(1)
    for index in (1, 2, 7):
        stance = upward.stance_leg(index)
        pose = np.r_[upward.heel_strike_configuration(index), 0.0, 0.0]
        for impulse in (3.0, 40.0):
            rates = np.r_[rng.normal(size=2), 0.0, 0.0]
            after, energy = model.push_off(pose, rates, impulse, stance)
            stance_mass = upward.robot.m1 if stance == 1 else upward.robot.m2
            charged = 0.5 * stance_mass * (after[2] ** 2 + after[3] ** 2)
            assert charged / energy == pytest.approx(ratios[index - 1], rel=1e-9)


def test_work_charging_objectives_share_the_bound_and_margaria_prices_it_at_four_joules(registry, two_steps_up):
    net = walk_bound(two_steps_up).acot
    assert walk_bound(two_steps_up, registry.create("objective", "actuator-work")).acot == pytest.approx(net)
    margaria = registry.create("objective", "actuator-work", margaria=True)
    assert walk_bound(two_steps_up, margaria).acot == pytest.approx(4 * net)  # no step gains by negative work
    with pytest.raises(NoBound, match="torque-squared"):
        walk_bound(two_steps_up, registry.create("objective", "torque-squared"))


def _bound(*args: str):
    result = CliRunner().invoke(main, ["bound", *args])
    assert result.exit_code == 0, result.output
    return result.output


def test_flat_ground_says_it_admits_no_useful_bound():
    text = _bound("-e", "forward")
    assert "forward admits no useful bound under net-power" in text and "ACOT bound =" not in text
    answer = json.loads(_bound("-e", "forward", "--json"))
    assert answer["useful"] is False and answer["acot"] == 0 and "no useful bound" in answer["message"]


def test_an_objective_that_charges_torque_says_it_admits_no_useful_bound():
    assert "admits no useful bound" in _bound("-e", "upward-slope", "--objective", "torque-squared")
    answer = json.loads(_bound("-e", "upward-slope", "--objective", "torque-squared", "--json"))
    assert answer["acot"] is None and answer["useful"] is False and answer["steps"] == []


def test_bound_json_gives_the_walk_then_each_step():
    answer = json.loads(_bound("-e", "upward-slope", "--json"))
    assert set(answer) == {"experiment", "objective", "push_off_cost", "start_pose", "start_kinetic_energy", "acot",
                           "useful", "message", "steps"}
    assert (answer["experiment"], answer["objective"], answer["push_off_cost"]) == (
        "upward-slope", "net-power", "impulse")
    assert 0.54 < answer["acot"] < 0.60 and answer["useful"]
    steps = answer["steps"]
    assert [step["index"] for step in steps] == list(range(1, 12))
    assert set(steps[0]) == {"index", "stance", "chord", "potential_gain", "push_off_ratio", "hip_work",
                             "push_off_energy", "cot", "prefix_acot"}
    assert steps[-1]["prefix_acot"] == pytest.approx(answer["acot"])
    thesis = json.loads(_bound("-e", "upward-slope", "--push-off-cost", "thesis", "--json", "--steps", "3"))
    assert len(thesis["steps"]) == 3 and thesis["acot"] < steps[2]["prefix_acot"]
    assert "ACOT bound = 0.57" in _bound("-e", "upward-slope")


def test_the_published_comparison_flags_figures_below_the_bound(registry):
    bounds = experiment_bounds(["forward", "upward-slope"], registry)
    upward = registry.create("experiment", "upward-slope")
    from_each_pose = {pose: walk_bound(upward, start_pose=pose).acot for pose in ("on-ground", "printed")}
    assert 0.54 < from_each_pose["on-ground"] < 0.60 and from_each_pose["printed"] < from_each_pose["on-ground"]
    # the flag must hold whichever start pose the thesis used: the lesser bound
    assert not bounds["forward"].useful and bounds["upward-slope"].impulse == min(from_each_pose.values())
    assert bounds["upward-slope"].thesis_push_off < bounds["upward-slope"].impulse
    minima = pd.DataFrame([{"experiment": experiment, "method": method, "thesis_method": method, "min_acot": 0.5,
                            "N_at_min": 40, "claimed_acot_at_min": math.nan, "thesis_reading_at_min": math.nan,
                            "N_values": "40", "N_solved": "40"}
                           for experiment in ("forward", "upward-slope", "stairs") for method in ("OP-DC", "D&C-DC")])
    bounds["stairs"] = ExperimentBounds(impulse=0.1, thesis_push_off=0.045)
    table = tables.published_comparison(minima, bounds).set_index(["experiment", "thesis_method"])
    assert list(tables.published_comparison(minima, bounds).columns) == tables.PUBLISHED_COLUMNS
    upward = table.loc["upward-slope"]
    assert upward["published_below_bound"].all() and upward["published_below_thesis_push_off_bound"].all()
    assert (upward["bound_acot"] == bounds["upward-slope"].impulse).all()
    forward = table.loc["forward"]
    assert forward["bound_acot"].isna().all() and not forward["published_below_bound"].any()
    stairs = table.loc["stairs"]  # OP-DC 0.1285 lies above 0.1, D&C-DC 0.039 below both
    assert stairs.loc["OP-DC", "published_below_bound"] == (MINIMUM_ACOT["stairs"]["OP-DC"][0] < 0.1)
    assert stairs.loc["D&C-DC", "published_below_thesis_push_off_bound"]
    assert table.loc[("stairs", "D&C-DC"), "published_below_bound"]
    unknown = tables.published_comparison(minima).set_index(["experiment", "thesis_method"])
    assert unknown["published_below_bound"].isna().all()  # no bounds given: no flag, rather than "not below"


def test_the_command_offers_the_choices_the_bound_and_the_problem_take():
    from gaitbench.cli import bound_command
    from gaitbench.problem.gait_problem import START_POSES
    from gaitbench.solve.bound import PUSH_OFF_COSTS

    assert bound_command.PUSH_OFF_COSTS == PUSH_OFF_COSTS and bound_command.START_POSES == START_POSES
