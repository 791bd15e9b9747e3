"""One walk assembled from plugin choices: each plugin built by name and options, and the walk problem they pose.
``gaitbench solve`` and the suite runner both assemble their walk here and solve it with
:func:`gaitbench.solve.walk_verification.solve_verified`."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any, Protocol

from gaitbench.contracts import Strategy, WalkProblem
from gaitbench.problem.gait_problem import ProblemOptions

Build = Callable[..., Any]
"""``build(kind, name, **options)``: the plugin (a registry's ``create``, or the CLI's, which turns a bad name or
option into a usage error)."""


class Choice(Protocol):
    """A plugin by registered name, with the keyword options its factory is called with
    (:class:`gaitbench.run.case.PluginChoice`)."""

    name: str
    options: Mapping[str, Any]


def assemble_walk(build: Build, n_nodes: int, *, experiment: Choice, transcription: Choice, solver: Choice,
                  strategy: Choice, objective: Choice, steps: int | None = None,
                  problem_options: Mapping[str, Any] | None = None, **walk: Any) -> tuple[Strategy, WalkProblem]:
    """The strategy and the problem it is to solve: the plugins built in the order above, ``problem_options``
    over the experiment's defaults (its limits), and ``walk`` the problem's other fields (``builds``, ``deadline``,
    ``checkpoint``, ``cores``). The problem keeps the experiment's, the transcription's and the strategy's options
    for the walk's record.
    Raises :class:`gaitbench.contracts.StepsOutOfRange` when ``steps`` does not fit the experiment."""
    built_experiment = build("experiment", experiment.name, **experiment.options)
    built_transcription = build("transcription", transcription.name, **transcription.options)
    built_solver = build("solver", solver.name, **solver.options)
    built_strategy = build("strategy", strategy.name, **strategy.options)
    built_objective = build("objective", objective.name, **objective.options)
    options = replace(ProblemOptions(limits=built_experiment.limits), **(problem_options or {}))
    problem = WalkProblem(built_experiment, built_transcription, built_solver, n_nodes, steps=steps, options=options,
                          objective=built_objective, experiment_options=dict(experiment.options),
                          transcription_options=dict(transcription.options), strategy_options=dict(strategy.options),
                          **walk)
    return built_strategy, problem
