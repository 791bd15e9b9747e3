"""The reference a tracking run follows: each solved step of a walk as twice-differentiable desired leg angles.

The reference of a step is the transcription's own interpolant of the stored solution (cubic Hermite for
Hermite–Simpson, the cubic of DMOC, the quadratic of trapezoidal collocation, ...), refitted exactly as a
polynomial per grid interval. The desired angles are its positions; the desired velocities and accelerations are
their exact time derivatives, so the reference is twice differentiable as computed torque requires (thesis §4.1.2). At
the nodes the derivative equals the stored velocity, which is what makes exact tracking possible across steps.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gaitbench.control.dynamics import inverse_dynamics
from gaitbench.model.energetics import cost_of_transport, hip_energy, hip_power
from gaitbench.model.experiment import Experiment
from gaitbench.model.mechanics import BipedModel
from gaitbench.plugins import PluginRegistry, load_registry
from gaitbench.problem.gait_problem import ProblemOptions
from gaitbench.problem.objective import NET_POWER
from gaitbench.problem.trajectory import StepTrajectory
from gaitbench.solve.verify import trajectory_cost
from gaitbench.solve.walk_file import load_walk
from gaitbench.step_info import StepInfo
from gaitbench.walk_types import WalkResult


class TrackingInputError(ValueError):
    """A walk that cannot be tracked (no solved step, or an interpolant the reference cannot differentiate)."""


@dataclass
class ReferenceStep:
    """One step of the reference: piecewise polynomials of the desired leg angles on the transcription's grid."""

    info: StepInfo
    times: np.ndarray  # node times, local
    coefficients: np.ndarray  # (N − 1, degree + 1, 2): q_d = Σ_j c_j s^j on interval k, s = (t − t_k) / h
    q_nodes: np.ndarray
    dq_nodes: np.ndarray
    torque: Callable[[float], np.ndarray]  # the transcription's control interpolant, leg order
    push_off: float
    cot: float
    velocity_mismatch: float  # max |interpolant's own q̇ − d/dt of its q| over the step (0 for DMOC, O(h³) for HS)
    piece: int | None = field(default=None, repr=False)
    """The interval an integration segment lies in, while it runs: read from that interval's polynomial up to and at
    its end node (the left-hand limit), since a C¹ interpolant's acceleration jumps at the nodes and a segment that
    saw the next interval's at its end would not be smooth. None: the interval that ``t`` lies in (the later one at
    a node)."""
    _last_key: tuple[float, int | None] | None = field(default=None, repr=False)
    _last_value: tuple[np.ndarray, np.ndarray, np.ndarray] | None = field(default=None, repr=False)

    def desired(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q_d, q̇_d, q̈_d) in leg order at local time ``t`` ∈ [0, T] (memoized: one loop evaluation asks for
        the same time several times)."""
        if (t, self.piece) != self._last_key:
            self._last_key, self._last_value = (t, self.piece), self._evaluate(t)
        return self._last_value

    def interval(self, t: float) -> int:
        """The interval that local time ``t`` lies in (the later one at a node)."""
        return int(np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 2))

    def _evaluate(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        h = self.info.time_step
        k = self.interval(t) if self.piece is None else self.piece
        s = (t - self.times[k]) / h
        c = self.coefficients[k]
        degree = c.shape[0] - 1
        q = c[degree].copy()
        dq = degree * c[degree].copy()
        ddq = degree * (degree - 1) * c[degree].copy()
        for j in range(degree - 1, -1, -1):
            q = q * s + c[j]
            if j >= 1:
                dq = dq * s + j * c[j]
            if j >= 2:
                ddq = ddq * s + j * (j - 1) * c[j]
        return q, dq / h, ddq / h**2


@dataclass
class Reference:
    """The walk to track: its steps' references, the experiment, and the model the walk was solved with."""

    walk: WalkResult
    experiment: Experiment
    model: BipedModel
    steps: list[ReferenceStep]
    trajectory: str = "walk"
    """Which trajectories are tracked: ``walk`` (each step's own) or ``polished`` (the motions decrease and conquer's
    steps report: each its polish or its complete solution, never its patchwork)."""

    @classmethod
    def from_walk(cls, walk: WalkResult, experiment: Experiment) -> Reference:
        """The solved prefix of ``walk``, each step through its trajectory's own interpolant.

        A walk whose steps report motions of their own (decrease and conquer: each step's polish or complete
        solution, :attr:`StepOutcome.verified`) is tracked along those and compared with their COT, the verified
        one; a step's own trajectory (for decrease and conquer, the patchwork) only when not every solved step
        has one.

        The tracked robot's cost is measured as net hip power plus the push-off's energy (the thesis's COT), so each
        step's reference COT is too: the verified COT of a walk solved under that measure, else the same measure
        taken of the step's trajectory (:func:`net_power_cot`), so that the tracked ACOT's increase is the
        control's and not a change of cost definition.
        """
        model = BipedModel(experiment.robot, 4 if walk.phase == "second" else 2)
        own_measure = walk.objective == NET_POWER.describe() and \
            walk.problem_options.get("push_off_cost", ProblemOptions.push_off_cost) == "impulse"
        solved = []
        for outcome in walk.steps:
            if not outcome.solved:
                break
            solved.append(outcome)
        polished = bool(solved) and all(outcome.verified is not outcome for outcome in solved)
        steps, start = [], 0.0
        for outcome in solved:
            outcome = outcome.verified if polished else outcome
            trajectory = outcome.trajectory
            geometry = experiment.terrain.steps[outcome.index - 1]
            info = StepInfo(outcome.index, outcome.stance, geometry.theta, geometry.D,
                            float(trajectory.times[1] - trajectory.times[0]), trajectory.duration, start)
            cot = outcome.verification.cot if own_measure else net_power_cot(trajectory, info, experiment, model)
            steps.append(_reference_step(trajectory, info, cot))
            start += trajectory.duration
        if not steps:
            raise TrackingInputError(f"the {walk.experiment} walk has no solved step to track ({walk.failure})")
        return cls(walk, experiment, model, steps, "polished" if polished else "walk")

    def step(self, info: StepInfo | int) -> ReferenceStep:
        return self.steps[(info.index if isinstance(info, StepInfo) else info) - 1]

    def desired(self, info: StepInfo, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q_d, q̇_d, q̈_d) of the leg angles at local time ``t`` of the step."""
        return self.step(info).desired(t)

    def full(self, info: StepInfo, angles: np.ndarray) -> np.ndarray:
        """Leg-angle values padded with the held stance foot's (zeros) to the model's coordinates."""
        return np.r_[angles, np.zeros(self.model.dof - 2)]

    def ideal_cot(self, info: StepInfo) -> float:
        """COT of the step driven by the exact model's inverse dynamics: what perfect tracking costs."""
        ref = self.step(info)
        energy = 0.0
        try:
            for k, (start, end) in enumerate(zip(ref.times[:-1], ref.times[1:], strict=True)):
                ref.piece = k  # each interval on its own: the torques jump with the acceleration at the nodes
                grid, power = np.linspace(start, end, 17), []
                for t in grid:
                    q, dq, ddq = ref.desired(t)
                    tau = inverse_dynamics(self.model, self.full(info, q), self.full(info, dq),
                                           self.full(info, ddq), info.stance)
                    power.append(hip_power(dq[0], dq[1], tau[0], tau[1]))
                energy += hip_energy(grid, np.array(power))
        finally:
            ref.piece = None
        if self.model.dof == 4:
            q, dq, _ = ref.desired(info.duration)
            energy += self.model.push_off(self.full(info, q), self.full(info, dq), ref.push_off, info.stance)[1]
        robot = self.experiment.robot
        return float(cost_of_transport(energy, robot.total_mass, info.chord, robot.g))

    def post_push_off_velocity(self, info: StepInfo) -> np.ndarray:
        """The reference's velocities (model coordinates) just after its own push-off at the step's end."""
        ref = self.step(info)
        q, dq, _ = ref.desired(info.duration)
        return self.model.push_off(self.full(info, q), self.full(info, dq), ref.push_off, info.stance)[0]


def net_power_cot(trajectory: StepTrajectory, info: StepInfo, experiment: Experiment, model: BipedModel) -> float:
    """The step's COT measured as tracking measures the tracked robot's: ∫|τ·q̇| dt on a fine grid of its
    interpolant plus the kinetic energy its push-off adds, over M g D."""
    return float(trajectory_cost(trajectory, NET_POWER, experiment.robot, info.chord, model, "impulse")[2])


def _reference_step(trajectory: StepTrajectory, info: StepInfo, cot: float) -> ReferenceStep:
    times = np.asarray(trajectory.times, dtype=float)
    h = info.time_step
    pieces, mismatch = [], 0.0
    for k in range(len(times) - 1):
        coefficients = None
        for degree in (3, 5):
            fit = np.cos(np.pi * (np.arange(degree + 1) + 0.5) / (degree + 1)) * 0.5 + 0.5  # Chebyshev, interior
            check = np.array([0.13, 0.61, 0.94])
            values = np.array([trajectory.state(times[k] + s * h)[0] for s in np.r_[fit, check]])
            vandermonde = np.vander(np.r_[fit, check], degree + 1, increasing=True)
            c = np.linalg.solve(vandermonde[: degree + 1], values[: degree + 1])
            if np.max(np.abs(vandermonde[degree + 1:] @ c - values[degree + 1:])) <= 1e-10 * (1 + np.abs(values).max()):
                coefficients = c
                break
        if coefficients is None:
            raise TrackingInputError(f"step {info.index}: the transcription's interpolant is not a polynomial of "
                                     "degree ≤ 5 on each grid interval, so its derivatives cannot be taken exactly")
        pieces.append(coefficients)
        for s in (0.25, 0.5, 0.75):
            rates = trajectory.state(times[k] + s * h)[1]
            slope = sum(j * coefficients[j] * s ** (j - 1) for j in range(1, len(coefficients))) / h
            mismatch = max(mismatch, float(np.max(np.abs(rates - slope))))
    degree = max(len(piece) for piece in pieces) - 1
    coefficients = np.array([np.pad(piece, ((0, degree + 1 - len(piece)), (0, 0))) for piece in pieces])
    return ReferenceStep(info=info, times=times, coefficients=coefficients, q_nodes=np.asarray(trajectory.q),
                         dq_nodes=np.asarray(trajectory.dq), torque=trajectory.control, push_off=trajectory.push_off,
                         cot=cot, velocity_mismatch=mismatch)


def load_reference(walk_or_path: str | Path | WalkResult, registry: PluginRegistry | None = None) -> Reference:
    """The reference of a walk file (JSON path, NPZ beside it) or of an in-memory :class:`WalkResult`, on the
    experiment the walk was solved for (built with the walk's experiment options)."""
    registry = registry or load_registry()
    if isinstance(walk_or_path, WalkResult):
        experiment = registry.create("experiment", walk_or_path.experiment, **walk_or_path.experiment_options)
        return Reference.from_walk(walk_or_path, experiment)
    return Reference.from_walk(*load_walk(walk_or_path, registry))
