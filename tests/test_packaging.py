"""What pyproject.toml installs: every package of the source tree, the built-in plugins under gaitbench's own
import name, and the entry points naming modules that exist."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
CONFIG = tomllib.loads((ROOT / "pyproject.toml").read_text())


def _installed_name(folder: Path) -> str:
    """The import name of a package folder, under pyproject's package-dir mapping."""
    parts = folder.relative_to(ROOT).parts
    mapping = {path: name for name, path in CONFIG["tool"]["setuptools"]["package-dir"].items()}
    return ".".join((mapping.get(parts[0], parts[0]), *parts[1:]))


def test_every_package_folder_is_installed():
    folders = [init.parent for top in ("gaitbench", "plugins") for init in (ROOT / top).rglob("__init__.py")]
    assert sorted(CONFIG["tool"]["setuptools"]["packages"]) == sorted(_installed_name(f) for f in folders)


def test_the_built_in_plugins_install_under_gaitbench_s_name():
    assert CONFIG["tool"]["setuptools"]["package-dir"] == {"gaitbench_plugins": "plugins"}
    entry_points = CONFIG["project"]["entry-points"]["gaitbench"]
    assert all(module.startswith("gaitbench_plugins.") for module in entry_points.values())
    for module in entry_points.values():
        assert importlib.util.find_spec(module) is not None, module
