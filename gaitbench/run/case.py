"""One case of a suite: everything that determines a walk's result, and the canonical key that names it.

A case is plain data (strings, numbers, dicts), so it pickles to any worker process or Dask worker and rebuilds
its plugins there by name. The key hashes only what changes the result; labels, time limits, plugin
directories and checkpoints are how a case is run or shown, not what it is, so they stay out of it.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class PluginChoice:
    """A plugin by kind and registered name, with the keyword options its factory is called with."""

    name: str
    options: dict[str, Any] = field(default_factory=dict)

    def describe(self) -> str:
        """``name`` or ``name(key=value, ...)``, options sorted: how tables and labels show the choice."""
        if not self.options:
            return self.name
        listed = ", ".join(f"{key}={_plain(value)}" for key, value in sorted(self.options.items()))
        return f"{self.name}({listed})"

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "options": dict(sorted(self.options.items()))}


SOLVE_SHARE = 0.25
"""The share of a case's time limit that one solve (one rung of the retry ladder) may take. A pathological solve
then leaves the rest of the walk's time to the next rungs: downward slope, OP-DM, N = 180, step 1 spent the whole
hour in the adaptive-μ rung (2,776 iterations, the last ones seconds each while MUMPS reallocated its workspace to
80 times its estimate), and the next rung then solved it in 2.5 s. The longest converged solve stored in
thesis-all took 669 s of its 3,600 (upward slope, OP-DM, N = 170, step 6)."""

DEFAULT_OBJECTIVE = PluginChoice("net-power")
"""The thesis's cost, what a case without an objective is solved for."""


@dataclass(frozen=True)
class TrackingStage:
    """Closed-loop tracking of the walk once it is solved (issue 8): which controller, observer, disturbance."""

    controller: str = "thesis"
    observer: str = "thesis"
    disturbance: str = "friction"
    options: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return {"controller": self.controller, "observer": self.observer, "disturbance": self.disturbance,
                "options": dict(sorted(self.options.items()))}


@dataclass(frozen=True)
class Case:
    """One walk to solve: an experiment at N nodes per step with a transcription, a solver and a strategy."""

    experiment: PluginChoice
    n_nodes: int
    transcription: PluginChoice
    solver: PluginChoice
    strategy: PluginChoice
    steps: int | None = None
    """How many steps of the experiment to walk; ``None`` walks all of them."""
    problem_options: dict[str, Any] = field(default_factory=dict)
    """Overrides of :class:`gaitbench.problem.gait_problem.ProblemOptions` fields (``absolute_value``, ...)."""
    repetition: int = 0
    tracking: TrackingStage | None = None
    method: str = ""
    """The suite's label for the transcription/solver/strategy combination (``OP-DC``); not part of the key."""
    objective: PluginChoice = DEFAULT_OBJECTIVE
    """What every step minimises and every COT measures."""
    time_limit_s: float | None = None
    """The walk's deadline: no solve starts after it (:class:`gaitbench.contracts.WalkProblem`). Not part of the
    key: it bounds how long the case may take, not what it computes, so a longer limit does not re-solve the cases
    that finished; the ones that ran out of time run again with ``--resume --retry-failed``."""
    plugin_dirs: tuple[str, ...] = ()
    checkpoint: str | None = None
    """Where the walk saves its solved steps as it goes, so that a run of the case after this one was stopped goes on
    from them (:mod:`gaitbench.checkpoint`); the runner sets it, in its store, where the worker can write."""

    @property
    def solve_time_limit_s(self) -> float | None:
        """The longest one solve of the walk may run: :data:`SOLVE_SHARE` of the case's time limit."""
        return None if self.time_limit_s is None else SOLVE_SHARE * self.time_limit_s

    @property
    def hard_limit_s(self) -> float | None:
        """When the case's process is stopped from outside: a solve started just before the deadline may run its
        whole share past it, and 30 s more leave room for verification and writing the result."""
        return None if self.time_limit_s is None else self.time_limit_s + self.solve_time_limit_s + 30.0

    def identity(self) -> dict[str, Any]:
        """What the result depends on, in canonical form: the key is a hash of exactly this. The default objective
        is left out, so cases keep the keys they had before objectives were plugins (and ``--resume`` finds them)."""
        identity = {
            "experiment": self.experiment.as_dict(),
            "N": self.n_nodes,
            "steps": self.steps,
            "transcription": self.transcription.as_dict(),
            "solver": self.solver.as_dict(),
            "strategy": self.strategy.as_dict(),
            "problem_options": dict(sorted(self.problem_options.items())),
            "repetition": self.repetition,
            "tracking": self.tracking.as_dict() if self.tracking else None,
        }
        if self.objective != DEFAULT_OBJECTIVE:
            identity["objective"] = self.objective.as_dict()
        return identity

    @property
    def key(self) -> str:
        """A 16-hex-digit hash of :meth:`identity`, the same whatever order the suite file listed things in."""
        canonical = json.dumps(self.identity(), sort_keys=True, separators=(",", ":"), default=_plain)
        return hashlib.sha256(canonical.encode()).hexdigest()[:16]

    @property
    def label(self) -> str:
        """A short human-readable name for progress lines and error messages."""
        return (f"{self.experiment.describe()} N={self.n_nodes} {self.method or self.strategy.name}: "
                f"{self.transcription.describe()} + {self.solver.describe()}"
                + (f" [{self.objective.describe()}]" if self.objective != DEFAULT_OBJECTIVE else "")
                + (f" #{self.repetition}" if self.repetition else ""))


def _plain(value: Any) -> Any:
    """JSON has no tuples or NumPy scalars; options from TOML are already plain, this covers Python callers."""
    if isinstance(value, tuple):
        return list(value)
    if hasattr(value, "item"):
        return value.item()
    return str(value)
