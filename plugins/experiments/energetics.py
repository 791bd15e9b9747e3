"""The virtual bipeds of the thesis's energetics study (§5.6), as one experiment with options.

``energetics`` walks ``steps`` equal steps (chord D, slope θ) with a biped whose mass and length distributions
are the study's ratios Rm = m_leg / M and Rl = b / l (thesis (5.1)). The thesis says its
parameters are non-dimensional (§5.6) but not how; these are the gaitbench choices:

- length: leg length l = 1 m; ``step_length`` is the chord D in units of l (so D ≤ 2).
- mass: total mass M + 2 m = 80 kg, the forward experiment's robot, so M = 80 / (1 + 2 Rm) and m = Rm M. The COT
  does not depend on the mass scale, but the NLP's smoothing ε (in W) and the solvers' tolerances are absolute,
  so the study's bipeds keep the thesis robots' scale. Rm = Rl = 0.5 is the forward experiment's robot.
- speed: ``speed`` V in units of √(g l) (the Froude scaling of walking), g = 9.81 m/s²; the step duration is
  T = D l / (V √(g l)). The thesis's own experiments (D ≈ 1 m, l = 1 m, T = 0.7343 s) walk at V ≈ 0.43, between
  the study's V = 0.4 and 0.6 (§5.6).
- slope: ``slope`` θ in degrees, > 0 uphill; every step has the same chord and slope.
- Rl sets a = l (1 − Rl); inertias m l²/12 (docs/model.md §1). No friction disturbance (the study compares gaits).

The initial state is the symmetric configuration just after a heel strike of a step of the same length, Leg 1
in stance: q1 = θ + α, q2 = θ − α with α = asin(D / 2). Its rates are the thesis's: its four initial states are
scaled copies of one base state, q̇1 = −4.995 q1 and q̇2 = −1.7256 q1 at T = 0.7343 s (derived from §5.2–5.5); here
q̇1 = −3.668 α / T and q̇2 = −1.267 α / T, the same shape scaled to the step's angle and duration.
"""

from __future__ import annotations

import math

from gaitbench import Registration, hookimpl

LEG_LENGTH = 1.0
"""l in m: the length unit of the study."""
TOTAL_MASS = 80.0
"""M + 2 m in kg: the forward experiment's robot."""
THESIS_RATE_SHAPE = (-4.995 * 0.7343, -1.7256 * 0.7343)
"""(q̇1, q̇2) · T / α of the thesis's initial states (derived from §5.2–5.5)."""

DESCRIPTION = ("Energetics study biped (thesis §5.6): options mass_ratio Rm, length_ratio Rl, speed V (√(g l)), "
               "step_length D (l), slope (deg), steps")


def energetics(mass_ratio: float = 0.5, length_ratio: float = 0.5, speed: float = 0.4, step_length: float = 0.8,
               slope: float = 0.0, steps: int = 11):
    """A biped with leg/hip mass ratio ``mass_ratio`` and CoM-to-hip ratio ``length_ratio`` walking ``steps``
    steps of chord ``step_length`` (in leg lengths) on a ``slope`` (degrees) at ``speed`` (in √(g l)).

    Raises ValueError, naming the option, for values out of range or a geometry the leg-angle bounds forbid.
    """
    from gaitbench.model.experiment import Experiment, Limits
    from gaitbench.model.robot import G_CONST, RobotParameters
    from gaitbench.model.terrain import Terrain

    for name, value in (("mass_ratio", mass_ratio), ("length_ratio", length_ratio), ("speed", speed),
                        ("step_length", step_length), ("slope", slope)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"energetics: {name} = {value!r}: expected a finite number")
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise ValueError(f"energetics: steps = {steps!r}: expected a positive integer")
    if mass_ratio <= 0:
        raise ValueError(f"energetics: mass_ratio = {mass_ratio}: Rm = m_leg / M must be positive")
    if not 0 < length_ratio < 1:
        raise ValueError(f"energetics: length_ratio = {length_ratio}: Rl = b / l must lie strictly between 0 "
                         "and 1 (the leg's centre of mass is between hip and foot)")
    if speed <= 0:
        raise ValueError(f"energetics: speed = {speed}: must be positive")
    if not 0 < step_length < 2:
        raise ValueError(f"energetics: step_length = {step_length}: the chord must lie strictly between 0 and 2 "
                         "leg lengths (the feet cannot reach further)")
    if not -90 < slope < 90:
        raise ValueError(f"energetics: slope = {slope}: expected degrees in (-90, 90)")

    l = LEG_LENGTH  # noqa: E741
    hip = TOTAL_MASS / (1 + 2 * mass_ratio)
    leg = mass_ratio * hip
    robot = RobotParameters(m1=leg, m2=leg, M=hip, l=l, a=l * (1 - length_ratio))
    theta = math.radians(slope)
    chord = step_length * l
    duration = chord / (speed * math.sqrt(G_CONST * l))
    alpha = math.asin(chord / (2 * l))
    rates = [shape * alpha / duration for shape in THESIS_RATE_SHAPE]
    limits = Limits()
    if max(abs(rate) for rate in rates) > limits.dq_max:
        raise ValueError(f"energetics: the initial leg rates {rates[0]:.3g}, {rates[1]:.3g} rad/s exceed the "
                         f"velocity limit {limits.dq_max:g} rad/s (step duration {duration:.3g} s is too short)")
    parameters = (f"Rm = {mass_ratio:g}, Rl = {length_ratio:g}, V = {speed:g}, D = {step_length:g} l, "
                  f"θ = {slope:g}°, {steps} steps")
    experiment = Experiment(
        name="energetics",
        description=f"Energetics study biped: {parameters}; M = {hip:.4g} kg, m = {leg:.4g} kg, l = {l:g} m, "
                    f"step duration {duration:.4g} s",
        robot=robot,
        terrain=Terrain.slope([chord] * steps, theta),
        initial_state=[theta + alpha, theta - alpha, 0.0, 0.0, rates[0], rates[1], 0.0, 0.0],
        step_duration=duration,
        friction=None,
        limits=limits,
        source="thesis §5.6 Energetics: Rm, Rl (5.1); normalization, mass scale and "
               "initial state are gaitbench choices (plugins/experiments/energetics.py)",
    )
    problems = [problem for check in experiment.feasibility() for problem in check.described]
    if problems:
        raise ValueError(f"energetics ({parameters}): infeasible geometry: {problems[0]}")
    return experiment


@hookimpl
def register_experiments():
    return [Registration("energetics", DESCRIPTION, energetics)]
