"""The plugin-package template (examples/plugin-package), loaded the way an installed package is: through the
entry points its pyproject.toml declares, which gaitbench's registry loads as it loads the built-in plugins. Nothing
is installed: the package's source directory goes on sys.path, and the registry sees the declared entry points."""

from __future__ import annotations

import sys
from importlib.metadata import EntryPoint
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from gait_steps import gait_step

import gaitbench.plugins
from gaitbench.plugins import ENTRY_POINT_GROUP, load_registry
from gaitbench.solver_result import SolverStatus

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

PACKAGE = Path(__file__).parents[1] / "examples" / "plugin-package"
PROVIDED = {("solver", "example-slsqp"), ("objective", "example-positive-work"), ("reporter", "example-markdown")}


def declared_entry_points() -> list[EntryPoint]:
    project = tomllib.loads((PACKAGE / "pyproject.toml").read_text())["project"]
    return [EntryPoint(name=name, value=value, group=ENTRY_POINT_GROUP)
            for name, value in project["entry-points"][ENTRY_POINT_GROUP].items()]


@pytest.fixture
def registry(monkeypatch):
    """The built-in plugins and the package's, as `pip install -e examples/plugin-package` would make them."""
    monkeypatch.syspath_prepend(str(PACKAGE / "src"))
    installed = gaitbench.plugins.entry_points

    def entry_points(group: str):
        return [*installed(group=group), *(declared_entry_points() if group == ENTRY_POINT_GROUP else [])]

    monkeypatch.setattr(gaitbench.plugins, "entry_points", entry_points)
    yield load_registry()
    for module in [name for name in sys.modules if name.startswith("gaitbench_example")]:
        del sys.modules[module]


def test_the_package_declares_its_plugins_in_the_gaitbench_group_from_modules_it_holds():
    meta = tomllib.loads((PACKAGE / "pyproject.toml").read_text())
    assert meta["build-system"]["build-backend"] == "setuptools.build_meta"
    assert meta["tool"]["setuptools"]["packages"]["find"]["where"] == ["src"]
    for entry_point in declared_entry_points():
        module = PACKAGE / "src" / (entry_point.value.replace(".", "/") + ".py")
        assert module.is_file(), entry_point
    assert "pip install -e examples/plugin-package" in (PACKAGE / "README.md").read_text()


def test_the_registry_loads_one_plugin_of_each_kind_from_the_entry_points(registry):
    assert not [problem for problem in registry.problems if "example" in problem.source], registry.problems
    found = {(plugin.kind, plugin.name): plugin for plugin in registry.plugins()}
    assert PROVIDED <= set(found)
    for kind, name in PROVIDED:
        assert found[(kind, name)].module.startswith("gaitbench_example."), found[(kind, name)]
    assert registry.create("objective", "example-positive-work", absorbed=0.5).describe() == \
        "example-positive-work(absorbed=0.5)"
    with pytest.raises(ValueError, match="absorbed = 2"):
        registry.create("objective", "example-positive-work", absorbed=2)


def test_the_solver_reaches_ipopts_optimum_and_honours_the_shared_limits(registry):
    problem = gait_step("dmoc", 10)
    start = problem.x_star * (1 + 1e-3 * np.random.default_rng(5).standard_normal(problem.x_star.size))
    result = registry.create("solver", "example-slsqp").solve(problem.nlp, problem.parameters, start)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.objective == pytest.approx(problem.f_star, rel=1e-4)
    assert result.constraint_violation < 1e-6
    limited = registry.create("solver", "example-slsqp", max_iterations=3).solve(problem.nlp, problem.parameters,
                                                                                 problem.x0)
    assert (limited.status, limited.iterations) == (SolverStatus.ITERATION_LIMIT, 3)
    timed = registry.create("solver", "example-slsqp", time_limit_s=1e-3)
    assert timed.solve(problem.nlp, problem.parameters, problem.x0).status is SolverStatus.TIME_LIMIT


def test_the_objective_charges_positive_work_and_absorbed_work_at_its_rate(registry):
    """Hip power τ_sw (q̇_sw − q̇_st) and ankle power (τ_st + τ_sw) q̇_st, at a sample where the hip does +2 W
    and the ankle −3 W (stance leg 1: role order is leg order)."""
    free = registry.create("objective", "example-positive-work")
    braked = registry.create("objective", "example-positive-work", absorbed=0.5)
    dq, tau = np.array([[1.0, 2.0]]), np.array([[-5.0, 2.0]])  # hip 2·(2 − 1) = 2, ankle (−5 + 2)·1 = −3
    robot = np.zeros(8)
    assert free.rate(dq, tau, 1, robot) == pytest.approx([2.0])
    assert braked.rate(dq, tau, 1, robot) == pytest.approx([2.0 + 0.5 * 3.0])
    assert free.event_cost(-4.0) == 0.0 and braked.event_cost(-4.0) == pytest.approx(2.0)


def test_the_reporter_writes_the_minima_as_markdown(registry, tmp_path):
    minima = pd.DataFrame({"experiment": ["forward", "forward"], "method": ["OP-DC", "a|b"],
                           "min_acot": [0.31234, float("nan")], "N_at_min": pd.array([40, None], dtype="Int64"),
                           "N_solved": [3, 0], "N_values": [3, 3]})
    report = SimpleNamespace(title="gaitbench report: demo", tables={"acot_minima": minima})
    (path,) = registry.create("reporter", "example-markdown").write(report, tmp_path)
    assert path.read_text().splitlines()[2:] == [
        "| experiment | method | minimum ACOT | at N | N solved | N run |", "|---|---|---|---|---|---|",
        "| forward | OP-DC | 0.3123 | 40 | 3 | 3 |", "| forward | a\\|b | — | — | 0 | 3 |"]
