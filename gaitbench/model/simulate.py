"""Hybrid forward simulation of the biped: continuous swing, then push-off and heel strike located by events.

Heel strike is found geometrically, not by the clock: the swing foot must first pass the stance foot
(leg crossing), then come down through the chord line of the current step. For equal legs the swing foot is
on that line exactly when the legs' mean angle equals the step inclination θ, which gives a smooth event
function. A swing foot that is below the line just after crossing is the classic compass-gait scuff; it is
recorded (the passive-walking literature ignores it, and so does the simulator) rather than treated as impact.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from scipy.integrate import solve_ivp

from gaitbench.model.mechanics import BipedModel, HeelStrike, other_leg
from gaitbench.model.terrain import swing_foot_advance


class Control(Protocol):
    """A control law for the whole walk: hip torques during swing and the push-off impulse at the end of a step."""

    def torque(self, t: float, q: np.ndarray, dq: np.ndarray, step: int) -> np.ndarray:
        """Hip torques (τ1, τ2) at time ``t`` since the start of ``step`` (1-based)."""

    def push_off(self, q: np.ndarray, dq: np.ndarray, step: int) -> float:
        """Push-off impulse (N·s, ≥ 0) applied just before the heel strike that ends ``step``."""


@dataclass(frozen=True)
class Passive:
    """No torque and no push-off: the passive dynamic walker."""

    def torque(self, t: float, q: np.ndarray, dq: np.ndarray, step: int) -> np.ndarray:
        return np.zeros(2)

    def push_off(self, q: np.ndarray, dq: np.ndarray, step: int) -> float:
        return 0.0


@dataclass(frozen=True)
class OpenLoop:
    """Torques as a function of (time since step start, step) and one push-off impulse per step."""

    torques: Callable[[float, int], Sequence[float]]
    push_off_impulses: Sequence[float] = ()

    def torque(self, t: float, q: np.ndarray, dq: np.ndarray, step: int) -> np.ndarray:
        return np.asarray(self.torques(t, step), dtype=float)

    def push_off(self, q: np.ndarray, dq: np.ndarray, step: int) -> float:
        return float(self.push_off_impulses[step - 1]) if step <= len(self.push_off_impulses) else 0.0


@dataclass
class SimulatedStep:
    """One step of a hybrid trajectory; times are global, states leg-labelled (q1, q2[, q3, q4])."""

    step: int
    stance: int
    slope: float
    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    tau: np.ndarray
    ground_reaction: np.ndarray | None  # (horizontal f_x, vertical f_y) at the stance foot, 4-DOF only
    scuffed: bool = False  # swing foot below the chord line just after leg crossing
    push_off_impulse: float = 0.0
    push_off_energy: float = 0.0
    dq_after_push_off: np.ndarray | None = None
    heel_strike: HeelStrike | None = None

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])


@dataclass
class HybridTrajectory:
    """A simulated walk. ``failure`` says which step went wrong and why; the steps before it are kept."""

    dof: int
    steps: list[SimulatedStep] = field(default_factory=list)
    failure: str | None = None

    @property
    def completed(self) -> bool:
        return self.failure is None

    @property
    def events(self) -> list[dict]:
        """Push-off and heel-strike events in time order, with the quantities a plot or a check needs."""
        events = []
        for step in self.steps:
            if step.heel_strike is None:
                continue
            t = float(step.t[-1])
            if self.dof == 4:
                events.append(
                    {
                        "time": t,
                        "step": step.step,
                        "kind": "push-off",
                        "impulse": step.push_off_impulse,
                        "energy": step.push_off_energy,
                    }
                )
            events.append(
                {
                    "time": t,
                    "step": step.step,
                    "kind": "heel-strike",
                    "impulse": step.heel_strike.impulse.tolist(),
                    "lift_off_velocity": step.heel_strike.lift_off_velocity,
                }
            )
        return events


def simulate(
    model: BipedModel,
    slopes: Sequence[float],
    q0: Sequence[float],
    dq0: Sequence[float],
    control: Control | None = None,
    *,
    first_stance: int = 1,
    max_step_duration: float = 5.0,
    rtol: float = 1e-10,
    atol: float = 1e-10,
    max_solver_step: float = np.inf,
    step_times: Sequence[Sequence[float]] | None = None,
) -> HybridTrajectory:
    """Simulate ``len(slopes)`` steps; ``slopes[i]`` is the inclination θ of step i+1's chord line (rad, uphill > 0).

    By default heel strike is located by event detection. With ``step_times`` (local times per step, starting at
    0) each step instead ends by the clock at its last time and its states are reported at exactly those times:
    this is how an optimized gait is re-simulated, since its heel strike happens at the step's end by construction.
    A step that finds no heel strike within ``max_step_duration`` seconds, or whose integration fails, ends the
    walk with ``failure`` set; everything simulated up to then is returned.
    """
    control = control or Passive()
    q = np.asarray(q0, dtype=float)
    dq = np.asarray(dq0, dtype=float)
    if q.shape != (model.dof,) or dq.shape != (model.dof,):
        raise ValueError(f"initial state must have {model.dof} positions and {model.dof} velocities")
    trajectory = HybridTrajectory(dof=model.dof)
    stance, t0 = first_stance, 0.0
    for index, slope in enumerate(slopes, start=1):
        if step_times is not None:
            step, failure = _simulate_clocked_step(
                model, control, index, stance, float(slope), t0, q, dq, np.asarray(step_times[index - 1]), rtol, atol
            )
        else:
            step, failure = _simulate_step(
                model, control, index, stance, float(slope), t0, q, dq, max_step_duration, rtol, atol, max_solver_step
            )
        trajectory.steps.append(step)
        if failure:
            trajectory.failure = failure
            break
        impulse = float(control.push_off(step.q[-1], step.dq[-1], index))
        if impulse < 0:
            trajectory.failure = f"step {index}: push-off impulse {impulse} N·s is negative"
            break
        dq_pre_impact = step.dq[-1]
        if model.dof == 4:
            dq_pre_impact, energy = model.push_off(step.q[-1], step.dq[-1], impulse, stance)
            step.push_off_impulse, step.push_off_energy = impulse, float(energy)
        elif impulse:
            trajectory.failure = f"step {index}: the 2-DOF model has no push-off actuator (impulse {impulse})"
            break
        step.dq_after_push_off = dq_pre_impact
        step.heel_strike = model.heel_strike(step.q[-1], dq_pre_impact, stance)
        q, dq = step.heel_strike.q, step.heel_strike.dq
        stance, t0 = other_leg(stance), float(step.t[-1])
    return trajectory


def _swing_rhs(model, control, index, stance, t0, inside: tuple[float, float] | None = None):
    """The swing ODE; with ``inside`` = (a, b), controls are read at times clamped a hair inside [a, b]."""
    n = model.dof
    if inside is None:
        def control_time(t):
            return t
    else:
        margin = _INSIDE * (inside[1] - inside[0])
        low, high = inside[0] + margin, inside[1] - margin

        def control_time(t):
            return min(max(t, low), high)

    def rhs(t, x):
        tau = control.torque(control_time(t) - t0, x[:n], x[n:], index)
        return np.concatenate([x[n:], model.forward_dynamics(x[:n], x[n:], tau, stance)[0]])

    return rhs


_INSIDE = 1e-9
"""How far inside a piece (relative to its length) its controls are read: far enough to be on the piece's own
side of a jump at its ends, near enough that a smooth control moves by ~1e-9 of its change over the piece."""


def _simulate_clocked_step(model, control, index, stance, slope, t0, q, dq, local_times, rtol, atol):
    """Integrate piece by piece between consecutive reporting times.

    An optimized gait's controls are smooth within an interval and kink or jump at its nodes (DMOC's torques are
    piecewise constant); one integration across the whole step spends most of its effort rejecting steps at
    those corners. Each piece reads its controls just inside itself: read at its end, a jump at the node enters
    DOP853's error estimate and makes it reject step after step (DMOC at N = 100: 0.75 s per step instead of 0.03 s).
    """
    times = t0 + local_times
    states = [np.concatenate([q, dq])]
    for a, b in zip(times[:-1], times[1:], strict=True):
        solution = solve_ivp(_swing_rhs(model, control, index, stance, t0, inside=(a, b)), (a, b), states[-1],
                             method="DOP853", rtol=rtol, atol=atol)
        if solution.status != 0:
            step = _record(model, control, index, stance, slope, [times[: len(states)]], [np.array(states)], False)
            return step, f"step {index}: integration failed at t = {a - t0:.4g} s ({solution.message})"
        states.append(solution.y[:, -1])
    return _record(model, control, index, stance, slope, [times], [np.array(states)], False), None


def _simulate_step(model, control, index, stance, slope, t0, q, dq, max_duration, rtol, atol, max_solver_step):
    st, sw = (0, 1) if stance == 1 else (1, 0)
    rhs = _swing_rhs(model, control, index, stance, t0)

    def advance(t, x):  # along-chord position of the swing foot ahead of the stance foot, over l
        return swing_foot_advance(x[st], x[sw], slope)

    def mean_angle(t, x):  # zero when the swing foot is on the chord line (equal legs, legs apart)
        return 0.5 * (x[st] + x[sw]) - slope

    phases = []
    if advance(t0, np.concatenate([q, dq])) <= 0:
        phases.append((advance, 1))
    x = np.concatenate([q, dq])
    scuffed = False
    times, states = [np.array([t0])], [x[None, :]]
    t_end = t0 + max_duration
    pending = phases + [("scuff-check", 0), (mean_angle, -1)]
    t = t0
    for event, direction in pending:
        if event == "scuff-check":
            if mean_angle(t, x) < 0:
                scuffed = True
                event, direction = mean_angle, 1
            else:
                continue
        event.terminal, event.direction = True, direction
        solution = solve_ivp(
            rhs, (t, t_end), x, method="DOP853", events=event, rtol=rtol, atol=atol, max_step=max_solver_step
        )
        times.append(solution.t[1:])
        states.append(solution.y[:, 1:].T)
        if solution.status == -1:
            return _record(model, control, index, stance, slope, times, states, scuffed), (
                f"step {index}: integration failed ({solution.message})"
            )
        if solution.status == 0:
            return _record(model, control, index, stance, slope, times, states, scuffed), (
                f"step {index}: no heel strike within {max_duration} s of the step's start"
            )
        t, x = float(solution.t_events[0][0]), solution.y_events[0][0]
        times[-1][-1], states[-1][-1] = t, x
    return _record(model, control, index, stance, slope, times, states, scuffed), None


def _record(model, control, index, stance, slope, times, states, scuffed) -> SimulatedStep:
    n = model.dof
    t = np.concatenate(times)
    x = np.vstack(states)
    t0 = t[0]
    tau = np.array([control.torque(ti - t0, xi[:n], xi[n:], index) for ti, xi in zip(t, x, strict=True)])
    reaction = None
    if n == 4:
        reaction = np.array(
            [model.forward_dynamics(xi[:n], xi[n:], ui, stance)[1] for xi, ui in zip(x, tau, strict=True)]
        )
    return SimulatedStep(
        step=index,
        stance=stance,
        slope=slope,
        t=t,
        q=x[:, :n],
        dq=x[:, n:],
        tau=tau,
        ground_reaction=reaction,
        scuffed=scuffed,
    )
