"""Closed-loop tracking of a solved walk: controller, observer and disturbance plugins on the hybrid robot.

The thesis's Chapter 4 tracks its optimal gaits with computed torque and collocated partial feedback
linearization, velocity and disturbance observers, and actuator friction as the disturbance (thesis Chapter 4;
docs/model.md §9). This module is the entry point of the CLI and the suite runner: it checks a run's options, builds
the plugins and runs the loop. The pieces:

- :mod:`~gaitbench.step_info`: what every plugin call is told about the current step (the plugins'
  contracts are in :mod:`gaitbench.contracts`);
- :mod:`~gaitbench.control.reference`: the walk to follow, as twice-differentiable desired leg angles;
- :mod:`~gaitbench.control.closed_loop`: the simulation, with :mod:`~gaitbench.control.falls` and the held-foot
  dynamics of :mod:`~gaitbench.control.dynamics`;
- :mod:`~gaitbench.control.results`: per-step errors and energies, the time series, and the saved result.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import fields
from pathlib import Path
from typing import Any

from gaitbench.control.closed_loop import DEFAULT_ATOL, DEFAULT_RTOL, track
from gaitbench.control.falls import FallCriteria
from gaitbench.control.reference import load_reference
from gaitbench.control.results import TrackingResult
from gaitbench.plugins import PluginRegistry, load_registry
from gaitbench.walk_types import WalkResult

TRACKING_OPTIONS = ("controller", "observer", "disturbance", "sample_rate", "steps", "fall", "rtol", "atol")
"""The keys of :func:`track_walk`'s ``options`` (a suite's ``[tracking].options``)."""

_INJECTED = {"controller": 2, "observer": 1, "disturbance": 1}
"""How many leading arguments gaitbench passes each tracking plugin itself (model and reference; model;
experiment): the rest of its parameters are its options."""


def check_tracking_options(options: Mapping[str, Any], registry: PluginRegistry, controller: str = "thesis",
                           observer: str = "thesis", disturbance: str = "friction") -> None:
    """Raise :class:`~gaitbench.options.OptionError` for the first of ``options`` that :func:`track_walk` would
    refuse, before any walk is solved: unknown keys, the plugins' own options (their signatures and
    ``check_options`` hooks), and the values of ``sample_rate``, ``steps``, ``fall``, ``rtol`` and ``atol``.
    The option is named as a dotted path (``controller.kp``, ``fall.hip_fraction``). Unknown plugin names raise
    :class:`~gaitbench.plugins.UnknownPluginError`, as building them would."""
    from gaitbench.options import OptionError, check_options, describe, unknown_option

    for name, value in options.items():
        if name not in TRACKING_OPTIONS:
            raise unknown_option(name, TRACKING_OPTIONS)
        if name in _INJECTED or name == "fall":
            if not isinstance(value, Mapping):
                raise OptionError(name, f"expected a table of options, found {describe(value)}")
        elif name == "steps":
            if not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
                raise OptionError(name, f"expected an integer ≥ 1, found {describe(value)}")
        elif not (value is None and name == "sample_rate") and not (
                isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value) and value > 0):
            raise OptionError(name, f"expected a number > 0, found {describe(value)}")
    names = {"controller": controller, "observer": observer, "disturbance": disturbance}
    for kind, name in names.items():
        factory = registry.get(kind, name).factory
        try:
            check_options(factory, options.get(kind) or {}, kind=kind, injected=_INJECTED[kind])
        except OptionError as error:
            raise OptionError(f"{kind}.{error.option}", f"{kind} {name!r}: {error.message}") from None
    fall = dict(options.get("fall") or {})
    allowed = [item.name for item in fields(FallCriteria)]
    for name in fall:
        if name not in allowed:
            raise OptionError(f"fall.{name}", unknown_option(name, allowed).message)
    try:
        FallCriteria(**fall)
    except (TypeError, ValueError) as error:
        raise OptionError("fall", str(error)) from None


def track_walk(walk_or_path: str | Path | WalkResult, controller: str = "thesis", observer: str = "thesis",
               disturbance: str = "friction", options: dict | None = None,
               registry: PluginRegistry | None = None) -> TrackingResult:
    """Track a walk file (path to its JSON, NPZ beside it) or an in-memory :class:`WalkResult`, on the experiment
    the walk was solved for (its name and options, :attr:`WalkResult.experiment_options`).

    ``options`` may hold ``controller``, ``observer`` and ``disturbance`` (dicts of plugin options), and
    ``sample_rate`` (Hz, zero-order hold; absent or None for continuous control), ``steps`` (track only the
    first K), ``fall`` (dict of :class:`FallCriteria` fields), ``rtol`` and ``atol``. Unknown plugin names raise
    :class:`~gaitbench.plugins.UnknownPluginError`; a bad walk file raises
    :class:`~gaitbench.solve.walk_file.WalkFileError`, a walk that cannot be tracked
    :class:`~gaitbench.control.reference.TrackingInputError`.
    """
    options = dict(options or {})
    registry = registry or load_registry()
    check_tracking_options(options, registry, controller, observer, disturbance)
    reference = load_reference(walk_or_path, registry)
    experiment = reference.experiment
    plugin_options = {kind: dict(options.get(kind) or {}) for kind in ("controller", "observer", "disturbance")}
    built_controller = registry.create("controller", controller, reference.model, reference,
                                       **plugin_options["controller"])
    built_observer = registry.create("observer", observer, reference.model, **plugin_options["observer"])
    built_disturbance = registry.create("disturbance", disturbance, experiment, **plugin_options["disturbance"])
    configuration = {"controller": {"name": controller, "options": plugin_options["controller"]},
                     "observer": {"name": observer, "options": plugin_options["observer"]},
                     "disturbance": {"name": disturbance, "options": plugin_options["disturbance"]}}
    result = track(reference, built_controller, built_observer, built_disturbance,
                   sample_rate=options.get("sample_rate"), steps=options.get("steps"),
                   fall=FallCriteria(**options.get("fall", {})), rtol=options.get("rtol", DEFAULT_RTOL),
                   atol=options.get("atol", DEFAULT_ATOL), configuration=configuration)
    result.walk["source"] = None if isinstance(walk_or_path, WalkResult) else str(walk_or_path)
    return result
