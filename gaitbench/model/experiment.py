"""A walking experiment: robot, terrain, initial state, step timing, friction disturbance and actuator limits.

Leg labels are fixed and roles alternate (docs/model.md §1): in step i (1-based) Leg 1 is the stance leg when i is
odd and Leg 2 when i is even, so Leg 2 swings first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np
from rich import box
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from gaitbench.model.robot import InvalidParameterError, RobotParameters
from gaitbench.model.terrain import (
    THESIS_ANGLE_BOUNDS,
    StepCheck,
    Terrain,
    check_feasibility,
    heel_strike_configuration,
)

STATE_NAMES = ("q1", "q2", "q3", "q4", "dq1", "dq2", "dq3", "dq4")
"""Order of the 8-vector state: leg angles, stance-foot position, and their rates (leg-labelled)."""


@dataclass(frozen=True)
class FrictionParameters:
    """Steady-state joint friction, the disturbance of the thesis's tracking runs (§5.1).

    D(q̇) = [F_c + (F_s − F_c) exp(−|q̇/v_s|^n)] sgn(q̇) + f_v q̇ per joint (docs/model.md §9). The rotational
    hip joints 1 and 2 share ``Fc`` (Nm), ``Fs`` (Nm), ``fv`` (Nm/(rad/s)) and ``vs`` (rad/s). For the linear
    stance-foot joints 3 and 4 the thesis gives F_c, F_s and f_v as multiples of the step's time step h^(i)
    ("Fc3 = Fc4 = 5h(i) Ns"); ``Fc_lin``, ``Fs_lin`` and ``fv_lin`` are those multipliers, ``vs_lin`` (m/s)
    is used as printed. The Stribeck exponent ``n`` was lost with Fig. 5.1; n = 2 is the gaitbench choice.
    """

    Fc: float
    Fs: float
    fv: float
    vs: float
    Fc_lin: float
    Fs_lin: float
    fv_lin: float
    vs_lin: float
    n: float = 2.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            _require_finite(f"friction {f.name}", value)
            if value < 0:
                raise InvalidParameterError(f"friction {f.name} = {value}: cannot be negative")
        for name in ("vs", "vs_lin", "n"):
            if getattr(self, name) == 0:
                raise InvalidParameterError(f"friction {name} = 0: must be positive")

    def joint_coefficients(self, h: float) -> dict[str, np.ndarray]:
        """Per-joint (j = 1..4) Fc, Fs, fv, vs for a step with time step ``h`` (linear ones scaled by h)."""
        return {
            "Fc": np.array([self.Fc, self.Fc, self.Fc_lin * h, self.Fc_lin * h]),
            "Fs": np.array([self.Fs, self.Fs, self.Fs_lin * h, self.Fs_lin * h]),
            "fv": np.array([self.fv, self.fv, self.fv_lin * h, self.fv_lin * h]),
            "vs": np.array([self.vs, self.vs, self.vs_lin, self.vs_lin]),
        }


@dataclass(frozen=True)
class Limits:
    """Actuator and joint limits of the gait problems (thesis §3.6, constraints (9)–(12)).

    The thesis's torque, velocity and push-off limits were in the lost Fig. 5.1 (docs/model.md §8). The defaults
    are gaitbench choices for the forward robot (80 kg, 1 m legs), generous enough for every thesis step to be
    feasible; :meth:`sized_for` scales them to another robot:

    - ``tau_max`` = 3000 Nm (|τ| ≤ tau_max). The thesis's long steps must swing the legs by up to 2.5 rad in the
      fixed 0.7343 s: with 300 Nm the forward walk is infeasible from step 4, with 1000 Nm from step 5 (measured
      with Hermite–Simpson at N = 51). The bound can be active at the optimum, because the thesis's cost
      (net hip power, i.e. the total variation of mechanical energy) does not penalize torque at all.
    - ``dq_max`` = 50 rad/s: the forward walk's optima reach 16 rad/s at N = 51.
    - ``push_off_max`` = 500 N·s: far above the impulse that restores a heel-strike loss at walking speed.

    Whether a bound is active is reported with every result. ``angle_bounds`` are the thesis's −π/2 ≤ q ≤ π,
    used only with the problem option ``angle_bounds = "thesis"``; the default limits are physical (docs/model.md §4).
    """

    tau_max: float = 3000.0
    dq_max: float = 50.0
    push_off_max: float = 500.0
    angle_bounds: tuple[float, float] = THESIS_ANGLE_BOUNDS

    def __post_init__(self) -> None:
        for name in ("tau_max", "dq_max", "push_off_max"):
            value = getattr(self, name)
            _require_finite(f"limit {name}", value)
            if value <= 0:
                raise InvalidParameterError(f"limit {name} = {value}: must be positive")
        bounds = tuple(self.angle_bounds)
        if len(bounds) != 2:
            raise InvalidParameterError(f"limit angle_bounds = {self.angle_bounds!r}: expected (low, high)")
        for value in bounds:
            _require_finite("limit angle_bounds", value)
        if not bounds[0] < bounds[1]:
            raise InvalidParameterError(f"limit angle_bounds = {bounds}: lower must be below upper")
        object.__setattr__(self, "angle_bounds", (float(bounds[0]), float(bounds[1])))

    @classmethod
    def sized_for(cls, robot: RobotParameters) -> Limits:
        """The default limits scaled from the forward robot's (80 kg, 1 m legs) to ``robot`` (docs/model.md §8).

        Each limit keeps its dimensionless size: torque in units of m g l, angular rate in √(g/l), impulse in
        m √(g l), with m the total mass. The downward slope's robot (120 kg, 1.5 m legs) gets 6750 Nm, where
        3000 Nm did not walk.
        """
        mass, leg = robot.total_mass / REFERENCE_MASS, robot.l / REFERENCE_LEG
        base = cls()
        return cls(tau_max=base.tau_max * mass * leg, dq_max=base.dq_max / math.sqrt(leg),
                   push_off_max=base.push_off_max * mass * math.sqrt(leg))


REFERENCE_MASS, REFERENCE_LEG = 80.0, 1.0
"""The forward robot's total mass (kg) and leg length (m): the robot the default :class:`Limits` are chosen for."""


GAITBENCH_LIMIT_CHOICES = {"tau_max": "Nm", "dq_max": "rad/s", "push_off_max": "N·s"}
"""Limits (with units) whose default values are gaitbench choices, not thesis values (docs/model.md §8)."""

GAITBENCH_CHOICE = "gaitbench choice, not thesis"
"""Marks a rendered value the thesis does not give (docs/model.md §8, §9)."""


@dataclass(frozen=True, eq=False)
class Experiment:
    """Everything that defines a walk, independent of the method that generates its gait.

    ``initial_state`` is (q1, q2, q3, q4, dq1, dq2, dq3, dq4) at the start of step 1, leg-labelled; it is
    stored as a read-only float array. Equality is identity (the array field has no plain ``==``).
    """

    name: str
    description: str
    robot: RobotParameters
    terrain: Terrain
    initial_state: np.ndarray
    step_duration: float
    friction: FrictionParameters | None = None
    limits: Limits = field(default_factory=Limits)
    source: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise InvalidParameterError(f"experiment name = {self.name!r}: expected a non-empty string")
        if not isinstance(self.robot, RobotParameters):
            raise InvalidParameterError(f"experiment robot: expected RobotParameters, got {type(self.robot)}")
        if not isinstance(self.terrain, Terrain):
            raise InvalidParameterError(f"experiment terrain: expected Terrain, got {type(self.terrain)}")
        if self.friction is not None and not isinstance(self.friction, FrictionParameters):
            raise InvalidParameterError("experiment friction: expected FrictionParameters or None")
        if not isinstance(self.limits, Limits):
            raise InvalidParameterError(f"experiment limits: expected Limits, got {type(self.limits)}")
        _require_finite("experiment step_duration", self.step_duration)
        if self.step_duration <= 0:
            raise InvalidParameterError(f"experiment step_duration = {self.step_duration}: must be positive")
        try:
            state = np.array(self.initial_state, dtype=float).ravel()
        except (TypeError, ValueError) as error:
            raise InvalidParameterError(f"experiment initial_state: not numeric ({error})") from error
        if state.size != len(STATE_NAMES):
            raise InvalidParameterError(
                f"experiment initial_state has {state.size} entries: expected 8 ({', '.join(STATE_NAMES)})"
            )
        bad = [name for name, value in zip(STATE_NAMES, state, strict=True) if not math.isfinite(value)]
        if bad:
            raise InvalidParameterError(f"experiment initial_state: {', '.join(bad)} not finite")
        state.flags.writeable = False
        object.__setattr__(self, "initial_state", state)

    @property
    def n_steps(self) -> int:
        return len(self.terrain)

    def stance_leg(self, step: int) -> int:
        """The stance leg's label in ``step`` (1-based): 1 for odd steps, 2 for even steps."""
        self._require_step(step)
        return 1 if step % 2 == 1 else 2

    def time_step(self, n_nodes: int) -> float:
        """h = T / (N − 1) for N nodes per step (docs/model.md §6)."""
        if n_nodes < 2:
            raise ValueError(f"n_nodes = {n_nodes}: a step needs at least 2 nodes")
        return self.step_duration / (n_nodes - 1)

    def heel_strike_configuration(self, step: int) -> tuple[float, float]:
        """Leg-labelled (q1, q2) at the end of ``step``; raises ValueError if the chord exceeds 2l."""
        geometry = self.terrain.steps[self._require_step(step) - 1]
        q_st, q_sw = heel_strike_configuration(geometry.D, geometry.theta, self.robot.l)
        return (q_st, q_sw) if self.stance_leg(step) == 1 else (q_sw, q_st)

    def feasibility(self, angle_bounds: str = "physical") -> list[StepCheck]:
        """Per-step geometry checks under the physical leg-angle limits, or the thesis's printed box."""
        box = self.limits.angle_bounds if angle_bounds == "thesis" else None
        return check_feasibility(self.terrain, self.robot.l, box)

    def start_state(self, pose: str = "on-ground") -> np.ndarray:
        """(q1, q2, q̇1, q̇2) at the start of step 1 (docs/model.md §4).

        ``on-ground``: the printed pose rotated about the stance foot until the trailing foot touches the ground
        behind it, which keeps the inter-leg angle and the rates. The thesis prints flat-ground poses (q2 = −q1)
        for its slopes, which puts the downward slope's trailing foot 0.79 m inside the ground. ``printed``: the
        state as printed.
        """
        state = np.array(self.initial_state)[[0, 1, 4, 5]]
        if pose == "printed":
            return state
        if pose != "on-ground":
            raise ValueError(f"start pose {pose!r}: expected 'on-ground' or 'printed'")
        stance, swing = self.stance_leg(1) - 1, 2 - self.stance_leg(1)
        half_angle = (state[stance] - state[swing]) / 2
        ground = self.terrain.ground_behind(1)
        state[stance], state[swing] = ground + half_angle, ground - half_angle
        return state

    def _require_step(self, step: int) -> int:
        if isinstance(step, bool) or not isinstance(step, (int, np.integer)) or not 1 <= step <= self.n_steps:
            raise ValueError(f"step = {step!r}: expected an integer in 1..{self.n_steps}")
        return int(step)


def render_experiment(experiment: Experiment, console: Console) -> None:
    """Print an experiment's parameters, its per-step geometry with feasibility, and a one-line summary."""
    console.print(f"[bold]{escape(experiment.name)}[/bold]: {escape(experiment.description)}")
    if experiment.source:
        console.print(f"Source: {escape(experiment.source)}")
    console.print(_parameter_table(experiment))
    checks = experiment.feasibility()
    console.print(_step_table(experiment, checks))
    for check in checks:
        for problem in check.described:
            console.print(f"✗ {escape(problem)}", style="red", highlight=False)
    console.print(feasibility_summary(checks))
    thesis = experiment.feasibility("thesis")
    refused = [problem for check in thesis if not check.ok for problem in check.described]
    if refused:
        console.print(f"Under the thesis's printed angle bounds (problem option angle_bounds = \"thesis\"): "
                      f"{feasibility_summary(thesis)}", highlight=False)
        for problem in refused:
            console.print(f"  {escape(problem)}", highlight=False)


def feasibility_summary(checks: list[StepCheck]) -> str:
    """E.g. "11 steps, 9 feasible, 2 infeasible: steps 1, 2"."""
    bad = [str(check.step) for check in checks if not check.ok]
    text = f"{len(checks)} steps, {len(checks) - len(bad)} feasible, {len(bad)} infeasible"
    if bad:
        text += f": step{'s' if len(bad) > 1 else ''} {', '.join(bad)}"
    return text


def _parameter_table(experiment: Experiment) -> Table:
    table = Table(title="Parameters", box=box.SIMPLE_HEAD, pad_edge=False)
    table.add_column("Parameter")
    table.add_column("Value", justify="right")
    table.add_column("Note")
    robot = experiment.robot
    for name, value, unit in (
        ("M (hip)", robot.M, "kg"), ("m1", robot.m1, "kg"), ("m2", robot.m2, "kg"),
        ("l", robot.l, "m"), ("a (foot to leg CoM)", robot.a, "m"), ("b (hip to leg CoM)", robot.b, "m"),
    ):
        table.add_row(name, f"{value:g} {unit}", "")
    for name, given, value in (("I1", robot.I1, robot.inertia1), ("I2", robot.I2, robot.inertia2)):
        table.add_row(name, f"{value:.4g} kg m²", "m l²/12 (uniform-rod default)" if given is None else "")
    table.add_row("step duration", f"{experiment.step_duration:g} s", "")
    units = ("rad", "rad", "m", "m", "rad/s", "rad/s", "m/s", "m/s")
    for name, value, unit in zip(STATE_NAMES, experiment.initial_state, units, strict=True):
        table.add_row(f"{name}(0)", f"{value:g} {unit}", "initial state")
    friction = experiment.friction
    if friction is None:
        table.add_row("friction", "none", "")
    else:
        table.add_row("Fc1 = Fc2", f"{friction.Fc:g} Nm", "")
        table.add_row("Fs1 = Fs2", f"{friction.Fs:g} Nm", "")
        table.add_row("fv1 = fv2", f"{friction.fv:g} Nm/(rad/s)", "")
        table.add_row("vs1 = vs2", f"{friction.vs:g} rad/s", "")
        table.add_row("Fc3 = Fc4", f"{friction.Fc_lin:g} h N·s", "times the step's time step h")
        table.add_row("Fs3 = Fs4", f"{friction.Fs_lin:g} h N·s", "times h")
        table.add_row("fv3 = fv4", f"{friction.fv_lin:g} h N·s/(m/s)", "times h")
        table.add_row("vs3 = vs4", f"{friction.vs_lin:g} m/s", "")
        table.add_row("Stribeck exponent n", f"{friction.n:g}", GAITBENCH_CHOICE)
    limits = experiment.limits
    defaults = Limits.sized_for(robot)
    for name, unit in GAITBENCH_LIMIT_CHOICES.items():
        value = getattr(limits, name)
        note = f"{GAITBENCH_CHOICE}, sized to the robot" if value == getattr(defaults, name) else ""
        table.add_row(name, f"{value:.4g} {unit}", note)
    table.add_row("leg-angle limits", "physical", "no leg points into the ground (docs/model.md §4)")
    lower, upper = limits.angle_bounds
    note = "thesis (10), as printed" if limits.angle_bounds == THESIS_ANGLE_BOUNDS else ""
    table.add_row("thesis angle bounds", f"[{lower:.4f}, {upper:.4f}] rad", f"{note}; angle_bounds = \"thesis\"")
    return table


def _step_table(experiment: Experiment, checks: list[StepCheck]) -> Table:
    table = Table(
        title="Steps: landing foothold (x, y) and heel-strike angles (rad)",
        box=box.SIMPLE_HEAD, pad_edge=False, collapse_padding=True,  # fits an 80-column terminal
    )
    for header in ("step", "stance", "D (m)", "θ (rad)", "θ (°)", "x (m)", "y (m)", "q_st", "q_sw", "ok"):
        table.add_column(header, justify="right")
    footholds = experiment.terrain.footholds()
    for check in checks:
        x, y = footholds[check.step]
        angles = ("—", "—") if check.q_st is None else (f"{check.q_st:.4f}", f"{check.q_sw:.4f}")
        table.add_row(
            str(check.step), f"Leg {experiment.stance_leg(check.step)}", f"{check.D:.4f}",
            f"{check.theta:.4f}", f"{math.degrees(check.theta):.2f}", f"{x:.3f}", f"{y:.3f}", *angles,
            "✓" if check.ok else "✗",
        )
    return table


def _require_finite(name: str, value: object) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InvalidParameterError(f"{name} = {value!r}: expected a finite number")
    if not math.isfinite(value):
        raise InvalidParameterError(f"{name} = {value!r}: expected a finite number")
