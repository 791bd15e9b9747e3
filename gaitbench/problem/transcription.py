"""Transcriptions turn a per-step gait problem into an :class:`~gaitbench.problem.nlp.NLP`.

A transcription plugin subclasses :class:`Transcription` and implements :meth:`Transcription.discretize`:
its decision variables, its dynamics constraints, the initial-state constraint, the quadrature of the objective's
running cost (:func:`running_cost`, :func:`interval_running_costs`) and the interpolant of its solution. Everything
else about a step — the heel-strike configuration, clearance, the approach to the ground, push-off and ground
reactions, and the objective's event cost — is added here, identically for every transcription, so that methods are
compared on the same problem.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from gaitbench.model.energetics import smooth_abs
from gaitbench.model.mechanics import BipedFunctions, biped_functions
from gaitbench.model.terrain import clearance, heel_strike_configuration, leg_angle_window, terrain_clearance
from gaitbench.problem.gait_problem import (
    N_STEP_PARAMETERS,
    PARAMETER_LAYOUT,
    StepData,
    StepStructure,
    legs_to_roles,
    roles_to_legs,
)
from gaitbench.problem.nlp import NLP, NLPBuilder


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


@dataclass
class Interpolant:
    """Continuous-time state and control of a solved step, in role order, from the transcription's own scheme."""

    state: Callable[[float], tuple[np.ndarray, np.ndarray]]  # t -> (q, dq)
    control: Callable[[float], np.ndarray]  # t -> tau


Seed = Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]]
"""An initial guess for a step as a function of time since the step's start: t ↦ (q, q̇, τ) in role order.
Transcriptions sample it wherever their variables live (nodes, midpoints, intervals)."""


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


@dataclass
class TranscribedStep:
    """A built step NLP with the maps between its variables and a trajectory."""

    structure: StepStructure
    nlp: NLP
    discretization: Discretization
    cost_of_transport: ca.Function | None = None
    """(x, p) -> the objective without its torque regularization: the transcription's quadrature of the running
    cost plus the push-off's event cost, over M g D."""

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
        """``x`` with each slack pair of :func:`charged` (blocks ``name_positive``, ``name_negative`` with the
        constraint ``name_split``) set to the positive and negative parts of the power it stands for."""
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
        """The variables sampled from ``seed``; by default the blended guess of DECISIONS §7, the same for every
        solver."""
        p = data.parameter_vector()
        guess = np.zeros(self.nlp.n_variables)
        for name, values in self.discretization.guess(seed or blended_seed(p, self.structure.n_nodes), p).items():
            guess[self.nlp.variable_blocks[name]] = values
        return guess

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
    """Base class of transcription plugins; builds are cached per structure, so a structure is built once."""

    name: str = ""

    def __init__(self) -> None:
        self._built: dict[StepStructure, TranscribedStep] = {}

    def build(self, structure: StepStructure) -> TranscribedStep:
        if structure not in self._built:
            self._built[structure] = self._build(structure)
        return self._built[structure]

    def builds_like(self, other: Transcription) -> bool:
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
        discretization = self.discretize(structure, builder, symbols, swing_model)
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
        cost_of_transport = ca.Function("objective_cot", [nlp.x, symbols.vector], [energy / weight])
        return TranscribedStep(structure=structure, nlp=nlp, discretization=discretization,
                               cost_of_transport=cost_of_transport)


def _configuration(transcription: Transcription) -> dict:
    return {name: value for name, value in vars(transcription).items() if name != "_built"}


def heel_strike_angles(symbols: StepSymbols) -> tuple[ca.SX, ca.SX]:
    """(q_st, q_sw) at heel strike: θ ∓ asin(D / 2l) (DECISIONS §4)."""
    alpha = ca.asin(symbols.chord / (2 * symbols.leg_length))
    return symbols.slope - alpha, symbols.slope + alpha


def _add_step_constraints(
    structure: StepStructure, builder: NLPBuilder, symbols: StepSymbols, discretization: Discretization
) -> ca.SX:
    """Constraints common to all transcriptions; returns the push-off energy (0 in the first phase)."""
    options = structure.options
    q, dq = discretization.positions, discretization.velocities
    theta = symbols.slope
    q_st_end, q_sw_end = heel_strike_angles(symbols)
    builder.constrain("heel_strike_configuration", q[:, -1] - ca.vertcat(q_st_end, q_sw_end))
    interior = q[:, 1:-1]
    if options.clearance == "terrain":
        height = terrain_clearance(interior[0, :], interior[1, :], theta, symbols.previous_slope)
        builder.constrain("clearance", height, options.clearance_margin, np.inf)
    elif options.clearance == "chord":
        builder.constrain("clearance", clearance(interior[0, :], interior[1, :], theta), options.clearance_margin,
                          np.inf)
    if options.angle_bounds == "physical":
        # No leg points into the ground (DECISIONS §4), linear in q: the windows of `leg_angle_window`.
        stance_low, stance_high = leg_angle_window(theta, symbols.previous_slope)
        swing_low, swing_high = leg_angle_window(theta)
        builder.constrain("leg_angles", ca.vertcat(q[0, :] - stance_low, stance_high - q[0, :],
                                                   q[1, :] - swing_low, swing_high - q[1, :]), 0.0, np.inf)
    # Replaces the thesis's infeasible "monotonically descending swing foot" (DECISIONS §4): d/dt of the
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
    push_off_energy = model4.kinetic_energy(q_end4, dq_plus, symbols.robot) - model4.kinetic_energy(
        q_end4, dq_end4, symbols.robot
    )

    if options.lift_off:
        # DECISIONS §3: the old stance foot leaves the ground. After heel strike it is the 4-DOF model's free foot
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
        # Rows 3–4 of M q̈ + C q̇ + G with the foot held: the exact stance-foot reaction (friction, normal).
        reactions.append(ca.mtimes(mass[2:4, 0:2], ddq) + bias[2:4])
    reaction = ca.horzcat(*reactions)
    if options.unilateral_contact:
        builder.constrain("unilateral_contact", reaction[1, :], 0.0, np.inf)
    if options.friction_coefficient is not None:
        mu = options.friction_coefficient
        builder.constrain(
            "friction_cone",
            ca.vertcat(reaction[0, :] - mu * reaction[1, :], -reaction[0, :] - mu * reaction[1, :]),
            -np.inf,
            0.0,
        )
    return push_off_energy


def running_cost(builder: NLPBuilder, structure: StepStructure, name: str, dq: ca.SX, tau: ca.SX,
                 robot: ca.SX) -> ca.SX:
    """The objective's running cost (:mod:`gaitbench.problem.objective`) at each column of the role-order rates and
    torques ``dq``, ``tau`` (2 × n), as a 1 × n row: its charged powers by :func:`charged`, plus its smooth rate."""
    objective = structure.objective
    args = (dq[0, :], dq[1, :], tau[0, :], tau[1, :])
    charges = charged(builder, structure, name, ca.vertcat(*objective.powers(*args)))
    rate = charges if charges.shape[0] <= 1 else ca.sum1(charges)
    smooth = objective.smooth_rate(*args, robot)
    return _plus(rate, smooth)


def charged(builder: NLPBuilder, structure: StepStructure, name: str, powers: ca.SX) -> ca.SX:
    """w⁺ max(P, 0) + w⁻ max(−P, 0) for each entry of ``powers`` (any shape), the weights the objective's, as the
    NLP sees it by ``structure.options.absolute_value``.

    ``slack`` (default): P = s⁺ − s⁻ with s± ≥ 0 as new variables (blocks ``name_positive``, ``name_negative``, the
    constraint ``name_split``) and the charge w⁺ s⁺ + w⁻ s⁻, exact at any optimum and smooth for the solver.
    ``smooth``: the thesis's √(P² + ε²) for |P| (DECISIONS §5), whose kink of curvature 1/ε makes interior-point
    solvers crawl; kept to reproduce the thesis.
    """
    if powers.numel() == 0:
        return powers
    objective = structure.objective
    positive_weight, negative_weight = objective.positive_weight, objective.negative_weight
    if structure.options.absolute_value == "smooth":
        magnitude = smooth_abs(powers, structure.options.smoothing_eps)
        if positive_weight == negative_weight:
            return _scaled(magnitude, positive_weight)
        return ((positive_weight + negative_weight) / 2 * magnitude
                + (positive_weight - negative_weight) / 2 * powers)
    positive = builder.variable(f"{name}_positive", powers.shape, 0.0, np.inf)
    negative = builder.variable(f"{name}_negative", powers.shape, 0.0, np.inf)
    builder.constrain(f"{name}_split", powers - positive + negative)
    return _scaled(positive, positive_weight) + _scaled(negative, negative_weight)


def _scaled(values: ca.SX, weight: float) -> ca.SX:
    return values if weight == 1.0 else weight * values


def _plus(values: ca.SX, more: ca.SX | None) -> ca.SX:
    if more is None:
        return values
    return more if values.numel() == 0 else values + more


def _channel_sum(charges: ca.SX, channels: int) -> ca.SX:
    """Rows i·c … i·c + c − 1 of ``charges`` (point-major, c = ``channels``) summed: one row per point."""
    if channels == 1 or charges.numel() == 0:
        return charges
    return ca.vertcat(*[ca.sum1(charges[i * channels:(i + 1) * channels, :])
                        for i in range(charges.shape[0] // channels)])


@dataclass(frozen=True)
class QuadratureRule:
    """An interpolatory rule on one interval, as fractions of it: the weight of each of its two ends and its
    interior points with their weights (the weights sum to 1)."""

    end_weight: float
    points: tuple[float, ...]
    weights: tuple[float, ...]


QUADRATURE_RULES = {
    "trapezoid": QuadratureRule(1 / 2, (), ()),
    "simpson": QuadratureRule(1 / 6, (1 / 2,), (4 / 6,)),
    "boole": QuadratureRule(7 / 90, (1 / 4, 1 / 2, 3 / 4), (32 / 90, 12 / 90, 32 / 90)),
}
"""Rules for the hip energy ∫|τ·q̇| dt of one interval, applied to the power of the transcription's own interpolant.

``boole`` (the default of every transcription) is exact for polynomials of degree 5. Each interpolant's power is a
polynomial on an interval (DMOC: quadratic, trapezoidal: cubic, Hermite–Simpson: quartic), so Boole's rule is its
exact energy wherever the power keeps its sign, and with five points no nonzero power of those degrees vanishes at
all of them. Rules with fewer points than that let the net-power optimizer put the power's zeros on the points
(docs/deviations.md, "Hip-energy quadrature"); where the power changes sign inside an interval every rule is
approximate, and Boole's is within 2.2 % for the sign change at the midpoint that zero net work on an interval
makes (a linear power through zero there)."""


def interval_running_costs(builder: NLPBuilder, structure: StepStructure, name: str, motion: ca.Function,
                           variables: list[ca.SX], parameters: ca.SX) -> ca.SX:
    """The objective's running cost at m points of each interval, as an m × M matrix.

    ``motion(z_k, p)`` gives the role-order (q̇_st, q̇_sw, τ_st, τ_sw) at the m points stacked (4m × 1); z_k stacks
    column k of each of ``variables``. The charged powers are split as in :func:`charged`, declared per interval,
    so that the NLP gets its per-interval Hessian.
    """
    objective = structure.objective
    n_intervals, m = variables[0].shape[1], motion.size1_out(0) // 4
    c = len(objective.channels)
    n_z = motion.size1_in(0)
    z, p = ca.SX.sym("z", n_z), ca.SX.sym("p", motion.size1_in(1))
    values = motion(z, p)
    powers, smooth = [], []
    for i in range(m):
        args = (values[4 * i], values[4 * i + 1], values[4 * i + 2], values[4 * i + 3])
        powers += objective.powers(*args)
        rate = objective.smooth_rate(*args, p[PARAMETER_LAYOUT["robot"]])
        if rate is not None:
            smooth.append(rate)
    stacked = ca.repmat(parameters, 1, n_intervals)
    smooth_rates = (ca.Function(f"{name}_smooth", [z, p], [ca.vertcat(*smooth)]).map(n_intervals)(
        ca.vertcat(*variables), stacked) if smooth else None)
    if not powers:
        return smooth_rates
    power_function = ca.Function(f"{name}_powers", [z, p], [ca.vertcat(*powers)])
    if structure.options.absolute_value != "slack":
        charges = charged(builder, structure, name, power_function.map(n_intervals)(ca.vertcat(*variables), stacked))
        return _plus(_channel_sum(charges, c), smooth_rates)
    rows = c * m
    positive = builder.variable(f"{name}_positive", (rows, n_intervals), 0.0, np.inf)
    negative = builder.variable(f"{name}_negative", (rows, n_intervals), 0.0, np.inf)
    split_z = ca.SX.sym("z", n_z + 2 * rows)
    split = ca.Function(f"{name}_split", [split_z, p], [power_function(split_z[:n_z], p)
                                                          - split_z[n_z:n_z + rows] + split_z[n_z + rows:]])
    builder.constrain_intervals([f"{name}_split"], split, [*variables, positive, negative], parameters)
    charges = (_scaled(positive, objective.positive_weight) + _scaled(negative, objective.negative_weight))
    return _plus(_channel_sum(charges, c), smooth_rates)


def blended_seed(p: np.ndarray, n_nodes: int) -> Seed:
    """DECISIONS §7: angles blend linearly from the initial state to the heel-strike configuration, with the
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


def state_derivative(model: BipedFunctions) -> ca.Function:
    """ẋ = (q̇, q̈) of the swing model as a CasADi function of (x, u, p): the ODE that collocation schemes discretize."""
    x, u, p = ca.SX.sym("x", 4), ca.SX.sym("u", 2), ca.SX.sym("p", 8)
    ddq = model.forward_dynamics(x[:2], x[2:], u, p)[0]
    return ca.Function("state_derivative", [x, u, p], [ca.vertcat(x[2:], ddq)])


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
                     stance: int) -> StepTrajectory:
    """Values at the nodes of a uniform grid (leg order, one torque per node) read as a step trajectory: cubic Hermite
    angles through the nodal (q, q̇), linear rates and torques. The smoothest reading of node values that carry no
    interpolant of their own, such as decrease and conquer's node-wise patchworks."""
    n, h = len(times), float(times[1] - times[0])
    q_roles, dq_roles, tau_roles = (legs_to_roles(np.asarray(a, dtype=float), stance) for a in (q, dq, tau))

    def state(t: float) -> tuple[np.ndarray, np.ndarray]:
        k, s = locate_interval(t, h, n)
        angles, _ = cubic_hermite(q_roles[k], q_roles[k + 1], h * dq_roles[k], h * dq_roles[k + 1], s)
        return angles, (1 - s) * dq_roles[k] + s * dq_roles[k + 1]

    def control(t: float) -> np.ndarray:
        k, s = locate_interval(t, h, n)
        return (1 - s) * tau_roles[k] + s * tau_roles[k + 1]

    return StepTrajectory(times=np.asarray(times, dtype=float), q=np.asarray(q), dq=np.asarray(dq),
                          tau=np.asarray(tau), control_times=np.asarray(times, dtype=float), push_off=push_off,
                          stance=stance, _interpolant=Interpolant(state, control))


PHYSICAL_ANGLE_BOX = (-np.pi, np.pi)
"""Variable bounds on leg angles under physical limits, which are constraints relative to the slope; the box only
keeps angles on one branch."""


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
