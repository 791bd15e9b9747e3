"""Plugin contracts: every kind has one, and every built-in and example plugin keeps to it."""

from __future__ import annotations

import inspect
import re
from pathlib import Path
from typing import get_args, get_overloads

import numpy as np
import pytest

import gaitbench.hookspecs as hookspecs
from gaitbench.contracts import CONTRACTS, Observer, contract_violations
from gaitbench.hookspecs import Kind
from gaitbench.plugins import KINDS, LoadedPlugin, PluginRegistry, load_registry

REGISTRY = load_registry()
EXAMPLES = load_registry([Path(__file__).resolve().parents[1] / "examples" / "plugins"], use_entry_points=False)


def _built(plugin: LoadedPlugin) -> object:
    """The class a factory instantiates, or, for a factory function, what it builds (the cheap ones need only a
    robot at most)."""
    if isinstance(plugin.factory, type):
        return plugin.factory
    args = (REGISTRY.create("experiment", "forward").robot,) if plugin.kind == "model" else ()
    return plugin.factory(*args)


def test_every_kind_has_a_contract():
    assert list(CONTRACTS) == list(KINDS) == list(get_args(Kind))


def test_every_kind_has_its_hook_and_no_hook_lacks_a_kind():
    declared = {name for name, hook in vars(hookspecs).items() if hasattr(hook, "gaitbench_spec")}
    assert declared == set(KINDS.values())
    assert len(declared) == len(KINDS)


def test_create_is_typed_with_each_kind_s_contract():
    """The typed overloads of ``PluginRegistry.create`` (written out for type checkers) return each kind's
    contract, for every kind."""
    typed = {}
    for overload in get_overloads(PluginRegistry.create):
        annotations = inspect.get_annotations(overload)
        if literal := re.fullmatch(r"Literal\[[\"'](\w+)[\"']\]", annotations["kind"]):
            typed[literal[1]] = annotations["return"]
    assert typed == {kind: contract.__name__ for kind, contract in CONTRACTS.items()}


@pytest.mark.parametrize("plugin", REGISTRY.plugins() + EXAMPLES.plugins(),
                         ids=lambda plugin: f"{plugin.kind}-{plugin.name}")
def test_plugin_keeps_to_its_kinds_contract(plugin):
    assert contract_violations(plugin.kind, _built(plugin)) == []


def test_plugins_were_found():
    assert not REGISTRY.problems and not EXAMPLES.problems
    assert {plugin.kind for plugin in REGISTRY.plugins()} == set(KINDS)


def test_an_object_of_a_value_kind_must_be_an_instance():
    assert contract_violations("experiment", object()) == ["is not a gaitbench.model.experiment.Experiment"]
    assert contract_violations("objective", dict) == ["is not a gaitbench.problem.objective.Objective"]


class _Drifted:
    """An observer gone wrong in every way the check catches: no ``size``, and two changed signatures."""

    def reset(self, q, dq, velocity, disturbance, step):  # keeps to the contract
        return np.zeros(2)

    def estimate(self, state, q):  # lost a parameter
        return np.zeros(2), np.zeros(2)

    def derivative(self, state, q, dq, tau, step, gain):  # requires one more
        return np.zeros(2)


def test_missing_members_and_changed_signatures_are_violations():
    assert contract_violations("observer", _Drifted) == [
        "has no 'size'",
        "estimate(): takes (state, q), the contract (state, q, dq)",
        "derivative(): requires gain beyond the contract's parameters",
    ]
    assert not isinstance(_Drifted(), Observer)


def test_optional_extra_parameters_and_instances_conform():
    class Patient:
        size = 0

        def reset(self, q, dq, velocity, disturbance, step, *, scale=1.0):
            return np.zeros(0)

        def estimate(self, state, q, dq, extra=None):
            return np.zeros(2), np.zeros(2)

        def derivative(self, state, q, dq, tau, step):
            return np.zeros(0)

    assert contract_violations("observer", Patient) == []
    assert contract_violations("observer", Patient()) == []
    assert isinstance(Patient(), Observer)
