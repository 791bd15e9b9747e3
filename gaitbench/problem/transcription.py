"""Transcriptions turn a per-step gait problem into an :class:`~gaitbench.problem.nlp.NLP`.

A transcription plugin subclasses :class:`Transcription` and implements :meth:`Transcription.discretize`:
its decision variables, its dynamics constraints, the initial-state constraint, the quadrature of the objective's
running cost (:mod:`gaitbench.problem.step_cost`) and the interpolant of its solution
(:mod:`gaitbench.problem.trajectory`). Everything else about a step — the heel-strike configuration, clearance, the
approach to the ground, push-off and ground reactions, and the objective's event cost — is added here, identically
for every transcription, so that methods are compared on the same problem.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from gaitbench.model.energetics import push_off_work
from gaitbench.model.mechanics import BipedFunctions, biped_functions
from gaitbench.model.terrain import clearance, leg_angle_window, terrain_clearance
from gaitbench.problem.gait_problem import N_STEP_PARAMETERS, PARAMETER_LAYOUT, StepData, StepStructure, roles_to_legs
from gaitbench.problem.nlp import NLP, NLPBuilder
from gaitbench.problem.objective import CONTROL_EFFORT
from gaitbench.problem.step_cost import charged
from gaitbench.problem.trajectory import Interpolant, Seed, StepTrajectory, blended_seed


@dataclass(frozen=True)
class StepSymbols:
    """Symbolic parameters of a step problem, in role coordinates (stance leg first)."""

    vector: ca.SX
    robot: ca.SX
    initial_state: ca.SX
    chord: ca.SX
    slope: ca.SX
    time_step: ca.SX
    previous_slope: ca.SX

    @classmethod
    def create(cls) -> StepSymbols:
        p = ca.SX.sym("p", N_STEP_PARAMETERS)
        layout = PARAMETER_LAYOUT
        return cls(
            vector=p,
            robot=p[layout["robot"]],
            initial_state=p[layout["initial_state"]],
            chord=p[layout["chord"]],
            slope=p[layout["slope"]],
            time_step=p[layout["time_step"]],
            previous_slope=p[layout["previous_slope"]],
        )

    @property
    def leg_length(self) -> ca.SX:
        return self.robot[3]

    @property
    def total_mass(self) -> ca.SX:
        return self.robot[0] + self.robot[1] + self.robot[2]

    @property
    def gravity(self) -> ca.SX:
        return self.robot[7]


@dataclass(frozen=True)
class Discretization:
    """What a transcription hands back: nodal quantities as SX (2 × N, role order) and its pieces of the step.

    ``accelerations`` may hold ``None`` columns where the scheme has none (ground reactions are then not
    evaluated there). The callables work on the solution split into named variable blocks:
    ``decode(blocks, p)`` returns (q, dq, tau, control_times) in role order, ``interpolant(blocks, p)`` the
    continuous reconstruction, and ``guess(seed, p)`` initial values per block sampled from a :data:`Seed`
    (blocks left out start at 0).
    """

    positions: ca.SX
    velocities: ca.SX
    accelerations: list[ca.SX | None]
    running_cost: ca.SX
    """∫ r dt over the step by the transcription's quadrature: the objective's running cost (J)."""
    decode: Callable[[dict[str, np.ndarray], np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]
    interpolant: Callable[[dict[str, np.ndarray], np.ndarray], Interpolant]
    guess: Callable[[Seed, np.ndarray], dict[str, np.ndarray]]


@dataclass
class TranscribedStep:
    """A built step NLP with the maps between its variables and a trajectory."""

    structure: StepStructure
    nlp: NLP
    discretization: Discretization
    cost_of_transport: ca.Function | None = None
    """(x, p) -> the objective without its torque regularization: the transcription's quadrature of the running
    cost plus the push-off's event cost, over M g D. None where the NLP minimises no COT (a First Phase under
    ``first_phase_cost = "effort"``)."""

    def objective_cot(self, x: np.ndarray, data: StepData) -> float:
        """The cost of transport the NLP's objective assigns to ``x``, without the torque regularization: what
        verification's COT is compared with.

        The |P| slacks are settled first (:meth:`settle_slacks`), so that any ``x`` (a patched trajectory too,
        whose slacks were never optimized) is valued with exact |P| by the transcription's own quadrature; at an
        optimum this changes nothing.
        """
        p = data.parameter_vector()
        return float(self.cost_of_transport(self.settle_slacks(x, p), p))

    def settle_slacks(self, x: np.ndarray, p: np.ndarray) -> np.ndarray:
        """``x`` with each slack pair of :func:`~gaitbench.problem.step_cost.charged` (blocks ``name_positive``,
        ``name_negative`` with the constraint ``name_split``) set to the positive and negative parts of the power it
        stands for."""
        x = np.array(x, dtype=float)
        g = self.nlp.constraint_values(x, p)
        variables = self.nlp.variable_blocks
        for name, rows in self.nlp.constraint_blocks.items():
            stem = name.removesuffix("_split")
            if stem != name and f"{stem}_positive" in variables and f"{stem}_negative" in variables:
                positive, negative = variables[f"{stem}_positive"], variables[f"{stem}_negative"]
                power = g[rows] + x[positive] - x[negative]
                x[positive], x[negative] = np.maximum(power, 0.0), np.maximum(-power, 0.0)
        return x

    def initial_guess(self, data: StepData, seed: Seed | None = None) -> np.ndarray:
        """The variables sampled from ``seed``; by default the blended guess of docs/model.md §7, the same for every
        solver."""
        p = data.parameter_vector()
        guess = np.zeros(self.nlp.n_variables)
        for name, values in self.discretization.guess(seed or blended_seed(p, self.structure.n_nodes), p).items():
            guess[self.nlp.variable_blocks[name]] = values
        return guess

    def variables(self, trajectory: StepTrajectory, data: StepData) -> np.ndarray:
        """The NLP's variables read off a trajectory (a patchwork, a saved step): its interpolant sampled where the
        transcription's variables live, and its push-off impulse, so that the NLP's functions value that
        trajectory."""
        x = self.initial_guess(data, trajectory.seed())
        if "push_off" in self.nlp.variable_blocks:
            x[self.nlp.variable_blocks["push_off"]] = trajectory.push_off
        return x

    def blocks(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """The solution vector split into its named variable blocks."""
        return {name: np.asarray(x)[block] for name, block in self.nlp.variable_blocks.items()}

    def trajectory(self, x: np.ndarray, data: StepData) -> StepTrajectory:
        p = data.parameter_vector()
        blocks = self.blocks(x)
        q, dq, tau, control_times = self.discretization.decode(blocks, p)
        push_off = float(blocks["push_off"][0]) if "push_off" in blocks else 0.0
        times = np.arange(self.structure.n_nodes) * data.time_step
        return StepTrajectory(
            times=times,
            q=roles_to_legs(q, data.stance),
            dq=roles_to_legs(dq, data.stance),
            tau=roles_to_legs(tau, data.stance),
            control_times=control_times,
            push_off=push_off,
            stance=data.stance,
            _interpolant=self.discretization.interpolant(blocks, p),
        )


class Transcription(ABC):
    """Base class of transcription plugins: implements :class:`gaitbench.contracts.Transcription` given
    :meth:`discretize`. Builds are cached per structure, so a structure is built once."""

    name: str = ""

    def __init__(self) -> None:
        self._built: dict[StepStructure, TranscribedStep] = {}

    def build(self, structure: StepStructure) -> TranscribedStep:
        if structure not in self._built:
            self._built[structure] = self._build(structure)
        return self._built[structure]

    def builds_like(self, other: object) -> bool:
        """Whether ``other`` builds the same NLP for every structure: the same class configured the same (equal
        attributes, the build cache aside), so one instance's builds can serve the other's problems."""
        return type(other) is type(self) and _configuration(other) == _configuration(self)

    def keep_builds(self, keep: Callable[[StepStructure], bool]) -> None:
        """Forget the built structures ``keep`` rejects, and with them their NLPs and built solvers."""
        self._built = {structure: built for structure, built in self._built.items() if keep(structure)}

    @abstractmethod
    def discretize(
        self, structure: StepStructure, builder: NLPBuilder, symbols: StepSymbols, model: BipedFunctions
    ) -> Discretization:
        """Declare variables (with the limits' bounds), dynamics and initial-state constraints; return the pieces.

        The dynamics constraints go in a block named ``"dynamics"``: verification reports its largest violation.
        """

    def _build(self, structure: StepStructure) -> TranscribedStep:
        symbols = StepSymbols.create()
        builder = NLPBuilder()
        swing_model = biped_functions(2, 1)  # role coordinates: the stance leg is "Leg 1"
        effort = structure.phase == "first" and structure.options.first_phase_cost == "effort"
        # The thesis's First Phase minimises control effort: its quadrature is the transcription's, its objective
        # no COT (verification still reports the step's COT under the walk's objective, from built.structure).
        cost_structure = replace(structure, objective=CONTROL_EFFORT) if effort else structure
        discretization = self.discretize(cost_structure, builder, symbols, swing_model)
        push_off_work = _add_step_constraints(structure, builder, symbols, discretization)
        if structure.objective.signed_event or structure.phase == "first":
            event_cost = push_off_work
        else:
            event_cost = charged(builder, structure, "push_off_work", push_off_work)
        energy = discretization.running_cost + event_cost
        weight = symbols.total_mass * symbols.gravity * symbols.chord
        rho = structure.options.torque_regularization
        regularization = rho * symbols.time_step * ca.sumsqr(builder.variables("torques")) if rho else 0
        nlp = builder.build(symbols.vector, (energy + regularization) / weight)
        cost_of_transport = (None if effort
                             else ca.Function("objective_cot", [nlp.x, symbols.vector], [energy / weight]))
        return TranscribedStep(structure=structure, nlp=nlp, discretization=discretization,
                               cost_of_transport=cost_of_transport)


def _configuration(transcription: object) -> dict:
    return {name: value for name, value in vars(transcription).items() if name != "_built"}


def heel_strike_angles(symbols: StepSymbols) -> tuple[ca.SX, ca.SX]:
    """(q_st, q_sw) at heel strike: θ ∓ asin(D / 2l) (docs/model.md §4)."""
    alpha = ca.asin(symbols.chord / (2 * symbols.leg_length))
    return symbols.slope - alpha, symbols.slope + alpha


def _add_step_constraints(
    structure: StepStructure, builder: NLPBuilder, symbols: StepSymbols, discretization: Discretization
) -> ca.SX:
    """Constraints common to all transcriptions; returns what the push-off is charged (``options.push_off_cost``;
    0 in the first phase)."""
    options = structure.options
    q, dq = discretization.positions, discretization.velocities
    theta = symbols.slope
    q_st_end, q_sw_end = heel_strike_angles(symbols)
    builder.constrain("heel_strike_configuration", q[:, -1] - ca.vertcat(q_st_end, q_sw_end))
    interior = q[:, 1:-1]
    if options.clearance == "terrain":
        height = terrain_clearance(interior[0, :], interior[1, :], theta, symbols.previous_slope,
                                    options.clearance_rounding)
        builder.constrain("clearance", height, options.clearance_margin, np.inf)
    elif options.clearance == "chord":
        builder.constrain("clearance", clearance(interior[0, :], interior[1, :], theta), options.clearance_margin,
                          np.inf)
    if options.angle_bounds == "physical":
        # No leg points into the ground (docs/model.md §4), linear in q: the windows of `leg_angle_window`.
        stance_low, stance_high = leg_angle_window(theta, symbols.previous_slope)
        swing_low, swing_high = leg_angle_window(theta)
        builder.constrain("leg_angles", ca.vertcat(q[0, :] - stance_low, stance_high - q[0, :],
                                                   q[1, :] - swing_low, swing_high - q[1, :]), 0.0, np.inf)
    # Replaces the thesis's infeasible "monotonically descending swing foot" (docs/model.md §4): d/dt of the
    # clearance at the last node is negative, i.e. the swing foot comes down onto the ground.
    approach = -ca.sin(q[0, -1] - theta) * dq[0, -1] + ca.sin(q[1, -1] - theta) * dq[1, -1]
    builder.constrain("approach", approach, -np.inf, -options.approach_rate)
    if structure.phase == "first":
        if options.lift_off and structure.walked:
            # The 2-DOF impact map alone decides where the old stance foot goes (no push-off): relative to the new
            # stance foot, pinned at the old swing foot Y(q), it is at −Y(q) and moves at −∂Y/∂q q̇⁺.
            model2 = biped_functions(2, 1)
            dq_after, _ = model2.heel_strike(q[:, -1], dq[:, -1], symbols.robot)
            velocity = -ca.mtimes(model2.swing_foot_jacobian(q[:, -1], symbols.robot), dq_after)
            normal_rate = -ca.sin(theta) * velocity[0] + ca.cos(theta) * velocity[1]
            builder.constrain("lift_off", normal_rate / symbols.leg_length, options.lift_off_rate, np.inf)
        return ca.SX(0)

    model4 = biped_functions(4, 1)
    impulse = builder.variable("push_off", (1, 1), 0.0, options.limits.push_off_max)
    q_end4 = ca.vertcat(q[:, -1], 0, 0)
    dq_end4 = ca.vertcat(dq[:, -1], 0, 0)
    dq_plus = model4.push_off(q_end4, dq_end4, impulse, symbols.robot)
    kinetic_gain = model4.kinetic_energy(q_end4, dq_plus, symbols.robot) - model4.kinetic_energy(
        q_end4, dq_end4, symbols.robot
    )
    push_off_energy = push_off_work(options.push_off_cost, kinetic_gain, dq_plus[2:4], symbols.robot[0])

    if options.lift_off:
        # docs/model.md §3: the old stance foot leaves the ground. After heel strike it is the 4-DOF model's free foot
        # (q3, q4); its velocity along the normal of the step's chord must not point into the ground.
        dq_after, _ = model4.heel_strike(q_end4, dq_plus, symbols.robot)
        normal_rate = -ca.sin(theta) * dq_after[2] + ca.cos(theta) * dq_after[3]
        builder.constrain("lift_off", normal_rate / symbols.leg_length, options.lift_off_rate, np.inf)

    reactions = []
    for k, ddq in enumerate(discretization.accelerations):
        if ddq is None:
            continue
        qk, dqk = ca.vertcat(q[:, k], 0, 0), ca.vertcat(dq[:, k], 0, 0)
        mass = model4.mass(qk, symbols.robot)
        bias = ca.mtimes(model4.coriolis(qk, dqk, symbols.robot), dqk) + model4.gravity(qk, symbols.robot)
        # Rows 3–4 of M q̈ + C q̇ + G with the foot held: the exact stance-foot reaction, horizontal and vertical.
        reactions.append(ca.mtimes(mass[2:4, 0:2], ddq) + bias[2:4])
    world = ca.horzcat(*reactions)
    # Along and normal to the ground the cone stands on: the step's chord, as the lift-off above (a slope's 40° would
    # otherwise read a reaction that needs little friction as one at |f_x| = f_y).
    tangential = ca.cos(theta) * world[0, :] + ca.sin(theta) * world[1, :]
    normal = -ca.sin(theta) * world[0, :] + ca.cos(theta) * world[1, :]
    if options.unilateral_contact:
        builder.constrain_columns("unilateral_contact", normal, 0.0, np.inf)
    if options.friction_coefficient is not None:
        mu = options.friction_coefficient
        builder.constrain_columns("friction_cone", ca.vertcat(tangential - mu * normal, -tangential - mu * normal),
                                  -np.inf, 0.0)
    if options.unilateral_contact or options.friction_coefficient is not None:
        # The step's largest ground impulses come at its end: the push-off's, along the stance leg from the foot, and
        # the heel strike's at the landing foot (a no-slip plastic impact). The same cone holds them: a push-off
        # along a leg at angle α to the ground's normal needs μ ≥ tan α.
        _, impact = model4.heel_strike(q_end4, dq_plus, symbols.robot)
        impulses = ca.horzcat(impulse * ca.vertcat(-ca.sin(q[0, -1]), ca.cos(q[0, -1])), impact)
        along = ca.cos(theta) * impulses[0, :] + ca.sin(theta) * impulses[1, :]
        across = -ca.sin(theta) * impulses[0, :] + ca.cos(theta) * impulses[1, :]
        if options.unilateral_contact:
            builder.constrain("impact_contact", across.T / symbols.total_mass, 0.0, np.inf)  # in m/s
        if options.friction_coefficient is not None:
            mu = options.friction_coefficient
            builder.constrain("impact_friction_cone",
                              ca.vertcat((along - mu * across).T, (-along - mu * across).T) / symbols.total_mass,
                              -np.inf, 0.0)
    return push_off_energy


def state_derivative(model: BipedFunctions) -> ca.Function:
    """ẋ = (q̇, q̈) of the swing model as a CasADi function of (x, u, p): the ODE that collocation schemes discretize."""
    x, u, p = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("p", 8)
    ddq = model.forward_dynamics(x[:2], x[2:], u, p)[0]
    return ca.Function("state_derivative", [x, u, p], [ca.vertcat(x[2:], ddq)])


PHYSICAL_ANGLE_BOX = (-np.pi, np.pi)
"""Variable bounds on leg angles under physical limits, which are constraints relative to the slope; the box only
keeps angles on one branch."""


def checked_quadrature(quadrature: str, offered: tuple[str, ...]) -> str:
    """``quadrature`` when the transcription offers that rule for its running cost; otherwise a ValueError that
    lists the ones it does, raised when the plugin is created, not at its first build."""
    if quadrature not in offered:
        raise ValueError(f"quadrature = {quadrature!r}: expected one of {', '.join(offered)}")
    return quadrature


def angle_box(structure: StepStructure) -> tuple[float, float]:
    """Bounds of the leg-angle variables: the thesis's printed box, or a wide one under physical limits."""
    options = structure.options
    return options.limits.angle_bounds if options.angle_bounds == "thesis" else PHYSICAL_ANGLE_BOX


def collocation_variables(structure: StepStructure, builder: NLPBuilder) -> tuple[ca.SX, ca.SX]:
    """Node states (q_st, q_sw, q̇_st, q̇_sw; 4 × N) and node torques (2 × N) with the limits as bounds."""
    n, limits = structure.n_nodes, structure.options.limits
    low, high = angle_box(structure)
    lower = [low] * 2 + [-limits.dq_max] * 2
    upper = [high] * 2 + [limits.dq_max] * 2
    states = builder.variable("states", (4, n), lower, upper)
    torques = builder.variable("torques", (2, n), -limits.tau_max, limits.tau_max)
    return states, torques
