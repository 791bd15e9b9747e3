"""Hybrid simulator: the published passive limit cycle, energy conservation, 2-DOF/4-DOF agreement, failures."""

import numpy as np
import pytest

from gaitbench.model.mechanics import BipedModel
from gaitbench.model.robot import RobotParameters
from gaitbench.model.simulate import OpenLoop, simulate
from gaitbench_plugins.experiments.compass_gait import (
    SLOPE,
    compass_gait_experiment,
    compass_gait_robot,
    passive_limit_cycle,
)

# Goswami, Thuilot and Espiau (1996): post-impact [q_sw, q_st, dq_sw, dq_st] and period on a 3° slope.
PUBLISHED_FIXED_POINT = np.array([-0.3234, 0.2187, -0.3774, -1.0924])
PUBLISHED_PERIOD = 0.7343


def test_passive_compass_gait_limit_cycle_matches_the_published_one():
    cycle = passive_limit_cycle()
    found = np.array([cycle.q_swing, cycle.q_stance, cycle.dq_swing, cycle.dq_stance])
    np.testing.assert_allclose(found, PUBLISHED_FIXED_POINT, atol=1e-3)
    assert cycle.period == pytest.approx(PUBLISHED_PERIOD, abs=1e-3)
    assert cycle.residual < 1e-9


def test_compass_gait_experiment_walks_its_limit_cycle_for_every_step():
    experiment = compass_gait_experiment()
    model = BipedModel(experiment.robot, 2)
    state = experiment.initial_state
    walk = simulate(model, [step.theta for step in experiment.terrain.steps], state[:2], state[4:6])
    assert walk.completed, walk.failure
    assert len(walk.steps) == experiment.n_steps
    for step in walk.steps:
        assert step.duration == pytest.approx(experiment.step_duration, abs=1e-6)
        q_st, q_sw = step.q[-1][step.stance - 1], step.q[-1][2 - step.stance]
        chord = 2 * experiment.robot.l * np.sin((q_sw - q_st) / 2)
        assert chord == pytest.approx(experiment.terrain.steps[0].D, abs=1e-6)
    # After an even number of steps Leg 1 is the stance leg again, at the same post-impact state.
    after = walk.steps[1].heel_strike
    np.testing.assert_allclose(np.r_[after.q, after.dq], np.r_[state[:2], state[4:6]], atol=1e-6)


@pytest.mark.parametrize("dof", [2, 4])
def test_unforced_swing_conserves_energy(dof):
    robot = RobotParameters(m1=7.0, m2=3.0, M=12.0, l=0.9, a=0.35, I1=0.4, I2=0.15)
    model = BipedModel(robot, dof)
    q0 = np.r_[0.25, -0.3, np.zeros(dof - 2)]
    dq0 = np.r_[-1.2, 0.8, np.zeros(dof - 2)]
    walk = simulate(model, [0.0], q0, dq0, max_step_duration=1.0, max_solver_step=0.01)
    step = walk.steps[0]
    energy = np.array([model.total_energy(q, dq, step.stance) for q, dq in zip(step.q, step.dq, strict=True)])
    assert len(energy) > 50
    assert np.ptp(energy) < 1e-7 * np.abs(energy).max()


def test_four_dof_walk_reproduces_two_dof_walk_and_feet_behave():
    robot = compass_gait_robot()
    cycle = passive_limit_cycle()
    q0, dq0 = [cycle.q_stance, cycle.q_swing], [cycle.dq_stance, cycle.dq_swing]
    two = simulate(BipedModel(robot, 2), [SLOPE] * 3, q0, dq0)
    four = simulate(BipedModel(robot, 4), [SLOPE] * 3, q0 + [0, 0], dq0 + [0, 0])
    assert two.completed and four.completed
    for step2, step4 in zip(two.steps, four.steps, strict=True):
        assert step4.duration == pytest.approx(step2.duration, abs=1e-8)
        np.testing.assert_allclose(step4.heel_strike.dq[:2], step2.heel_strike.dq, atol=1e-8)
        assert step4.heel_strike.lift_off_velocity > 0  # the old stance foot leaves the ground
        assert step4.ground_reaction[:, 1].min() > 0  # the stance foot is pressed on the ground
    # The stance foot of step k+1 is where the swing foot of step k landed: one chord further down the slope.
    footholds = np.array([step.q[0, 2:] for step in four.steps])
    np.testing.assert_allclose(
        np.diff(footholds, axis=0),
        [[cycle.chord * np.cos(SLOPE), cycle.chord * np.sin(SLOPE)]] * 2,
        atol=1e-8,
    )


def test_push_off_energy_is_recorded_and_feeds_the_heel_strike():
    robot = compass_gait_robot()
    cycle = passive_limit_cycle()
    walk = simulate(
        BipedModel(robot, 4),
        [SLOPE],
        [cycle.q_stance, cycle.q_swing, 0, 0],
        [cycle.dq_stance, cycle.dq_swing, 0, 0],
        OpenLoop(lambda t, step: [0.0, 0.0], [4.0]),
    )
    step = walk.steps[0]
    model = BipedModel(robot, 4)
    gain = model.kinetic_energy(step.q[-1], step.dq_after_push_off, 1) - model.kinetic_energy(
        step.q[-1], step.dq[-1], 1
    )
    assert step.push_off_energy == pytest.approx(gain) and gain > 0
    kinds = [event["kind"] for event in walk.events]
    assert kinds == ["push-off", "heel-strike"]


def test_a_step_without_heel_strike_fails_with_its_number_and_keeps_earlier_steps():
    robot = compass_gait_robot()
    cycle = passive_limit_cycle()

    def torques(t, step):  # 60 N·m on Leg 1, the swing leg of step 2, spins it past any heel strike
        return [0.0, 0.0] if step == 1 else [60.0, 0.0]

    walk = simulate(
        BipedModel(robot, 2),
        [SLOPE] * 3,
        [cycle.q_stance, cycle.q_swing],
        [cycle.dq_stance, cycle.dq_swing],
        OpenLoop(torques),
        max_step_duration=1.5,
    )
    assert not walk.completed
    assert walk.failure.startswith("step 2:")
    assert len(walk.steps) == 2 and walk.steps[0].heel_strike is not None


def test_clocked_step_integrates_piecewise_constant_torques_from_each_interval_own_side():
    """DMOC's torques jump at the nodes: the clocked re-simulation must use interval k's torque on all of [t_k, t_k+1],
    which a reference built from one constant-torque integration per interval pins down, and must not read the
    next interval's torque at a piece's end, where the jump would make DOP853 reject step after step."""
    from scipy.integrate import solve_ivp

    robot = RobotParameters(m1=7.0, m2=3.0, M=12.0, l=0.9, a=0.35, I1=0.4, I2=0.15)
    model = BipedModel(robot, 2)
    times = np.linspace(0.0, 0.3, 7)
    torques = np.array([[3.0, -2.0], [-4.0, 1.0], [2.5, 2.5], [-1.0, -3.0], [0.5, 4.0], [-2.0, 0.0]])
    reads = []

    def piecewise(t, step):  # at a node, the next interval's value, as a DMOC interpolant gives it
        reads.append(t)
        return torques[min(int(np.searchsorted(times, t, side="right")) - 1, len(torques) - 1)]

    q0, dq0 = np.array([0.25, -0.3]), np.array([-1.2, 0.8])
    walk = simulate(model, [0.0], q0, dq0, OpenLoop(piecewise), step_times=[times])
    assert walk.completed, walk.failure
    # Read inside each piece: 163 torque evaluations here; read at the piece's end, 3283.
    assert len(reads) < 50 * len(torques)

    x, reference = np.r_[q0, dq0], [np.r_[q0, dq0]]
    for (a, b), tau in zip(zip(times[:-1], times[1:], strict=True), torques, strict=True):
        def rhs(t, state, tau=tau):
            return np.r_[state[2:], model.forward_dynamics(state[:2], state[2:], tau, 1)[0]]
        x = solve_ivp(rhs, (a, b), x, method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1]
        reference.append(x)
    step = walk.steps[0]
    np.testing.assert_allclose(np.hstack([step.q, step.dq]), np.array(reference), atol=1e-8)
    np.testing.assert_allclose(step.t, times)
