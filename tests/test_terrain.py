import math

import casadi
import numpy as np
import pytest

from gaitbench.model.robot import InvalidParameterError
from gaitbench.model.terrain import (
    TERRAIN_KINK_SMOOTHING,
    THESIS_ANGLE_BOUNDS,
    StepGeometry,
    Terrain,
    check_feasibility,
    clearance,
    heel_strike_configuration,
    leg_angle_window,
    swing_foot_advance,
    terrain_clearance,
)


def convention_a_swing_foot(stance_foot, q_st, q_sw, l):  # noqa: E741
    hip = np.asarray(stance_foot) + l * np.array([-math.sin(q_st), math.cos(q_st)])
    return hip + l * np.array([math.sin(q_sw), -math.cos(q_sw)])


def test_slope_footholds_follow_the_chords_uphill_positive():
    theta = 0.3
    footholds = Terrain.slope([1.0, 0.5], theta).footholds()
    direction = np.array([math.cos(theta), math.sin(theta)])
    np.testing.assert_allclose(footholds, [[0.0, 0.0], direction, 1.5 * direction], atol=1e-15)


def test_stairs_footholds_are_the_cumulative_run_and_rise():
    terrain = Terrain.stairs([(1.0, 0.6), (0.9, -0.8), (0.2, -0.4)])
    expected = [[0, 0], [1.0, 0.6], [1.9, -0.2], [2.1, -0.6]]
    np.testing.assert_allclose(terrain.footholds(), expected, atol=1e-12)
    assert len(terrain) == 3
    assert terrain.steps[0].D == pytest.approx(math.hypot(1.0, 0.6))
    assert terrain.steps[1].theta == pytest.approx(math.atan2(-0.8, 0.9))


def test_flat_terrain_has_zero_inclination():
    terrain = Terrain.flat([0.6, 0.8])
    assert [step.theta for step in terrain.steps] == [0.0, 0.0]
    np.testing.assert_allclose(terrain.footholds()[:, 1], 0.0)


@pytest.mark.parametrize(("D", "theta"), [(0.6, 0.0), (1.7, 0.49), (2.8, -0.677), (1.2806, -0.8961)])
def test_heel_strike_configuration_puts_the_swing_foot_on_the_next_foothold(D, theta):
    l = 1.5  # noqa: E741
    q_st, q_sw = heel_strike_configuration(D, theta, l)
    stance_foot = np.array([0.3, -0.2])
    swing_foot = convention_a_swing_foot(stance_foot, q_st, q_sw, l)
    chord = D * np.array([math.cos(theta), math.sin(theta)])
    np.testing.assert_allclose(swing_foot - stance_foot, chord, atol=1e-12)
    assert clearance(q_st, q_sw, theta) == pytest.approx(0.0, abs=1e-12)
    assert swing_foot_advance(q_st, q_sw, theta) * l == pytest.approx(D)
    assert q_st < theta < q_sw  # stance trails, swing leads


def test_heel_strike_configuration_rejects_a_chord_longer_than_both_legs():
    with pytest.raises(ValueError, match="exceeds twice the leg length"):
        heel_strike_configuration(3.2, 0.0, 1.5)


def test_clearance_is_positive_for_a_swing_foot_above_the_chord_and_matches_geometry():
    l, theta = 1.0, 0.2  # noqa: E741
    q_st, q_sw = 0.1, 0.7  # stance leg near the chord normal, swing leg tilted further: foot is lifted
    foot = convention_a_swing_foot((0.0, 0.0), q_st, q_sw, l)
    normal = np.array([-math.sin(theta), math.cos(theta)])  # upward unit normal of the chord line
    along = np.array([math.cos(theta), math.sin(theta)])
    assert foot @ normal > 0
    assert clearance(q_st, q_sw, theta) == pytest.approx(foot @ normal / l)
    assert swing_foot_advance(q_st, q_sw, theta) == pytest.approx(foot @ along / l)
    assert clearance(0.3, -0.2, 0.0) < 0  # crossed legs the other way round: swing foot below the ground


def test_clearance_and_advance_work_on_numpy_and_casadi():
    q_st = np.array([0.1, -0.2])
    q_sw = np.array([0.3, 0.4])
    np.testing.assert_allclose(clearance(q_st, q_sw, 0.1), np.cos(q_st - 0.1) - np.cos(q_sw - 0.1))
    a, b = casadi.SX.sym("a"), casadi.SX.sym("b")
    f = casadi.Function("f", [a, b], [clearance(a, b, 0.1), swing_foot_advance(a, b, 0.1)])
    c, s = f(0.1, 0.3)
    assert float(c) == pytest.approx(clearance(0.1, 0.3, 0.1))
    assert float(s) == pytest.approx(swing_foot_advance(0.1, 0.3, 0.1))
    x = casadi.MX.sym("x")
    assert isinstance(clearance(x, 0.3, 0.1), casadi.MX)


DOWNWARD = Terrain.slope([2.8, 2.6, 2.3, 2.15, 1.95, 1.8, 1.75, 1.35, 1.15, 1.05, 0.6], -0.677)
STAIRS = Terrain.stairs([(1.0, 0.6), (1.4, 0.6), (1.5, 0.8), (1.2, 0.4), (1.1, 0.5), (0.9, -0.8), (0.8, -1.0),
                         (0.75, -0.7), (0.6, -0.6), (0.5, -0.6), (0.2, -0.4)])


def test_printed_downward_slope_step_1_is_flagged_below_the_thesis_angle_bound():
    terrain = DOWNWARD
    checks = check_feasibility(terrain, 1.5, THESIS_ANGLE_BOUNDS)
    assert len(checks) == 11
    first = checks[0]
    assert not first.ok
    assert first.step == 1
    assert first.q_st == pytest.approx(-1.8806, abs=1e-3)
    assert len(first.problems) == 1
    message = first.problems[0]
    assert message.startswith("stance angle at heel strike -1.881 rad")
    assert "below the lower angle bound -1.571 rad" in message
    assert "D = 2.8 m" in message and "l = 1.5 m" in message
    assert [c.step for c in checks if not c.ok] == [1, 2]


def test_feasibility_reports_a_chord_beyond_reach():
    checks = check_feasibility(Terrain.flat([1.0, 3.2]), 1.5)
    assert checks[0].ok
    assert checks[1].q_st is None and checks[1].q_sw is None
    assert checks[1].described == ["step 2: chord 3.2 m exceeds twice the leg length 3 m"]


def test_feasibility_checks_the_swing_leg_against_the_upper_bound():
    checks = check_feasibility(Terrain.slope([1.0], 1.2), 1.0, angle_bounds=(-1.0, 1.5))
    assert checks[0].problems and "swing angle" in checks[0].problems[0]
    assert "above the upper angle bound 1.500 rad" in checks[0].problems[0]


def test_physical_angle_limits_accept_the_downward_slope_and_the_stairs():
    """docs/model.md §4: −1.88 rad on a −0.677 rad slope is 18° below horizontal where the ground falls at 39°."""
    assert all(check.ok for check in check_feasibility(DOWNWARD, 1.5))
    assert all(check.ok for check in check_feasibility(STAIRS, 1.0))
    assert [c.step for c in check_feasibility(STAIRS, 1.0, THESIS_ANGLE_BOUNDS) if not c.ok] == [7]


def test_physical_angle_limits_refuse_a_leg_that_points_into_the_ground():
    # A steep climb after a steep drop: the landing leg of step 1 leans back into the rising ground of step 2.
    checks = check_feasibility(Terrain((StepGeometry(0.4, -1.2), StepGeometry(1.0, 1.0))), 1.0)
    assert not checks[0].ok and "landing (step 2's stance) leg" in checks[0].problems[0]
    assert check_feasibility(Terrain((StepGeometry(0.4, -1.2), StepGeometry(1.0, -1.0))), 1.0)[0].ok


def test_leg_angle_window_is_the_hip_above_the_ground_where_the_foot_stands():
    for theta, behind in ((0.0, 0.0), (0.4, -0.3), (-0.7, 0.5)):
        low, high = leg_angle_window(theta, behind)
        for q in np.linspace(-3.1, 3.1, 241):
            hip = np.array([-math.sin(q), math.cos(q)])
            ahead_line = hip[1] - math.tan(theta) * hip[0]
            behind_line = hip[1] - math.tan(behind) * hip[0]
            above = ahead_line > 0 if hip[0] > 0 else behind_line > 0
            if abs(q - low) > 1e-9 and abs(q - high) > 1e-9:
                assert above == (low <= q <= high), (theta, behind, q)


@pytest.mark.parametrize(("behind", "ahead"), [(0.0, 0.0), (0.5, -0.7), (-0.6, 0.4), (0.54, 0.54)])
def test_terrain_clearance_is_the_height_above_the_ground_profile(behind, ahead):
    """Height above the two chords meeting at the stance foot, in leg lengths, up to the rounding of the bend."""
    rng = np.random.default_rng(3)
    for q_st, q_sw in rng.uniform(-1.2, 1.2, size=(200, 2)):
        foot = convention_a_swing_foot([0.0, 0.0], q_st, q_sw, 1.0)
        ground = foot[0] * math.tan(ahead if foot[0] > 0 else behind)
        bound = 0.28 * abs(math.tan(ahead) - math.tan(behind)) / 2 * TERRAIN_KINK_SMOOTHING
        assert terrain_clearance(q_st, q_sw, ahead, behind) == pytest.approx(foot[1] - ground, abs=bound + 1e-12)
    assert terrain_clearance(0.3, 0.3, ahead, behind) == pytest.approx(0.0, abs=1e-15)  # legs crossing
    q_st, q_sw = heel_strike_configuration(1.2, ahead, 1.0)
    x = math.sin(q_sw) - math.sin(q_st)  # the rounding's error at the foothold: |δ| x (1 − tanh(x / ε))
    off = abs(math.tan(ahead) - math.tan(behind)) / 2 * x * (1 - math.tanh(x / TERRAIN_KINK_SMOOTHING))
    assert terrain_clearance(q_st, q_sw, ahead, behind) == pytest.approx(0.0, abs=off + 1e-12)  # landing


def test_terrain_clearance_sees_the_stairs_the_chord_does_not():
    """At the start of stairs step 6 (the first step down) the lifting foot stands on the ground of step 5, below
    the line of step 6's descending chord: the chord form calls it buried, the terrain form on the ground."""
    behind, ahead = STAIRS.ground_behind(6), STAIRS.steps[5].theta
    q_sw, q_st = heel_strike_configuration(STAIRS.steps[4].D, behind, 1.0)  # step 5's landing pose, roles swapped
    assert clearance(q_st, q_sw, ahead) < -0.1
    # on the ground up to the rounding's error at a foothold 1.2 l away, |δ| x (1 − tanh(x / ε)) < 1e-9
    assert terrain_clearance(q_st, q_sw, ahead, behind) == pytest.approx(0.0, abs=1e-9)


def _passes_above_unrounded_ground(behind: float, ahead: float) -> bool:
    """Whether some stance-leg angle lets straight legs cross with the swing foot above the unrounded ground on
    both sides of the stance foot (just before and just after the crossing)."""
    for q in np.linspace(-1.5, 1.5, 3001):
        before = terrain_clearance(q, q - 1e-4, ahead, behind, eps=1e-12)
        after = terrain_clearance(q, q + 1e-4, ahead, behind, eps=1e-12)
        if before >= 0 and after >= 0:
            return True
    return False


def test_a_leg_without_a_knee_swings_through_a_peak_but_not_through_a_dip():
    bends = [STAIRS.bend(step) for step in range(1, len(STAIRS.steps) + 1)]
    assert [step for step, bend in enumerate(bends, 1) if bend == "dips"] == [1, 3, 5, 8]
    for step, bend in enumerate(bends, 1):
        behind, ahead = STAIRS.ground_behind(step), STAIRS.steps[step - 1].theta
        assert _passes_above_unrounded_ground(behind, ahead) == (bend != "dips"), step
    assert {DOWNWARD.bend(step) for step in range(1, len(DOWNWARD.steps) + 1)} == {"even"}  # starts on its slope


def test_stairs_start_on_a_level_floor_and_slopes_on_their_slope():
    assert STAIRS.ground_behind(1) == 0.0
    assert DOWNWARD.ground_behind(1) == -0.677
    assert STAIRS.ground_behind(7) == STAIRS.steps[5].theta


def test_all_forward_walking_steps_are_feasible():
    terrain = Terrain.flat([0.6, 0.8, 1.0, 1.4, 1.7, 1.9, 1.6, 1.3, 1.1, 0.8, 0.6])
    assert all(check.ok for check in check_feasibility(terrain, 1.0))


@pytest.mark.parametrize(
    ("D", "theta"), [(0.0, 0.0), (-1.0, 0.0), (float("nan"), 0.0), (1.0, float("inf")), (1.0, 1.6)]
)
def test_invalid_step_geometry_is_rejected(D, theta):
    with pytest.raises(InvalidParameterError):
        StepGeometry(D, theta)


def test_stairs_need_a_positive_run_and_a_terrain_needs_steps():
    with pytest.raises(InvalidParameterError, match="stair 2"):
        Terrain.stairs([(1.0, 0.2), (0.0, 0.5)])
    with pytest.raises(InvalidParameterError, match="at least one step"):
        Terrain.flat([])
