"""The per-step gait problem: what is fixed by its structure, and what changes from solve to solve.

A step is posed in *role* coordinates (stance leg first, swing leg second) with the stance-1 equations of the
robot whose legs are relabelled accordingly. This is exact — the two stance cases are mirror images under
relabelling (tested in ``tests/test_mechanics.py``) — and it lets one built NLP serve odd and even steps.

Phases (docs/model.md §3, §5): ``first`` is the 2-DOF First-Phase problem (stance foot pinned, no push-off);
``second`` adds the 4-DOF quantities: the push-off impulse and its energy, and the exact stance-foot ground
reaction with optional unilateral-contact and friction-cone constraints. During swing the stance foot is held,
so the swing dynamics of both phases are the pinned model's (identical to the 2-DOF model, tested).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gaitbench.model.experiment import Limits
from gaitbench.model.robot import RobotParameters
from gaitbench.model.terrain import TERRAIN_KINK_SMOOTHING
from gaitbench.problem.objective import NET_POWER, Objective

PHASES = ("first", "second")
ABSOLUTE_VALUE_FORMS = ("slack", "smooth")
CLEARANCE_FORMS = ("terrain", "chord", "off")
ANGLE_LIMIT_FORMS = ("physical", "thesis")
START_POSES = ("on-ground", "printed")
PUSH_OFF_COSTS = ("impulse", "thesis")
FIRST_PHASE_COSTS = ("objective", "effort")

OPTION_CHOICES: dict[str, tuple[str, ...]] = {
    "absolute_value": ABSOLUTE_VALUE_FORMS,
    "clearance": CLEARANCE_FORMS,
    "angle_bounds": ANGLE_LIMIT_FORMS,
    "start_pose": START_POSES,
    "push_off_cost": PUSH_OFF_COSTS,
    "first_phase_cost": FIRST_PHASE_COSTS,
}
"""The allowed values of every string-valued :class:`ProblemOptions` field (suites and ``solve -p`` check them)."""


@dataclass(frozen=True)
class ProblemOptions:
    """Modelling options of a step problem; part of the NLP's structure (changing them rebuilds)."""

    limits: Limits = field(default_factory=Limits)
    absolute_value: str = "slack"  # |hip power| in the objective: "slack" (exact split) or "smooth" (thesis)
    smoothing_eps: float = 0.1  # ε of the thesis's √(x² + ε²), used with absolute_value = "smooth" (docs/model.md §5)
    # Interior nodes keep the swing foot above: "terrain" (docs/model.md §4), the ground profile through the footholds
    # it passes; "chord", the line of the current step's chord (the thesis's form); "off", nowhere (scuffing allowed,
    # as the passive-walking literature allows it).
    clearance: str = "terrain"
    # Swing-foot height over l above that ground at interior nodes. The legs must cross, and at the crossing the
    # height is exactly 0 (docs/deviations.md, "Swing-foot clearance"), so any positive margin makes fine grids
    # infeasible.
    clearance_margin: float = 0.0
    # The length (over l) over which the "terrain" profile's bend under the stance foot is rounded
    # (:func:`gaitbench.model.terrain.terrain_clearance`). Where the ground dips at the stance foot, a leg without a
    # knee cannot swing through the bend above the ground, and only this rounding lets it pass; a grid fine enough
    # to resolve it then charges a detour that a coarser grid steps over (docs/model.md §4).
    clearance_rounding: float = TERRAIN_KINK_SMOOTHING
    # The old stance foot leaves the ground at push-off: its velocity after heel strike along the normal of the
    # step's chord is at least this (l/s; docs/model.md §3). ``lift_off = False`` is the thesis's literal problem.
    lift_off: bool = True
    lift_off_rate: float = 0.0
    # Leg-angle limits (docs/model.md §4): "physical", no leg points into the ground of its step (|q − θ| ≤ π/2);
    # "thesis", the printed −π/2 ≤ q ≤ π from the vertical (``limits.angle_bounds``).
    angle_bounds: str = "physical"
    # The state step 1 starts from (docs/model.md §4): "on-ground", the printed pose rotated so that both feet touch the
    # ground, keeping its inter-leg angle and rates; "printed", the experiment's initial state as printed.
    start_pose: str = "on-ground"
    approach_rate: float = 1e-3  # the swing foot nears the chord line at the last node at least this fast (l/s)
    # ρ in ρ·∫|τ|² dt added to the energy. The thesis's cost ∫|τ·q̇| dt is the total variation of the robot's
    # mechanical energy (τ·q̇ = dE/dt with torques on absolute angles), blind to torque: without a tie-break the
    # optimum is a continuum and solvers end at arbitrary, limit-saturating torques. Reported COTs exclude it.
    torque_regularization: float = 0.0
    # What the push-off costs (:func:`gaitbench.model.energetics.push_off_work`): "impulse", the kinetic energy its
    # impulse adds to the robot; "thesis", (3.77)'s ½ m_stance |v_foot|², the stance leg's mass at the foot's
    # velocity after it, a fraction of that energy. In the NLP and in what verification charges alike.
    push_off_cost: str = "impulse"
    # What the First Phase (2-DOF) minimises: "objective", the walk's objective (its COT); "effort", the thesis's
    # control effort ∫ (τ1² + τ2²) dt (§2.5; :data:`gaitbench.problem.objective.CONTROL_EFFORT`).
    first_phase_cost: str = "objective"
    # f_n ≥ 0, and |f_t| ≤ μ f_n, for the stance foot's reaction at the nodes with an acceleration (DMOC: the
    # interior ones) and the push-off and heel-strike impulses (second phase; docs/model.md §2)
    unilateral_contact: bool = False
    friction_coefficient: float | None = None


@dataclass(frozen=True)
class StepStructure:
    """Everything that fixes the NLP's shape: a built NLP is cached under this key."""

    phase: str
    n_nodes: int
    options: ProblemOptions = field(default_factory=ProblemOptions)
    objective: Objective = NET_POWER
    """What the step's NLP minimises and its verification reports (:mod:`gaitbench.problem.objective`)."""
    walked: bool = False
    """A First-Phase step the walk goes on from (the 2-DOF walk), whose impact map must then lift the old stance
    foot (``lift_off``). A First-Phase step that only seeds a 4-DOF one (decrease-and-conquer, warm start, the
    retry ladder) is not walked from, and the row would only refuse starts the 4-DOF step, with its push-off, can
    take (measured: downward slope, D&C-DC, N = 50, step 6)."""

    def __post_init__(self) -> None:
        for name, choices in OPTION_CHOICES.items():
            value = getattr(self.options, name)
            if value not in choices:
                raise ValueError(f"{name} must be one of {choices}, got {value!r}")
        if self.phase not in PHASES:
            raise ValueError(f"phase must be one of {PHASES}, got {self.phase!r}")
        if self.n_nodes < 3:
            raise ValueError(f"a step needs at least 3 nodes, got N = {self.n_nodes}")


@dataclass(frozen=True)
class StepData:
    """The numbers of one solve: robot, stance leg, initial state (leg order q1, q2, q̇1, q̇2), chord, slope, h.

    ``previous_slope`` is the inclination of the ground behind the stance foot (the previous step's chord, or the
    ground the walk starts on): with ``slope`` it gives the terrain profile the swing foot passes over. It defaults
    to ``slope``, a uniform slope.
    """

    robot: RobotParameters
    stance: int
    initial_state: np.ndarray
    chord: float
    slope: float
    time_step: float
    previous_slope: float | None = None

    def parameter_vector(self) -> np.ndarray:
        """Parameters in the order of :data:`PARAMETER_LAYOUT`, in role coordinates."""
        return np.concatenate([
            role_robot_vector(self.robot, self.stance),
            legs_to_roles(self.initial_state, self.stance),
            [self.chord, self.slope, self.time_step],
            [self.slope if self.previous_slope is None else self.previous_slope],
        ])


PARAMETER_LAYOUT = {"robot": slice(0, 8), "initial_state": slice(8, 12), "chord": 12, "slope": 13, "time_step": 14,
                    "previous_slope": 15}
N_STEP_PARAMETERS = 16


def role_robot_vector(robot: RobotParameters, stance: int) -> np.ndarray:
    """The robot's parameter vector with the stance leg's mass and inertia in Leg 1's place."""
    vector = robot.vector()
    if stance == 2:
        vector[[0, 1]] = vector[[1, 0]]
        vector[[5, 6]] = vector[[6, 5]]
    return vector


def legs_to_roles(values: np.ndarray, stance: int) -> np.ndarray:
    """Reorder (leg 1, leg 2) pairs — in a vector of pairs, or the last axis of (…, 2) arrays — to (stance, swing).

    The map is its own inverse, so it also takes role order back to leg order.
    """
    values = np.asarray(values, dtype=float)
    if stance == 1:
        return values.copy()
    if values.ndim == 1:
        return values.reshape(-1, 2)[:, ::-1].ravel()
    return values[..., ::-1].copy()


roles_to_legs = legs_to_roles


def sectional_structure(structure: StepStructure, start_node: int) -> StepStructure:
    """The Decrease & Conquer sectional problem: the same step started at node k0 (1-based) from a given state.

    It covers nodes k0 … N with the same time step h (pass the complete step's h in :class:`StepData`), so it is
    a step problem with N − k0 + 1 nodes; its NLP is built once per node count and reused for every step.
    """
    if not 1 <= start_node <= structure.n_nodes - 2:
        raise ValueError(f"start node k0 = {start_node} must lie in 1 … N − 2 = {structure.n_nodes - 2}")
    return StepStructure(structure.phase, structure.n_nodes - start_node + 1, structure.options, structure.objective)
