"""Finding plugins and turning their registrations into one registry of named factories.

Plugins come from two places: the ``gaitbench`` entry-point group (the built-in plugins use it too, so they
get no special treatment) and plugin directories, whose ``*.py`` files are loaded as one-off plugins. Every
source is loaded and asked for its registrations on its own, so one broken plugin becomes a recorded
:class:`PluginProblem` instead of taking the whole tool down: whatever it raises, ``SystemExit`` included, except
a ``KeyboardInterrupt``, which is the user's.
"""

from __future__ import annotations

import importlib.util
import os
import re
import sys
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any, Literal, overload

import pluggy

import gaitbench.hookspecs as hookspecs
from gaitbench.hookspecs import KINDS
from gaitbench.registration import Registration

if TYPE_CHECKING:
    from gaitbench.contracts import (
        BipedModel,
        Controller,
        Disturbance,
        Experiment,
        Objective,
        Observer,
        Reporter,
        Solver,
        Strategy,
        Transcription,
    )

PLUGINS_DIR_ENV = "GAITBENCH_PLUGINS_DIR"
"""Environment variable with extra plugin directories, separated by ``os.pathsep``."""

ENTRY_POINT_GROUP = "gaitbench"

_DIR_MODULE_PREFIX = "gaitbench_plugin_dir"

CONFLICT_SOURCE = "plugin conflict"
"""The ``source`` of a :class:`PluginProblem` that is a name registered twice rather than a plugin that failed."""


@dataclass(frozen=True)
class LoadedPlugin:
    """One registration together with the plugin it came from, so conflicts and listings can name it."""

    kind: str
    name: str
    description: str
    module: str
    """The plugin module's ``__name__`` (entry points) or its file path (plugin directories)."""
    factory: Callable[..., Any]


@dataclass(frozen=True)
class PluginProblem:
    """Something wrong with a plugin, kept instead of raised so the other plugins stay usable."""

    source: str
    message: str


class UnknownPluginError(LookupError):
    """A plugin kind or name that is not registered; the message lists what is available."""


class PluginConflictError(LookupError):
    """A name registered more than once within a kind; it is unusable until one plugin renames it."""


class PluginBuildError(ValueError):
    """A plugin's factory failed with something other than the errors it refuses options with (a fault of the plugin,
    or of the environment it needs): named with the plugin and the module it comes from."""


class PluginDirectoryError(Exception):
    """A missing plugin directory: a usage mistake, so it is raised rather than recorded as a problem."""


class PluginRegistry:
    """All usable plugins, looked up by kind and name.

    Names registered twice within a kind are left out and reported as a conflict: picking one silently would
    make results depend on plugin load order.
    """

    def __init__(self, plugins: Iterable[LoadedPlugin] = (), problems: Iterable[PluginProblem] = ()) -> None:
        self._problems = list(problems)
        found: dict[tuple[str, str], list[LoadedPlugin]] = {}
        for plugin in plugins:
            found.setdefault((plugin.kind, plugin.name), []).append(plugin)
        self._plugins: dict[tuple[str, str], LoadedPlugin] = {}
        self._conflicts: dict[tuple[str, str], str] = {}
        for (kind, name), candidates in found.items():
            if len(candidates) == 1:
                self._plugins[kind, name] = candidates[0]
                continue
            modules = [candidate.module for candidate in candidates]
            if len(modules) == 2:
                message = f"{kind} {name!r} is registered by both {modules[0]} and {modules[1]}; rename one"
            else:
                listed = ", ".join(modules[:-1]) + f" and {modules[-1]}"
                message = f"{kind} {name!r} is registered by {listed}; rename all but one"
            self._conflicts[kind, name] = message
            self._problems.append(PluginProblem(CONFLICT_SOURCE, message))

    @property
    def problems(self) -> list[PluginProblem]:
        """Import failures, broken hooks and conflicts, in the order they were found."""
        return list(self._problems)

    def plugins(self, kind: str | None = None) -> list[LoadedPlugin]:
        """Usable plugins (of one kind, or all), sorted by kind then name."""
        if kind is not None:
            _check_kind(kind)
        return sorted(
            (plugin for plugin in self._plugins.values() if kind is None or plugin.kind == kind),
            key=lambda plugin: (plugin.kind, plugin.name),
        )

    def names(self, kind: str) -> list[str]:
        """Sorted names of the usable plugins of one kind."""
        return [plugin.name for plugin in self.plugins(kind)]

    def get(self, kind: str, name: str) -> LoadedPlugin:
        """The plugin registered under ``kind`` and ``name``.

        Raises :class:`UnknownPluginError` (listing the available names) or :class:`PluginConflictError`.
        """
        _check_kind(kind)
        if (kind, name) in self._conflicts:
            raise PluginConflictError(self._conflicts[kind, name])
        try:
            return self._plugins[kind, name]
        except KeyError:
            available = self.names(kind)
            listing = f"available: {', '.join(available)}" if available else f"no {kind} is registered"
            raise UnknownPluginError(f"unknown {kind} {name!r}; {listing}{self._failures_note()}") from None

    @property
    def load_failures(self) -> list[PluginProblem]:
        """The problems that kept a plugin's registrations out (import failures, broken hooks), not conflicts."""
        return [problem for problem in self._problems if problem.source != CONFLICT_SOURCE]

    def _failures_note(self) -> str:
        """Why a name may be missing: the plugins that failed to load, each with its error."""
        failures = self.load_failures
        if not failures:
            return ""
        which = "1 plugin" if len(failures) == 1 else f"{len(failures)} plugins"
        listed = "; ".join(f"{problem.source}: {problem.message}" for problem in failures)
        return f"; {which} failed to load and may have registered it: {listed}"

    @overload
    def create(self, kind: Literal["experiment"], name: str, *args: Any, **kwargs: Any) -> Experiment: ...
    @overload
    def create(self, kind: Literal["model"], name: str, *args: Any, **kwargs: Any) -> BipedModel: ...
    @overload
    def create(self, kind: Literal["transcription"], name: str, *args: Any, **kwargs: Any) -> Transcription: ...
    @overload
    def create(self, kind: Literal["objective"], name: str, *args: Any, **kwargs: Any) -> Objective: ...
    @overload
    def create(self, kind: Literal["solver"], name: str, *args: Any, **kwargs: Any) -> Solver: ...
    @overload
    def create(self, kind: Literal["strategy"], name: str, *args: Any, **kwargs: Any) -> Strategy: ...
    @overload
    def create(self, kind: Literal["controller"], name: str, *args: Any, **kwargs: Any) -> Controller: ...
    @overload
    def create(self, kind: Literal["observer"], name: str, *args: Any, **kwargs: Any) -> Observer: ...
    @overload
    def create(self, kind: Literal["disturbance"], name: str, *args: Any, **kwargs: Any) -> Disturbance: ...
    @overload
    def create(self, kind: Literal["reporter"], name: str, *args: Any, **kwargs: Any) -> Reporter: ...
    @overload
    def create(self, kind: str, name: str, *args: Any, **kwargs: Any) -> Any: ...

    def create(self, kind: str, name: str, *args: Any, **kwargs: Any) -> Any:
        """Build the named plugin's object: ``get(kind, name).factory(*args, **kwargs)``.

        Typed by the kind's contract (:mod:`gaitbench.contracts`) when ``kind`` is a literal: a type checker takes
        ``create("solver", ...)`` for a :class:`~gaitbench.contracts.Solver`.
        """
        plugin = self.get(kind, name)
        try:
            return plugin.factory(*args, **kwargs)
        except (TypeError, ValueError, LookupError):
            raise  # how a factory refuses its options: the caller names the options
        except Exception as exc:
            raise PluginBuildError(f"cannot build {kind} {name!r} (from {plugin.module}): {_describe(exc)}") from exc


def load_registry(plugin_dirs: Sequence[str | Path] = (), *, use_entry_points: bool = True) -> PluginRegistry:
    """Load entry-point plugins, then the files in ``plugin_dirs`` and in ``$GAITBENCH_PLUGINS_DIR``.

    ``use_entry_points=False`` skips installed plugins, which keeps tests independent of what is installed.
    Raises :class:`PluginDirectoryError` for a missing plugin directory; every other failure is recorded in
    :attr:`PluginRegistry.problems`.
    """
    manager = pluggy.PluginManager("gaitbench")
    manager.add_hookspecs(hookspecs)
    problems: list[PluginProblem] = []
    if use_entry_points:
        _load_entry_points(manager, problems)
    for path in plugin_files(plugin_dirs):
        source = str(path)
        try:
            module = _import_file(path)
        except KeyboardInterrupt:
            raise
        except BaseException as exc:  # SystemExit too: one plugin's exit() must not end every command
            problems.append(PluginProblem(source, f"import failed: {_describe(exc)}"))
            continue
        _register(manager, module, source, problems)
    problems.extend(_unknown_hooks(manager))
    return PluginRegistry(_collect(manager, problems), problems)


def _load_entry_points(manager: pluggy.PluginManager, problems: list[PluginProblem]) -> None:
    for entry_point in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda ep: ep.name):
        try:
            plugin = entry_point.load()
        except KeyboardInterrupt:
            raise
        except BaseException as exc:  # SystemExit too, as for plugin files
            problems.append(
                PluginProblem(
                    f"entry point {entry_point.name!r} ({entry_point.value})",
                    f"import failed: {_describe(exc)}",
                )
            )
            continue
        _register(manager, plugin, entry_point.value, problems)


def plugin_files(plugin_dirs: Sequence[str | Path]) -> list[Path]:
    """Every ``*.py`` file of the given directories, then of ``$GAITBENCH_PLUGINS_DIR``, each once."""
    env_dirs = [entry for entry in os.environ.get(PLUGINS_DIR_ENV, "").split(os.pathsep) if entry]
    directories = [(Path(d), "") for d in plugin_dirs]
    directories += [(Path(d), f" (from {PLUGINS_DIR_ENV})") for d in env_dirs]
    seen: set[Path] = set()
    files: list[Path] = []
    for directory, origin in directories:
        if not directory.is_dir():
            raise PluginDirectoryError(
                f"plugin directory '{directory}'{origin} does not exist or is not a directory"
            )
        directory = directory.resolve()
        if directory in seen:
            continue
        seen.add(directory)
        files.extend(sorted(directory.glob("*.py")))
    return files


def _import_file(path: Path) -> ModuleType:
    """Import a plugin file under a module name of its own, kept in ``sys.modules`` as dataclasses need."""
    name = _module_name(path)
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot import {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module


def _module_name(path: Path) -> str:
    """``gaitbench_plugin_dir.<stem>``, numbered when another file with the same stem already took it."""
    base = f"{_DIR_MODULE_PREFIX}.{re.sub(r'[^0-9A-Za-z_]', '_', path.stem)}"
    name, number = base, 1
    while name in sys.modules and getattr(sys.modules[name], "__file__", None) != str(path):
        number += 1
        name = f"{base}_{number}"
    return name


def _register(
    manager: pluggy.PluginManager, plugin: object, source: str, problems: list[PluginProblem]
) -> None:
    if manager.is_registered(plugin):  # two entry points naming the same module: load it once
        return
    try:
        manager.register(plugin, name=source)
    except Exception as exc:  # pluggy rejects hook implementations whose arguments do not match the spec
        problems.append(PluginProblem(source, f"cannot register: {_describe(exc)}"))


def _unknown_hooks(manager: pluggy.PluginManager) -> list[PluginProblem]:
    """Hook implementations with no matching spec: usually a misspelt hook name, which would do nothing."""
    problems = []
    for name, caller in vars(manager.hook).items():
        if name.startswith("_") or caller.has_spec():
            continue
        for impl in caller.get_hookimpls():
            if not impl.optionalhook:
                message = f"implements unknown hook {name!r}; see gaitbench/hookspecs.py"
                problems.append(PluginProblem(impl.plugin_name, message))
    return problems


def _collect(manager: pluggy.PluginManager, problems: list[PluginProblem]) -> list[LoadedPlugin]:
    """Call every hook implementation on its own, so one that raises or returns garbage spoils only itself."""
    loaded = []
    for kind, hook_name in KINDS.items():
        for impl in getattr(manager.hook, hook_name).get_hookimpls():
            try:
                result = impl.function()
            except KeyboardInterrupt:
                raise
            except BaseException as exc:
                problems.append(PluginProblem(impl.plugin_name, f"{hook_name}() raised {_describe(exc)}"))
                continue
            error = _registration_error(result)
            if error:
                problems.append(PluginProblem(impl.plugin_name, f"{hook_name}() {error}"))
                continue
            loaded.extend(
                LoadedPlugin(kind, reg.name, reg.description, impl.plugin_name, reg.factory) for reg in result
            )
    return loaded


def _registration_error(result: object) -> str | None:
    if not isinstance(result, (list, tuple)):
        return f"returned {type(result).__name__}, expected a list of gaitbench.Registration"
    for item in result:
        if not isinstance(item, Registration):
            return f"returned a {type(item).__name__} in its list, expected only gaitbench.Registration"
        if not isinstance(item.name, str) or not item.name:
            return f"returned a Registration with name {item.name!r}, expected a non-empty string"
        if not callable(item.factory):
            return f"returned Registration {item.name!r} whose factory is not callable"
    return None


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise UnknownPluginError(f"unknown plugin kind {kind!r}; available: {', '.join(sorted(KINDS))}")


def _describe(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"
