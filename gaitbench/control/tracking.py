"""Closed-loop tracking of a solved walk: controller, observer and disturbance plugins on the hybrid robot.

The thesis's Chapter 4 tracks its optimal gaits with computed torque and collocated partial feedback
linearization, velocity and disturbance observers, and actuator friction as the disturbance (ch4-control.md;
DECISIONS §9). This module runs that loop for any stored walk:

- The **reference** of each step is the transcription's own interpolant of the stored solution (cubic Hermite for
  Hermite–Simpson, the cubic of DMOC, the quadratic of trapezoidal collocation, ...). The desired angles are its
  positions; the desired velocities and accelerations are their exact time derivatives, so the reference is a
  twice-differentiable trajectory as computed torque requires (ch4 §2.1). At the nodes the derivative equals the
  stored velocity, which is what makes exact tracking possible across steps.
- The **plant** is the model the walk was solved with (4-DOF with the stance foot held, or the 2-DOF First Phase
  model): M q̈ + C q̇ + G + d = B τ + Sᵀ f, with the disturbance d on the left-hand side as the thesis's "+ d̂" in
  its laws implies (ch4 §5.2). Each step runs for the reference's duration; at its end come the push-off the
  controller commands (4-DOF) and the plastic heel strike, exactly as in DECISIONS §3. Heel strike is timed by the
  reference, as in the thesis (impact at t = T of every step), and the landing is checked instead.
- Control is continuous, or sampled with a zero-order hold at a given rate (restarted at every impact). The
  observer always runs in continuous time on the measured angles and the applied torques.
- A **fall** (hip too low, swing foot through the ground or missing it at heel strike, a leg angle out of its
  bounds) ends the run and is reported with its step, time and reason.
"""

from __future__ import annotations

import functools
import json
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Protocol

import casadi as ca
import numpy as np
from scipy.integrate import solve_ivp

from gaitbench.model.energetics import average_cot, cost_of_transport, hip_energy, hip_power
from gaitbench.model.experiment import Experiment
from gaitbench.model.mechanics import BipedModel, other_leg
from gaitbench.model.numeric import NumericFunction
from gaitbench.model.terrain import clearance
from gaitbench.plugins import PluginRegistry, load_registry
from gaitbench.problem.gait_problem import ProblemOptions, StepData, StepStructure, legs_to_roles
from gaitbench.problem.trajectory import Seed, StepTrajectory, nodal_trajectory
from gaitbench.solve.verify import StepVerification
from gaitbench.solve.walk import POLISHED, StepOutcome, WalkResult, next_step_state

DEFAULT_RTOL = 1e-10
DEFAULT_ATOL = 1e-10
SAMPLES_PER_INTERVAL = 8
"""Recorded samples per reference grid interval: the grid the error metrics and the time series use."""


class TrackingInputError(ValueError):
    """A walk that cannot be tracked (missing or incomplete result file, NPZ, or trajectories); says how to fix it."""


@dataclass(frozen=True)
class StepInfo:
    """What every plugin call knows about the current step (1-based ``index``; times in seconds)."""

    index: int
    stance: int
    slope: float
    chord: float
    time_step: float  # h of the reference grid: the friction of the linear joints scales with it (ch4 §7)
    duration: float
    start_time: float  # global time at the step's start (after the previous heel strike)


class Controller(Protocol):
    """A tracking control law (a ``controller`` plugin, built as ``factory(model, reference, **options)``)."""

    def torque(self, t: float, q: np.ndarray, dq: np.ndarray, disturbance: np.ndarray, step: StepInfo) -> np.ndarray:
        """Hip torques (τ1, τ2) at local time ``t`` from the measured q, the estimated q̇ (model coordinates; the
        held stance foot's rates are exact zeros) and the estimated leg disturbance (d̂1, d̂2)."""

    def push_off(self, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> float:
        """Push-off impulse (N·s) along the stance leg at the end of ``step``; clipped to [0, push_off_max]."""


class Observer(Protocol):
    """Velocity and disturbance estimates of the leg angles (an ``observer`` plugin, ``factory(model, **options)``).

    The estimates live on the actuated coordinates (q1, q2): during swing the stance foot is held, so its rates are
    known to be zero and any disturbance on it is absorbed by the ground reaction (ch4 §5.2). ``q`` and ``dq`` are
    the full model state; ``dq`` is the true velocity, which only observers that model a velocity sensor may use.
    """

    size: int  # number of internal states

    def reset(self, q: np.ndarray, velocity: np.ndarray, disturbance: np.ndarray, step: StepInfo) -> np.ndarray:
        """Internal state whose estimates are exactly ``velocity`` and ``disturbance`` at configuration ``q``."""

    def estimate(self, state: np.ndarray, q: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(q̂̇1, q̂̇2) and (d̂1, d̂2)."""

    def derivative(self, state: np.ndarray, q: np.ndarray, dq: np.ndarray, tau: np.ndarray,
                   step: StepInfo) -> np.ndarray:
        """Rate of the internal state given the applied hip torques."""


class Disturbance(Protocol):
    """Generalized forces on the robot (a ``disturbance`` plugin, built as ``factory(experiment, **options)``).

    Both are on the left-hand side, M q̈ + C q̇ + G + d = B τ + Sᵀ f: friction returns its resisting force along the
    motion, an external force F returns −Jᵀ F.
    """

    def force(self, t: float, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> np.ndarray:
        """Continuous generalized force d (model coordinates) at local time ``t``."""

    def impulse(self, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> np.ndarray:
        """Generalized impulse acting with the push-off, evaluated at the post-push-off velocity ``dq``."""


@dataclass(frozen=True)
class FallCriteria:
    """When the robot counts as fallen.

    ``hip_fraction``: the hip's height above the stance foot drops below this fraction of the lowest height the
    reference asks for in that step (the thesis's long steps legitimately bring the hip down to 0.3 l).
    ``ground_tolerance`` (m): the swing foot goes that much deeper below the step's chord line than the reference
    does, or is that far from the chord line when the reference's heel strike comes. Leg angles must stay within
    the experiment's angle bounds (DECISIONS §8).
    """

    hip_fraction: float = 0.5
    ground_tolerance: float = 0.01

    def __post_init__(self) -> None:
        if not 0 <= self.hip_fraction < 1:
            raise ValueError(f"hip_fraction = {self.hip_fraction}: expected a fraction in [0, 1)")
        if not self.ground_tolerance > 0:
            raise ValueError(f"ground_tolerance = {self.ground_tolerance}: expected a positive length in m")


# --------------------------------------------------------------------------------------------------------------
# Loading a stored walk


def load_walk(path: str | Path, registry: PluginRegistry | None = None) -> tuple[WalkResult, Experiment]:
    """A walk saved by :meth:`WalkResult.save` (JSON + NPZ), with each step's trajectory and its transcription's
    interpolant rebuilt from the stored nodal values; also the experiment it was solved for.

    Only the solved steps are loaded (a prefix of the walk). Raises :class:`TrackingInputError` naming the file and
    the fix when the JSON or its NPZ is missing, unreadable or incomplete.
    """
    path = Path(path)
    rerun = f"write it with `gaitbench solve ... --out {path}`"
    if not path.is_file():
        raise TrackingInputError(f"{path}: no such result file; {rerun}")
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise TrackingInputError(f"{path}: not a readable walk result ({exc}); {rerun}") from None
    missing = [key for key in ("experiment", "transcription", "solver", "strategy", "N", "phase", "steps")
               if key not in (data if isinstance(data, dict) else {})]
    if missing:
        raise TrackingInputError(f"{path}: not a walk result, missing {', '.join(missing)}; {rerun}")
    if "trajectories" not in data:
        raise TrackingInputError(f"{path}: holds no trajectories (no solved step, or saved without its NPZ); {rerun}")
    npz_path = path.parent / data["trajectories"]
    if not npz_path.is_file():
        raise TrackingInputError(f"{path}: its trajectories file {npz_path} is missing; keep the .npz beside the "
                                 f"JSON or {rerun}")
    registry = registry or load_registry()
    experiment = registry.create("experiment", data["experiment"])
    transcription = registry.create("transcription", data["transcription"])
    n_nodes, phase = int(data["N"]), data["phase"]
    built = transcription.build(StepStructure(phase, n_nodes, ProblemOptions(limits=experiment.limits)))
    model = BipedModel(experiment.robot, 4 if phase == "second" else 2)
    walk = WalkResult(experiment=data["experiment"], transcription=data["transcription"], solver=data["solver"],
                      strategy=data["strategy"], N=n_nodes, phase=phase, requested_steps=int(data.get(
                          "requested_steps", len(data["steps"]))), wall_time_s=float(data.get("wall_time_s", 0.0)),
                      strategy_details=data.get("strategy_details", {}))
    try:
        with np.load(npz_path) as arrays:
            stored = {key: arrays[key] for key in arrays.files}
    except (OSError, ValueError) as exc:
        raise TrackingInputError(f"{npz_path}: unreadable trajectories ({exc}); {rerun}") from None
    for step in data["steps"]:
        prefix = f"step{int(step['index']):02d}"
        if f"{prefix}_q" not in stored or step.get("cot") is None:
            break
        arrays = {key[len(prefix) + 1:]: value for key, value in stored.items() if key.startswith(prefix)}
        try:
            if "chosen" in (step.get("details") or {}):  # decrease and conquer's patchwork: no interpolant of its own
                nodes = (np.asarray(arrays[key], dtype=float) for key in ("t", "q", "dq", "tau"))
                trajectory = nodal_trajectory(*nodes, float(np.asarray(arrays["push_off"]).ravel()[0]),
                                              int(step["stance"]))
            else:
                trajectory = _rebuild_trajectory(built, data["transcription"], experiment, step, arrays)
        except KeyError as exc:
            raise TrackingInputError(f"{npz_path}: step {step['index']} lacks {exc.args[0]!r}; {rerun}") from None
        verification = _verification(step)
        outcome = StepOutcome(int(step["index"]), int(step["stance"]), step["status"], step["message"], None,
                              trajectory, verification, next_state=next_step_state(model, trajectory),
                              details=step.get("details") or {})
        polished = outcome.details.get(POLISHED)
        if f"{POLISHED}_q" in arrays and isinstance(polished, dict) and polished.get("cot") is not None:
            own = {key[len(POLISHED) + 1:]: value for key, value in arrays.items()
                   if key.startswith(f"{POLISHED}_")}
            try:
                polished_trajectory = _rebuild_trajectory(built, data["transcription"], experiment, step, own)
            except KeyError as exc:
                raise TrackingInputError(f"{npz_path}: step {step['index']} lacks {POLISHED}_{exc.args[0]}; "
                                         f"{rerun}") from None
            outcome.polished = StepOutcome(outcome.index, outcome.stance, polished["status"], "polished", None,
                                           polished_trajectory, _verification(polished),
                                           next_state=next_step_state(model, polished_trajectory))
        walk.steps.append(outcome)
    if not walk.steps:
        raise TrackingInputError(f"{path}: no solved step to track ({data.get('failure')}); solve the walk again")
    return walk, experiment


def _verification(step: dict) -> StepVerification:
    """A step's stored verification (a step of the walk JSON, or its ``details["polished"]``); figures a file
    written before they were recorded lacks are NaN."""
    return StepVerification(**{key: float(step[key]) if step.get(key) is not None else math.nan for key in (
        "max_defect", "resim_error", "resim_max_error", "hip_energy", "push_off_energy", "cot")})


def _rebuild_trajectory(built, transcription: str, experiment: Experiment, step: dict,
                        arrays: dict[str, np.ndarray]) -> StepTrajectory:
    """The transcription's interpolant of stored nodal values: its variables are sampled from a seed that returns
    exactly the stored values where the transcription samples (nodes for states, the control grid for torques)."""
    index, stance = int(step["index"]), int(step["stance"])
    times, q, dq, tau, tau_t = (np.asarray(arrays[key], dtype=float) for key in ("t", "q", "dq", "tau", "tau_t"))
    push_off = float(np.asarray(arrays["push_off"]).ravel()[0])
    h = float(times[1] - times[0])
    geometry = experiment.terrain.steps[index - 1]
    data = StepData(experiment.robot, stance, np.r_[q[0], dq[0]], geometry.D, geometry.theta, h)
    p = data.parameter_vector()
    roles = [legs_to_roles(values, stance) for values in (q, dq, tau)]
    seed = _nodal_seed(times, *roles, tau_t)
    discretization = built.discretization
    interpolant = discretization.interpolant(discretization.guess(seed, p), p)
    trajectory = StepTrajectory(times=times, q=q, dq=dq, tau=tau, control_times=tau_t, push_off=push_off,
                                stance=stance, _interpolant=interpolant)
    mismatch = max(float(np.max(np.abs(np.r_[trajectory.state(t)] - np.r_[q[k], dq[k]])))
                   for k, t in enumerate(times))
    if mismatch > 1e-8 * (1 + float(np.max(np.abs(dq)))):
        raise TrackingInputError(f"step {index}: the stored nodes do not fit the {transcription} "
                                 f"transcription's interpolant (off by {mismatch:.1e}); was it saved by another "
                                 "transcription?")
    return trajectory


def _nodal_seed(times: np.ndarray, q: np.ndarray, dq: np.ndarray, tau: np.ndarray, tau_t: np.ndarray) -> Seed:
    """Stored values as a :data:`~gaitbench.problem.transcription.Seed`: exact at nodes; torques linear between control
    times when there is one per node, constant per interval when there is one per interval (DMOC)."""
    h = float(times[1] - times[0])
    per_interval = len(tau_t) == len(times) - 1

    def seed(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        k = int(round(t / h))
        if abs(t - k * h) <= 1e-9 * h and 0 <= k < len(times):
            angles, rates = q[k], dq[k]
        else:
            angles = np.array([np.interp(t, times, q[:, j]) for j in range(2)])
            rates = np.array([np.interp(t, times, dq[:, j]) for j in range(2)])
        if per_interval:
            torque = tau[int(np.clip(np.floor(t / h), 0, len(tau_t) - 1))]
        else:
            torque = np.array([np.interp(t, tau_t, tau[:, j]) for j in range(2)])
        return angles, rates, torque

    return seed


# --------------------------------------------------------------------------------------------------------------
# The reference


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
    _last_time: float | None = field(default=None, repr=False)
    _last_value: tuple[np.ndarray, np.ndarray, np.ndarray] | None = field(default=None, repr=False)

    def desired(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q_d, q̇_d, q̈_d) in leg order at local time ``t`` ∈ [0, T] (memoized: one loop evaluation asks for
        the same time several times)."""
        if t != self._last_time:
            self._last_time, self._last_value = t, self._evaluate(t)
        return self._last_value

    def _evaluate(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        h = self.info.time_step
        k = int(np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 2))
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
    """Which trajectories are tracked: ``walk`` (each step's own) or ``polished`` (the verified ones, re-solved from
    decrease and conquer's chosen patchworks)."""

    @classmethod
    def from_walk(cls, walk: WalkResult, experiment: Experiment) -> Reference:
        """The solved prefix of ``walk``, each step through its trajectory's own interpolant.

        A walk whose steps were polished (decrease and conquer) is tracked along its verified trajectories, the
        polished ones, and compared with their COT, the verified one; a step's own (chosen, patchwork) trajectory
        is tracked only when the walk has no polished trajectory for every solved step (``polish = false``).
        """
        model = BipedModel(experiment.robot, 4 if walk.phase == "second" else 2)
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
            steps.append(_reference_step(trajectory, info, outcome.verification.cot))
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

    def post_push_off_velocity(self, info: StepInfo) -> np.ndarray:
        """The reference's velocities (model coordinates) just after its own push-off at the step's end."""
        ref = self.step(info)
        q, dq, _ = ref.desired(info.duration)
        return self.model.push_off(self.full(info, q), self.full(info, dq), ref.push_off, info.stance)[0]


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


# --------------------------------------------------------------------------------------------------------------
# Results


@dataclass(frozen=True)
class Fall:
    step: int
    time: float  # global, s
    reason: str

    def as_dict(self) -> dict:
        return {"step": self.step, "time": self.time, "reason": self.reason}


@dataclass
class StepTracking:
    """Errors and energy of one tracked step; per-leg arrays are (leg 1, leg 2)."""

    index: int
    stance: int
    completed: bool
    max_position_error: np.ndarray  # rad, |q − q_d|
    rms_position_error: np.ndarray
    max_velocity_error: np.ndarray  # rad/s, velocity-estimation error |q̇ − q̂̇|
    rms_velocity_error: np.ndarray
    max_velocity_tracking_error: np.ndarray  # rad/s, |q̇ − q̇_d|
    max_torque: float  # N·m, largest |τ| applied
    hip_energy: float  # J, ∫ |τ·q̇| dt of the applied torques along the actual motion
    push_off_impulse: float  # N·s, commanded
    push_off_impulse_reference: float
    push_off_energy: float  # J, the push-off actuator's work F·J(q̇⁻ + q̇⁺)/2 (= ΔKE without friction)
    cot_reference: float
    cot_tracked: float | None  # None for a step the robot did not finish
    cot_ideal: float  # the reference's torques by inverse dynamics of the exact model (ideal tracking)

    def as_dict(self) -> dict:
        legs = ("leg1", "leg2")
        return {
            "index": self.index,
            "stance": self.stance,
            "completed": self.completed,
            **{f"{name}": dict(zip(legs, map(float, getattr(self, name)), strict=True)) for name in (
                "max_position_error", "rms_position_error", "max_velocity_error", "rms_velocity_error",
                "max_velocity_tracking_error")},
            "max_torque": self.max_torque,
            "hip_energy": self.hip_energy,
            "push_off_impulse": self.push_off_impulse,
            "push_off_impulse_reference": self.push_off_impulse_reference,
            "push_off_energy": self.push_off_energy,
            "cot_reference": self.cot_reference,
            "cot_tracked": self.cot_tracked,
            "cot_ideal": self.cot_ideal,
        }


SERIES_KEYS = ("t", "step", "q_desired", "q", "dq_desired", "dq", "dq_estimated", "tau", "disturbance",
               "disturbance_estimated")
"""Time series of a run (leg order, 2 columns where per leg): what a report plots, desired against actual."""


@dataclass
class TrackingResult:
    walk: dict  # experiment, transcription, solver, strategy, N, phase, trajectory (walk | polished), source file
    configuration: dict  # plugin names and options, sample rate, tolerances
    steps: list[StepTracking]
    series: dict[str, np.ndarray]
    fall: Fall | None = None
    failure: str | None = None  # the integrator gave up (not a fall)
    reference_velocity_mismatch: float = 0.0
    wall_time_s: float = 0.0
    torque_limit: float = math.inf

    @property
    def fell(self) -> bool:
        return self.fall is not None

    @property
    def completed_steps(self) -> list[StepTracking]:
        return [step for step in self.steps if step.completed]

    def _acot(self, attribute: str) -> float | None:
        done = self.completed_steps
        return average_cot([getattr(step, attribute) for step in done]) if done else None

    @property
    def acot_reference(self) -> float | None:
        """ACOT of the reference over the steps the robot completed (the walk's verified COTs)."""
        return self._acot("cot_reference")

    @property
    def acot_tracked(self) -> float | None:
        return self._acot("cot_tracked")

    @property
    def acot_increase_percent(self) -> float | None:
        reference, tracked = self.acot_reference, self.acot_tracked
        return None if reference is None or tracked is None else 100.0 * (tracked - reference) / reference

    def _max(self, attribute: str) -> float:
        return float(max((np.max(getattr(step, attribute)) for step in self.steps), default=0.0))

    def as_dict(self) -> dict:
        ideal = self._acot("cot_ideal")
        return {
            "walk": self.walk,
            "configuration": self.configuration,
            "max_position_error": self._max("max_position_error"),
            "rms_position_error": float(np.sqrt(np.mean([np.mean(step.rms_position_error**2)
                                                         for step in self.steps]))) if self.steps else 0.0,
            "max_velocity_error": self._max("max_velocity_error"),
            "max_velocity_tracking_error": self._max("max_velocity_tracking_error"),
            "max_torque": self._max("max_torque"),
            "torque_limit": self.torque_limit,
            "torque_limit_exceeded": self._max("max_torque") > self.torque_limit,
            "acot_reference": self.acot_reference,
            "acot_tracked": self.acot_tracked,
            "acot_increase_percent": self.acot_increase_percent,
            "acot_ideal": ideal,
            "reference_velocity_mismatch": self.reference_velocity_mismatch,
            "steps_tracked": len(self.completed_steps),
            "fell": self.fell,
            "fall": self.fall.as_dict() if self.fall else None,
            "failure": self.failure,
            "wall_time_s": self.wall_time_s,
            "steps": [step.as_dict() for step in self.steps],
        }

    def save(self, path: str | Path) -> Path:
        """Write the result as JSON and its time series beside it as NPZ (named in the JSON under ``series``)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        npz = path.with_suffix(".npz")
        np.savez_compressed(npz, **self.series)
        data = self.as_dict() | {"series": npz.name}
        path.write_text(json.dumps(data, indent=2, default=_json_default))
        return path


def _json_default(value: Any) -> Any:
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"cannot serialize {type(value).__name__}")


# --------------------------------------------------------------------------------------------------------------
# The closed loop


def track(reference: Reference, controller: Controller, observer: Observer, disturbance: Disturbance, *,
          sample_rate: float | None = None, steps: int | None = None, fall: FallCriteria | None = None,
          rtol: float = DEFAULT_RTOL, atol: float = DEFAULT_ATOL, samples_per_interval: int = SAMPLES_PER_INTERVAL,
          configuration: Mapping[str, Any] | None = None) -> TrackingResult:
    """Run the closed loop over the reference's steps (or the first ``steps``) from the walk's initial state.

    ``sample_rate`` (Hz) samples the control law with a zero-order hold; ``None`` is continuous control.
    """
    if sample_rate is not None and not sample_rate > 0:
        raise ValueError(f"sample_rate = {sample_rate}: expected a positive rate in Hz")
    fall = fall or FallCriteria()
    run = _ClosedLoop(reference, controller, observer, disturbance, sample_rate, fall, rtol, atol,
                      samples_per_interval)
    started = time.perf_counter()
    run.simulate(len(reference.steps) if steps is None else min(steps, len(reference.steps)))
    walk = reference.walk
    return TrackingResult(
        walk={"experiment": walk.experiment, "transcription": walk.transcription, "solver": walk.solver,
              "strategy": walk.strategy, "N": walk.N, "phase": walk.phase, "trajectory": reference.trajectory},
        configuration=dict(configuration or {}) | {"sample_rate": sample_rate, "rtol": rtol, "atol": atol,
                                                   "fall": {"hip_fraction": fall.hip_fraction,
                                                            "ground_tolerance": fall.ground_tolerance}},
        steps=run.records, series=run.series(), fall=run.fall, failure=run.failure,
        reference_velocity_mismatch=max(step.velocity_mismatch for step in reference.steps),
        wall_time_s=time.perf_counter() - started, torque_limit=reference.experiment.limits.tau_max)


class _ClosedLoop:
    """The augmented state is (q, q̇, observer state, ∫|τ·q̇| dt), integrated step by step."""

    def __init__(self, reference, controller, observer, disturbance, sample_rate, fall, rtol, atol, samples):
        self.reference, self.controller, self.observer, self.disturbance = reference, controller, observer, disturbance
        self.model: BipedModel = reference.model
        self.n = self.model.dof
        self.sample_rate, self.criteria, self.rtol, self.atol, self.samples = sample_rate, fall, rtol, atol, samples
        self.records: list[StepTracking] = []
        self.fall: Fall | None = None
        self.failure: str | None = None
        self._series: list[dict[str, np.ndarray]] = []

    # -- pieces of the right-hand side ------------------------------------------------------------------------
    def _estimates(self, x):
        n = self.n
        q, dq = x[:n], x[n:2 * n]
        velocity, disturbance = self.observer.estimate(x[2 * n:2 * n + self.observer.size], q, dq)
        dq_hat = dq.copy()
        dq_hat[:2] = velocity  # the held stance foot's rates are known zeros, kept exact
        return q, dq, dq_hat, np.asarray(disturbance, dtype=float)

    def _control(self, t, x, info):
        q, _, dq_hat, d_hat = self._estimates(x)
        return np.asarray(self.controller.torque(t, q, dq_hat, d_hat, info), dtype=float)

    def _rhs(self, info: StepInfo, held: np.ndarray | None):
        n, m = self.n, self.observer.size

        def rhs(t, x):
            tau = self._control(t, x, info) if held is None else held
            q, dq = x[:n], x[n:2 * n]
            d = np.asarray(self.disturbance.force(t, q, dq, info), dtype=float)
            # Rows 3–4 of d act on the held stance foot: the ground reaction absorbs them, so only d1, d2 move it.
            ddq = held_foot_acceleration(self.model, q, dq, tau - d[:2], info.stance)
            rates = self.observer.derivative(x[2 * n:2 * n + m], q, dq, tau, info)
            power = abs(float(hip_power(dq[0], dq[1], tau[0], tau[1])))
            return np.concatenate([dq, ddq, np.asarray(rates, dtype=float).ravel(), [power]])

        return rhs

    def _events(self, info: StepInfo):
        """Terminal fall events, each positive while the robot is fine; returned with their reasons."""
        ref = self.reference.step(info)
        lower, upper = self.reference.experiment.limits.angle_bounds
        st, sw = info.stance - 1, other_leg(info.stance) - 1
        leg = self.reference.experiment.robot.l
        grid = np.linspace(0.0, info.duration, 20 * len(ref.times))
        hip_floor = self.criteria.hip_fraction * min(math.cos(ref.desired(t)[0][st]) for t in grid)
        depth = self.criteria.ground_tolerance / leg

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

    # -- one step ---------------------------------------------------------------------------------------------
    def _integrate(self, info, x, grid):
        """States at the grid times (rows), the applied torques there, and the fall if one happened."""
        events = self._events(info)
        functions = [event for event, _ in events]
        # Segments end at every node, where the reference's acceleration may jump (C¹ interpolants), and at every
        # sampling instant; each is then smooth for the integrator.
        breaks = np.asarray(self.reference.step(info).times, dtype=float)
        samples = np.zeros(0)
        if self.sample_rate is not None:
            samples = np.arange(0.0, info.duration, 1.0 / self.sample_rate)
            breaks = np.r_[breaks, samples]
        breaks = np.unique(np.clip(breaks, 0.0, info.duration))
        breaks = breaks[np.r_[True, np.diff(breaks) > 1e-12]]
        held = None
        times, states, torques = [0.0], [x], [self._control(0.0, x, info)]
        for a, b in zip(breaks[:-1], breaks[1:], strict=True):
            if samples.size and np.min(np.abs(samples - a)) <= 1e-12:
                held = self._control(a, x, info)
            inside = grid[(grid > a + 1e-12) & (grid < b - 1e-12)]
            solution = solve_ivp(self._rhs(info, held), (a, b), x, method="DOP853", t_eval=np.r_[inside, b],
                                 rtol=self.rtol, atol=self.atol, events=functions)
            recorded = [(t, state) for t, state in zip(solution.t, solution.y.T, strict=True)
                        if np.min(np.abs(grid - t)) <= 1e-12]
            for t, state in recorded:
                times.append(float(t))
                states.append(state)
                torques.append(held if held is not None else self._control(t, state, info))
            if solution.status == -1:
                self.failure = f"step {info.index}: integration failed at t = {solution.t[-1]:.4f} s " \
                               f"({solution.message})"
                break
            if solution.status == 1:
                which = next(i for i, hits in enumerate(solution.t_events) if len(hits))
                t, state = float(solution.t_events[which][0]), solution.y_events[which][0]
                times.append(t)
                states.append(state)
                torques.append(held if held is not None else self._control(t, state, info))
                self.fall = Fall(info.index, info.start_time + t, events[which][1])
                break
            x = solution.y[:, -1]
        return np.array(times), np.array(states), np.array(torques)

    def _step(self, info: StepInfo, x0: np.ndarray) -> np.ndarray | None:
        """Track one step from ``x0``; returns the next step's initial augmented state, or None if the run ended."""
        n, m = self.n, self.observer.size
        ref = self.reference.step(info)
        grid = np.linspace(0.0, info.duration, self.samples * (len(ref.times) - 1) + 1)
        times, states, torques = self._integrate(info, x0, grid)
        x_end = states[-1]
        completed = self.fall is None and self.failure is None and math.isclose(times[-1], info.duration)
        q_end, dq_end = x_end[:n], x_end[n:2 * n]
        impulse = energy = 0.0
        next_state = None
        if completed:
            _, _, dq_hat, d_hat = self._estimates(x_end)
            if self.n == 4:
                limit = self.reference.experiment.limits.push_off_max
                impulse = float(np.clip(self.controller.push_off(q_end, dq_hat, info), 0.0, limit))
                dq_plus, energy = self._push_off(q_end, dq_end, impulse, info)
                dq_hat_plus = self.model.push_off(q_end, dq_hat, impulse, info.stance)[0]
            else:
                dq_plus, dq_hat_plus = dq_end, dq_hat
            q_d_end = ref.desired(info.duration)[0]
            miss = abs(clearance(q_end[info.stance - 1], q_end[other_leg(info.stance) - 1], info.slope)
                       - clearance(q_d_end[info.stance - 1], q_d_end[other_leg(info.stance) - 1], info.slope))
            if miss * self.reference.experiment.robot.l > self.criteria.ground_tolerance:
                self.fall = Fall(info.index, info.start_time + info.duration, "swing foot missed the ground at heel "
                                 f"strike ({miss * self.reference.experiment.robot.l:.3f} m off)")
                completed = False
            else:
                strike = self.model.heel_strike(q_end, dq_plus, info.stance)
                estimate = self.model.heel_strike(q_end, dq_hat_plus, info.stance).dq[:2]
                next_info = self._info(info.index + 1, info.start_time + info.duration)
                observer_state = (self.observer.reset(strike.q, estimate, d_hat, next_info)
                                  if next_info else np.zeros(m))
                next_state = np.concatenate([strike.q, strike.dq, observer_state, [0.0]])
        self._record(info, ref, times, states, torques, completed, impulse, energy)
        return next_state

    def _push_off(self, q, dq, impulse, info):
        """Velocities after the commanded impulse and the disturbance's impulse, and the actuator's work."""
        dq_plus = self.model.push_off(q, dq, impulse, info.stance)[0]
        extra = np.asarray(self.disturbance.impulse(q, dq_plus, info), dtype=float)
        if np.any(extra):
            dq_plus = dq_plus - np.linalg.solve(self.model.mass_matrix(q, info.stance), extra)
        st = info.stance - 1
        axis = np.r_[0.0, 0.0, -math.sin(q[st]), math.cos(q[st])]
        return dq_plus, float(impulse * axis @ (dq + dq_plus) / 2)

    def _info(self, index: int, start: float) -> StepInfo | None:
        if index > len(self.reference.steps):
            return None
        info = self.reference.step(index).info
        return StepInfo(info.index, info.stance, info.slope, info.chord, info.time_step, info.duration, start)

    def _record(self, info, ref, times, states, torques, completed, impulse, energy):
        n, m = self.n, self.observer.size
        desired = [ref.desired(t) for t in times]
        q_d = np.array([d[0] for d in desired])
        dq_d = np.array([d[1] for d in desired])
        estimates = [self._estimates(x) for x in states]
        dq_hat = np.array([e[2][:2] for e in estimates])
        d_hat = np.array([e[3] for e in estimates])
        q, dq = states[:, :2], states[:, n:n + 2]
        d_true = np.array([np.asarray(self.disturbance.force(t, x[:n], x[n:2 * n], info), dtype=float)[:2]
                           for t, x in zip(times, states, strict=True)])
        position, velocity = np.abs(q - q_d), np.abs(dq - dq_hat)
        robot = self.reference.experiment.robot
        hip = float(states[-1, 2 * n + m])
        self.records.append(StepTracking(
            index=info.index, stance=info.stance, completed=completed,
            max_position_error=position.max(axis=0), rms_position_error=_rms(times, position),
            max_velocity_error=velocity.max(axis=0), rms_velocity_error=_rms(times, velocity),
            max_velocity_tracking_error=np.abs(dq - dq_d).max(axis=0),
            max_torque=float(np.abs(torques).max()), hip_energy=hip, push_off_impulse=impulse,
            push_off_impulse_reference=ref.push_off, push_off_energy=energy, cot_reference=ref.cot,
            cot_tracked=float(cost_of_transport(hip + energy, robot.total_mass, info.chord, robot.g))
            if completed else None,
            cot_ideal=self._ideal_cot(info, ref),
        ))
        self._series.append({"t": info.start_time + times, "step": np.full(len(times), info.index),
                             "q_desired": q_d, "q": q, "dq_desired": dq_d, "dq": dq, "dq_estimated": dq_hat,
                             "tau": torques, "disturbance": d_true, "disturbance_estimated": d_hat})

    def _ideal_cot(self, info: StepInfo, ref: ReferenceStep) -> float:
        """COT of the reference driven by the exact model's inverse dynamics: what perfect tracking costs."""
        grid = np.linspace(0.0, info.duration, 16 * (len(ref.times) - 1) + 1)
        power = []
        for t in grid:
            q, dq, ddq = ref.desired(t)
            tau = inverse_dynamics(self.model, self.reference.full(info, q), self.reference.full(info, dq),
                                   self.reference.full(info, ddq), info.stance)
            power.append(hip_power(dq[0], dq[1], tau[0], tau[1]))
        energy = hip_energy(grid, np.array(power))
        if self.n == 4:
            q, dq, _ = ref.desired(info.duration)
            energy += self.model.push_off(self.reference.full(info, q), self.reference.full(info, dq), ref.push_off,
                                          info.stance)[1]
        robot = self.reference.experiment.robot
        return float(cost_of_transport(energy, robot.total_mass, info.chord, robot.g))

    # -- the walk ---------------------------------------------------------------------------------------------
    def simulate(self, n_steps: int) -> None:
        n = self.n
        first = self.reference.steps[0]
        q0 = self.reference.full(first.info, first.q_nodes[0])
        dq0 = self.reference.full(first.info, first.dq_nodes[0])
        if n == 4:
            q0[2:] = self.reference.experiment.initial_state[2:4]
        info = self._info(1, 0.0)
        _, dq_d, _ = first.desired(0.0)
        x = np.concatenate([q0, dq0, self.observer.reset(q0, dq_d, np.zeros(2), info), [0.0]])
        for index in range(1, n_steps + 1):
            x = self._step(info, x)
            if x is None or index == n_steps:
                break
            info = self._info(index + 1, info.start_time + info.duration)

    def series(self) -> dict[str, np.ndarray]:
        if not self._series:
            return {key: np.zeros(0) for key in SERIES_KEYS}
        return {key: np.concatenate([part[key] for part in self._series]) for key in SERIES_KEYS}


def _rms(times: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Time-RMS over the recorded samples (trapezoid rule), per column."""
    duration = times[-1] - times[0]
    if duration <= 0:
        return np.abs(values[-1])
    return np.sqrt(np.trapezoid(values**2, times, axis=0) / duration)


def inverse_dynamics(model: BipedModel, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, stance: int) -> np.ndarray:
    """Hip torques that give the leg accelerations ``ddq`` with the stance foot held: rows 1–2 of M q̈ + C q̇ + G.

    With the foot held, q̈3 = q̈4 = 0, and rows 3–4 only fix the ground reaction; this is computed torque on the
    constrained model and equals collocated PFL with the exact contact force (ch4 §3.4).
    """
    mass, coriolis, gravity = model_terms(model)(q, dq, stance)
    return (mass @ ddq + coriolis @ dq + gravity)[:2]


def held_foot_acceleration(model: BipedModel, q: np.ndarray, dq: np.ndarray, tau: np.ndarray,
                           stance: int) -> np.ndarray:
    """q̈ with the stance foot held (q̇3 = q̇4 = 0) under hip torques ``tau``: M11 q̈_a = τ − (C q̇ + G)_a, q̈_na = 0.

    The same accelerations as the model's constrained forward dynamics (the KKT system of DECISIONS §2), from the
    memoized terms, which the loop's controller and observer need anyway.
    """
    mass, coriolis, gravity = model_terms(model)(q, dq, stance)
    ddq = np.zeros(model.dof)
    ddq[:2] = np.linalg.solve(mass[:2, :2], tau - (coriolis @ dq + gravity)[:2])
    return ddq


class ModelTerms:
    """M(q), C(q, q̇) and G(q) of a model from one CasADi call per configuration, memoized on the last one.

    In the closed loop's right-hand side the plant (true velocity), the controller and the observer (estimated
    velocity) all need the terms at the same configuration, and a CasADi call from Python costs far more than the
    arithmetic. C is linear in q̇ (Christoffel form), so the call returns Γ(q) = ∂ vec C / ∂q̇ and C(q, v) = Γ(q) v
    for any velocity v is a matrix product.
    """

    def __init__(self, model: BipedModel) -> None:
        n = model.dof
        self.dof, self.parameters = n, model.parameters
        self._functions = {}
        for stance in (1, 2):
            raw = model.functions(stance)
            q, dq, p = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("p", len(model.parameters))
            christoffel = ca.substitute(ca.jacobian(ca.vec(raw.coriolis(q, dq, p)), dq), dq, ca.SX.zeros(n))
            outputs = ca.vertcat(ca.vec(raw.mass(q, p)), ca.vec(christoffel), raw.gravity(q, p))
            self._functions[stance] = NumericFunction(ca.Function(f"terms_{stance}", [q, p], [outputs]))
        self._key: bytes | None = None
        self._terms: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def __call__(self, q: np.ndarray, dq: np.ndarray, stance: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        q = np.asarray(q, dtype=float)
        key = bytes([stance]) + q.tobytes()
        if key != self._key:
            n = self.dof
            values = self._functions[stance](q, self.parameters)
            self._key = key
            self._terms = (values[: n * n].reshape(n, n, order="F"),
                           values[n * n: n * n * (n + 1)].reshape(n * n, n, order="F"), values[n * n * (n + 1):])
        mass, christoffel, gravity = self._terms
        coriolis = (christoffel @ np.asarray(dq, dtype=float)).reshape(self.dof, self.dof, order="F")
        return mass, coriolis, gravity


@functools.cache
def model_terms(model: BipedModel) -> ModelTerms:
    """The (cached) :class:`ModelTerms` of a model."""
    return ModelTerms(model)


# --------------------------------------------------------------------------------------------------------------
# The entry point for the CLI and the suite runner


TRACKING_OPTIONS = ("controller", "observer", "disturbance", "sample_rate", "steps", "fall", "rtol", "atol")
"""The keys of :func:`track_walk`'s ``options`` (a suite's ``[tracking].options``)."""

_INJECTED = {"controller": 2, "observer": 1, "disturbance": 1}
"""How many leading arguments gaitbench passes each tracking plugin itself (model and reference; model;
experiment): the rest of its parameters are its options."""


def check_tracking_options(options: Mapping[str, Any], registry: PluginRegistry, controller: str = "thesis",
                           observer: str = "thesis", disturbance: str = "friction") -> None:
    """Raise :class:`~gaitbench.options.OptionError` for the first of ``options`` that :func:`track_walk` would
    refuse, before any walk is solved: unknown keys, the plugins' own options (their signatures and
    ``check_options`` hooks), and the values of ``sample_rate``, ``steps``, ``fall``, ``rtol`` and ``atol``.
    The option is named as a dotted path (``controller.kp``, ``fall.hip_fraction``). Unknown plugin names raise
    :class:`~gaitbench.plugins.UnknownPluginError`, as building them would."""
    from gaitbench.options import OptionError, check_options, describe, unknown_option

    for name, value in options.items():
        if name not in TRACKING_OPTIONS:
            raise unknown_option(name, TRACKING_OPTIONS)
        if name in _INJECTED or name == "fall":
            if not isinstance(value, Mapping):
                raise OptionError(name, f"expected a table of options, found {describe(value)}")
        elif name == "steps":
            if not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
                raise OptionError(name, f"expected an integer ≥ 1, found {describe(value)}")
        elif not (value is None and name == "sample_rate") and not (
                isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value) and value > 0):
            raise OptionError(name, f"expected a number > 0, found {describe(value)}")
    names = {"controller": controller, "observer": observer, "disturbance": disturbance}
    for kind, name in names.items():
        factory = registry.get(kind, name).factory
        try:
            check_options(factory, options.get(kind) or {}, kind=kind, injected=_INJECTED[kind])
        except OptionError as error:
            raise OptionError(f"{kind}.{error.option}", f"{kind} {name!r}: {error.message}") from None
    fall = dict(options.get("fall") or {})
    allowed = [item.name for item in fields(FallCriteria)]
    for name in fall:
        if name not in allowed:
            raise OptionError(f"fall.{name}", unknown_option(name, allowed).message)
    try:
        FallCriteria(**fall)
    except (TypeError, ValueError) as error:
        raise OptionError("fall", str(error)) from None


def track_walk(walk_json_path_or_result: str | Path | WalkResult, controller: str = "thesis",
               observer: str = "thesis", disturbance: str = "friction", options: dict | None = None,
               registry: PluginRegistry | None = None, experiment: Experiment | None = None) -> TrackingResult:
    """Track a stored walk (path to its JSON, NPZ beside it) or an in-memory :class:`WalkResult`.

    ``experiment`` is the walk's experiment when it was built with options (the energetics family); by default
    it is rebuilt from the walk's experiment name.

    ``options`` may hold ``controller``, ``observer`` and ``disturbance`` (dicts of plugin options), and
    ``sample_rate`` (Hz, zero-order hold; absent or None for continuous control), ``steps`` (track only the
    first K), ``fall`` (dict of :class:`FallCriteria` fields), ``rtol`` and ``atol``. Unknown plugin names raise
    :class:`~gaitbench.plugins.UnknownPluginError`; a bad result file raises :class:`TrackingInputError`.
    """
    options = dict(options or {})
    registry = registry or load_registry()
    check_tracking_options(options, registry, controller, observer, disturbance)
    reference = load_reference(walk_json_path_or_result, registry, experiment)
    experiment = reference.experiment
    plugin_options = {kind: dict(options.get(kind) or {}) for kind in ("controller", "observer", "disturbance")}
    built_controller = registry.create("controller", controller, reference.model, reference,
                                       **plugin_options["controller"])
    built_observer = registry.create("observer", observer, reference.model, **plugin_options["observer"])
    built_disturbance = registry.create("disturbance", disturbance, experiment, **plugin_options["disturbance"])
    configuration = {"controller": {"name": controller, "options": plugin_options["controller"]},
                     "observer": {"name": observer, "options": plugin_options["observer"]},
                     "disturbance": {"name": disturbance, "options": plugin_options["disturbance"]}}
    result = track(reference, built_controller, built_observer, built_disturbance,
                   sample_rate=options.get("sample_rate"), steps=options.get("steps"),
                   fall=FallCriteria(**options.get("fall", {})), rtol=options.get("rtol", DEFAULT_RTOL),
                   atol=options.get("atol", DEFAULT_ATOL), configuration=configuration)
    result.walk["source"] = None if isinstance(walk_json_path_or_result, WalkResult) else str(walk_json_path_or_result)
    return result


def load_reference(walk_json_path_or_result: str | Path | WalkResult, registry: PluginRegistry | None = None,
                   experiment: Experiment | None = None) -> Reference:
    """The reference of a stored walk (JSON path, NPZ beside it) or of an in-memory :class:`WalkResult`."""
    registry = registry or load_registry()
    if isinstance(walk_json_path_or_result, WalkResult):
        walk = walk_json_path_or_result
        return Reference.from_walk(walk, experiment or registry.create("experiment", walk.experiment))
    return Reference.from_walk(*load_walk(walk_json_path_or_result, registry))
