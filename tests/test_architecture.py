"""The layout is the architecture (docs/architecture.md): packages import only the layers below them, the core never
imports a plugin, and no module outgrows one concept."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

LAYERS = ["spine", "model", "problem", "contracts", "solve", "control", "run", "reports", "cli"]
"""Bottom to top: each package may import the ones before it, never one after. ``contracts`` (one module) names the
model's and problem's value classes and is what solving and everything above it programs against."""

FACADE = "gaitbench"
"""The package face (``gaitbench/__init__.py``) re-exports for users, so it may reach any layer (lazily)."""

MAX_LINES = 500


def _layer(module: str) -> str | None:
    parts = module.split(".")
    if parts[0] != "gaitbench" or module == FACADE:
        return None
    return parts[1] if len(parts) > 1 and parts[1] in LAYERS[1:] else "spine"


def _core_modules() -> list[tuple[str, Path]]:
    modules = []
    for path in sorted((ROOT / "gaitbench").rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        modules.append((name, path))
    return modules


def _type_only(tree: ast.Module) -> set[ast.AST]:
    """The nodes under ``if TYPE_CHECKING:``: names for annotations, not arrows a running program follows."""
    return {node for block in ast.walk(tree)
            if isinstance(block, ast.If) and isinstance(block.test, ast.Name) and block.test.id == "TYPE_CHECKING"
            for statement in block.body for node in ast.walk(statement)}


def _imports(path: Path) -> list[str]:
    """Every module a file imports at run time, at top level or inside a function (a lazy import is still an
    arrow)."""
    found = []
    tree = ast.parse(path.read_text(), filename=str(path))
    type_only = _type_only(tree)
    for node in ast.walk(tree):
        if node in type_only:
            continue
        if isinstance(node, ast.Import):
            found += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.append(node.module)
            found += [f"{node.module}.{alias.name}" for alias in node.names]
    return found


def test_the_core_never_imports_a_plugin():
    offenders = [f"{path.relative_to(ROOT)} imports {target}" for _, path in _core_modules()
                 for target in _imports(path) if target.split(".")[0] == "plugins"]
    assert not offenders, offenders


def test_each_package_imports_only_the_layers_below_it():
    upward = []
    for name, path in _core_modules():
        source = _layer(name)
        if source is None:
            continue
        for target in _imports(path):
            layer = _layer(target)
            if layer is not None and LAYERS.index(layer) > LAYERS.index(source):
                upward.append(f"{path.relative_to(ROOT)} ({source}) imports {target} ({layer})")
    assert not upward, upward


def test_plugins_use_each_other_only_through_the_core():
    offenders = []
    for path in sorted((ROOT / "plugins").rglob("*.py")):
        own = path.relative_to(ROOT).parts[:3]  # plugins/<kind>/<plugin>[.py | /...]
        own_module = ".".join(own).removesuffix(".py")
        for target in _imports(path):
            if target.split(".")[0] == "plugins" and not (target + ".").startswith(own_module + "."):
                offenders.append(f"{path.relative_to(ROOT)} imports {target}")
    assert not offenders, offenders


def test_no_module_outgrows_one_concept():
    long = [f"{path.relative_to(ROOT)}: {n} lines" for path in sorted(ROOT.glob("*/**/*.py"))
            if path.parts[len(ROOT.parts)] in ("gaitbench", "plugins", "benchmarks")
            and (n := len(path.read_text().splitlines())) > MAX_LINES]
    assert not long, long
