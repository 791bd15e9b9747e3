"""A biped model bound to one robot: numeric evaluation for simulation, symbolic for transcriptions."""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from gaitbench.model.mechanics.biped import BipedFunctions, biped_functions
from gaitbench.model.numeric import NumericFunction
from gaitbench.model.robot import RobotParameters


@dataclass(frozen=True)
class HeelStrike:
    """Result of the end-of-step events, in the coordinates of the next step (roles swapped)."""

    q: np.ndarray  # configuration at the start of the next step
    dq: np.ndarray  # velocities just after impact, new stance foot at rest
    impulse: np.ndarray  # impact impulse on the striking foot (x, y), N·s
    lift_off_velocity: (
        float  # vertical velocity of the old stance foot after impact (4-DOF); > 0 lifts off on level ground only:
    )  # on a slope lifting off is along the ground's normal (docs/model.md §3), from lifting_foot_velocity
    lifting_foot_velocity: np.ndarray | None = None  # (x, y) velocity of the old stance foot after impact (4-DOF)


def other_leg(stance: int) -> int:
    return 2 if stance == 1 else 1


class BipedModel:
    """The thesis's planar biped with ``dof`` = 2 (stance foot pinned) or 4 (stance-foot coordinates q3, q4).

    Methods take the stance leg's label (1 or 2) because the dynamics of the two stance cases differ when the
    legs differ. Arguments may be numbers/arrays (numpy results) or CasADi symbols (symbolic results).
    """

    def __init__(self, robot: RobotParameters, dof: int) -> None:
        self.robot = robot
        self.dof = dof
        self.parameters = robot.vector()
        self._functions = {stance: biped_functions(dof, stance) for stance in (1, 2)}
        self._numeric: dict[tuple[str, int], NumericFunction] = {}

    def functions(self, stance: int) -> BipedFunctions:
        """The raw CasADi functions (parameters as last input) for building NLPs."""
        return self._functions[stance]

    def _eval(self, name: str, stance: int, *args):
        fn = getattr(self._functions[stance], name)
        if fn is None:
            raise NotImplementedError(f"the {self.dof}-DOF model has no {name.replace('_', ' ')}")
        if any(isinstance(arg, (ca.SX, ca.MX)) for arg in args):
            return fn(*args, self.parameters)
        key = (name, stance)
        if key not in self._numeric:  # simulators call these thousands of times: evaluate through buffers
            self._numeric[key] = NumericFunction(fn)
        return self._numeric[key](*args, self.parameters)

    def mass_matrix(self, q, stance: int):
        return self._eval("mass", stance, q)

    def coriolis_matrix(self, q, dq, stance: int):
        return self._eval("coriolis", stance, q, dq)

    def gravity_vector(self, q, stance: int):
        return self._eval("gravity", stance, q)

    def mass_matrix_derivative(self, q, dq, stance: int):
        return self._eval("mass_derivative", stance, q, dq)

    def input_matrix(self) -> np.ndarray:
        """Generalized forces of the two hip torques: they act directly on the absolute angles (B_a, thesis)."""
        return np.eye(self.dof, 2)

    def kinetic_energy(self, q, dq, stance: int):
        return _scalar(self._eval("kinetic_energy", stance, q, dq))

    def potential_energy(self, q, stance: int):
        return _scalar(self._eval("potential_energy", stance, q))

    def total_energy(self, q, dq, stance: int):
        return self.kinetic_energy(q, dq, stance) + self.potential_energy(q, stance)

    def hip_position(self, q, stance: int):
        return self._eval("hip", stance, q)

    def swing_foot_position(self, q, stance: int):
        return self._eval("swing_foot", stance, q)

    def forward_dynamics(self, q, dq, tau, stance: int):
        """Accelerations and the stance-foot ground reaction (horizontal f_x, vertical f_y: world axes, not the
        ground's); zero reaction for 2 DOF."""
        return self._eval("forward_dynamics", stance, q, dq, tau)

    def angular_momentum_about_swing_foot(self, q, dq, stance: int):
        return _scalar(self._eval("angular_momentum_about_swing_foot", stance, q, dq))

    def push_off(self, q, dq, impulse, stance: int):
        """Velocities after a push-off impulse along the stance leg, and the kinetic energy it added."""
        dq_plus = self._eval("push_off", stance, q, dq, impulse)
        energy = self.kinetic_energy(q, dq_plus, stance) - self.kinetic_energy(q, dq, stance)
        return dq_plus, energy

    def heel_strike(self, q, dq, stance: int) -> HeelStrike:
        """Plastic impact at the swing foot followed by the role swap; the next step has the other stance leg.

        For 4 DOF the next step's stance foot (q3, q4) is the impact point and starts at rest; for 2 DOF the
        configuration is unchanged and the next stance foot is again the origin.
        """
        q = np.asarray(q, dtype=float)
        dq_plus, impulse = self._eval("heel_strike", stance, q, dq)
        if self.dof == 2:
            return HeelStrike(q=q.copy(), dq=dq_plus, impulse=impulse, lift_off_velocity=float("nan"))
        foot = self.swing_foot_position(q, stance)
        q_next = np.concatenate([q[:2], foot])
        dq_next = np.concatenate([dq_plus[:2], np.zeros(2)])
        return HeelStrike(q=q_next, dq=dq_next, impulse=impulse, lift_off_velocity=float(dq_plus[3]),
                          lifting_foot_velocity=np.asarray(dq_plus[2:4], dtype=float))


def _scalar(value):
    if isinstance(value, np.ndarray):
        return float(value.reshape(-1)[0])
    return value
