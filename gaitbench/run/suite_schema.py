"""Suite files as written: TOML parsing and every structural check, before any plugin is looked up.

:func:`parse_suite` turns a suite file's text into a :class:`SuiteSpec` or raises :class:`SuiteError` naming the
file, the key (``[sweep].solvers[1]``) and what was expected and found. Whether a plugin name exists and accepts
its options is the registry's business and is checked by :mod:`gaitbench.run.suite`. The format is documented in
``docs/suites.md``.
"""

from __future__ import annotations

import difflib
import math
import os
import re
import sys
from dataclasses import fields
from pathlib import Path
from typing import Any

from gaitbench.options import describe, show_value
from gaitbench.run.case import TrackingStage
from gaitbench.run.suite_spec import Entry, Exclusion, MethodSpec, SuiteError, SuiteSpec

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

NAME_PATTERN = re.compile(r"[a-z0-9-]+")
MIN_NODES = 3
"""The smallest N a step problem accepts (``gaitbench.problem.gait_problem.StepStructure``)."""

DEFAULT_REPETITIONS = 1
DEFAULT_TIME_LIMIT_S = 3600.0

TABLES = ("suite", "sweep", "exclude", "method", "tracking")
SUITE_KEYS = ("name", "description", "output", "repetitions", "time_limit_s", "steps", "plugins", "problem_options")
SWEEP_KEYS = ("experiments", "N", "transcriptions", "solvers", "strategies")
ENTRY_KEYS = ("name", "options", "grid", "label")
METHOD_KEYS = ("label", "transcription", "solver", "strategy", "objective", "time_limit_s")
METHOD_PARTS = ("transcription", "solver", "strategy")
EXCLUDE_KEYS = ("experiment", "N", "transcription", "solver", "strategy", "method")
TRACKING_KEYS = ("controller", "observer", "disturbance", "options")
RANGE_KEYS = ("start", "stop", "step")
PRODUCT_KEYS = {"transcription": "transcriptions", "solver": "solvers", "strategy": "strategies"}
"""Each method part and the ``[sweep]`` list that gives it when there is no ``[[method]]``."""


def parse_suite(path: str | Path, text: str) -> SuiteSpec:
    """Parse and check a suite file's text; ``path`` only names the file in errors."""
    return _Parser(Path(path)).parse(text)


class _Parser:
    def __init__(self, path: Path) -> None:
        self.path = path

    def error(self, key: str, message: str) -> SuiteError:
        return SuiteError(self.path, key, message)

    # The file and its tables

    def parse(self, text: str) -> SuiteSpec:
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise self._syntax_error(exc) from None
        self.keys(data, "", TABLES, what="table")
        suite = self.table(data, "suite", "[suite]", required=True)
        sweep = self.table(data, "sweep", "[sweep]", required=True)
        self.keys(suite, "[suite]", SUITE_KEYS)
        self.keys(sweep, "[sweep]", SWEEP_KEYS)

        name = self.string(suite, "name", "[suite]", required=True)
        if not NAME_PATTERN.fullmatch(name):
            raise self.error("[suite].name", f"expected lowercase letters, digits and dashes ([a-z0-9-]+), "
                                             f"found {name!r}")
        description = self.string(suite, "description", "[suite]") or ""
        output = self.output(suite)
        repetitions = self.integer(suite, "repetitions", "[suite]", minimum=1, default=DEFAULT_REPETITIONS)
        time_limit = self.number(suite, "time_limit_s", "[suite]", default=DEFAULT_TIME_LIMIT_S)
        steps = self.integer(suite, "steps", "[suite]", minimum=1, default=None)
        plugins = tuple(self.strings(suite, "plugins", "[suite]"))
        problem_options = self.problem_options(suite.get("problem_options"), "[suite].problem_options")

        experiments = self.entries(sweep, "experiments", "[sweep]", required=True)
        n_nodes = self.nodes(sweep.get("N"), "[sweep].N")
        methods = self.methods(data.get("method"))
        given = [PRODUCT_KEYS[part] for part in METHOD_PARTS if PRODUCT_KEYS[part] in sweep]
        product = None
        if methods is not None:
            if given:
                raise self.error(f"[sweep].{given[0]}", "give either [[method]] tables or the [sweep] lists "
                                                        "transcriptions, solvers and strategies, not both")
        else:
            product = {part: self.entries(sweep, PRODUCT_KEYS[part], "[sweep]", required=True)
                       for part in METHOD_PARTS}
        return SuiteSpec(
            name=name, description=description, output=Path(output or f"results/{name}"),
            repetitions=repetitions, time_limit_s=time_limit, steps=steps, plugins=plugins,
            problem_options=problem_options, experiments=experiments, n_nodes=n_nodes, product=product,
            methods=methods, exclusions=self.exclusions(data.get("exclude")),
            tracking=self.tracking(data.get("tracking")),
        )

    def output(self, suite: dict) -> str | None:
        """``[suite].output``: absolute as written (``~`` for the home directory), or relative to the current
        directory and inside it (``..`` that climbs out is refused), so that a suite file from elsewhere cannot point
        a run at any directory."""
        output = self.string(suite, "output", "[suite]")
        if output and output.startswith("~"):  # as the plugins' directories are, not a directory named "~"
            output = os.path.expanduser(output)
        if output and not Path(output).is_absolute() and Path(os.path.normpath(output)).parts[:1] == ("..",):
            raise self.error("[suite].output", f"{output!r} leads out of the current directory, which a relative "
                                               "output is inside; write an absolute path to keep the results there")
        return output

    def _syntax_error(self, exc: Exception) -> SuiteError:
        message = str(exc)
        where = re.search(r"\s*\(at (line \d+, column \d+|end of document)\)$", message)
        if where:
            return self.error(where.group(1), f"TOML syntax error: {message[:where.start()]}")
        return self.error("", f"TOML syntax error: {message}")

    def methods(self, value: Any) -> list[MethodSpec] | None:
        if value is None:
            return None
        tables = self.array_of_tables(value, "[[method]]")
        methods = []
        for index, table in enumerate(tables):
            key = f"[[method]][{index}]"
            self.keys(table, key, METHOD_KEYS)
            label = self.string(table, "label", key)
            if label is not None and not label.strip():
                raise self.error(f"{key}.label", "expected a non-empty string, found ''")
            parts = {}
            for part in METHOD_PARTS:
                if part not in table:
                    raise self.error(key, f"missing required key '{part}' (a {part} name or a table "
                                          f"{{name, options}})")
                parts[part] = self.entry(table[part], f"{key}.{part}")
            if "objective" in table:
                parts["objective"] = self.entry(table["objective"], f"{key}.objective")
            time_limit = self.number(table, "time_limit_s", key, default=None)
            methods.append(MethodSpec(key, label, parts, time_limit))
        return methods

    def exclusions(self, value: Any) -> list[Exclusion]:
        if value is None:
            return []
        exclusions = []
        for index, table in enumerate(self.array_of_tables(value, "[[exclude]]")):
            key = f"[[exclude]][{index}]"
            self.keys(table, key, EXCLUDE_KEYS)
            if not table:
                raise self.error(key, f"an exclusion needs at least one key of {', '.join(EXCLUDE_KEYS)}; an "
                                      "empty one would drop every case")
            match = {}
            for name, item in table.items():
                items = item if isinstance(item, list) else [item]
                if not items:
                    raise self.error(f"{key}.{name}", "expected a non-empty array, found []")
                for position, single in enumerate(items):
                    where = f"{key}.{name}" + (f"[{position}]" if isinstance(item, list) else "")
                    if name == "N":
                        if not _is_int(single):
                            raise self.error(where, f"expected an integer N or an array of them, found "
                                                    f"{describe(single)}")
                    elif not isinstance(single, str) or not single:
                        raise self.error(where, f"expected a {name} name or label (or an array of them), "
                                                f"found {describe(single)}")
                match[name] = tuple(items)
            exclusions.append(Exclusion(key, match))
        return exclusions

    def tracking(self, value: Any) -> TrackingStage | None:
        if value is None:
            return None
        if not isinstance(value, dict):
            raise self.error("[tracking]", f"expected a table, found {describe(value)}")
        self.keys(value, "[tracking]", TRACKING_KEYS)
        names = {part: self.string(value, part, "[tracking]") for part in ("controller", "observer", "disturbance")}
        options = self.table(value, "options", "[tracking].options") or {}
        return TrackingStage(**{part: name for part, name in names.items() if name is not None}, options=options)

    def problem_options(self, value: Any, key: str) -> dict[str, Any]:
        if value is None:
            return {}
        if not isinstance(value, dict):
            raise self.error(key, f"expected a table of ProblemOptions overrides, found {describe(value)}")
        self.keys(value, key, tuple(problem_option_kinds()))
        for name, option in value.items():
            problem = problem_option_error(name, option)
            if problem is not None:
                raise self.error(f"{key}.{name}", problem)
        return dict(value)

    # Plugin entries

    def entries(self, table: dict, name: str, where: str, *, required: bool = False) -> list[Entry]:
        key = f"{where}.{name}"
        if name not in table:
            if required:
                raise self.error(where, f"missing required key '{name}' (an array of {name})")
            return []
        value = table[name]
        if not isinstance(value, list):
            raise self.error(key, f"expected an array of {name}, found {describe(value)}")
        if not value:
            raise self.error(key, f"expected a non-empty array of {name}, found []")
        entries = [self.entry(item, f"{key}[{index}]") for index, item in enumerate(value)]
        seen: dict[tuple, str] = {}
        for entry in entries:
            identity = (entry.name, _canonical(entry.options), _canonical(entry.grid), entry.label)
            if identity in seen:
                raise self.error(entry.key, f"the same entry as {seen[identity]}")
            seen[identity] = entry.key
        return entries

    def entry(self, value: Any, key: str) -> Entry:
        if isinstance(value, str):
            if not value:
                raise self.error(key, "expected a plugin name, found ''")
            return Entry(value, key)
        if not isinstance(value, dict):
            raise self.error(key, f"expected a plugin name or a table {{name, options, grid, label}}, found "
                                  f"{describe(value)}")
        self.keys(value, key, ENTRY_KEYS)
        name = self.string(value, "name", key, required=True)
        if not name:
            raise self.error(f"{key}.name", "expected a plugin name, found ''")
        options = self.table(value, "options", f"{key}.options") or {}
        grid = self.table(value, "grid", f"{key}.grid") or {}
        for option, values in grid.items():
            if not isinstance(values, list):
                raise self.error(f"{key}.grid.{option}", f"expected an array of values, found {describe(values)}")
            if not values:
                raise self.error(f"{key}.grid.{option}", "expected a non-empty array of values, found []")
            if option in options:
                raise self.error(f"{key}.grid.{option}", f"'{option}' is given both in options and in grid")
            if len({_canonical(item) for item in values}) < len(values):
                raise self.error(f"{key}.grid.{option}", f"a value is listed twice in {show_value(values)}")
        label = self.string(value, "label", key)
        if label is not None and not label.strip():
            raise self.error(f"{key}.label", "expected a non-empty string, found ''")
        return Entry(name, key, dict(options), {option: list(values) for option, values in grid.items()}, label)

    def nodes(self, value: Any, key: str) -> list[int]:
        if value is None:
            raise self.error("[sweep]", "missing required key 'N' (an array of integers, or {start, stop, step})")
        if isinstance(value, dict):
            self.keys(value, key, RANGE_KEYS)
            start = self.integer(value, "start", key, minimum=MIN_NODES, required=True)
            stop = self.integer(value, "stop", key, minimum=MIN_NODES, required=True)
            step = self.integer(value, "step", key, minimum=1, default=1)
            if stop < start:
                raise self.error(f"{key}.stop", f"expected stop ≥ start = {start}, found {stop}")
            return list(range(start, stop + 1, step))
        if not isinstance(value, list):
            raise self.error(key, f"expected an array of integers or a table {{start, stop, step}}, found "
                                  f"{describe(value)}")
        if not value:
            raise self.error(key, "expected a non-empty array of integers, found []")
        for index, item in enumerate(value):
            self.check_nodes(item, f"{key}[{index}]")
            if item in value[:index]:
                raise self.error(f"{key}[{index}]", f"N = {item} is listed twice")
        return list(value)

    def check_nodes(self, value: Any, key: str) -> None:
        if not _is_int(value):
            raise self.error(key, f"expected an integer number of nodes per step, found {describe(value)}")
        if value < MIN_NODES:
            raise self.error(key, f"expected N ≥ {MIN_NODES} (a step needs at least {MIN_NODES} nodes), "
                                  f"found {value}")

    # Typed values

    def keys(self, table: dict, where: str, allowed: tuple[str, ...], *, what: str = "key") -> None:
        for name in table:
            if name in allowed:
                continue
            shown = [_table_name(item) for item in allowed] if what == "table" else list(allowed)
            close = difflib.get_close_matches(name, allowed, n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            unknown = _table_name(name) if what == "table" else f"'{name}'"
            raise self.error(where or "(top level)", f"unknown {what} {unknown}{hint}; allowed: {', '.join(shown)}")

    def table(self, data: dict, name: str, where: str, *, required: bool = False) -> dict | None:
        """``data[name]``, which must be a table; ``where`` is its key in messages."""
        if name not in data:
            if required:
                raise self.error("", f"missing required table [{name}]")
            return None
        value = data[name]
        if not isinstance(value, dict):
            raise self.error(where, f"expected a table, found {describe(value)}")
        return value

    def array_of_tables(self, value: Any, key: str) -> list[dict]:
        if not isinstance(value, list) or not all(isinstance(item, dict) for item in value):
            raise self.error(key, f"expected an array of tables ({key} headers), found {describe(value)}")
        return value

    def string(self, table: dict, name: str, where: str, *, required: bool = False) -> str | None:
        if name not in table:
            if required:
                raise self.error(where, f"missing required key '{name}' (a string)")
            return None
        value = table[name]
        if not isinstance(value, str):
            raise self.error(f"{where}.{name}", f"expected a string, found {describe(value)}")
        return value

    def strings(self, table: dict, name: str, where: str) -> list[str]:
        value = table.get(name, [])
        if not isinstance(value, list):
            raise self.error(f"{where}.{name}", f"expected an array of strings, found {describe(value)}")
        for index, item in enumerate(value):
            if not isinstance(item, str) or not item:
                raise self.error(f"{where}.{name}[{index}]", f"expected a non-empty string, found {describe(item)}")
        return value

    def integer(self, table: dict, name: str, where: str, *, minimum: int, default: Any = None,
                required: bool = False) -> Any:
        if name not in table:
            if required:
                raise self.error(where, f"missing required key '{name}' (an integer)")
            return default
        value = table[name]
        if not _is_int(value):
            raise self.error(f"{where}.{name}", f"expected an integer, found {describe(value)}")
        if value < minimum:
            raise self.error(f"{where}.{name}", f"expected an integer ≥ {minimum}, found {value}")
        return value

    def number(self, table: dict, name: str, where: str, *, default: float | None) -> float | None:
        if name not in table:
            return default
        value = table[name]
        if not _is_number(value) or not math.isfinite(value) or value <= 0:
            raise self.error(f"{where}.{name}", f"expected a positive number, found {describe(value)}")
        return float(value)


def problem_option_kinds() -> dict[str, str]:
    """Every :class:`~gaitbench.problem.gait_problem.ProblemOptions` field a suite's ``problem_options`` (or ``gaitbench
    solve -p``) may set, in declaration order, with what it takes: its allowed values (``OPTION_CHOICES``), true or
    false, or a non-negative number. ``limits`` is not among them: it comes from the experiment."""
    from gaitbench.problem.gait_problem import OPTION_CHOICES, ProblemOptions

    defaults = ProblemOptions()
    kinds = {}
    for item in fields(ProblemOptions):
        if item.name == "limits":
            continue
        default = getattr(defaults, item.name)
        if item.name in OPTION_CHOICES:
            kinds[item.name] = _alternatives(OPTION_CHOICES[item.name])
        elif isinstance(default, bool):
            kinds[item.name] = "true or false"
        elif isinstance(default, str):
            kinds[item.name] = "a string"
        else:  # floats, and friction_coefficient whose default None means "no friction cone"
            kinds[item.name] = "a non-negative number"
    return kinds


def problem_option_error(name: str, value: Any) -> str | None:
    """What is wrong with ``name = value`` as a ProblemOptions override, or None if nothing is.

    The message names the allowed keys (for an unknown one) or values: ``expected 'terrain', 'chord' or 'off',
    found a string 'of'``. Suites and ``gaitbench solve -p`` share it.
    """
    from gaitbench.problem.gait_problem import OPTION_CHOICES

    kinds = problem_option_kinds()
    if name not in kinds:
        close = difflib.get_close_matches(name, kinds, n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        return f"unknown key '{name}'{hint}; allowed: {', '.join(kinds)}"
    expected = kinds[name]
    if name in OPTION_CHOICES:
        ok = isinstance(value, str) and value in OPTION_CHOICES[name]
    elif expected == "true or false":
        ok = isinstance(value, bool)
    elif expected == "a string":
        ok = isinstance(value, str)
    else:
        ok = _is_number(value) and math.isfinite(value) and value >= 0
    return None if ok else f"expected {expected}, found {describe(value)}"


def _alternatives(choices: tuple[str, ...]) -> str:
    """``'a'``, ``'a' or 'b'``, ``'a', 'b' or 'c'``."""
    quoted = [f"'{choice}'" for choice in choices]
    return quoted[0] if len(quoted) == 1 else f"{', '.join(quoted[:-1])} or {quoted[-1]}"


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _table_name(name: str) -> str:
    return f"[[{name}]]" if name in ("exclude", "method") else f"[{name}]"


def _canonical(value: Any) -> str:
    import json

    return json.dumps(value, sort_keys=True, default=str)
