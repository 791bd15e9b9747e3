"""Walking terrain as a sequence of footholds, and the step geometry every gait problem shares.

Step i moves the foothold by the chord D_i at inclination θ_i, Δ = D_i (cos θ_i, sin θ_i), with θ > 0 uphill
(thesis §2.4; docs/model.md §4). The heel-strike configuration and the clearance below are written in
that convention; the thesis's own formulas treat θ > 0 as downhill (see docs/deviations.md, H1).

Leg angles are absolute from the vertical, counter-clockwise positive, in "Convention A":
hip = stance foot + l(−sin q_st, cos q_st), swing foot = hip + l(sin q_sw, −cos q_sw).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

from gaitbench.model.robot import InvalidParameterError

THESIS_ANGLE_BOUNDS = (-math.pi / 2, math.pi)
"""Leg-angle bounds −π/2 ≤ q1, q2 ≤ π as printed (thesis §3.6, constraint (10); kept as printed, docs/model.md §8)."""


@dataclass(frozen=True)
class StepGeometry:
    """One step's foothold displacement: chord ``D`` (m) at inclination ``theta`` (rad, > 0 uphill)."""

    D: float
    theta: float

    def __post_init__(self) -> None:
        for name in ("D", "theta"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise InvalidParameterError(f"step {name} = {value!r}: expected a finite number")
        if self.D <= 0:
            raise InvalidParameterError(f"step chord D = {self.D}: must be positive")
        if not -math.pi / 2 < self.theta < math.pi / 2:
            raise InvalidParameterError(
                f"step inclination theta = {self.theta}: must lie in (-pi/2, pi/2), the robot walks along +x"
            )

    @property
    def displacement(self) -> np.ndarray:
        """Foothold displacement D (cos θ, sin θ) in metres."""
        return self.D * np.array([math.cos(self.theta), math.sin(self.theta)])


@dataclass(frozen=True)
class Terrain:
    """The footholds of a walk, one :class:`StepGeometry` per step, starting from the origin.

    Between footholds the ground is the straight chord; behind the first foothold it rises at
    ``start_inclination`` (rad, > 0 uphill; ``None``: the first step's inclination, a walk that starts on its
    slope). Stairs start on a level floor.
    """

    steps: tuple[StepGeometry, ...]
    start_inclination: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "steps", tuple(self.steps))
        if not self.steps:
            raise InvalidParameterError("terrain steps: a terrain needs at least one step")
        for step in self.steps:
            if not isinstance(step, StepGeometry):
                raise InvalidParameterError(f"terrain steps: expected StepGeometry, got {step!r}")
        if self.start_inclination is not None:
            StepGeometry(1.0, self.start_inclination)  # the same range check as a step's

    def ground_behind(self, step: int) -> float:
        """Inclination of the ground behind the stance foot of ``step`` (1-based): the previous chord's."""
        if step == 1:
            return self.steps[0].theta if self.start_inclination is None else float(self.start_inclination)
        return self.steps[step - 2].theta

    def bend(self, step: int) -> str:
        """How the ground bends under the stance foot of ``step``: ``dips`` where the chord ahead is steeper upward
        than the one behind (a valley, through which a leg without a knee cannot swing above the ground, so that
        only the clearance's rounding lets it pass: docs/model.md §4), ``peaks`` the other way, else ``even``."""
        turn = self.steps[step - 1].theta - self.ground_behind(step)
        return "dips" if turn > BEND_TOLERANCE else "peaks" if turn < -BEND_TOLERANCE else "even"

    @classmethod
    def flat(cls, chords: Iterable[float]) -> Terrain:
        return cls.slope(chords, 0.0)

    @classmethod
    def slope(cls, chords: Iterable[float], theta: float) -> Terrain:
        """A uniform slope; each chord is measured along the slope."""
        return cls(tuple(StepGeometry(float(D), float(theta)) for D in chords))

    @classmethod
    def stairs(cls, run_rise_pairs: Iterable[tuple[float, float]]) -> Terrain:
        """Stairs from (run L_i, rise H_i) pairs: D = √(L² + H²), θ = atan2(H, L) (thesis §2.4)."""
        steps = []
        for i, (run, rise) in enumerate(run_rise_pairs, start=1):
            if not (math.isfinite(run) and math.isfinite(rise)) or run <= 0:
                raise InvalidParameterError(
                    f"stair {i} (run, rise) = ({run!r}, {rise!r}): run must be positive and both finite"
                )
            steps.append(StepGeometry(math.hypot(run, rise), math.atan2(rise, run)))
        return cls(tuple(steps), start_inclination=0.0)

    def __len__(self) -> int:
        return len(self.steps)

    def footholds(self) -> np.ndarray:
        """(H+1, 2) foothold positions: row 0 is the start (0, 0), row i where step i lands."""
        displacements = np.array([step.displacement for step in self.steps])
        return np.vstack([np.zeros((1, 2)), np.cumsum(displacements, axis=0)])


def heel_strike_configuration(D: float, theta: float, l: float) -> tuple[float, float]:  # noqa: E741
    """Stance and swing angles (q_st, q_sw) at heel strike of a step with chord D and inclination θ.

    The legs are symmetric about the normal of the chord: α = asin(D / 2l), q_st = θ − α, q_sw = θ + α.
    """
    if l <= 0:
        raise ValueError(f"leg length l = {l}: must be positive")
    if D > 2 * l:
        raise ValueError(f"chord {D:g} m exceeds twice the leg length {2 * l:g} m: the feet cannot reach")
    alpha = math.asin(D / (2 * l))
    return theta - alpha, theta + alpha


def clearance(q_st: Any, q_sw: Any, theta: Any) -> Any:
    """Swing-foot height above the chord line, divided by l: cos(q_st − θ) − cos(q_sw − θ).

    Zero at heel strike; the gait problem requires it > 0 (optionally > a margin) at interior nodes.
    Works on floats, numpy arrays and casadi expressions.
    """
    ns = _namespace(q_st, q_sw, theta)
    return ns.cos(q_st - theta) - ns.cos(q_sw - theta)


BEND_TOLERANCE = 1e-9
"""Inclinations (rad) closer than this are one straight ground."""

TERRAIN_KINK_SMOOTHING = 0.1
"""ε (in leg lengths) over which the ground profile's bend under the stance foot is rounded by default (the problem
option ``clearance_rounding``). Where the ground dips, only this rounding lets a leg without a knee swing through
(:meth:`Terrain.bend`), and a grid must resolve it for the detour it asks to cost the same on every grid: ε is a
few of the swing foot's advances per interval on the coarsest grids a sweep uses, and about a foot's length
(docs/decisions/0019-clearance-rounding.md)."""


def terrain_clearance(q_st: Any, q_sw: Any, theta: Any, theta_behind: Any,
                      eps: float = TERRAIN_KINK_SMOOTHING) -> Any:
    """Swing-foot height over l above the ground profile through the footholds it passes (docs/model.md §4).

    The stance foot stands where the ground bends from ``theta_behind`` (the chord the swing foot comes from) to
    ``theta`` (the chord it lands on). With the foot at (x, y) from the stance foot, in leg lengths, the profile is
    s̄ x + δ |x| with s̄, δ the mean and half-difference of the two chords' slopes: exact on either side. |x| is
    rounded as x tanh(x / ε), exact at the crossing (x = y = 0, where the legs pass each other), nearly so at the
    footholds (|δ| x (1 − tanh(x / ε))), and off by at most 0.28 |δ| ε in between (2 cm for a 1 m leg on the stairs
    at the default ε): conservative where the ground peaks, lenient where it dips. On a uniform slope (δ = 0) this
    is the chord clearance / cos θ.
    """
    ns = _namespace(q_st, q_sw, theta, theta_behind)
    x = ns.sin(q_sw) - ns.sin(q_st)
    y = ns.cos(q_st) - ns.cos(q_sw)
    ahead, behind = ns.tan(theta), ns.tan(theta_behind)
    mean, half_bend = (ahead + behind) / 2, (ahead - behind) / 2
    return y - mean * x - half_bend * x * ns.tanh(x / eps)


def swing_foot_advance(q_st: Any, q_sw: Any, theta: Any) -> Any:
    """Swing-foot position along the chord direction, relative to the stance foot, divided by l.

    sin(q_sw − θ) − sin(q_st − θ); equals D / l at heel strike. Works on floats, numpy arrays and casadi.
    """
    ns = _namespace(q_st, q_sw, theta)
    return ns.sin(q_sw - theta) - ns.sin(q_st - theta)


def _namespace(*values: Any) -> ModuleType:
    """casadi for casadi inputs (numpy ufuncs do not handle SX/MX cleanly), else numpy.

    casadi is imported only when a casadi value arrives, so experiments load without it.
    """
    if any(type(v).__module__.startswith("casadi") for v in values):
        import casadi

        return casadi
    return np


@dataclass(frozen=True)
class StepCheck:
    """Geometric feasibility of one step, before any solve. ``q_st``/``q_sw`` are None when D > 2l."""

    step: int
    D: float
    theta: float
    q_st: float | None
    q_sw: float | None
    problems: list[str]
    """What makes the step infeasible, each without the step's number: a walk's failure adds it once."""

    @property
    def described(self) -> list[str]:
        """The problems each led by "step i:", for lists that span steps."""
        return [f"step {self.step}: {problem}" for problem in self.problems]

    @property
    def ok(self) -> bool:
        return not self.problems


def check_feasibility(
    terrain: Terrain, l: float, angle_bounds: tuple[float, float] | None = None  # noqa: E741
) -> list[StepCheck]:
    """Check every step's heel-strike configuration against reach (D ≤ 2l) and the leg-angle limits.

    ``angle_bounds`` ``None`` (the default) checks the physical limits (docs/model.md §4): at heel strike neither leg
    points into the ground of the step it ends, nor of the step it starts (the same angles begin step i+1). A
    (low, high) pair checks that box instead, e.g. the thesis's printed :data:`THESIS_ANGLE_BOUNDS`. Each
    problem names the violated limit and the numbers behind it (``StepCheck.described`` adds the step).
    """
    if angle_bounds is None:
        return _check_physical(terrain, l)
    lower, upper = angle_bounds
    checks = []
    for i, step in enumerate(terrain.steps, start=1):
        context = f"(D = {step.D:g} m, θ = {step.theta:.3f} rad, l = {l:g} m)"
        if step.D > 2 * l:
            problem = f"chord {step.D:g} m exceeds twice the leg length {2 * l:g} m"
            checks.append(StepCheck(i, step.D, step.theta, None, None, [problem]))
            continue
        q_st, q_sw = heel_strike_configuration(step.D, step.theta, l)
        problems = []
        for role, angle in (("stance", q_st), ("swing", q_sw)):
            if angle < lower:
                problems.append(
                    f"{role} angle at heel strike {angle:.3f} rad is below the lower angle bound "
                    f"{lower:.3f} rad {context}"
                )
            if angle > upper:
                problems.append(
                    f"{role} angle at heel strike {angle:.3f} rad is above the upper angle bound "
                    f"{upper:.3f} rad {context}"
                )
        checks.append(StepCheck(i, step.D, step.theta, q_st, q_sw, problems))
    return checks


def _check_physical(terrain: Terrain, l: float) -> list[StepCheck]:  # noqa: E741
    """Step i's heel-strike angles against the limits of the gait problem (see ``leg_angle_window``): in step i
    as its final angles, and in step i + 1, where the landing leg stands and the other swings."""
    checks = []
    for i, step in enumerate(terrain.steps, start=1):
        if step.D > 2 * l:
            problem = f"chord {step.D:g} m exceeds twice the leg length {2 * l:g} m"
            checks.append(StepCheck(i, step.D, step.theta, None, None, [problem]))
            continue
        q_st, q_sw = heel_strike_configuration(step.D, step.theta, l)
        legs = [("stance", q_st, *leg_angle_window(step.theta, terrain.ground_behind(i))),
                ("swing", q_sw, *leg_angle_window(step.theta))]
        if i < len(terrain.steps):
            ahead = terrain.steps[i].theta
            legs += [(f"landing (step {i + 1}'s stance)", q_sw, *leg_angle_window(ahead, step.theta)),
                     (f"lifting (step {i + 1}'s swing)", q_st, *leg_angle_window(ahead))]
        problems = [
            f"{role} leg at heel strike ({angle:.3f} rad) points into the ground: outside [{low:.3f}, {high:.3f}] rad"
            for role, angle, low, high in legs
            if not low <= angle <= high
        ]
        checks.append(StepCheck(i, step.D, step.theta, q_st, q_sw, problems))
    return checks


def leg_angle_window(theta: float, theta_behind: float | None = None) -> tuple[float, float]:
    """Physical leg-angle limits (docs/model.md §4) in a step of inclination θ.

    With ``theta_behind`` (the stance leg, whose foot stands where the ground bends from θ_behind to θ): the hip
    above the ground, θ − π/2 ≤ q ≤ θ_behind + π/2, which is above both lines in a valley and above either on a
    crest. Without it (the swing leg): pointing down from the hip relative to the chord, |q − θ| ≤ π/2.
    """
    behind = theta if theta_behind is None else theta_behind
    return theta - math.pi / 2, behind + math.pi / 2
