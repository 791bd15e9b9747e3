"""The layout is the architecture (docs/architecture.md): packages import only the layers below them, the core never
imports a plugin, no two packages and no two modules import each other, and no module outgrows one concept.

Every check reads the source with :mod:`ast`: relative imports are resolved against their package,
``importlib.import_module("...")`` / ``__import__("...")`` with a literal name count as imports, and so do imports
under ``if TYPE_CHECKING:`` (a name in an annotation ties two packages as much as a call does). Each check also says
how many modules it read, and the tests compare that with the package that is actually imported, so a check that
finds no files fails instead of passing.
"""

from __future__ import annotations

import ast
import functools
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

import gaitbench

ROOT = Path(__file__).resolve().parents[1]

LAYERS = ["model", "problem", "contracts", "solve", "control", "run", "reports", "cli"]
"""Bottom to top: each package may import the ones before it, never one after. ``contracts`` is every module at the
top of ``gaitbench/``: the plugin contracts, the values they name (the walk a strategy solves included), the
registry that builds plugins to them, and the option checks; it names the model's and problem's value classes and
is what solving and everything above it programs against."""

FACADE = "gaitbench"
"""The package face (``gaitbench/__init__.py``) re-exports for users, so it may reach any layer (lazily)."""

PLUGINS = "gaitbench_plugins"
"""The import name of the built-in plugins, whose folder is ``plugins/`` (pyproject.toml's package-dir)."""

MIN_CORE_MODULES = 80
"""A floor under the number of core modules a check reads (the core has more); the exact count is compared with the
imported package's own files."""

MAX_LINES = 500

_DYNAMIC_IMPORTS = {"import_module", "__import__"}


@dataclass(frozen=True)
class Module:
    name: str
    path: Path
    is_package: bool

    @property
    def package(self) -> str:
        """The package a relative import in this module starts from."""
        return self.name if self.is_package else self.name.rpartition(".")[0]


@dataclass(frozen=True)
class Arrow:
    source: Module
    target: str
    line: int
    takes_names: bool = False
    """The module of a ``from ... import`` statement, whose names have arrows of their own (each to the name, or to
    the submodule of that name)."""

    def __str__(self) -> str:
        return f"{self.source.path.name}:{self.line} ({self.source.name}) imports {self.target}"


def modules(root: Path, top: str, name: str | None = None) -> list[Module]:
    """Every module of the package in the folder ``top`` under ``root``, named as imported (``name``, by default
    the folder's)."""
    found = []
    for path in sorted((root / top).rglob("*.py")):
        parts = (name or top, *path.relative_to(root / top).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        found.append(Module(".".join(parts[:-1] if is_package else parts), path, is_package))
    return found


def _absolute(module: Module, node: ast.ImportFrom) -> str:
    """The module a ``from ... import`` names, relative imports resolved against the importing module's package."""
    if node.level == 0:
        return node.module or ""
    base = module.package.split(".")
    base = base[:len(base) - (node.level - 1)] if node.level > 1 else base
    return ".".join([*base, *([node.module] if node.module else [])])


def _dynamic_target(node: ast.Call) -> str | None:
    """The module ``importlib.import_module(...)`` or ``__import__(...)`` loads, when its name is written in the
    source (a literal, or the literal start of an f-string)."""
    function = node.func
    name = function.attr if isinstance(function, ast.Attribute) else getattr(function, "id", None)
    if name not in _DYNAMIC_IMPORTS or not node.args:
        return None
    first = node.args[0]
    if isinstance(first, ast.Constant) and isinstance(first.value, str):
        return first.value
    if isinstance(first, ast.JoinedStr) and first.values and isinstance(first.values[0], ast.Constant):
        return str(first.values[0].value).rstrip(".") or None
    return None


@functools.cache
def imports(module: Module) -> list[Arrow]:
    """Every module a file imports, at top level, inside a function (a lazy import is still an arrow) or for type
    checking, relative and dynamic imports included."""
    tree = ast.parse(module.path.read_text(), filename=str(module.path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [Arrow(module, alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            target = _absolute(module, node)
            found.append(Arrow(module, target, node.lineno, takes_names=True))
            found += [Arrow(module, f"{target}.{alias.name}", node.lineno) for alias in node.names]
        elif isinstance(node, ast.Call) and (target := _dynamic_target(node)):
            found.append(Arrow(module, target, node.lineno))
    return found


def _layer(module: str) -> str | None:
    parts = module.split(".")
    if parts[0] != "gaitbench" or module == FACADE:
        return None
    return parts[1] if len(parts) > 1 and parts[1] in LAYERS else "contracts"


def _room(module: str) -> str | None:
    """The package a module belongs to in the structure: a core layer, or one built-in plugin."""
    parts = module.split(".")
    if parts[0] == "gaitbench":
        return None if module == FACADE else f"gaitbench:{_layer(module)}"
    if parts[0] == PLUGINS and len(parts) > 1:
        return ".".join(parts[:3])
    return None


def core_imports_plugin(core: list[Module]) -> list[str]:
    return [str(arrow) for module in core for arrow in imports(module) if arrow.target.split(".")[0] == PLUGINS]


def upward_imports(core: list[Module]) -> list[str]:
    upward = []
    for module in core:
        source = _layer(module.name)
        if source is None:
            continue
        for arrow in imports(module):
            layer = _layer(arrow.target)
            if layer is not None and LAYERS.index(layer) > LAYERS.index(source):
                upward.append(f"{arrow} ({source} -> {layer})")
    return upward


def plugins_reaching_other_plugins(plugins: list[Module]) -> list[str]:
    offenders = []
    for module in plugins:
        own = ".".join(module.name.split(".")[:3])  # gaitbench_plugins.<kind>.<plugin>
        offenders += [str(arrow) for arrow in imports(module)
                      if arrow.target.split(".")[0] == PLUGINS and not (arrow.target + ".").startswith(own + ".")]
    return offenders


def _strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """The groups of nodes that reach one another round a circle: the strongly connected components of ``graph``
    (every target a key too) with more than one member, found by Tarjan's algorithm."""
    order: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found = []

    def visit(node: str) -> None:
        order[node] = low[node] = len(order)
        stack.append(node)
        for target in sorted(graph[node]):
            if target not in order:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in stack:
                low[node] = min(low[node], order[target])
        if low[node] == order[node]:
            component = []
            while (member := stack.pop()) != node:
                component.append(member)
            if component:
                found.append(sorted([node, *component]))

    for node in sorted(graph):
        if node not in order:
            visit(node)
    return found


def circles(all_modules: list[Module]) -> list[list[str]]:
    """The groups of packages (core layers and built-in plugins) that import one another, directly or round a
    circle."""
    graph: dict[str, set[str]] = {}
    for module in all_modules:
        source = _room(module.name)
        if source is None:
            continue
        graph.setdefault(source, set())
        for arrow in imports(module):
            target = _room(arrow.target)
            if target is not None and target != source:
                graph[source].add(target)
                graph.setdefault(target, set())
    return _strongly_connected(graph)


def module_circles(all_modules: list[Module]) -> list[list[str]]:
    """The groups of modules (files) that import one another, directly or round a circle: within a layer or a plugin,
    where :func:`circles` sees one package. An imported name counts as an arrow to the module that defines it, or to
    the submodule of that name; the package face is left out, as in :func:`circles`."""
    names = {module.name for module in all_modules} - {FACADE}
    graph: dict[str, set[str]] = {name: set() for name in names}
    for module in all_modules:
        if module.name not in names:
            continue
        for arrow in imports(module):
            if arrow.takes_names:
                continue
            target = _longest_known(arrow.target, names)
            if target is not None and target != module.name:
                graph[module.name].add(target)
    return _strongly_connected(graph)


def _longest_known(target: str, names: set[str]) -> str | None:
    """The module of ``names`` that an imported ``target`` (a module, or a name in one) lies in, or None."""
    parts = target.split(".")
    return next((".".join(parts[:n]) for n in range(len(parts), 0, -1) if ".".join(parts[:n]) in names), None)


def too_long(root: Path) -> list[str]:
    return [f"{path.relative_to(root)}: {n} lines" for path in sorted(root.glob("*/**/*.py"))
            if path.parts[len(root.parts)] in ("gaitbench", "plugins", "benchmarks")
            and (n := len(path.read_text().splitlines())) > MAX_LINES]


@pytest.fixture(scope="module")
def tree() -> tuple[list[Module], list[Module]]:
    return modules(ROOT, "gaitbench"), modules(ROOT, "plugins", PLUGINS)


def test_the_checks_read_every_core_module(tree):
    core, plugins = tree
    expected = sum(1 for _ in Path(gaitbench.__file__).parent.rglob("*.py"))
    assert len(core) == expected, f"read {len(core)} core modules under {ROOT}, the imported package has {expected}"
    assert len(core) >= MIN_CORE_MODULES
    assert plugins, f"no plugin modules under {ROOT}"


def test_the_core_never_imports_a_plugin(tree):
    offenders = core_imports_plugin(tree[0])
    assert not offenders, offenders


def test_each_package_imports_only_the_layers_below_it(tree):
    upward = upward_imports(tree[0])
    assert not upward, upward


def test_no_packages_import_each_other(tree):
    core, plugins = tree
    found = circles(core + plugins)
    assert not found, found


def test_no_modules_import_each_other(tree):
    core, plugins = tree
    found = module_circles(core + plugins)
    assert not found, found


def test_plugins_use_each_other_only_through_the_core(tree):
    offenders = plugins_reaching_other_plugins(tree[1])
    assert not offenders, offenders


def test_no_module_outgrows_one_concept():
    long = too_long(ROOT)
    assert not long, long


def _replace(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text, f"{old!r} not in {path}"
    path.write_text(text.replace(old, new, 1))


def _import_plugin_from_core(root: Path) -> None:
    _replace(root / "gaitbench" / "model" / "terrain.py", "from __future__ import annotations\n",
             "from __future__ import annotations\n\nimport importlib\n\n"
             "_SOLVER = importlib.import_module(\"gaitbench_plugins.solvers.sqp\")\n")


def _move_the_test_deeper(root: Path) -> None:
    deeper = root / "tests" / "deeper"
    deeper.mkdir()
    (root / "tests" / "test_architecture.py").rename(deeper / "test_architecture.py")


def _import_the_cli_from_the_model(root: Path) -> None:
    _replace(root / "gaitbench" / "model" / "robot.py", "from __future__ import annotations\n",
             "from __future__ import annotations\n\nfrom ..cli import main  # noqa: F401\n")


def _close_a_circle_of_modules(root: Path) -> None:
    """The thresholds name the walk's values, which name the thresholds: within one layer, so only the module check
    sees it, and under ``if TYPE_CHECKING:``, which counts as well."""
    _replace(root / "gaitbench" / "acceptance.py", "from __future__ import annotations\n",
             "from __future__ import annotations\n\nfrom typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n"
             "    from gaitbench.walk_types import WalkResult  # noqa: F401\n")


MUTATIONS = {
    "relative import of the CLI in the model": (_import_the_cli_from_the_model,
                                                "test_each_package_imports_only_the_layers_below_it"),
    "importlib loads a plugin in the core": (_import_plugin_from_core, "test_the_core_never_imports_a_plugin"),
    "the test moved a folder deeper": (_move_the_test_deeper, "test_the_checks_read_every_core_module"),
    "a circle of modules within a layer": (_close_a_circle_of_modules, "test_no_modules_import_each_other"),
}
"""Each way to break the tree, and the test that must catch it."""


@pytest.mark.parametrize("mutation", sorted(MUTATIONS))
def test_the_checks_fail_on_a_broken_copy_of_the_tree(tmp_path, mutation):
    """Each mutation breaks the architecture (or the test's view of it) in a copy of the tree; the import checks of
    this file, run on that copy in their own process, pass on the unbroken copy and fail on the broken one."""
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for top in ("gaitbench", "plugins"):
        shutil.copytree(ROOT / top, tmp_path / top, ignore=ignore)
    (tmp_path / "tests").mkdir()
    shutil.copy(Path(__file__), tmp_path / "tests" / "test_architecture.py")

    def run() -> subprocess.CompletedProcess:
        test = next((tmp_path / "tests").rglob("test_architecture.py"))
        return subprocess.run([sys.executable, "-m", "pytest", str(test), "-q", "-rf", "-p", "no:cacheprovider",
                               "-k", "not broken_copy and not outgrows"], cwd=tmp_path, capture_output=True, text=True,
                              env={**os.environ, "PYTHONPATH": str(tmp_path)}, timeout=120)

    before = run()
    assert before.returncode == 0, before.stdout + before.stderr
    mutate, catcher = MUTATIONS[mutation]
    mutate(tmp_path)
    after = run()
    assert after.returncode == 1, after.stdout + after.stderr
    test = next((tmp_path / "tests").rglob("test_architecture.py")).relative_to(tmp_path)
    assert f"FAILED {test.as_posix()}::{catcher}" in after.stdout, after.stdout
