"""The passive compass-gait walker (Goswami, Thuilot and Espiau, 1996) as an experiment.

Its steps are not typed in: the passive limit cycle on the 3° slope is found by shooting (Newton on the
step-to-step map of the unactuated 2-DOF model), and each step gets the cycle's chord length and period and
starts from its fixed point. A gait optimizer should find zero energy here, which makes it a sharp check.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.optimize import root

from gaitbench import Registration, hookimpl

LEG_MASS = 5.0  # kg
HIP_MASS = 10.0  # kg
LEG_LENGTH = 1.0  # m, with a = b = 0.5 m and point-mass legs (no inertia about the leg CoM)
SLOPE = -math.radians(3.0)  # downhill (θ > 0 is uphill, docs/model.md §4)
STEPS = 11
INITIAL_GUESS = (0.27, -1.1, -0.4)  # half inter-leg angle, stance and swing rates: only a starting point


@dataclass(frozen=True)
class LimitCycle:
    """Post-impact fixed point in role order (stance, swing) and the step period."""

    q_stance: float
    q_swing: float
    dq_stance: float
    dq_swing: float
    period: float
    residual: float

    @property
    def chord(self) -> float:
        return 2 * LEG_LENGTH * math.sin((self.q_stance - self.q_swing) / 2)


def compass_gait_robot():
    from gaitbench.model.robot import RobotParameters

    return RobotParameters(m1=LEG_MASS, m2=LEG_MASS, M=HIP_MASS, l=LEG_LENGTH, a=0.5, I1=0.0, I2=0.0)


@lru_cache(maxsize=1)
def passive_limit_cycle(tolerance: float = 1e-10) -> LimitCycle:
    """Shoot for the fixed point of the passive step-to-step map on the slope."""
    from gaitbench.model.mechanics import BipedModel
    from gaitbench.model.simulate import simulate

    model = BipedModel(compass_gait_robot(), 2)

    def one_step(z):
        half_angle, dq_stance, dq_swing = z
        q0 = [SLOPE + half_angle, SLOPE - half_angle]  # post-impact: on the slope line, Leg 1 in front
        walk = simulate(model, [SLOPE], q0, [dq_stance, dq_swing], rtol=1e-12, atol=1e-12)
        if walk.failure:
            raise RuntimeError(f"compass-gait shooting: {walk.failure}")
        step = walk.steps[0]
        after = step.heel_strike
        # Roles swap: Leg 2 is now the stance leg.
        return np.array([after.q[1] - SLOPE, after.dq[1], after.dq[0]]), step.duration

    solution = root(lambda z: one_step(z)[0] - z, INITIAL_GUESS, method="hybr", tol=tolerance)
    if not solution.success:
        raise RuntimeError(f"compass-gait shooting did not converge: {solution.message}")
    image, period = one_step(solution.x)
    half_angle, dq_stance, dq_swing = solution.x
    return LimitCycle(
        q_stance=float(SLOPE + half_angle),
        q_swing=float(SLOPE - half_angle),
        dq_stance=float(dq_stance),
        dq_swing=float(dq_swing),
        period=float(period),
        residual=float(np.max(np.abs(image - solution.x))),
    )


def compass_gait_experiment():
    from gaitbench.model.experiment import Experiment
    from gaitbench.model.terrain import Terrain

    cycle = passive_limit_cycle()
    return Experiment(
        name="compass-gait",
        description="Passive compass gait on a 3° downhill slope; steps follow its computed limit cycle",
        robot=compass_gait_robot(),
        terrain=Terrain.slope([cycle.chord] * STEPS, SLOPE),
        initial_state=np.array([cycle.q_stance, cycle.q_swing, 0, 0, cycle.dq_stance, cycle.dq_swing, 0, 0]),
        step_duration=cycle.period,
        source="Goswami, Thuilot and Espiau (1996); fixed point and period computed by shooting at build time",
    )


@hookimpl
def register_experiments():
    return [
        Registration(
            "compass-gait",
            "Passive compass gait, 3° downhill, 5/10/5 kg, 1 m legs; steps from its passive limit cycle",
            compass_gait_experiment,
        )
    ]
