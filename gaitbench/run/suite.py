"""Suites: a TOML file that names a benchmark's cases, checked against the plugins and expanded into cases.

:func:`load_suite` reads a suite file (format in ``docs/suites.md``; parsing in :mod:`gaitbench.run.suite_schema`),
looks every plugin up in the registry, builds each distinct plugin choice once so a bad option fails at load
time rather than hours into a run, and expands the sweep into :class:`gaitbench.run.case.Case` objects:
experiments × N × methods × repetitions, in file order, minus the exclusions. Everything wrong with a file is a
:class:`SuiteError` naming the file and the key.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gaitbench.options import OptionError, check_options
from gaitbench.plugins import (
    PluginBuildError,
    PluginConflictError,
    PluginDirectoryError,
    PluginProblem,
    PluginRegistry,
    UnknownPluginError,
    load_registry,
)
from gaitbench.run.case import DEFAULT_OBJECTIVE, Case, TrackingStage
from gaitbench.run.suite_schema import METHOD_PARTS, parse_suite
from gaitbench.run.suite_spec import Entry, SuiteError, SuiteSpec, Variant

__all__ = ["Suite", "SuiteError", "expand", "load_suite"]


@dataclass(frozen=True)
class Suite:
    """A checked suite file and its cases, ready to run."""

    name: str
    description: str
    path: Path
    text: str
    """The file's text as read, kept for provenance."""
    output: Path
    """The results store directory; relative paths are relative to the current working directory."""
    repetitions: int
    time_limit_s: float
    """Wall-clock limit per case, in seconds."""
    steps: int | None
    plugin_dirs: tuple[str, ...]
    """Absolute plugin directories (``[suite].plugins`` resolved against the suite file's directory)."""
    problem_options: dict[str, Any]
    tracking: TrackingStage | None
    cases: list[Case]
    methods: tuple[str, ...] = ()
    """The method labels, in file order."""
    memory_mb: dict[str, float] = dataclasses.field(default_factory=dict)
    """Each case's estimated peak memory by case key (:mod:`gaitbench.run.memory`), for a run to check what its workers
    need together."""
    plugin_problems: tuple[PluginProblem, ...] = ()
    """Plugins that failed to load (or names registered twice) when the suite was loaded: a run shows them and
    records them in its provenance, since a missing plugin changes what can run."""

    def with_methods(self, labels: Iterable[str]) -> Suite:
        """This suite with only the cases of the methods ``labels``: a long sweep run one part at a time (the
        cases keep their keys, so a later run of the whole suite with ``--resume`` skips them)."""
        chosen = set(labels)
        unknown = sorted(chosen - set(self.methods))
        if unknown:
            raise ValueError(f"{self.path} has no method {', '.join(map(repr, unknown))}; its methods are "
                             + ", ".join(self.methods))
        return dataclasses.replace(self, cases=[case for case in self.cases if case.method in chosen],
                                   methods=tuple(label for label in self.methods if label in chosen))


@dataclass(frozen=True)
class Method:
    """A labelled transcription/solver/strategy combination."""

    label: str
    key: str
    parts: dict[str, Variant]
    time_limit_s: float | None = None
    """Its cases' limit where the method sets one (``[[method]].time_limit_s``), else the suite's."""


def load_suite(path: str | Path, registry: PluginRegistry | None = None, text: str | None = None) -> Suite:
    """Read, check and expand the suite file at ``path``.

    ``registry`` defaults to the entry-point plugins plus the suite's ``[suite].plugins`` directories (and
    ``$GAITBENCH_PLUGINS_DIR``); a given registry is used as it is. ``text``, when given, is the suite as a run
    recorded it (the file at ``path`` may since have moved or changed), and the file is not read. Raises
    :class:`SuiteError`.
    """
    path = Path(path)
    if text is None:
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise SuiteError(path, "", f"cannot read the suite file: {exc}") from None
    spec = parse_suite(path, text)
    plugin_dirs = _plugin_dirs(path, spec)
    if registry is None:
        try:
            registry = load_registry(plugin_dirs)
        except PluginDirectoryError as exc:
            raise SuiteError(path, "", str(exc)) from None
    methods, cases, memory = _expand(path, spec, registry, plugin_dirs)
    return Suite(
        name=spec.name, description=spec.description, path=path, text=text, output=spec.output,
        repetitions=spec.repetitions, time_limit_s=spec.time_limit_s, steps=spec.steps, plugin_dirs=plugin_dirs,
        problem_options=dict(spec.problem_options), tracking=spec.tracking, cases=cases,
        methods=tuple(method.label for method in methods), memory_mb=memory,
        plugin_problems=tuple(registry.problems),
    )


def expand(path: Path, spec: SuiteSpec, registry: PluginRegistry,
           plugin_dirs: tuple[str, ...] = ()) -> tuple[list[Method], list[Case]]:
    """The suite's methods and its cases, in file order, exclusions dropped and duplicates merged.

    Every plugin choice is built once with its options; the experiments also check ``[suite].steps``, and every
    case must fit in memory (:mod:`gaitbench.run.memory`).
    """
    methods, cases, _ = _expand(path, spec, registry, plugin_dirs)
    return methods, cases


def _expand(path: Path, spec: SuiteSpec, registry: PluginRegistry,
            plugin_dirs: tuple[str, ...]) -> tuple[list[Method], list[Case], dict[str, float]]:
    """:func:`expand`, with each case's memory estimate by key."""
    builder = _Builder(path, registry)
    experiments = [variant for entry in spec.experiments for variant in builder.variants("experiment", entry)]
    if spec.steps is not None:
        for variant in experiments:
            experiment = builder.built[_identity("experiment", variant)]
            if spec.steps > experiment.n_steps:
                raise SuiteError(path, "[suite].steps", f"steps = {spec.steps} exceeds the {experiment.n_steps} "
                                                        f"steps of experiment {variant.label!r}")
    methods = _methods(path, spec, builder)
    _check_tracking(path, spec, registry)
    _check_disturbance(path, spec, registry,
                       {variant.label: builder.built[_identity("experiment", variant)] for variant in experiments})

    planned: list[tuple[Case, dict[str, set]]] = []
    for experiment, n_nodes, method in itertools.product(experiments, spec.n_nodes, methods):
        tags = {"experiment": experiment.names, "N": {n_nodes}, "method": {method.label}}
        tags.update({part: method.parts[part].names for part in METHOD_PARTS})
        # `steps` equal to the experiment's whole walk is the whole walk: the same case (and key, and report rows)
        whole = builder.built[_identity("experiment", experiment)].n_steps
        steps = None if spec.steps == whole else spec.steps
        for repetition in range(spec.repetitions):
            case = Case(
                experiment=experiment.choice, n_nodes=n_nodes,
                transcription=method.parts["transcription"].choice, solver=method.parts["solver"].choice,
                strategy=method.parts["strategy"].choice, steps=steps,
                objective=method.parts["objective"].choice if "objective" in method.parts else DEFAULT_OBJECTIVE,
                problem_options=dict(spec.problem_options), repetition=repetition, tracking=spec.tracking,
                method=method.label, time_limit_s=method.time_limit_s or spec.time_limit_s, plugin_dirs=plugin_dirs,
            )
            planned.append((case, tags))

    kept = []
    matched = [0] * len(spec.exclusions)
    for case, tags in planned:
        hits = [index for index, exclusion in enumerate(spec.exclusions)
                if all(tags[key] & set(values) for key, values in exclusion.match.items())]
        for index in hits:
            matched[index] += 1
        if not hits:
            kept.append(case)
    excluded_by = {key for exclusion in spec.exclusions for key in exclusion.match}
    known = {key: set().union(*(tags[key] for _, tags in planned)) for key in excluded_by}  # every case's tags
    for exclusion, count in zip(spec.exclusions, matched, strict=True):
        for key, values in exclusion.match.items():  # each value of an array, not only the array as a whole
            unknown = [value for value in values if value not in known[key]]
            if unknown:
                raise SuiteError(path, f"{exclusion.key}.{key}", f"{unknown[0]!r} matches no case (a typo?); names "
                                                                 "and labels are matched exactly")
        if not count:
            given = "; ".join(f"{key} = {list(values)}" for key, values in exclusion.match.items())
            raise SuiteError(path, exclusion.key, f"matches no case (a typo?): no case has {given}; names "
                                                  "and labels are matched exactly")
    if not kept:
        raise SuiteError(path, "[[exclude]]", f"the exclusions drop all {len(planned)} cases: nothing to run")

    cases: dict[str, Case] = {}
    for case in kept:
        earlier = cases.setdefault(case.key, case)
        if earlier is not case and earlier.method != case.method:
            raise SuiteError(path, "[[method]]", f"methods {earlier.method!r} and {case.method!r} are the same "
                                       f"transcription, solver and strategy ({case.label}); remove one")
    memory = _check_memory(path, list(cases.values()), builder)
    return methods, list(cases.values()), memory


def _check_memory(path: Path, cases: list[Case], builder: _Builder) -> dict[str, float]:
    """Each case's memory estimate by key; a suite with a case that cannot fit (:mod:`gaitbench.run.memory`) is refused,
    naming the largest N that fits. Cases are looked at largest N first, so the message is about the worst one."""
    from gaitbench.run.memory import estimate_case_memory, memory_limit, memory_problem

    try:
        limit = memory_limit()
    except ValueError as exc:
        raise SuiteError(path, "", str(exc)) from None
    estimates: dict[tuple, float] = {}
    memory = {}
    for case in sorted(cases, key=lambda case: -case.n_nodes):
        experiment = builder.built[("experiment", json.dumps(case.experiment.as_dict(), sort_keys=True,
                                                             default=str))]
        shape = (case.transcription.name, case.strategy.name, case.n_nodes, case.steps or experiment.n_steps)
        if shape not in estimates:
            problem = memory_problem(*shape, what=repr(case.method), limit=limit)
            if problem is not None:
                raise SuiteError(path, "[sweep].N", problem)
            estimates[shape] = estimate_case_memory(*shape).mb
        memory[case.key] = estimates[shape]
    return memory


class _Builder:
    """Looks plugins up and builds each distinct choice once, turning every failure into a SuiteError."""

    def __init__(self, path: Path, registry: PluginRegistry) -> None:
        self.path = path
        self.registry = registry
        self.built: dict[tuple[str, str], Any] = {}

    def variants(self, kind: str, entry: Entry) -> list[Variant]:
        try:
            self.registry.get(kind, entry.name)
        except (UnknownPluginError, PluginConflictError) as exc:
            raise SuiteError(self.path, entry.key, str(exc)) from None
        variants = entry.variants()
        for variant in variants:
            identity = _identity(kind, variant)
            if identity in self.built:
                continue
            try:
                check_options(self.registry.get(kind, entry.name).factory, variant.choice.options, kind=kind)
            except OptionError as exc:
                head = exc.option.split(".")[0]
                where = f"{entry.key}.{'grid' if head in entry.grid else 'options'}.{exc.option}"
                raise SuiteError(self.path, where, f"{kind} {entry.name!r}: {exc.message}") from None
            try:
                self.built[identity] = self.registry.create(kind, variant.choice.name, **variant.choice.options)
            except PluginBuildError as exc:  # the plugin's own fault, whatever the options
                raise SuiteError(self.path, entry.key, str(exc)) from None
            except (TypeError, ValueError) as exc:
                options = ", ".join(f"{k}={v!r}" for k, v in variant.choice.options.items()) or "no options"
                raise SuiteError(self.path, entry.key, f"cannot build {kind} {variant.choice.name!r} with "
                                                       f"{options}: {exc}") from None
        return variants


def _methods(path: Path, spec: SuiteSpec, builder: _Builder) -> list[Method]:
    methods = []
    if spec.methods is None:
        assert spec.product is not None
        lists = [[v for entry in spec.product[part] for v in builder.variants(part, entry)] for part in METHOD_PARTS]
        for transcription, solver, strategy in itertools.product(*lists):
            label = f"{strategy.label} {transcription.label} {solver.label}"
            methods.append(Method(label, "[sweep]", {"transcription": transcription, "solver": solver,
                                                     "strategy": strategy}))
    else:
        for method in spec.methods:
            lists = [builder.variants(part, method.parts[part]) for part in METHOD_PARTS]
            objectives = builder.variants("objective", method.parts["objective"]) if "objective" in method.parts \
                else [None]
            for transcription, solver, strategy, objective in itertools.product(*lists, objectives):
                parts = {"transcription": transcription, "solver": solver, "strategy": strategy}
                if objective is not None:
                    parts["objective"] = objective
                if method.label is None:
                    label = f"{strategy.label} {transcription.label} {solver.label}"
                    label += f" {objective.label}" if objective is not None else ""
                else:
                    suffixes = [part.grid_suffix for part in parts.values() if part.grid_suffix]
                    label = f"{method.label}({'; '.join(suffixes)})" if suffixes else method.label
                methods.append(Method(label, method.key, parts, method.time_limit_s))
    seen: dict[str, Method] = {}
    for method in methods:
        if method.label in seen:
            raise SuiteError(path, method.key, f"method label {method.label!r} is used twice; labels name the "
                                          "methods in results and must be distinct")
        seen[method.label] = method
    return methods


def _check_tracking(path: Path, spec: SuiteSpec, registry: PluginRegistry) -> None:
    """Tracking plugin names must exist, for each kind of which any plugin is registered, and the stage's options
    must be ones the tracking accepts (checked before any walk is solved, rather than after each one)."""
    if spec.tracking is None:
        return
    kinds = [kind for kind in ("controller", "observer", "disturbance") if registry.names(kind)]
    for kind in kinds:
        try:
            registry.get(kind, getattr(spec.tracking, kind))
        except (UnknownPluginError, PluginConflictError) as exc:
            raise SuiteError(path, f"[tracking].{kind}", str(exc)) from None
    if len(kinds) < 3:
        return  # no tracking plugins to check the options against (a registry without them)
    from gaitbench.control.tracking import check_tracking_options

    try:
        check_tracking_options(spec.tracking.options, registry, spec.tracking.controller, spec.tracking.observer,
                               spec.tracking.disturbance)
    except OptionError as exc:
        raise SuiteError(path, f"[tracking].options.{exc.option}", exc.message) from None


def _check_disturbance(path: Path, spec: SuiteSpec, registry: PluginRegistry, experiments: dict) -> None:
    """The tracking stage's disturbance, built for each experiment: one that cannot act on an experiment (friction on
    one without friction parameters, a push in a step it does not walk) would fail every case after its walk."""
    if spec.tracking is None or not registry.names("disturbance"):
        return
    options = dict(spec.tracking.options.get("disturbance") or {})
    for label, experiment in experiments.items():
        try:
            registry.create("disturbance", spec.tracking.disturbance, experiment, **options)
        except (TypeError, ValueError) as exc:
            raise SuiteError(path, "[tracking].disturbance", f"{spec.tracking.disturbance!r} on experiment "
                                                             f"{label!r}: {exc}") from None
        step = options.get("step")
        if spec.steps is not None and isinstance(step, int) and step > spec.steps:
            raise SuiteError(path, "[tracking].options.disturbance.step", f"step = {step}: the suite walks "
                                                                          f"{spec.steps} steps ([suite].steps)")


def _plugin_dirs(path: Path, spec: SuiteSpec) -> tuple[str, ...]:
    directories = []
    for index, given in enumerate(spec.plugins):
        directory = (path.parent / Path(given).expanduser()).resolve()
        if not directory.is_dir():
            raise SuiteError(path, f"[suite].plugins[{index}]", f"plugin directory '{given}' ({directory}, "
                                                                 "relative to the suite file) does not exist")
        directories.append(str(directory))
    return tuple(directories)


def _identity(kind: str, variant: Variant) -> tuple[str, str]:
    return kind, json.dumps(variant.choice.as_dict(), sort_keys=True, default=str)

