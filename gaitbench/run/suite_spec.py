"""A suite as parsed: its plugin entries, methods and exclusions, before any plugin is looked up.

:func:`gaitbench.run.suite_schema.parse_suite` makes a :class:`SuiteSpec` from a suite file's text (or raises
:class:`SuiteError`); :mod:`gaitbench.run.suite` turns it into cases.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gaitbench.options import show_value
from gaitbench.run.case import PluginChoice, TrackingStage


class SuiteError(Exception):
    """A suite file that cannot be run: ``<file>: <key>: <message>``, the key as ``[sweep].solvers[1]``."""

    def __init__(self, path: str | Path, key: str, message: str) -> None:
        self.path = Path(path)
        self.key = key
        self.message = message
        super().__init__(path, key, message)  # so it pickles

    def __str__(self) -> str:
        return f"{self.path}: {self.key}: {self.message}" if self.key else f"{self.path}: {self.message}"


@dataclass(frozen=True)
class Entry:
    """One plugin entry as written: a name, or ``{name, options, grid, label}``; ``key`` is where it stands."""

    name: str
    key: str
    options: dict[str, Any] = field(default_factory=dict)
    grid: dict[str, list[Any]] = field(default_factory=dict)
    label: str | None = None

    def variants(self) -> list[Variant]:
        """One variant per combination of the grid's values (cartesian, in file order); one without a grid."""
        if not self.grid:
            return [Variant(self, PluginChoice(self.name, dict(self.options)), "")]
        names = list(self.grid)
        variants = []
        for values in itertools.product(*(self.grid[name] for name in names)):
            chosen = dict(zip(names, values, strict=True))
            suffix = ", ".join(f"{name}={show_value(value)}" for name, value in chosen.items())
            variants.append(Variant(self, PluginChoice(self.name, {**self.options, **chosen}), suffix))
        return variants


@dataclass(frozen=True)
class Variant:
    """An entry with its grid values filled in: the plugin choice and how tables and exclusions name it."""

    entry: Entry
    choice: PluginChoice
    grid_suffix: str
    """``option=value, ...`` of the grid values, empty without a grid."""

    @property
    def label(self) -> str:
        """The entry's label (with the grid values in parentheses) or, unlabelled, ``name(option=value, ...)``."""
        if self.entry.label is None:
            return self.choice.describe()
        return f"{self.entry.label}({self.grid_suffix})" if self.grid_suffix else self.entry.label

    @property
    def names(self) -> set[str]:
        """What an exclusion may call it: the plugin name, the entry's label, the variant's label."""
        return {self.choice.name, self.label} | ({self.entry.label} if self.entry.label else set())


@dataclass(frozen=True)
class MethodSpec:
    """One ``[[method]]``: an optional label, its three parts and optionally its ``objective`` (an entry under the
    part name ``objective``; net-power when not given) and its own ``time_limit_s``."""

    key: str
    label: str | None
    parts: dict[str, Entry]
    time_limit_s: float | None = None
    """Its cases' limit in place of the suite's: a method far slower than the others (the reference column, an SQP
    in Python standing in for SNOPT) gets the time it needs without lifting the guard on every case."""


@dataclass(frozen=True)
class Exclusion:
    """One ``[[exclude]]``: each key with the names (or N values) it matches."""

    key: str
    match: dict[str, tuple[Any, ...]]


@dataclass(frozen=True)
class SuiteSpec:
    """A suite file after parsing and structural checks, plugins not yet looked up."""

    name: str
    description: str
    output: Path
    repetitions: int
    time_limit_s: float
    steps: int | None
    plugins: tuple[str, ...]
    """Plugin directories as written (relative to the suite file)."""
    problem_options: dict[str, Any]
    experiments: list[Entry]
    n_nodes: list[int]
    product: dict[str, list[Entry]] | None
    """``transcription``/``solver``/``strategy`` → entries, when the methods are their product."""
    methods: list[MethodSpec] | None
    """The ``[[method]]`` list, when given (then ``product`` is None)."""
    exclusions: list[Exclusion]
    tracking: TrackingStage | None
