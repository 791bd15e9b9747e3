"""Physics invariants of the symbolic biped model; each would catch a wrong sign or a transcription error."""

import numpy as np
import pytest

from gaitbench.model.mechanics import BipedModel
from gaitbench.model.robot import InvalidParameterError, RobotParameters

THESIS_FORWARD = RobotParameters(m1=20, m2=20, M=40, l=1.0, a=0.5)
# Unequal legs and off-centre masses: symmetric robots can hide index mistakes.
LOPSIDED = RobotParameters(m1=7.0, m2=3.0, M=12.0, l=0.9, a=0.35, I1=0.4, I2=0.15)
ROBOTS = [THESIS_FORWARD, LOPSIDED]
rng = np.random.default_rng(7)


def random_state(dof):
    q = np.concatenate([rng.uniform(-0.8, 0.8, 2), rng.uniform(-1, 1, dof - 2)])
    return q, rng.uniform(-2, 2, dof)


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("dof", [2, 4])
@pytest.mark.parametrize("stance", [1, 2])
def test_mass_matrix_symmetric_positive_definite(robot, dof, stance):
    model = BipedModel(robot, dof)
    for _ in range(10):
        q, _ = random_state(dof)
        mass = model.mass_matrix(q, stance)
        np.testing.assert_allclose(mass, mass.T, atol=1e-12)
        assert np.linalg.eigvalsh(mass).min() > 0


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("dof", [2, 4])
@pytest.mark.parametrize("stance", [1, 2])
def test_mass_derivative_minus_twice_coriolis_is_skew(robot, dof, stance):
    model = BipedModel(robot, dof)
    for _ in range(10):
        q, dq = random_state(dof)
        dmass = model.mass_matrix_derivative(q, dq, stance)
        # Ṁ itself checked against a finite difference of M along q̇.
        h = 1e-6
        numeric = (model.mass_matrix(q + h * dq, stance) - model.mass_matrix(q - h * dq, stance)) / (2 * h)
        np.testing.assert_allclose(dmass, numeric, atol=1e-6)
        skew = dmass - 2 * model.coriolis_matrix(q, dq, stance)
        np.testing.assert_allclose(skew, -skew.T, atol=1e-10)


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("stance", [1, 2])
def test_pinned_four_dof_model_reproduces_two_dof_model(robot, stance):
    two, four = BipedModel(robot, 2), BipedModel(robot, 4)
    for _ in range(10):
        q, dq = random_state(2)
        tau = rng.uniform(-50, 50, 2)
        foot = rng.uniform(-3, 3, 2)
        ddq2, _ = two.forward_dynamics(q, dq, tau, stance)
        ddq4, _ = four.forward_dynamics(np.r_[q, foot], np.r_[dq, 0, 0], tau, stance)
        np.testing.assert_allclose(ddq4[:2], ddq2, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(ddq4[2:], 0, atol=1e-9)


def _centre_of_mass(model, q, stance):
    robot = model.robot
    foot = np.asarray(q[2:4])
    hip = model.hip_position(q, stance)
    swing = model.swing_foot_position(q, stance)
    m_st, m_sw = (robot.m1, robot.m2) if stance == 1 else (robot.m2, robot.m1)
    com_st = foot + robot.a / robot.l * (hip - foot)
    com_sw = hip + robot.b / robot.l * (swing - hip)
    return (m_st * com_st + robot.M * hip + m_sw * com_sw) / robot.total_mass


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("stance", [1, 2])
def test_ground_reaction_is_newtons_law_for_the_whole_robot(robot, stance):
    """f = m_total · (CoM acceleration) + (0, m_total g): the exact multiplier, not the thesis's (3.39)."""
    model = BipedModel(robot, 4)
    q, dq = random_state(4)
    dq[2:] = 0
    tau = rng.uniform(-30, 30, 2)
    ddq, reaction = model.forward_dynamics(q, dq, tau, stance)
    h = 1e-4
    # CoM acceleration by a second-order Taylor step of the configuration along the motion.
    com = [_centre_of_mass(model, q + s * h * dq + 0.5 * (s * h) ** 2 * ddq, stance) for s in (-1, 0, 1)]
    acceleration = (com[2] - 2 * com[1] + com[0]) / h**2
    expected = robot.total_mass * acceleration + np.array([0, robot.total_mass * robot.g])
    np.testing.assert_allclose(reaction, expected, rtol=1e-5, atol=1e-3)


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("stance", [1, 2])
def test_heel_strike_conserves_momentum_about_impact_point_and_stops_new_stance_foot(robot, stance):
    model = BipedModel(robot, 4)
    functions = model.functions(stance)
    for _ in range(5):
        q, dq = random_state(4)
        dq_plus, _ = functions.heel_strike(q, dq, model.parameters)
        dq_plus = np.asarray(dq_plus).ravel()
        before = model.angular_momentum_about_swing_foot(q, dq, stance)
        after = model.angular_momentum_about_swing_foot(q, dq_plus, stance)
        assert after == pytest.approx(before, rel=1e-10, abs=1e-10)
        jacobian = np.asarray(functions.swing_foot_jacobian(q, model.parameters))
        np.testing.assert_allclose(jacobian @ dq_plus, 0, atol=1e-10)
        strike = model.heel_strike(q, dq, stance)
        np.testing.assert_allclose(strike.q[2:], model.swing_foot_position(q, stance))
        np.testing.assert_allclose(strike.dq[2:], 0)
        # A plastic impact never creates kinetic energy.
        assert model.kinetic_energy(q, dq_plus, stance) <= model.kinetic_energy(q, dq, stance) + 1e-9


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("stance", [1, 2])
def test_two_dof_angular_momentum_map_equals_four_dof_impact(robot, stance):
    two, four = BipedModel(robot, 2), BipedModel(robot, 4)
    for _ in range(5):
        q, dq = random_state(2)
        strike2 = two.heel_strike(q, dq, stance)
        strike4 = four.heel_strike(np.r_[q, 0, 0], np.r_[dq, 0, 0], stance)
        np.testing.assert_allclose(strike2.dq, strike4.dq[:2], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(strike2.impulse, strike4.impulse, rtol=1e-8, atol=1e-8)


def test_two_dof_impact_map_matches_a_hand_check():
    """A hand check of the impact map (2.24)–(2.26): a = b = 0.5, l = 1, m = 20, M = 40, I = 20/12 at
    q = (−0.2187, 0.2187)."""
    model = BipedModel(THESIS_FORWARD, 2)
    q = np.array([-0.2187, 0.2187])
    matrix = np.column_stack([model.heel_strike(q, e, 1).dq for e in np.eye(2)])
    np.testing.assert_allclose(matrix, [[0.745, -0.083], [0.917, -0.061]], atol=6e-4)


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("stance", [1, 2])
def test_push_off_adds_exactly_the_reported_energy(robot, stance):
    model = BipedModel(robot, 4)
    q, dq = random_state(4)
    dq[2:] = 0
    impulse = 35.0
    dq_plus, energy = model.push_off(q, dq, impulse, stance)
    gain = model.kinetic_energy(q, dq_plus, stance) - model.kinetic_energy(q, dq, stance)
    assert energy == pytest.approx(gain, rel=1e-12)
    # Independent check: an impulse does work F · (mean of the point's velocity before and after).
    q_st = q[stance - 1]
    direction = np.array([0, 0, -np.sin(q_st), np.cos(q_st)])
    assert energy == pytest.approx(impulse * direction @ (dq + dq_plus) / 2, rel=1e-9)


@pytest.mark.parametrize("dof", [2, 4])
def test_stance_cases_are_mirror_images_under_leg_relabelling(dof):
    """Case 2 of a robot equals case 1 of the robot with its legs' labels swapped, coordinates permuted."""
    robot = LOPSIDED
    swapped = RobotParameters(
        m1=robot.m2, m2=robot.m1, M=robot.M, l=robot.l, a=robot.a, I1=robot.inertia2, I2=robot.inertia1
    )
    case2, case1 = BipedModel(robot, dof), BipedModel(swapped, dof)
    perm = np.eye(dof)
    perm[[0, 1]] = perm[[1, 0]]
    for _ in range(5):
        q, dq = random_state(dof)
        tau = rng.uniform(-20, 20, 2)
        np.testing.assert_allclose(
            case2.mass_matrix(q, 2), perm @ case1.mass_matrix(perm @ q, 1) @ perm, atol=1e-12
        )
        ddq2, f2 = case2.forward_dynamics(q, dq, tau, 2)
        ddq1, f1 = case1.forward_dynamics(perm @ q, perm @ dq, tau[::-1], 1)
        np.testing.assert_allclose(ddq2, perm @ ddq1, atol=1e-9)
        np.testing.assert_allclose(f2, f1, atol=1e-9)
        np.testing.assert_allclose(
            case2.heel_strike(q, dq, 2).dq, perm @ case1.heel_strike(perm @ q, perm @ dq, 1).dq, atol=1e-9
        )


def test_model_functions_accept_symbols():
    import casadi as ca

    model = BipedModel(THESIS_FORWARD, 4)
    q, dq, tau = ca.SX.sym("q", 4), ca.SX.sym("dq", 4), ca.SX.sym("tau", 2)
    ddq, reaction = model.forward_dynamics(q, dq, tau, 1)
    assert isinstance(ddq, ca.SX) and ddq.shape == (4, 1) and reaction.shape == (2, 1)


@pytest.mark.parametrize(
    ("field", "kwargs"),
    [
        ("m1", dict(m1=-1.0)),
        ("a", dict(a=1.0)),
        ("a", dict(a=1.5)),
        ("M", dict(M=float("nan"))),
        ("I2", dict(I2=-0.1)),
        ("l", dict(l=0.0, a=0.0)),
    ],
)
def test_impossible_robot_parameters_are_rejected_naming_the_field(field, kwargs):
    values = dict(m1=20, m2=20, M=40, l=1.0, a=0.5) | kwargs
    with pytest.raises(InvalidParameterError, match=rf"\b{field}\b"):
        RobotParameters(**values)
