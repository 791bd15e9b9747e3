"""What every kind of plugin provides, declared in one place.

:mod:`gaitbench.hookspecs` declares the hooks a plugin implements to *register* things; this module declares what
the registered factories *build*: the interface the core (and the plugins that receive one another through it)
calls. ``registry.create(kind, name, ...)`` is typed with these, so a type checker knows that
``registry.create("solver", "ipopt")`` is a :class:`Solver`.

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
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, runtime_checkable

from gaitbench.model.experiment import Experiment
from gaitbench.model.mechanics import BipedModel
from gaitbench.plugins import Kind
from gaitbench.problem.objective import Objective

if TYPE_CHECKING:
    import numpy as np

    from gaitbench.problem.gait_problem import StepStructure
    from gaitbench.problem.nlp import NLP
    from gaitbench.problem.transcription import TranscribedStep
    from gaitbench.report_data import ReportData
    from gaitbench.solver_result import SolverResult
    from gaitbench.step_info import StepInfo
    from gaitbench.walk_types import StepOutcome, WalkProblem, WalkResult

__all__ = ["CONTRACTS", "BipedModel", "Controller", "Disturbance", "Experiment", "Kind", "Objective", "Observer",
           "Reporter", "Solver", "Strategy", "Transcription", "contract_violations"]



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

    def reset(self, q: np.ndarray, velocity: np.ndarray, disturbance: np.ndarray, step: StepInfo) -> np.ndarray:
        """The internal state whose estimates are exactly ``velocity`` (q̇1, q̇2) and ``disturbance`` (d1, d2) at the
        configuration ``q``, at the start of ``step`` (after each impact)."""

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
        ``q`` and the post-push-off velocity ``dq``."""


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
