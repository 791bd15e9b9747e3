"""The closed loop: the hybrid robot under a controller, an observer and a disturbance, step after step.

The plant is the model the walk was solved with (4-DOF with the stance foot held, or the 2-DOF First Phase
model): M q̈ + C q̇ + G + d = B τ + Sᵀ f, with the disturbance d on the left-hand side as the thesis's "+ d̂" in
its laws implies (thesis §4.3). Each step runs for the reference's duration; at its end come the push-off the
controller commands (4-DOF) and the plastic heel strike, exactly as in docs/model.md §3 (the landing is checked,
:mod:`gaitbench.control.falls`). Control is continuous, or sampled with a zero-order hold at a given rate
(restarted at every impact). The observer always runs in continuous time on the measured angles and the applied
torques.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from gaitbench.contracts import Controller, Disturbance, Observer
from gaitbench.control.dynamics import held_foot_acceleration
from gaitbench.control.falls import FallCriteria, fall_events, landing_miss
from gaitbench.control.reference import Reference
from gaitbench.control.results import SERIES_KEYS, Fall, StepTracking, TrackingResult
from gaitbench.model.energetics import cost_of_transport, hip_power
from gaitbench.model.mechanics import BipedModel
from gaitbench.step_info import StepInfo

DEFAULT_RTOL = 1e-10
DEFAULT_ATOL = 1e-10
SAMPLES_PER_INTERVAL = 8
"""Recorded samples per reference grid interval: the grid the error metrics and the time series use."""


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
        walk={"experiment": walk.experiment, "experiment_options": walk.experiment_options,
              "transcription": walk.transcription, "solver": walk.solver, "strategy": walk.strategy, "N": walk.N,
              "phase": walk.phase, "trajectory": reference.trajectory},
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

    # -- one step ---------------------------------------------------------------------------------------------
    def _integrate(self, info, x, grid):
        """States at the grid times (rows), the applied torques there, and the fall if one happened."""
        events = fall_events(self.reference, info, self.criteria)
        functions = [event for event, _ in events]
        # Segments end at every node, where the reference's acceleration may jump (C¹ interpolants), and at every
        # sampling instant; each is then smooth for the integrator, the reference read on its interval up to and at
        # its end (ReferenceStep.piece).
        reference = self.reference.step(info)
        breaks = np.asarray(reference.times, dtype=float)
        samples = np.zeros(0)
        if self.sample_rate is not None:
            samples = np.arange(0.0, info.duration, 1.0 / self.sample_rate)
            breaks = np.r_[breaks, samples]
        breaks = np.unique(np.clip(breaks, 0.0, info.duration))
        breaks = breaks[np.r_[True, np.diff(breaks) > 1e-12]]
        held = None
        times, states, torques = [0.0], [x], [self._control(0.0, x, info)]
        try:
            for a, b in zip(breaks[:-1], breaks[1:], strict=True):
                reference.piece = reference.interval(a)
                if samples.size and np.min(np.abs(samples - a)) <= 1e-12:
                    held = self._control(a, x, info)
                inside = grid[(grid > a + 1e-12) & (grid < b - 1e-12)]
                solution = solve_ivp(self._rhs(info, held), (a, b), x, method="DOP853", t_eval=np.r_[inside, b],
                                     rtol=self.rtol, atol=self.atol, events=functions)
                # an integration stopped (a fall, a failure) before its first output time returns its states as []
                reached = np.asarray(solution.y, dtype=float).reshape(len(x), -1).T
                recorded = [(t, state) for t, state in zip(solution.t, reached, strict=True)
                            if np.min(np.abs(grid - t)) <= 1e-12]
                for t, state in recorded:
                    times.append(float(t))
                    states.append(state)
                    torques.append(held if held is not None else self._control(t, state, info))
                if solution.status == -1:
                    after = solution.t[-1] if len(solution.t) else a  # no output time reached: after the start
                    self.failure = f"step {info.index}: integration failed after t = {after:.4f} s " \
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
        finally:
            reference.piece = None
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
            miss = landing_miss(self.reference, info, q_end)
            if miss > self.criteria.ground_tolerance:
                self.fall = Fall(info.index, info.start_time + info.duration, "swing foot missed the ground at heel "
                                 f"strike ({miss:.3f} m off)")
                completed = False
            else:
                strike = self.model.heel_strike(q_end, dq_plus, info.stance)
                estimate = self.model.heel_strike(q_end, dq_hat_plus, info.stance).dq[:2]
                next_info = self._info(info.index + 1, info.start_time + info.duration)
                observer_state = (self.observer.reset(strike.q, strike.dq, estimate, d_hat, next_info)
                                  if next_info else np.zeros(m))
                next_state = np.concatenate([strike.q, strike.dq, observer_state, [0.0]])
        self._record(info, ref, times, states, torques, completed, impulse, energy)
        return next_state

    def _push_off(self, q, dq, impulse, info):
        """Velocities after the commanded impulse and the disturbance's impulse, and the actuator's work."""
        dq_plus = self.model.push_off(q, dq, impulse, info.stance)[0]
        extra = np.asarray(self.disturbance.impulse(q, dq_plus, info), dtype=float)
        if np.any(extra):
            dq_plus = resisted_velocities(dq_plus, np.linalg.solve(self.model.mass_matrix(q, info.stance), extra),
                                          extra)
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
            cot_ideal=self.reference.ideal_cot(info),
        ))
        self._series.append({"t": info.start_time + times, "step": np.full(len(times), info.index),
                             "q_desired": q_d, "q": q, "dq_desired": dq_d, "dq": dq, "dq_estimated": dq_hat,
                             "tau": torques, "disturbance": d_true, "disturbance_estimated": d_hat})

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
        x = np.concatenate([q0, dq0, self.observer.reset(q0, dq0, dq_d, np.zeros(2), info), [0.0]])
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


def resisted_velocities(dq: np.ndarray, change: np.ndarray, impulse: np.ndarray) -> np.ndarray:
    """The velocities ``dq − α·change`` after a disturbance's generalized ``impulse`` (whose effect on the
    velocities is ``change`` = M⁻¹ impulse), with α ≤ 1 as large as lets no velocity the impulse resists change sign.

    A disturbance's impulse resists the motion (friction's does, evaluated at the velocities ``dq``); applied in full
    it would, on a slow foot, reverse the very velocity it brakes and add energy. Scaled this way it at most brings
    that velocity to rest, as a Coulomb impulse does."""
    alpha = 1.0
    for velocity, delta, push in zip(dq, change, impulse, strict=True):
        if push * velocity > 0 and delta * velocity > 0 and abs(delta) > abs(velocity):
            alpha = min(alpha, velocity / delta)
    return dq - alpha * change

