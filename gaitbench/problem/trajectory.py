"""A solved step as a continuous-time trajectory, and seeds: initial guesses read off trajectories.

:class:`StepTrajectory` is what a transcription's solution becomes once decoded: nodal values in leg order plus the
transcription's own interpolant. The helpers here read node values as curves (:func:`locate_interval`,
:func:`cubic_hermite`, :func:`nodal_trajectory`) and make and sample :data:`Seed` guesses, for transcriptions and
for whoever patches or re-seeds trajectories (strategies, tracking).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from gaitbench.model.terrain import heel_strike_configuration
from gaitbench.problem.gait_problem import PARAMETER_LAYOUT, legs_to_roles, roles_to_legs


@dataclass
class Interpolant:
    """Continuous-time state and control of a solved step, in role order, from the transcription's own scheme."""

    state: Callable[[float], tuple[np.ndarray, np.ndarray]]  # t -> (q, dq)
    control: Callable[[float], np.ndarray]  # t -> tau


Seed = Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]]
"""An initial guess for a step as a function of time since the step's start: t ↦ (q, q̇, τ) in role order.
Transcriptions sample it wherever their variables live (nodes, midpoints, intervals)."""


@dataclass
class StepTrajectory:
    """A solved step in leg order: nodal states, controls (at ``control_times``) and the push-off impulse."""

    times: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    tau: np.ndarray
    control_times: np.ndarray
    push_off: float
    stance: int
    _interpolant: Interpolant
    _seed_samples: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]] = field(
        default_factory=dict, repr=False, compare=False)

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        q, dq = self._interpolant.state(t)
        return roles_to_legs(q, self.stance), roles_to_legs(dq, self.stance)

    def control(self, t: float) -> np.ndarray:
        return roles_to_legs(self._interpolant.control(t), self.stance)

    def seed(self, offset: float = 0.0) -> Seed:
        """This trajectory from time ``offset`` on, as the initial guess of another step problem.

        Meant for problems with the same stance leg: a First-Phase trajectory seeding the Second Phase, or the
        tail of a complete trajectory seeding a sectional problem that starts ``offset`` seconds in. The samples
        are kept per time: Decrease & Conquer seeds its N − 3 sections from one trajectory, mostly at the same
        node times.
        """
        interpolant, samples = self._interpolant, self._seed_samples

        def seed(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            time = t + offset
            if time not in samples:
                q, dq = interpolant.state(time)
                samples[time] = (q, dq, interpolant.control(time))
            return tuple(values.copy() for values in samples[time])  # the caller's to change

        return seed

    @property
    def duration(self) -> float:
        return float(self.times[-1] - self.times[0])


def blended_seed(p: np.ndarray, n_nodes: int) -> Seed:
    """docs/model.md §7: angles blend linearly from the initial state to the heel-strike configuration, with the
    matching constant rates and zero torque."""
    layout = PARAMETER_LAYOUT
    x0 = p[layout["initial_state"]]
    chord, slope, h, leg = p[layout["chord"]], p[layout["slope"]], p[layout["time_step"]], p[3]
    q_end = np.array(heel_strike_configuration(chord, slope, leg))
    duration = h * (n_nodes - 1)
    rate = (q_end - x0[:2]) / duration

    def seed(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return x0[:2] + rate * t, rate.copy(), np.zeros(2)

    return seed


def sample_seed(seed: Seed, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The seed at ``times``: (q, q̇, τ), each 2 × len(times), role order."""
    samples = [seed(float(t)) for t in times]
    return tuple(np.column_stack([sample[i] for sample in samples]) for i in range(3))


def locate_interval(t: float, h: float, n_nodes: int) -> tuple[int, float]:
    """Interval k (0-based) holding time t on a uniform grid, and the fraction s ∈ [0, 1] of it elapsed.

    A time equal to a node opens the interval starting there, which matters for piecewise-constant controls.
    """
    # Scalar arithmetic, not a search over the node times: interpolants call this thousands of times per step.
    # Node k's time is k * h exactly as the grid computes it, so the comparisons below match a search of the grid.
    k = int(t // h)
    if (k + 1) * h <= t:
        k += 1
    elif k * h > t:
        k -= 1
    k = min(max(k, 0), n_nodes - 2)
    return k, min(max((t - k * h) / h, 0.0), 1.0)


def cubic_hermite(y0: np.ndarray, y1: np.ndarray, m0: np.ndarray, m1: np.ndarray, s: float):
    """The cubic with values y0, y1 and slopes m0, m1 (per unit s) at s = 0, 1: its value and d/ds at s."""
    c2 = -3 * y0 - 2 * m0 + 3 * y1 - m1
    c3 = 2 * y0 + m0 - 2 * y1 + m1
    return y0 + m0 * s + c2 * s**2 + c3 * s**3, m0 + 2 * c2 * s + 3 * c3 * s**2


def nodal_trajectory(times: np.ndarray, q: np.ndarray, dq: np.ndarray, tau: np.ndarray, push_off: float,
                     stance: int, per_interval: bool = False) -> StepTrajectory:
    """Values at the nodes of a uniform grid (leg order, one torque per node) read as a step trajectory: cubic Hermite
    angles through the nodal (q, q̇), linear rates and torques. The smoothest reading of node values that carry no
    interpolant of their own, such as decrease and conquer's node-wise patchworks.

    With ``per_interval`` the torque at node k is that of the interval k to k + 1, held on it (a transcription with
    one control per interval, DMOC), and the last node's is left out: a transcription reading the torques back
    gets the ones it solved for, not averages of two intervals'."""
    n, h = len(times), float(times[1] - times[0])
    q_roles, dq_roles, tau_roles = (legs_to_roles(np.asarray(a, dtype=float), stance) for a in (q, dq, tau))

    def state(t: float) -> tuple[np.ndarray, np.ndarray]:
        k, s = locate_interval(t, h, n)
        angles, _ = cubic_hermite(q_roles[k], q_roles[k + 1], h * dq_roles[k], h * dq_roles[k + 1], s)
        return angles, (1 - s) * dq_roles[k] + s * dq_roles[k + 1]

    def control(t: float) -> np.ndarray:
        k, s = locate_interval(t, h, n)
        return tau_roles[k] if per_interval else (1 - s) * tau_roles[k] + s * tau_roles[k + 1]

    controls = slice(0, n - 1) if per_interval else slice(0, n)
    return StepTrajectory(times=np.asarray(times, dtype=float), q=np.asarray(q), dq=np.asarray(dq),
                          tau=np.asarray(tau)[controls], control_times=np.asarray(times, dtype=float)[controls],
                          push_off=push_off, stance=stance, _interpolant=Interpolant(state, control))
