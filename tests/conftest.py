"""Shared fixtures: fake entry-point plugins and plugin-directory files, isolated from what is installed."""

from __future__ import annotations

import sys
import textwrap
from collections.abc import Callable, Iterator
from importlib.metadata import EntryPoint
from pathlib import Path

import pytest

import gaitbench.plugins


@pytest.fixture(autouse=True)
def _no_plugin_dirs_from_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    """A developer's own GAITBENCH_PLUGINS_DIR must not leak into the tests."""
    monkeypatch.delenv(gaitbench.plugins.PLUGINS_DIR_ENV, raising=False)


@pytest.fixture
def experiment_plugin() -> Callable[..., str]:
    """Source of a plugin registering experiments whose factories return their own name."""

    def source(*names: str) -> str:
        registrations = ", ".join(f"Registration({n!r}, 'test experiment {n}', lambda: {n!r})" for n in names)
        return (
            "from gaitbench import Registration, hookimpl\n\n\n"
            "@hookimpl\n"
            f"def register_experiments():\n    return [{registrations}]\n"
        )

    return source


@pytest.fixture
def fake_entry_points(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> Iterator[Callable[[str, str], None]]:
    """``add(module, source)`` writes a module on sys.path and makes it the next ``gaitbench`` entry point.

    Only the added entry points are visible (the installed built-in plugins are hidden), and the modules are
    removed from ``sys.modules`` afterwards so later tests can reuse their names.
    """
    site = tmp_path / "site"
    site.mkdir()
    monkeypatch.syspath_prepend(str(site))
    found: list[EntryPoint] = []

    def entry_points(group: str) -> list[EntryPoint]:
        return found if group == "gaitbench" else []

    monkeypatch.setattr(gaitbench.plugins, "entry_points", entry_points)

    def add(module: str, source: str) -> None:
        (site / f"{module}.py").write_text(textwrap.dedent(source))
        found.append(EntryPoint(name=module, value=module, group="gaitbench"))

    yield add
    for entry_point in found:
        sys.modules.pop(entry_point.value, None)


@pytest.fixture
def plugin_file(tmp_path: Path) -> Callable[..., Path]:
    """``plugin_file(stem, source, directory="plugin_dir")`` writes ``<tmp>/<directory>/<stem>.py``."""

    def write(stem: str, source: str, directory: str = "plugin_dir") -> Path:
        folder = tmp_path / directory
        folder.mkdir(exist_ok=True)
        path = folder / f"{stem}.py"
        path.write_text(textwrap.dedent(source))
        return path

    return write
