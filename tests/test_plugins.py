"""The plugin registry: loading from entry points and plugin directories, and surviving broken plugins."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from gaitbench.plugins import (
    KINDS,
    LoadedPlugin,
    PluginBuildError,
    PluginConflictError,
    PluginDirectoryError,
    PluginProblem,
    PluginRegistry,
    UnknownPluginError,
    load_registry,
)

REPO = Path(__file__).resolve().parents[1]

SOLVER_PLUGIN = """
    from gaitbench import Registration, hookimpl

    @hookimpl
    def register_solvers():
        return [Registration("toy-solver", "a solver", lambda **options: ("solver", options))]
"""


def _problem_text(registry: PluginRegistry) -> str:
    return "\n".join(f"{p.source}: {p.message}" for p in registry.problems)


def test_entry_point_plugins_load(fake_entry_points, experiment_plugin):
    fake_entry_points("ep_experiments", experiment_plugin("flat", "hill"))
    fake_entry_points("ep_solvers", SOLVER_PLUGIN)

    registry = load_registry()

    assert registry.problems == []
    assert [(p.kind, p.name, p.module) for p in registry.plugins()] == [
        ("experiment", "flat", "ep_experiments"),
        ("experiment", "hill", "ep_experiments"),
        ("solver", "toy-solver", "ep_solvers"),
    ]
    assert registry.get("experiment", "hill").description == "test experiment hill"
    assert registry.create("experiment", "flat") == "flat"
    assert registry.create("solver", "toy-solver", tol=1e-8) == ("solver", {"tol": 1e-8})


def test_use_entry_points_false_skips_installed_plugins(fake_entry_points, experiment_plugin):
    fake_entry_points("ep_experiments", experiment_plugin("flat"))

    assert load_registry(use_entry_points=False).plugins() == []


def test_plugin_dir_file_registers_an_experiment(plugin_file, experiment_plugin):
    path = plugin_file("my_walks", experiment_plugin("my-walk"))

    registry = load_registry([path.parent], use_entry_points=False)

    plugin = registry.get("experiment", "my-walk")
    assert plugin.module == str(path.resolve())
    assert plugin.kind == "experiment"
    assert registry.create("experiment", "my-walk") == "my-walk"


def test_a_factory_that_fails_is_named_with_its_plugin_and_a_refused_option_is_left_to_the_caller(plugin_file):
    path = plugin_file("fragile", """
        from gaitbench import Registration, hookimpl

        def broken(**options):
            if options:
                raise TypeError(f"unexpected options {sorted(options)}")
            raise RuntimeError("no licence for the solver it needs")

        @hookimpl
        def register_experiments():
            return [Registration("fragile", "fails to build", broken)]
    """)
    registry = load_registry([path.parent], use_entry_points=False)
    with pytest.raises(PluginBuildError, match=r"cannot build experiment 'fragile' \(from .*fragile\.py\): "
                                                r"RuntimeError: no licence"):
        registry.create("experiment", "fragile")
    with pytest.raises(TypeError, match="unexpected options"):
        registry.create("experiment", "fragile", bogus=1)


def test_plugin_dirs_from_environment_variable(plugin_file, experiment_plugin, monkeypatch):
    first = plugin_file("a", experiment_plugin("from-a"), directory="one")
    second = plugin_file("b", experiment_plugin("from-b"), directory="two")
    monkeypatch.setenv("GAITBENCH_PLUGINS_DIR", os.pathsep.join([str(first.parent), str(second.parent)]))

    registry = load_registry(use_entry_points=False)

    assert registry.names("experiment") == ["from-a", "from-b"]


def test_same_directory_given_twice_is_loaded_once(plugin_file, experiment_plugin, monkeypatch):
    path = plugin_file("walks", experiment_plugin("walk"))
    monkeypatch.setenv("GAITBENCH_PLUGINS_DIR", str(path.parent))

    registry = load_registry([path.parent], use_entry_points=False)

    assert registry.problems == []
    assert registry.names("experiment") == ["walk"]


def test_files_with_the_same_name_in_two_directories_both_load(plugin_file, experiment_plugin):
    first = plugin_file("walks", experiment_plugin("walk-one"), directory="one")
    second = plugin_file("walks", experiment_plugin("walk-two"), directory="two")

    registry = load_registry([first.parent, second.parent], use_entry_points=False)

    assert registry.problems == []
    assert registry.get("experiment", "walk-one").module == str(first.resolve())
    assert registry.get("experiment", "walk-two").module == str(second.resolve())
    loaded = {getattr(module, "__file__", None) for module in sys.modules.values()}
    assert {str(first.resolve()), str(second.resolve())} <= loaded  # neither evicted the other


def test_missing_plugin_dir_is_an_error_naming_it(tmp_path, monkeypatch):
    missing = tmp_path / "no-such-dir"
    with pytest.raises(PluginDirectoryError, match="no-such-dir"):
        load_registry([missing], use_entry_points=False)

    monkeypatch.setenv("GAITBENCH_PLUGINS_DIR", str(missing))
    with pytest.raises(PluginDirectoryError, match="no-such-dir.*GAITBENCH_PLUGINS_DIR"):
        load_registry(use_entry_points=False)


def test_plugins_that_fail_to_import_are_problems_and_others_still_load(
    fake_entry_points, plugin_file, experiment_plugin
):
    fake_entry_points("ep_broken", "import no_such_module_for_gaitbench_tests\n")
    fake_entry_points("ep_good", experiment_plugin("good-ep"))
    broken_file = plugin_file("broken_file", "def oops(:\n")
    plugin_file("good_file", experiment_plugin("good-file"))

    registry = load_registry([broken_file.parent])

    assert registry.names("experiment") == ["good-ep", "good-file"]
    problems = {p.source: p.message for p in registry.problems}
    entry_point = "entry point 'ep_broken' (ep_broken)"
    assert set(problems) == {entry_point, str(broken_file.resolve())}
    assert "No module named 'no_such_module_for_gaitbench_tests'" in problems[entry_point]
    assert "SyntaxError" in problems[str(broken_file.resolve())]


def test_plugins_that_exit_at_import_are_problems_and_others_still_load(
    fake_entry_points, plugin_file, experiment_plugin
):
    fake_entry_points("ep_exits", "import sys\nsys.exit('no licence server')\n")
    fake_entry_points("ep_good", experiment_plugin("good-ep"))
    exiting_file = plugin_file("exiting_file", "raise SystemExit(3)\n")
    plugin_file("good_file", experiment_plugin("good-file"))

    registry = load_registry([exiting_file.parent])

    assert registry.names("experiment") == ["good-ep", "good-file"]
    problems = {p.source: p.message for p in registry.problems}
    assert problems == {"entry point 'ep_exits' (ep_exits)": "import failed: SystemExit: no licence server",
                        str(exiting_file.resolve()): "import failed: SystemExit: 3"}


def test_a_keyboard_interrupt_at_plugin_import_is_not_swallowed(plugin_file):
    interrupting = plugin_file("interrupting", "raise KeyboardInterrupt\n")

    with pytest.raises(KeyboardInterrupt):
        load_registry([interrupting.parent], use_entry_points=False)


def test_hook_that_raises_is_a_problem_and_others_still_load(fake_entry_points, experiment_plugin):
    fake_entry_points(
        "ep_raises",
        """
        from gaitbench import hookimpl

        @hookimpl
        def register_experiments():
            raise RuntimeError("boom")
        """,
    )
    fake_entry_points("ep_good", experiment_plugin("good"))

    registry = load_registry()

    assert registry.names("experiment") == ["good"]
    assert registry.problems == [
        PluginProblem("ep_raises", "register_experiments() raised RuntimeError: boom"),
    ]


@pytest.mark.parametrize(
    "returned, expected",
    [
        ("None", "returned NoneType, expected a list of gaitbench.Registration"),
        ("['forward']", "returned a str in its list"),
        ("[Registration('', 'no name', dict)]", "name ''"),
        ("[Registration('x', 'no factory', None)]", "factory is not callable"),
    ],
)
def test_hook_returning_something_else_than_registrations_is_a_problem(
    fake_entry_points, experiment_plugin, returned, expected
):
    fake_entry_points(
        "ep_bad_return",
        f"""
        from gaitbench import Registration, hookimpl

        @hookimpl
        def register_experiments():
            return {returned}
        """,
    )
    fake_entry_points("ep_good", experiment_plugin("good"))

    registry = load_registry()

    assert registry.names("experiment") == ["good"]
    [problem] = registry.problems
    assert problem.source == "ep_bad_return"
    assert expected in problem.message


def test_misspelt_hook_is_a_problem(fake_entry_points):
    fake_entry_points(
        "ep_typo",
        """
        from gaitbench import Registration, hookimpl

        @hookimpl
        def register_experiment():
            return [Registration("lost", "never registered", dict)]
        """,
    )

    registry = load_registry()

    assert registry.plugins() == []
    assert registry.problems == [
        PluginProblem("ep_typo", "implements unknown hook 'register_experiment'; see gaitbench/hookspecs.py")
    ]


def test_hook_with_arguments_the_spec_lacks_is_a_problem(plugin_file, experiment_plugin):
    bad = plugin_file(
        "wants_robot",
        """
        from gaitbench import hookimpl

        @hookimpl
        def register_experiments(robot):
            return []
        """,
    )
    plugin_file("good", experiment_plugin("good"))

    registry = load_registry([bad.parent], use_entry_points=False)

    assert registry.names("experiment") == ["good"]
    [problem] = registry.problems
    assert problem.source == str(bad.resolve())
    assert "cannot register" in problem.message and "'robot'" in problem.message


def test_duplicate_kind_and_name_is_a_conflict_naming_both_modules(
    fake_entry_points, plugin_file, experiment_plugin
):
    fake_entry_points("ep_thesis", experiment_plugin("forward", "only-in-thesis"))
    fake_entry_points("ep_solvers", SOLVER_PLUGIN)
    path = plugin_file("mine", experiment_plugin("forward", "only-in-mine"))

    registry = load_registry([path.parent])

    message = f"experiment 'forward' is registered by both ep_thesis and {path.resolve()}; rename one"
    assert registry.problems == [PluginProblem("plugin conflict", message)]
    with pytest.raises(PluginConflictError) as error:
        registry.get("experiment", "forward")
    assert str(error.value) == message
    assert registry.names("experiment") == ["only-in-mine", "only-in-thesis"]
    assert registry.create("experiment", "only-in-thesis") == "only-in-thesis"
    assert registry.get("solver", "toy-solver").module == "ep_solvers"


def test_same_name_in_different_kinds_is_not_a_conflict():
    registry = PluginRegistry(
        [LoadedPlugin("experiment", "x", "", "a", dict), LoadedPlugin("solver", "x", "", "b", dict)]
    )

    assert registry.problems == []
    assert registry.get("solver", "x").module == "b"


def test_conflict_between_three_plugins_names_all_of_them():
    registry = PluginRegistry([LoadedPlugin("model", "m", "", module, dict) for module in ("a", "b", "c")])

    assert [p.message for p in registry.problems] == [
        "model 'm' is registered by a, b and c; rename all but one"
    ]


def test_unknown_name_lists_the_available_names():
    registry = PluginRegistry(
        [LoadedPlugin("experiment", name, "", "m", dict) for name in ("stairs", "forward", "compass-gait")]
    )

    with pytest.raises(UnknownPluginError) as error:
        registry.get("experiment", "fwd")

    assert isinstance(error.value, LookupError)
    assert str(error.value) == "unknown experiment 'fwd'; available: compass-gait, forward, stairs"
    with pytest.raises(UnknownPluginError, match="unknown solver 'ipopt'; no solver is registered"):
        registry.create("solver", "ipopt")


def test_unknown_name_names_the_plugins_that_failed_to_load(plugin_file, experiment_plugin):
    """A name that a broken plugin would have registered: the error says which plugin failed and why."""
    broken = plugin_file("gentle_slope", "raise ImportError('half-finished plugin')\n")
    plugin_file("flat", experiment_plugin("flat"))
    registry = load_registry([broken.parent], use_entry_points=False)

    with pytest.raises(UnknownPluginError) as error:
        registry.get("experiment", "gentle-slope")

    assert str(error.value) == (
        "unknown experiment 'gentle-slope'; available: flat; 1 plugin failed to load and may have registered it: "
        f"{broken.resolve()}: import failed: ImportError: half-finished plugin")
    assert registry.load_failures == registry.problems


def test_a_conflict_is_not_a_load_failure():
    registry = PluginRegistry([LoadedPlugin("model", "m", "", module, dict) for module in ("a", "b")])

    assert registry.load_failures == [] and len(registry.problems) == 1
    with pytest.raises(UnknownPluginError) as error:
        registry.get("model", "n")
    assert "failed to load" not in str(error.value)


def test_unknown_kind_lists_the_kinds():
    with pytest.raises(UnknownPluginError) as error:
        PluginRegistry().names("experiments")

    assert str(error.value) == f"unknown plugin kind 'experiments'; available: {', '.join(sorted(KINDS))}"


def test_plugins_are_sorted_by_kind_then_name():
    registry = PluginRegistry(
        LoadedPlugin(kind, name, "", "m", dict)
        for kind, name in [("solver", "b"), ("experiment", "z"), ("solver", "a"), ("experiment", "a")]
    )

    assert [(p.kind, p.name) for p in registry.plugins()] == [
        ("experiment", "a"), ("experiment", "z"), ("solver", "a"), ("solver", "b"),
    ]
    assert [p.name for p in registry.plugins("solver")] == ["a", "b"]


def test_every_kind_is_collected_from_its_hook(fake_entry_points):
    hooks = "\n".join(
        f"@hookimpl\ndef {hook}():\n    return [Registration('{kind}-one', '', dict)]\n"
        for kind, hook in KINDS.items()
    )
    fake_entry_points("ep_everything", f"from gaitbench import Registration, hookimpl\n\n{hooks}")

    registry = load_registry()

    assert registry.problems == []
    assert {kind: registry.names(kind) for kind in KINDS} == {kind: [f"{kind}-one"] for kind in KINDS}


def test_example_plugin_builds_its_experiment():
    registry = load_registry([REPO / "examples" / "plugins"], use_entry_points=False)

    assert registry.problems == []
    assert registry.create("experiment", "gentle-slope").name == "gentle-slope"


def test_importing_gaitbench_stays_light():
    heavy = ("casadi", "plugins", "gaitbench.plugins")
    code = f"import sys, gaitbench; print(sorted(m for m in {heavy} if m in sys.modules))"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)

    assert result.stdout.strip() == "[]"


def test_builtin_experiments_are_registered():
    registry = load_registry()

    assert {"forward", "downward-slope", "upward-slope", "stairs", "compass-gait"} <= set(
        registry.names("experiment")
    ), _problem_text(registry)
