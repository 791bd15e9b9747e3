"""Checking a plugin's options before anything runs, so that a typo fails at suite load and not hours into a run.

:func:`check_options` looks at options without solving anything: the factory's signature (unknown keywords, and
values against simple type hints such as ``int``, ``float | None`` or ``Literal["a", "b"]``), then the factory's
own optional ``check_options(options)`` hook, for what a signature cannot say (the ``**options`` a solver hands to
its library). Every problem is an :class:`OptionError` naming the option; suites turn it into
``<file>: [sweep].solvers[0].options.<option>: ...`` and ``gaitbench solve`` into a usage error. Plugins raise it
from their hook (docs/plugins.md, "Checking options").
"""

from __future__ import annotations

import difflib
import inspect
import math
import re
import types
import typing
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any


@dataclass(frozen=True, eq=False)
class SolverOptions:
    """The options every gaitbench solver shares (docs/solvers.md), with the defaults every built-in solver gives them:
    the base of a solver's options written as a frozen dataclass. Compared by identity, as a solver built on them is.
    """

    max_iterations: int = 3000
    time_limit_s: float | None = None
    tolerance: float = 1e-8
    print_level: int = 0

    def __post_init__(self) -> None:
        """The counts as integers and the tolerance as a float, whatever number the options gave."""
        for name, kind in (("max_iterations", int), ("tolerance", float), ("print_level", int)):
            object.__setattr__(self, name, kind(getattr(self, name)))


COMMON_SOLVER_OPTIONS = tuple(field.name for field in fields(SolverOptions))
"""The options every gaitbench solver shares, checked for every solver plugin that is given them."""


class OptionError(ValueError):
    """An option a plugin refuses: which one (``option``, dotted for nested ones) and why."""

    def __init__(self, option: str, message: str) -> None:
        self.option = option
        self.message = message
        super().__init__(option, message)  # so it pickles

    def __str__(self) -> str:
        return f"{self.option}: {self.message}"


def unknown_option(option: str, allowed: Iterable[str], *, candidates: Iterable[str] | None = None,
                   more: str = "", cutoff: float = 0.6) -> OptionError:
    """``unknown option 'x' (did you mean 'y'?); allowed: a, b``, with ``more`` appended (e.g. where the rest of a
    library's options are listed). Close matches come from ``candidates`` (default: ``allowed``), which may be
    longer than what is worth listing; with hundreds of them, a higher ``cutoff`` keeps far-fetched ones out."""
    allowed = list(allowed)
    close = difflib.get_close_matches(option, list(allowed if candidates is None else candidates), n=1,
                                      cutoff=cutoff)
    hint = f" (did you mean '{close[0]}'?)" if close else ""
    listing = f"; allowed: {', '.join(allowed)}" if allowed else "; it takes no options"
    return OptionError(option, f"unknown option {option!r}{hint}{listing}{more}")


def check_options(factory: Callable[..., Any], options: Mapping[str, Any], *, kind: str = "",
                  injected: int = 0) -> None:
    """Raise :class:`OptionError` for the first option ``factory`` would refuse, without building anything.

    ``injected`` is how many leading positional arguments gaitbench passes itself (a controller's ``model`` and
    ``reference``), which are not options. Solvers (``kind="solver"``) also have the shared options checked:
    ``max_iterations`` an integer ≥ 1, ``time_limit_s`` a number > 0 (or None), ``tolerance`` a number > 0,
    ``print_level`` an integer ≥ 0.
    """
    parameters, takes_any = _keyword_parameters(factory, injected)
    if parameters is not None:
        for name in options:
            if name not in parameters and not takes_any:
                raise unknown_option(name, parameters)
    if kind == "solver":
        check_common_solver_options(options)
    if parameters is not None:
        hints = _type_hints(factory)
        for name, value in options.items():
            if name in parameters and name in hints:
                expected = _expected(hints[name], value)
                if expected is not None:
                    raise OptionError(name, f"expected {expected}, found {describe(value)}")
    hook = getattr(factory, "check_options", None)
    if callable(hook):
        hook(dict(options))


def check_common_solver_options(options: Mapping[str, Any]) -> None:
    """The shared solver options' types and ranges (see :data:`COMMON_SOLVER_OPTIONS`)."""
    checks = {
        "max_iterations": (lambda v: _is_int(v) and v >= 1, "an integer ≥ 1"),
        "time_limit_s": (lambda v: v is None or (_is_number(v) and math.isfinite(v) and v > 0),
                         "a number > 0 (seconds)"),
        "tolerance": (lambda v: _is_number(v) and math.isfinite(v) and v > 0, "a number > 0"),
        "print_level": (lambda v: _is_int(v) and v >= 0, "an integer ≥ 0"),
    }
    for name, (ok, expected) in checks.items():
        if name in options and not ok(options[name]):
            raise OptionError(name, f"expected {expected}, found {describe(options[name])}")


def describe(value: Any) -> str:
    """``a string 'x'``, ``an integer (3)``, ``a table``: what was given where something else was expected."""
    if isinstance(value, bool):
        return f"a boolean ({'true' if value else 'false'})"
    if isinstance(value, int):
        return f"an integer ({value})"
    if isinstance(value, float):
        return f"a float ({value!r})"
    if isinstance(value, str):
        return f"a string {value!r}"
    if isinstance(value, list):
        return "an empty array" if not value else f"an array ({show_value(value)})"
    if isinstance(value, dict):
        return "a table"
    return f"a {type(value).__name__} ({value})"


def show_value(value: Any) -> str:
    """A value as TOML would write it, for labels (a suite's grid variants) and messages."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"' if not re.fullmatch(r"[A-Za-z0-9_.+-]+", value) else value
    if isinstance(value, list):
        return "[" + ", ".join(show_value(item) for item in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {show_value(v)}" for k, v in value.items()) + "}"
    return repr(value) if isinstance(value, float) else str(value)


def _keyword_parameters(factory: Callable[..., Any], injected: int) -> tuple[list[str] | None, bool]:
    """The factory's option names and whether it takes any keyword (``**options``); None when it has no readable
    signature (then only its hook can check)."""
    try:
        signature = inspect.signature(factory)
    except (TypeError, ValueError):
        return None, True
    names, takes_any, skipped = [], False, 0
    for parameter in signature.parameters.values():
        if parameter.kind is parameter.VAR_KEYWORD:
            takes_any = True
        elif parameter.kind is parameter.VAR_POSITIONAL:
            continue
        elif skipped < injected and parameter.kind in (parameter.POSITIONAL_ONLY, parameter.POSITIONAL_OR_KEYWORD):
            skipped += 1
        elif parameter.kind is not parameter.POSITIONAL_ONLY:
            names.append(parameter.name)
    return names, takes_any


def _type_hints(factory: Callable[..., Any]) -> dict[str, Any]:
    """The factory's parameter annotations, each resolved on its own: one that cannot be (a name imported only for
    type checking) is left out, and its option goes unchecked."""
    target = factory.__init__ if inspect.isclass(factory) else factory
    annotations = getattr(target, "__annotations__", {})
    namespace = getattr(inspect.getmodule(target), "__dict__", {})
    hints = {}
    for name, annotation in annotations.items():
        try:
            hints[name] = eval(annotation, namespace) if isinstance(annotation, str) else annotation  # noqa: S307
        except Exception:
            continue
    return hints


def _expected(hint: Any, value: Any) -> str | None:
    """What ``hint`` expects when ``value`` does not match it, else None; hints it cannot judge pass."""
    if hint is typing.Any:
        return None
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        options = typing.get_args(hint)
        wanted = [_expected(option, value) for option in options]
        if any(item is None for item in wanted):
            return None
        return " or ".join(dict.fromkeys(item for item in wanted if item))
    if origin is typing.Literal:
        choices = typing.get_args(hint)
        return None if value in choices else "one of " + ", ".join(repr(choice) for choice in choices)
    if hint is type(None):
        return None if value is None else "none"
    if hint is bool:
        return None if isinstance(value, bool) else "true or false"
    if hint is int:
        return None if _is_int(value) else "an integer"
    if hint is float:
        return None if _is_number(value) else "a number"
    if hint is str:
        return None if isinstance(value, str) else "a string"
    if origin is not None and inspect.isclass(origin) and issubclass(origin, Sequence):
        return None if isinstance(value, (list, tuple)) else "an array"
    return None


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)
