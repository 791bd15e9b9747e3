"""What every kind of plugin provides, declared in one place.

:mod:`gaitbench.hookspecs` declares the hooks a plugin implements to *register* things; this module declares what
the registered factories *build*: the interface the core (and the plugins that receive one another through it)
calls. ``registry.create(kind, name, ...)`` is typed with these, so a type checker knows that
``registry.create("solver", "ipopt")`` is a :class:`Solver`.

It also holds what the contracts hand a plugin beyond the values below them: the walk a strategy is asked to solve
(:class:`WalkProblem`, which carries a transcription and a solver), and the boundary every solve of a walk passes
(:class:`CheckedSolver`). The values the contracts name (:mod:`gaitbench.solver_result`, :mod:`gaitbench.walk_types`,
:mod:`gaitbench.acceptance`, :mod:`gaitbench.step_info`, :mod:`gaitbench.report_data`) name no contract, and the plugin
kinds are listed once, in :mod:`gaitbench.hookspecs`.

Three kinds are value types the core defines and reads field by field, so their contract is that class itself:

- ``experiment``: :class:`gaitbench.model.experiment.Experiment` (a frozen dataclass; build one, do not subclass);
- ``model``: :class:`gaitbench.model.mechanics.BipedModel`;
- ``objective``: a subclass of :class:`gaitbench.problem.objective.Objective` (a frozen dataclass, since built NLPs
  are cached under it; every method has a default, so an objective overrides only what it charges).

The other kinds are :class:`typing.Protocol` classes below: a plugin satisfies one by having the members, and needs
no base class. Where the core offers a base class with the shared work (a transcription subclasses
:class:`gaitbench.problem.transcription.Transcription` and writes only ``discretize``), the protocol is what the
core calls, and the base class implements it. :func:`contract_violations` checks an object or class against its
kind's contract; the tests run it on every built-in plugin.
"""

from __future__ import annotations

import inspect
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, TypeVar, runtime_checkable

import numpy as np

from gaitbench.cores import IdleCores
from gaitbench.model.experiment import Experiment
from gaitbench.model.mechanics import BipedModel
from gaitbench.problem.build_cache import BuildCache
from gaitbench.problem.gait_problem import ProblemOptions, StepData, StepStructure
from gaitbench.problem.objective import NET_POWER, Objective
from gaitbench.solver_result import SolverResult, finite_or_flagged
from gaitbench.walk_types import StepOutcome, WalkResult

if TYPE_CHECKING:
    from gaitbench.checkpoint import WalkCheckpoint
    from gaitbench.hookspecs import Kind
    from gaitbench.model.terrain import StepCheck as GeometryCheck
    from gaitbench.problem.nlp import NLP
    from gaitbench.problem.transcription import TranscribedStep
    from gaitbench.report_data import ReportData
    from gaitbench.step_info import StepInfo

__all__ = ["CONTRACTS", "BipedModel", "CheckedSolver", "Controller", "Disturbance", "Experiment", "Objective",
           "Observer", "Reporter", "Solver", "StepsOutOfRange", "Strategy", "Transcription", "WalkProblem", "checked",
           "contract_violations"]


@runtime_checkable
class Transcription(Protocol):
    """Turns a per-step gait problem into an NLP (a ``transcription`` plugin, built as ``factory(**options)``).

    Subclass :class:`gaitbench.problem.transcription.Transcription`: it implements everything here once the plugin
    writes ``discretize`` (its variables, dynamics, quadrature and interpolant).
    """

    name: str
    """The registered name, recorded in every walk solved with it."""

    def build(self, structure: StepStructure) -> TranscribedStep:
        """The NLP of one step shape.

        ``structure``: phase (``"first"``, 2-DOF, or ``"second"``, 4-DOF), number of nodes N, problem options and
        objective. Returns the built NLP with the maps between its variables and a trajectory (initial guess,
        decoding, objective COT). Builds are kept per structure: building one again returns the same object.
        """

    def builds_like(self, other: Transcription) -> bool:
        """Whether ``other`` builds the same NLP for every structure, so its builds can serve this one's problems."""

    def keep_builds(self, keep: Callable[[StepStructure], bool]) -> None:
        """Forget the kept builds whose structure ``keep`` rejects (with their NLPs and built solvers)."""


@runtime_checkable
class Solver(Protocol):
    """Solves NLPs (a ``solver`` plugin, built as ``factory(**options)``).

    Optional members are used when present: ``prepare(nlp) -> None`` builds what the solver reuses across solves of
    ``nlp`` ahead of the first one (a strategy calls it before forking workers); ``for_sections() -> Solver`` is the
    variant that solves decrease and conquer's sectional NLPs (:func:`gaitbench.solve.solver.section_solver`). The
    retry ladder (docs/solvers.md, "Retries") asks for named variants, each a ``list[tuple[str, Solver]]``:
    ``continuations()``, started from the last iterate of a solve that ran out of iterations, before any other rung;
    ``remedies()``, worth a retry after a failed solve; ``seed_remedies()``, worth one only when the retry starts
    from a trajectory (the First-Phase seed, say), not from the blended guess; and ``last_resorts()``, tried only
    after every other rung has failed, because they tend to reach worse optima.
    """

    name: str
    """The registered name, recorded in every walk solved with it."""

    def solve(self, nlp: NLP, parameters: np.ndarray, initial_guess: np.ndarray) -> SolverResult:
        """Solve ``nlp`` for the parameter vector ``parameters`` (a step's data) from the variable vector
        ``initial_guess``. Returns the shared result: status, message, solution x, objective, constraint violation,
        iterations and timings. A failure is a status with a message, never an exception."""


VARIANT_KINDS = ("continuations", "remedies", "seed_remedies", "last_resorts")
"""The optional solver members that return named variants of the solver for the retry ladder."""

SECTION_VARIANT = "for_sections"
"""The optional solver member that returns the variant a strategy solves its sectional NLPs with
(:func:`gaitbench.solve.solver.section_solver`): checked like the solver, as every solve of a walk is."""


class CheckedSolver:
    """A solver plugin behind the boundary every solve of a walk passes (:class:`WalkProblem` holds its solver so):
    a result that claims convergence at a non-finite ``x`` or objective becomes
    :attr:`gaitbench.solver_result.SolverStatus.NON_FINITE`, with a message that says so, instead of a point the
    verification would fail on for another reason. The solver's variants, its sectional one among them, are checked
    alike; everything else is the plugin's own."""

    def __init__(self, solver: Solver) -> None:
        self.plugin = solver

    def solve(self, nlp: NLP, parameters: np.ndarray, initial_guess: np.ndarray) -> SolverResult:
        return finite_or_flagged(self.plugin.solve(nlp, parameters, initial_guess), self.plugin.name)

    def __getattr__(self, name: str) -> Any:
        if name == "plugin":  # not set yet (an object being unpickled): no recursion through it
            raise AttributeError(name)
        member = getattr(self.plugin, name)
        if name in VARIANT_KINDS:
            return lambda: [(label, checked(variant)) for label, variant in member()]
        if name == SECTION_VARIANT:
            return lambda: checked(member())
        return member


def checked(solver: Solver) -> Solver:
    """``solver`` behind :class:`CheckedSolver` (once)."""
    return solver if isinstance(solver, CheckedSolver) else CheckedSolver(solver)  # type: ignore[return-value]


@runtime_checkable
class Strategy(Protocol):
    """How the per-step gait problems of a walk are posed, solved and combined (a ``strategy`` plugin, built as
    ``factory(**options)``)."""

    name: str
    """The registered name, recorded in the walk it returns."""

    def solve(self, problem: WalkProblem, on_step: Callable[[StepOutcome], None] | None = None) -> WalkResult:
        """Walk ``problem`` (experiment, transcription, solver, N, steps, problem options, objective), calling
        ``on_step`` with each step's outcome as it is finished. Returns the walk: its steps up to the first that
        failed, each with its status, trajectory and verification. Failures end the walk, never raise."""


Item = TypeVar("Item")
State = TypeVar("State")
Result = TypeVar("Result")


class FanOut(Protocol):
    """A map over the run's workers for one walk (one case)."""

    def map(self, task: Callable[[Item, State], Result], items: Sequence[Item],
            state: Callable[[WalkProblem], State]) -> list[Result]:
        """``task(item, state(problem))`` for every item, on the run's workers; the results in the items' order.
        ``task`` and ``state`` are module-level (pickled); ``problem`` is this walk's, rebuilt on the worker.
        Raises what a task raised, or :class:`~gaitbench.fan_out.FanOutError` when a task could not be run."""
        ...


class StepsOutOfRange(ValueError):
    """A walk asked for fewer than one step, or more than its experiment has."""


@dataclass(frozen=True)
class WalkProblem:
    """What a strategy is asked to do: walk ``steps`` steps of an experiment with N nodes per step, using one
    transcription and one solver, under the given problem options, for the given objective. ``builds`` keeps
    what a strategy builds beyond the walk's own steps for later walks: this walk's alone unless its runner
    passes one it keeps (a suite's worker)."""

    experiment: Experiment
    transcription: Transcription
    solver: Solver
    n_nodes: int
    steps: int | None = None
    options: ProblemOptions | None = None
    objective: Objective = NET_POWER
    builds: BuildCache = field(default_factory=BuildCache, compare=False, repr=False)
    deadline: float | None = field(default=None, compare=False)
    """``time.monotonic()`` at which the walk's time runs out (a suite case's time limit): a step that would start
    later is not started, and the walk stops there with ``time_limit``, keeping the steps it solved, instead of
    running on until its process is stopped and losing them all."""
    cores: IdleCores | None = field(default=None, compare=False, repr=False)
    """The machine's ledger of the cores walks are using, when the walk may borrow idle ones (a suite's case, a
    `gaitbench solve`): a strategy whose solves are independent may spread them over the cores it can hold."""
    checkpoint: WalkCheckpoint | None = field(default=None, compare=False, repr=False)
    """Where the walk keeps its solved steps as it goes, and the steps an earlier, stopped run of it kept:
    the walk resumes after them (:func:`walk_step_by_step`)."""
    fan_out: FanOut | None = field(default=None, compare=False, repr=False)
    """The run's map over its workers, when the run's executor has workers beyond the walk's machine (a Dask
    cluster, :mod:`gaitbench.fan_out`): a strategy with independent solves may send them there instead of to
    local processes."""
    experiment_options: dict = field(default_factory=dict, compare=False, repr=False)
    """The options the experiment was built with, recorded in the walk (:attr:`WalkResult.experiment_options`)."""
    transcription_options: dict = field(default_factory=dict, compare=False, repr=False)
    """The options the transcription was built with, recorded in the walk
    (:attr:`WalkResult.transcription_options`)."""
    strategy_options: dict = field(default_factory=dict, compare=False, repr=False)
    """The options the strategy was built with, recorded in the walk (:attr:`WalkResult.strategy_options`)."""

    @property
    def out_of_time(self) -> bool:
        """Whether the walk's deadline has passed."""
        return self.deadline is not None and time.monotonic() >= self.deadline

    def __post_init__(self) -> None:
        object.__setattr__(self, "solver", checked(self.solver))  # every solve of the walk: the solver boundary
        if self.steps is not None and not 1 <= self.steps <= self.experiment.n_steps:
            raise StepsOutOfRange(f"steps = {self.steps}: the {self.experiment.name} experiment has "
                                  f"{self.experiment.n_steps} steps")
        if self.options is None:
            object.__setattr__(self, "options", ProblemOptions(limits=self.experiment.limits))

    @property
    def n_steps(self) -> int:
        return self.experiment.n_steps if self.steps is None else self.steps

    def structure(self, phase: str, n_nodes: int | None = None, walked: bool = False) -> StepStructure:
        """The step NLP's shape; ``walked``: a First-Phase step the walk goes on from (see StepStructure). Only the
        First Phase tells the two apart, so a 4-DOF step is one structure, and one build, for every strategy."""
        return StepStructure(phase, n_nodes or self.n_nodes, self.options, self.objective,
                             walked and phase == "first")

    def step_data(self, index: int, state: np.ndarray) -> StepData:
        """Step ``index`` (1-based) from ``state`` = (q1, q2, q̇1, q̇2), leg order, with the walk's time step."""
        terrain = self.experiment.terrain
        geometry = terrain.steps[index - 1]
        return StepData(self.experiment.robot, self.experiment.stance_leg(index), np.asarray(state, dtype=float),
                        geometry.D, geometry.theta, self.experiment.time_step(self.n_nodes),
                        previous_slope=terrain.ground_behind(index))

    def start_state(self) -> np.ndarray:
        """(q1, q2, q̇1, q̇2) at the start of step 1, in the start pose the options ask for."""
        return self.experiment.start_state(self.options.start_pose)

    def feasibility(self) -> list[GeometryCheck]:
        """The experiment's per-step geometry checks under the options' leg-angle limits."""
        return self.experiment.feasibility(self.options.angle_bounds)

    def model(self, phase: str) -> BipedModel:
        """The model a step of ``phase`` is verified with: 4-DOF (push-off acts) or the 2-DOF First Phase."""
        return BipedModel(self.experiment.robot, 4 if phase == "second" else 2)

    def result(self, strategy: str, phase: str = "second") -> WalkResult:
        return WalkResult(experiment=self.experiment.name, transcription=self.transcription.name,
                          solver=self.solver.name, strategy=strategy, N=self.n_nodes, phase=phase,
                          requested_steps=self.n_steps, problem_options=asdict(self.options),
                          objective=self.objective.describe(), objective_options=asdict(self.objective))


@runtime_checkable
class Controller(Protocol):
    """A tracking control law (a ``controller`` plugin, built as ``factory(model, reference, **options)`` with the
    :class:`~gaitbench.model.mechanics.BipedModel` the walk was solved with and the
    :class:`~gaitbench.control.reference.Reference` it tracks)."""

    def torque(self, t: float, q: np.ndarray, dq: np.ndarray, disturbance: np.ndarray, step: StepInfo) -> np.ndarray:
        """Hip torques (τ1, τ2) at local time ``t`` (s) of ``step``, from the measured configuration ``q`` and the
        estimated velocity ``dq`` (model coordinates; the held stance foot's rates are exact zeros) and the
        estimated leg disturbance ``disturbance`` (d̂1, d̂2)."""

    def push_off(self, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> float:
        """The push-off impulse (N·s) along the stance leg at the end of ``step``, from the configuration ``q`` and
        estimated velocity ``dq`` just before it; the core clips it to [0, push_off_max]."""


@runtime_checkable
class Observer(Protocol):
    """Velocity and disturbance estimates of the leg angles (an ``observer`` plugin, built as
    ``factory(model, **options)``).

    The estimates live on the actuated coordinates (q1, q2): during swing the stance foot is held, so its rates are
    known to be zero and any disturbance on it is absorbed by the ground reaction (thesis §4.3). ``q`` and ``dq`` are
    the full model state; ``dq`` is the true velocity, which only observers that model a velocity sensor may use.
    """

    size: int
    """The number of internal states, which the core integrates with the robot's."""

    def reset(self, q: np.ndarray, dq: np.ndarray, velocity: np.ndarray, disturbance: np.ndarray,
              step: StepInfo) -> np.ndarray:
        """The internal state whose estimates (:meth:`estimate` at ``q`` and ``dq``) are exactly ``velocity``
        (q̇1, q̇2) and ``disturbance`` (d1, d2), at the start of ``step`` (after each impact). ``dq`` is the true
        velocity after the impact, which only observers that model a velocity sensor may use (and must, when their
        estimates read it)."""

    def estimate(self, state: np.ndarray, q: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The estimates (q̂̇1, q̂̇2) and (d̂1, d̂2) from the internal ``state`` and the robot's ``q`` and ``dq``."""

    def derivative(self, state: np.ndarray, q: np.ndarray, dq: np.ndarray, tau: np.ndarray,
                   step: StepInfo) -> np.ndarray:
        """The rate of the internal ``state`` given the robot's ``q``, ``dq`` and the applied hip torques ``tau``."""


@runtime_checkable
class Disturbance(Protocol):
    """Generalized forces on the robot (a ``disturbance`` plugin, built as ``factory(experiment, **options)``).

    Both act on the left-hand side, M q̈ + C q̇ + G + d = B τ + Sᵀ f: friction returns its resisting force along the
    motion, an external force F returns −Jᵀ F.
    """

    def force(self, t: float, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> np.ndarray:
        """The continuous generalized force d (model coordinates) at local time ``t`` (s) of ``step`` and the
        state ``q``, ``dq``."""

    def impulse(self, q: np.ndarray, dq: np.ndarray, step: StepInfo) -> np.ndarray:
        """The generalized impulse acting with the push-off at the end of ``step``, evaluated at the configuration
        ``q`` and the post-push-off velocity ``dq``. It resists the motion: the loop applies it at most until a
        velocity it resists comes to rest, never reversing it."""


@runtime_checkable
class Reporter(Protocol):
    """Renders stored benchmark results into files (a ``reporter`` plugin, built as ``factory(**options)``)."""

    def write(self, report: ReportData, out_dir: Path) -> list[Path]:
        """Write ``report`` (the tables, figures and gait and tracking sections that
        :func:`gaitbench.reports.write_report` builds once from a store) into the existing directory ``out_dir``.
        Returns the files written."""


CONTRACTS: dict[Kind, type] = {
    "experiment": Experiment,
    "model": BipedModel,
    "transcription": Transcription,
    "objective": Objective,
    "solver": Solver,
    "strategy": Strategy,
    "controller": Controller,
    "observer": Observer,
    "disturbance": Disturbance,
    "reporter": Reporter,
}
"""Each kind's contract: what its factories return (an instance of the class, or an object with the protocol's
members)."""


def contract_violations(kind: str, plugin: object) -> list[str]:
    """How ``plugin`` (what a factory of ``kind`` returns, or the class it instantiates) breaks the kind's contract.

    For a value type: not an instance or subclass of it. For a protocol: each member it lacks, and each method that
    does not take the protocol's parameters under their names and in their order (extra parameters must have
    defaults). An empty list means it conforms; :func:`isinstance` on a protocol checks only that members exist.
    """
    contract = CONTRACTS[kind]
    if Protocol not in contract.__mro__:
        conforms = issubclass(plugin, contract) if isinstance(plugin, type) else isinstance(plugin, contract)
        return [] if conforms else [f"is not a {contract.__module__}.{contract.__qualname__}"]
    problems = []
    for member in _protocol_members(contract):
        if not hasattr(plugin, member):
            problems.append(f"has no {member!r}")
            continue
        expected = getattr(contract, member, None)
        if callable(expected):
            problem = _signature_problem(getattr(plugin, member), expected, bound=not isinstance(plugin, type))
            if problem:
                problems.append(f"{member}(): {problem}")
    return problems


def _protocol_members(protocol: type) -> list[str]:
    """The protocol's attributes (annotated) and methods, in declaration order."""
    annotated = list(protocol.__dict__.get("__annotations__", {}))
    methods = [name for name, value in protocol.__dict__.items()
               if inspect.isfunction(value) and not name.startswith("_")]
    return annotated + [name for name in methods if name not in annotated]


def _signature_problem(method: Callable, expected: Callable, bound: bool) -> str | None:
    """Why ``method`` cannot be called as the protocol's ``expected`` is, or None."""
    wanted = [parameter.name for parameter in inspect.signature(expected).parameters.values()][1:]  # without self
    parameters = list(inspect.signature(method).parameters.values())[0 if bound else 1:]
    positional = [parameter for parameter in parameters
                  if parameter.kind in (parameter.POSITIONAL_ONLY, parameter.POSITIONAL_OR_KEYWORD)]
    names = [parameter.name for parameter in positional]
    if names[:len(wanted)] != wanted:
        return f"takes ({', '.join(names)}), the contract ({', '.join(wanted)})"
    extra = [parameter.name for parameter in positional[len(wanted):] if parameter.default is parameter.empty]
    extra += [parameter.name for parameter in parameters
              if parameter.kind is parameter.KEYWORD_ONLY and parameter.default is parameter.empty]
    if extra:
        return f"requires {', '.join(extra)} beyond the contract's parameters"
    return None
