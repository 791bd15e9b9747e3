"""What a tracking run produces: per-step errors and energies, the time series, a fall, and the JSON + NPZ file."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gaitbench.model.energetics import average_cot


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
    walk: dict  # experiment (and options), transcription, solver, strategy, N, phase, trajectory, source file
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
        """ACOT of the reference over the steps the robot completed, in the tracked measure
        (:meth:`gaitbench.control.reference.Reference.from_walk`)."""
        return self._acot("cot_reference")

    @property
    def acot_tracked(self) -> float | None:
        return self._acot("cot_tracked")

    @property
    def acot_increase_percent(self) -> float | None:
        """How much more the tracked walk cost than its reference, in percent; None without both, or for a free
        reference (a passive gait), against which no increase is a percentage."""
        reference, tracked = self.acot_reference, self.acot_tracked
        if reference is None or tracked is None or reference == 0:
            return None
        return 100.0 * (tracked - reference) / reference

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
