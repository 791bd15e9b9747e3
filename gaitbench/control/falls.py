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
from gaitbench.model.terrain import clearance
from gaitbench.step_info import StepInfo

FallEvent = Callable[[float, np.ndarray], float]
"""A terminal event of :func:`scipy.integrate.solve_ivp` on the loop's augmented state: positive while upright."""


@dataclass(frozen=True)
class FallCriteria:
    """When the robot counts as fallen.

    ``hip_fraction``: the hip's height above the stance foot drops below this fraction of the lowest height the
    reference asks for in that step (the thesis's long steps legitimately bring the hip down to 0.3 l).
    ``ground_tolerance`` (m): the swing foot goes that much deeper below the step's chord line than the reference
    does, or is that far from the chord line when the reference's heel strike comes. Leg angles must stay within
    the experiment's angle bounds (docs/model.md §8).
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
    lower, upper = reference.experiment.limits.angle_bounds
    st, sw = info.stance - 1, other_leg(info.stance) - 1
    leg = reference.experiment.robot.l
    grid = np.linspace(0.0, info.duration, 20 * len(ref.times))
    hip_floor = criteria.hip_fraction * min(math.cos(ref.desired(t)[0][st]) for t in grid)
    depth = criteria.ground_tolerance / leg

    def angles(t, x):
        return min(x[0] - lower, x[1] - lower, upper - x[0], upper - x[1])

    def hip(t, x):
        return math.cos(x[st]) - hip_floor

    def ground(t, x):
        q_d = ref.desired(t)[0]
        return clearance(x[st], x[sw], info.slope) - min(0.0, clearance(q_d[st], q_d[sw], info.slope)) + depth

    events = [(angles, "leg angle out of range"), (hip, "hip too low"), (ground, "foot through the ground")]
    for event, _ in events:
        event.terminal, event.direction = True, -1
    return events


def landing_miss(reference: Reference, info: StepInfo, q: np.ndarray) -> float:
    """How far (m) the swing foot at ``q`` is from the chord line, compared with the reference's, when the
    reference's heel strike comes: beyond ``ground_tolerance`` the foot missed the ground."""
    q_d = reference.step(info).desired(info.duration)[0]
    st, sw = info.stance - 1, other_leg(info.stance) - 1
    miss = abs(clearance(q[st], q[sw], info.slope) - clearance(q_d[st], q_d[sw], info.slope))
    return miss * reference.experiment.robot.l
