"""When a tracked robot counts as fallen: the criteria, the integrator's terminal events, and the landing check.

A fall (hip too low, swing foot through the ground or missing it at heel strike, a leg angle out of its bounds)
ends the run and is reported with its step, time and reason. Heel strike is timed by the reference, as in the
thesis (impact at t = T of every step), so the landing is checked instead of detected.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from gaitbench.control.reference import Reference
from gaitbench.model.mechanics import other_leg
from gaitbench.model.terrain import clearance, leg_angle_window
from gaitbench.problem.gait_problem import ProblemOptions
from gaitbench.step_info import StepInfo

FallEvent = Callable[[float, np.ndarray], float]
"""A terminal event of :func:`scipy.integrate.solve_ivp` on the loop's augmented state: positive while upright."""


@dataclass(frozen=True)
class FallCriteria:
    """When the robot counts as fallen.

    ``hip_fraction``: the hip's height above the step's chord line (normal to it, through the stance foot) drops
    below this fraction of the lowest such height the reference asks for in that step (the thesis's long steps
    legitimately bring the hip down to 0.3 l; measured from the chord, not vertically, because on the thesis's
    downward slope the hip goes below the stance foot's level). ``ground_tolerance`` (m): the swing foot goes that
    much deeper below the step's chord line than the reference does, or is that far from the chord line when the
    reference's heel strike comes. Leg angles must stay within the bounds the walk was solved under (its
    ``angle_bounds`` problem option, docs/model.md §4 and §8): the thesis's printed box, or the physical windows in
    which no leg points into the ground; widened to where the reference itself goes (its interpolant may cross a
    bound that is active at the nodes) and by ``ground_tolerance`` / l (a foot that far off at a leg's length).
    """

    hip_fraction: float = 0.5
    ground_tolerance: float = 0.01

    def __post_init__(self) -> None:
        if not 0 <= self.hip_fraction < 1:
            raise ValueError(f"hip_fraction = {self.hip_fraction}: expected a fraction in [0, 1)")
        if not self.ground_tolerance > 0:
            raise ValueError(f"ground_tolerance = {self.ground_tolerance}: expected a positive length in m")


def fall_events(reference: Reference, info: StepInfo, criteria: FallCriteria) -> list[tuple[FallEvent, str]]:
    """The step's terminal fall events, each positive while the robot is fine, with their reasons."""
    ref = reference.step(info)
    st, sw = info.stance - 1, other_leg(info.stance) - 1
    leg = reference.experiment.robot.l
    grid = np.linspace(0.0, info.duration, 20 * len(ref.times))
    desired = np.array([ref.desired(t)[0] for t in grid])
    hip_floor = criteria.hip_fraction * float(np.min(np.cos(desired[:, st] - info.slope)))
    depth = criteria.ground_tolerance / leg
    (st_low, st_high), (sw_low, sw_high) = (
        (min(low, float(desired[:, i].min())) - depth, max(high, float(desired[:, i].max())) + depth)
        for i, (low, high) in zip((st, sw), angle_windows(reference, info), strict=True))

    def angles(t, x):
        return min(x[st] - st_low, st_high - x[st], x[sw] - sw_low, sw_high - x[sw])

    def hip(t, x):
        return math.cos(x[st] - info.slope) - hip_floor

    def ground(t, x):
        q_d = ref.desired(t)[0]
        return clearance(x[st], x[sw], info.slope) - min(0.0, clearance(q_d[st], q_d[sw], info.slope)) + depth

    events = [(angles, "leg angle out of range"), (hip, "hip too low"), (ground, "foot through the ground")]
    for event, _ in events:
        event.terminal, event.direction = True, -1
    return events


def angle_windows(reference: Reference, info: StepInfo) -> tuple[tuple[float, float], tuple[float, float]]:
    """The (low, high) leg-angle bounds of the step's stance leg and swing leg under the walk's ``angle_bounds``: the
    experiment's printed box for ``thesis``, else the physical windows (:func:`leg_angle_window`)."""
    if reference.walk.problem_options.get("angle_bounds", ProblemOptions.angle_bounds) == "thesis":
        box = tuple(reference.experiment.limits.angle_bounds)
        return box, box
    behind = reference.experiment.terrain.ground_behind(info.index)
    return leg_angle_window(info.slope, behind), leg_angle_window(info.slope)


def landing_miss(reference: Reference, info: StepInfo, q: np.ndarray) -> float:
    """How far (m) the swing foot at ``q`` is from the chord line, compared with the reference's, when the
    reference's heel strike comes: beyond ``ground_tolerance`` the foot missed the ground."""
    q_d = reference.step(info).desired(info.duration)[0]
    st, sw = info.stance - 1, other_leg(info.stance) - 1
    miss = abs(clearance(q[st], q[sw], info.slope) - clearance(q_d[st], q_d[sw], info.slope))
    return miss * reference.experiment.robot.l
